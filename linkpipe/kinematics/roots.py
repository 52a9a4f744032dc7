"""Newton's method on whole batches of steps, and what rescues or classifies a step it fails on
(polishing to rounding level, the mirror root, deflated Newton, damped least squares)."""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..status import NO_ASSEMBLY, NOT_CONVERGED
from .linalg import MODE_SETTLED_BELOW, condition, is_singular, lin_solve
from .step import _step_kernels


def newton(model: Model, q: np.ndarray, s: np.ndarray, tol_abs: float, max_iter: int,
           jacobian: str = "analytic"):
    """Refine ``q`` (S, n_q) at driver values ``s`` (S, nd) by Newton-Raphson, step by step.

    Returns (q, residual (S,), iterations (S,), converged (S,) bool). The iteration is the one
    loop of :meth:`linkpipe.kinematics.step._Step.newton` (on Python floats: this is called for
    one or a few steps at a time; whole sweeps go through the vectorised path's batched
    refinement). A step is iterated until its residual (max abs of Phi) is below ``tol_abs``;
    one whose residual has made no progress (a new best, or half the previous residual) for
    ``NEWTON_STALL`` iterations is given up early (Newton wandering where there is no
    solution: a step past an assembly limit).
    """
    q = np.array(q, dtype=float)
    n_steps = q.shape[0]
    if not model.n_q:  # nothing to move: the residual is the drivers' own
        F = model.phi(model.positions(q), s)
        res = np.abs(F).max(axis=1) if F.shape[1] else np.zeros(n_steps)
        return q, res, np.zeros(n_steps, dtype=np.int32), res <= tol_abs
    kernels = _step_kernels(model)
    out = [kernels.newton(q[i], s[i], tol_abs, max_iter, jacobian) for i in range(n_steps)]
    if not out:
        return q, np.zeros(0), np.zeros(0, dtype=np.int32), np.zeros(0, dtype=bool)
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _polish(model: Model, q: np.ndarray, s_row: np.ndarray, max_iter: int):
    """Return (q, residual, iterations): Newton on past the tolerance while the residual falls.

    At a singular root Newton converges only linearly (the error halves, the residual quarters
    per iteration), so it stops at ``tol`` with the position off by about ``sqrt(tol) * size``
    along the near-null direction; going on to rounding level tells a step near a singularity
    from one at it. ``q`` (1, n_q).
    """
    X = model.positions(q)
    F = model.phi(X, s_row[None])
    best_q, best_r = q, float(np.abs(F).max())
    it = 0
    while it < max_iter and best_r > 0.0:
        it += 1
        qn = best_q + lin_solve(model.jacobian(X, s_row[None]), -F)
        Xn = model.positions(qn)
        Fn = model.phi(Xn, s_row[None])
        r = float(np.abs(Fn).max())
        if not r < best_r:
            break
        best_q, X, F, progress, best_r = qn, Xn, Fn, r / best_r, r
        if progress > 0.5:  # no longer converging: rounding level reached
            break
    return best_q, best_r, it


def _null_line_roots(model: Model, q: np.ndarray, s_row: np.ndarray):
    """Return (v, roots): where Phi vanishes along the Jacobian's near-null direction from ``q``.

    Phi is at most quadratic in natural coordinates (J is affine in q), so along a line
    ``q + t v`` it is exactly ``Phi(q) + t J v + t^2/2 H(v, v)`` with
    ``H(v, v) = (J(q + h v) - J(q)) v / h``. With ``J v = sigma u`` (v, u the singular vectors of
    the smallest singular value), the component along u vanishes at the roots of
    ``kappa/2 t^2 + sigma t + u.Phi(q) = 0``, ``kappa = u.H(v, v)``: the two sides of a fold or
    change point near q. ``q`` (1, n_q); roots may be empty.
    """
    s1 = s_row[None]
    J = model.jacobian(model.positions(q), s1)[0]
    U, sv, Vt = np.linalg.svd(J)
    n = J.shape[1]
    v, u, sigma = Vt[n - 1], U[:, n - 1], sv[n - 1]
    h = model.size
    kappa = float(u @ ((model.jacobian(model.positions(q + h * v), s1)[0] - J) @ v) / h)
    c = float(u @ model.phi(model.positions(q), s1)[0])
    disc = sigma**2 - 2.0 * kappa * c
    if not np.isfinite(kappa) or kappa == 0.0 or not disc >= 0.0:
        return v, []
    return v, [(-sigma + np.sqrt(disc)) / kappa, (-sigma - np.sqrt(disc)) / kappa]


def _mirror_root(model: Model, q: np.ndarray, s_row: np.ndarray, tol_abs: float, max_iter: int,
                 jacobian: str, accept, guesses=()):
    """Return (q, iterations): another root than ``q`` (1, n_q) for which ``accept(q)`` holds.

    First the other root of :func:`_null_line_roots` (one is ``t = 0``: q itself), polished by
    Newton: the root across a nearby fold. Then deflated Newton (Farrell et al. 2015: Newton on
    ``Phi / |x - q|^2 + Phi``, which cannot converge to q again) from ``guesses`` and from q
    moved along each right singular vector of the Jacobian. Returns (None, iterations) when
    none is found.
    """
    s1 = s_row[None]
    total = 0
    v, roots = _null_line_roots(model, q, s_row)
    if roots:
        qn, _, it, conv = newton(model, q + max(roots, key=abs) * v, s1, tol_abs, max_iter, jacobian)
        total += int(it[0])
        if conv[0] and drivers_aligned(model, qn, s1)[0] and accept(qn):
            return qn, total
    Vt = np.linalg.svd(model.jacobian(model.positions(q), s1)[0])[2]
    starts = [np.asarray(g, dtype=float).reshape(1, -1) for g in guesses]
    starts += [q + sign * 0.1 * model.size * w for w in Vt[::-1] for sign in (1.0, -1.0)]
    for x in starts:
        qn, it, ok = _deflated_newton(model, x, s_row, q, tol_abs, max_iter)
        total += it
        if ok and drivers_aligned(model, qn, s1)[0] and accept(qn):
            return qn, total
    return None, total


def _deflated_newton(model: Model, x: np.ndarray, s_row: np.ndarray, q_known: np.ndarray,
                     tol_abs: float, max_iter: int):
    """Newton on ``G = m(x) Phi(x)``, ``m = size^2 / |x - q_known|^2 + 1``: roots other than q_known.

    The step is Newton's scaled by ``1 / (1 - g . dx)`` with ``g = grad m / m`` (Sherman-Morrison),
    capped at half the size. Returns (x (1, n_q), iterations, converged).
    """
    s1 = s_row[None]
    x = np.array(x, dtype=float)
    cap = 0.5 * model.size
    for it in range(1, 2 * max_iter + 1):
        F = model.phi(model.positions(x), s1)[0]
        if np.abs(F).max() <= tol_abs:
            near = np.abs(x - q_known).max() <= 1e-6 * model.size
            return x, it - 1, not near
        J = model.jacobian(model.positions(x), s1)[0]
        dx = lin_solve(J[None], -F[None])[0]
        r = (x - q_known)[0] / model.size  # scale-free: the same deflation in m and in mm
        r2 = float(r @ r)
        if r2 == 0.0:
            return x, it, False
        m = 1.0 / r2 + 1.0
        g = (-2.0 * r / r2**2) / m / model.size
        denom = 1.0 - float(g @ dx)
        if abs(denom) > 1e-12:
            dx = dx / denom
        big = np.abs(dx).max()
        if not np.isfinite(big):
            return x, it, False
        if big > cap:
            dx *= cap / big
        x = x + dx
    return x, 2 * max_iter, False


def _lm_root(model: Model, q_guess: np.ndarray, s_row: np.ndarray, tol_abs: float,
             max_iter: int = 100):
    """Return (q, residual, iterations): Levenberg-Marquardt on |Phi|^2 from ``q_guess`` (n_q,).

    Runs until the residual (max abs of Phi) is within ``tol_abs`` or stops falling: towards a
    root it keeps shrinking by a large factor per step (quadratically, or by 4 at a double root,
    where Newton's undamped steps may wander); towards a non-zero minimum (no assembly) its
    decrease dies out at once. A root with an angle driver's vector pointing backwards (the
    angle row's other root) is not this step's mechanism: from there it tries once more with the
    driven point aimed, and reports an infinite residual if that fails too.
    """
    q, r, it = _lm_loop(model, q_guess, s_row, tol_abs, max_iter)
    if r <= tol_abs and not drivers_aligned(model, q[None], s_row[None])[0]:
        q, r, it2 = _lm_loop(model, aim_drivers(model, q, s_row), s_row, tol_abs, max_iter)
        it += it2
        if r <= tol_abs and not drivers_aligned(model, q[None], s_row[None])[0]:
            r = np.inf
    return q, r, it


def _lm_loop(model: Model, q_guess: np.ndarray, s_row: np.ndarray, tol_abs: float, max_iter: int):
    """The Levenberg-Marquardt iteration of :func:`_lm_root`. Phi and Phi_q come from the
    one-step kernels (:mod:`.step`: the same rows on Python floats, equal to ``Model.phi`` and
    ``Model.jacobian`` to the last bit, without numpy's per-call overhead): a sweep that mostly
    cannot assemble runs this on every step of its gaps (issue 34: 5x faster)."""

    fast = _step_kernels(model) if model.n_q else None
    s_row = np.asarray(s_row, dtype=float)

    def fun(qq):
        if fast is not None:
            return fast.phi(qq, s_row)
        return model.phi(model.positions(qq[None]), s_row[None])[0]

    def jac(qq):
        if fast is not None:
            return fast.jac(qq, s_row)
        return model.jacobian(model.positions(qq[None]), s_row[None])[0]

    q = np.array(q_guess, dtype=float)
    if not np.all(np.isfinite(q)):
        return q, np.inf, 0
    F = fun(q)
    r = float(np.abs(F).max()) if F.size else 0.0
    mu = 1e-3
    it = 0
    slow = 0  # accepted steps in a row that shrank the residual by less than 1 %
    while it < max_iter and r > tol_abs:
        it += 1
        J = jac(q)
        A = J.T @ J
        scale = np.maximum(np.diag(A), 1e-12)
        try:
            dq = np.linalg.solve(A + mu * np.diag(scale), -(J.T @ F))
        except np.linalg.LinAlgError:
            mu *= 10.0
            continue
        Fn = fun(q + dq)
        rn = float(np.abs(Fn).max())
        if np.isfinite(rn) and Fn @ Fn < F @ F:
            q, F, progress, r = q + dq, Fn, rn / r, rn
            mu = max(mu / 3.0, 1e-12)
            slow = slow + 1 if progress > 0.99 else 0
            if slow == 2:
                break
        else:
            mu *= 4.0
            if mu > 1e12:
                break
    return q, r, it


def _classify_failure(model: Model, q_guesses, s_row: np.ndarray, tol_abs: float):
    """Tell no_assembly (least-squares minimum of Phi above tolerance) from not_converged.

    Returns (status, the root found or None). Damped least squares from each guess in turn (the
    step's guess, where Newton stopped, the last assembled shape): a poor guess (a singular
    start) can sit in a local minimum that is not a root, and one root found from any of them
    means the step has one."""
    for q_guess in q_guesses:
        if q_guess is None or not np.all(np.isfinite(q_guess)):
            continue
        q, r, _ = _lm_root(model, np.asarray(q_guess, float).reshape(-1), s_row, 10 * tol_abs)
        if r <= 10 * tol_abs and drivers_aligned(model, q[None], s_row[None])[0]:
            return NOT_CONVERGED, q
    return NO_ASSEMBLY, None


def _converging_at_cap(model: Model, fast, guess: np.ndarray, q_end: np.ndarray, s_row: np.ndarray,
                       iterations: int, residual: float, converged: bool, max_iter: int):
    """Return (whether a Newton run from ``guess`` used all ``max_iter`` iterations while
    converging, stopped at ``q_end`` (n_q,) with ``residual``; the guess's residual).

    Converging: its residual fell to a thousandth of the guess's or less, or fell at all and
    ended where Φq is well clear of singular (there Newton converges quadratically, so a run cut
    short is the cap's doing, however low the cap). Such a step is not_converged, as
    ``max_iter`` says: no other method finishes it. A run that reached the cap wandering (no
    progress, e.g. after a gap) or creeping towards a near-singular root (Newton is only
    linear there) failed like one that stalled: damped least squares takes over."""
    if converged or iterations < max_iter or not np.isfinite(residual):
        return False, np.nan
    F = fast.phi(guess, s_row) if fast is not None else model.phi(
        model.positions(guess[None]), s_row[None])[0]
    start = float(np.abs(F).max()) if F.size else 0.0
    if not residual < start:
        return False, start
    if residual <= 1e-3 * start:
        return True, start
    q_end = np.asarray(q_end, float).reshape(-1)
    if not np.all(np.isfinite(q_end)):
        return False, start
    J = model.jacobian(model.positions(q_end[None]), s_row[None])
    return not bool(is_singular(condition(J)[0], model.scene.solver.singular_rcond,
                                MODE_SETTLED_BELOW)), start


def aim_drivers(model: Model, q: np.ndarray, s_row: np.ndarray) -> np.ndarray:
    """Return a guess q (n_q,) with each angle driver's head point placed along its direction."""
    X = model.positions(q[None])[0]
    for j in np.flatnonzero(model.drv_angle):
        a, b = model.drv_a[j], model.drv_b[j]
        if model.fixed[b] or not np.all(np.isfinite(X[[a, b]])):
            continue
        L = np.hypot(*(X[b] - X[a]))
        direction = np.array([np.cos(s_row[j]), np.sin(s_row[j])])
        if model.drv_c[j] >= 0:  # relative: turned from the reference vector's direction
            r = X[model.drv_d[j]] - X[model.drv_c[j]]
            if not np.all(np.isfinite(r)) or not np.hypot(*r) > 0:
                continue
            r = r / np.hypot(*r)
            direction = np.array([direction[0] * r[0] - direction[1] * r[1],
                                  direction[1] * r[0] + direction[0] * r[1]])
        X[b] = X[a] + L * direction
    return model.q_of(X[None])[0]


def drivers_aligned(model: Model, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return (S,) True where every angle driver's vector points along (not against) its angle."""
    if not model.drv_angle.any():
        return np.ones(q.shape[0], dtype=bool)
    return model.aligned(model.positions(q), s)
