"""Stage 1: solve a mechanism over its whole sweep (positions, velocities, accelerations).

Positions: Newton-Raphson with the analytic Jacobian from a predicted start (the previous
step's position plus its velocity times the driver increment), so the solver stays on the
assembly branch it starts on. Velocities ``Phi_q qd = -Phi_t`` and accelerations
``Phi_q qdd = gamma`` are linear solves over all steps at once. A step that cannot be solved
gets NaN and a status; the sweep goes on.
"""
from __future__ import annotations

import numpy as np

from .errors import SceneError
from .model import Model, constraint_source, driver_scale, driver_values
from .model import equations as eq
from .status import NO_ASSEMBLY, NOT_CONVERGED, OK, SINGULAR

NEWTON_STALL = 8  # Newton iterations without a new best residual before a step is given up
SUBSTEPS, SUBDIVIDE = 8, 2  # a failing step's retry: 8 sub-steps, at most 2 levels deep


def driver_motion(model: Model):
    """Return driver values in scene units and (s, s_dot, s_ddot) in internal units, each (S, nd)."""
    scene = model.scene
    value = driver_values(scene)
    scale = driver_scale(scene)
    rate = np.array([d.rate for d in scene.drivers], dtype=float) * scale
    acc = np.array([d.acceleration for d in scene.drivers], dtype=float) * scale
    S = value.shape[0]
    return value, value * scale, np.broadcast_to(rate, (S, len(rate))).copy(), np.broadcast_to(acc, (S, len(acc))).copy()


def jacobian_condition(J: np.ndarray) -> np.ndarray:
    """Return the condition (S,) of Jacobians (S, m, n) as derivatives() measures it.

    Square: the 1-norm condition ``|J|_1 |J^-1|_1`` (inf when exactly singular); more rows than
    columns (known redundancy): ``sigma_1 / sigma_n``, the rank deficiency beyond the redundancy.
    """
    if J.shape[1] == J.shape[2]:
        return np.linalg.cond(J, 1)
    sv = np.linalg.svd(J, compute_uv=False)
    n = J.shape[2]
    return sv[:, 0] / np.where(sv[:, n - 1] > 0, sv[:, n - 1], np.finfo(float).tiny)


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
        qn = best_q + _lin_solve(model.jacobian(X, s_row[None]), -F)
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
        dx = _lin_solve(J[None], -F[None])[0]
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


def _lin_solve(J, b):
    """Solve J x = b for stacks (S, m, n), (S, m) in the least-squares, minimum-norm sense."""
    S, m, n = J.shape
    if m == n:
        try:
            return np.linalg.solve(J, b[..., None])[..., 0]
        except np.linalg.LinAlgError:
            pass
    return np.einsum("sij,sj->si", np.linalg.pinv(J, rcond=1e-13), b)


def fd_jacobian(model: Model, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return Phi_q (S, n_rows, n_q) by central differences (the accuracy ladder's knob)."""
    h = np.cbrt(np.finfo(float).eps) * model.size
    cols = []
    for k in range(q.shape[1]):
        dq = np.zeros_like(q)
        dq[:, k] = h
        cols.append((model.phi(model.positions(q + dq), s) - model.phi(model.positions(q - dq), s)) / (2 * h))
    return np.stack(cols, axis=2)


def newton(model: Model, q: np.ndarray, s: np.ndarray, tol_abs: float, max_iter: int,
           jacobian: str = "analytic"):
    """Refine ``q`` (S, n_q) at driver values ``s`` (S, nd) by Newton-Raphson, all steps at once.

    Returns (q, residual (S,), iterations (S,), converged (S,) bool). Steps are iterated until
    their residual (max abs of Phi) is below ``tol_abs``; converged ones are frozen. A step whose
    residual has made no progress (a new best, or half the previous residual) for
    ``NEWTON_STALL`` iterations is given up early (Newton wandering where there is no solution:
    a step past an assembly limit); near a singular root the residual falls by about 4 per
    iteration after a jump, which counts as progress.
    """
    q = np.array(q, dtype=float)
    S = q.shape[0]
    iters = np.zeros(S, dtype=np.int32)
    res = np.full(S, np.inf)
    best = np.full(S, np.inf)
    prev = np.full(S, np.inf)
    stall = np.zeros(S, dtype=np.int32)
    active = np.arange(S)
    step_cap = 0.5 * model.size
    for it in range(max_iter + 1):
        X = model.positions(q[active])
        F = model.phi(X, s[active])
        r = np.abs(F).max(axis=1) if F.shape[1] else np.zeros(len(active))
        res[active] = r
        progress = (r < best[active]) | (r < 0.5 * prev[active])
        stall[active] = np.where(progress, 0, stall[active] + 1)
        best[active] = np.fmin(best[active], r)
        prev[active] = r
        done = ~(r > tol_abs)  # NaN counts as not done
        bad = ~np.isfinite(r) | (stall[active] >= NEWTON_STALL)
        keep = ~done & ~bad
        if it == max_iter or not keep.any():
            break
        active, F, X = active[keep], F[keep], X[keep]
        J = (model.jacobian(X, s[active]) if jacobian == "analytic"
             else fd_jacobian(model, q[active], s[active]))
        dq = _lin_solve(J, -F)
        big = np.abs(dq).max(axis=1)
        scale = np.where(big > step_cap, step_cap / np.where(big > 0, big, 1.0), 1.0)
        q[active] += dq * scale[:, None]
        iters[active] += 1
    converged = res <= tol_abs
    return q, res, iters, converged


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
    """The Levenberg-Marquardt iteration of :func:`_lm_root`."""
    def fun(qq):
        return model.phi(model.positions(qq[None]), s_row[None])[0]

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
        J = model.jacobian(model.positions(q[None]), s_row[None])[0]
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


#: largest driver move per step when the drawn pose is carried to the sweep's first value:
#: 2 degrees for an angle driver, 0.5 % of the mechanism's size for a coordinate driver
CARRY_ANGLE_STEP = np.deg2rad(2.0)
CARRY_LENGTH_STEP = 0.005


def start_state(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """Return (q (n_q,), slope): the assembled start's q and, when the drawn pose was carried
    to ``s0`` by a one-driver path, dq/ds (n_q, 1) along that path's last step (a secant), else
    None. The sweep's first predictor uses it: a sweep that starts on a change point then leaves
    it on the branch the path arrived on instead of on a side chosen by rounding."""
    carried = _carry_drawn_pose(model, s0, tol_abs, max_iter)
    if carried is not None:
        return carried
    return _assemble_directly(model, s0, tol_abs, max_iter), None


def _assemble_directly(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int) -> np.ndarray:
    """Newton (then least squares) at ``s0`` from the drawing itself; SceneError if impossible."""
    q0 = model.q_of(model.start_position[None])
    fast = _step_kernels(model) if model.n_q else None  # the same Newton on plain floats
    q, res, _, conv = (fast.newton(q0[0], s0, tol_abs, max(max_iter, 50)) if fast is not None
                       else newton(model, q0, s0[None], tol_abs, max(max_iter, 50)))
    if conv[0]:
        return q[0]
    # Newton may wander from a poor guess: a least-squares solve tells whether a solution exists.
    def fun(qq):
        return model.phi(model.positions(qq[None]), s0[None])[0]

    def jac(qq):
        return model.jacobian(model.positions(qq[None]), s0[None])[0]

    from scipy.optimize import least_squares  # here: importing scipy.optimize costs ~0.3 s

    sol = least_squares(fun, q0[0], jac=jac, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=500)
    if np.abs(sol.fun).max() <= tol_abs:
        qq, res2, _, conv2 = newton(model, sol.x[None], s0[None], tol_abs, max_iter)
        if conv2[0]:
            return qq[0]
    path = model.scene.path
    if model.n_q and not jacobian_condition(jac(sol.x)[None])[0] * model.scene.solver.singular_rcond < 1.0:
        # stuck on a singular shape (links in line): Newton and least squares cannot leave a
        # mirror-symmetric guess; if either side of it assembles, the guess is just ambiguous
        v, roots = _null_line_roots(model, sol.x[None], s0)
        for t in roots:
            _, _, _, conv3 = newton(model, (sol.x + t * v)[None], s0[None], tol_abs, max_iter)
            if conv3[0]:
                k = int(np.argmax(np.hypot(*v.reshape(-1, 2).T)))
                name = model.point_names[model.moving[k]]
                raise SceneError(path, "points", name,
                                 "the start positions put links in line (a singular "
                                 "configuration), so they do not say which of the mirror-image "
                                 "assemblies is meant",
                                 f"move {name} a little off the line, to the side of the "
                                 "assembly you want")
    worst = float(np.abs(sol.fun).max())
    if worst <= 1e-13 * model.size:
        # assembled to rounding level: it is the tolerance that cannot be met, not the scene
        raise SceneError(path, "solver", "tol",
                         f"tol = {model.scene.solver.tol:g} ({tol_abs:.3g} for this mechanism's "
                         f"size) is below what double precision reaches here: the start "
                         f"assembles to {worst:.3g} and no closer",
                         "use tol >= 1e-15 (a solved step's residual is rounded to about 1e-16 "
                         "of the size)")
    table, key = constraint_source(model, int(np.argmax(np.abs(sol.fun))))
    length = dict(model.scene.units).get("length", "length units")
    where = f"[{table}]" + (f" {key}" if key else "")
    raise SceneError(path, "points", None,
                     f"the start configuration cannot be assembled at the first driver value: "
                     f"at the best fit the constraint of {where} is still off by {worst:.3g} "
                     f"{length} (tolerance {tol_abs:.3g})",
                     "check the link lengths, the `local` coordinates and the drivers' `from`; "
                     "the points' x, y must be close to an assembled position")


def _carry_drawn_pose(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int):
    """Return (q (n_q,), slope) at ``s0`` carried by continuation from the drawn pose, or None.

    None when the drawing is within one carrying step of ``s0``, when it cannot be assembled at
    its own driver values, or when the path to ``s0`` leaves the assembly range. ``slope`` as
    :func:`start_state` says (None with several drivers: one path gives one direction only).
    """
    if not model.n_drivers or not model.n_q:
        return None
    s_drawn = model.driver_values_at(model.start_position[None])[0]
    delta = s0 - s_drawn
    angle = model.drv_angle
    delta[angle] = (delta[angle] + np.pi) % (2 * np.pi) - np.pi  # the shorter way round
    step = np.where(angle, CARRY_ANGLE_STEP, CARRY_LENGTH_STEP * model.size)
    n = int(np.ceil(np.max(np.abs(delta) / step)))
    if n <= 1:
        return None
    start = s0 - delta  # the drawn values, next to s0 for the angles
    q0 = model.q_of(model.start_position[None])
    fast = _step_kernels(model)
    q_drawn, _, _, conv = (fast.newton(q0[0], start, tol_abs, max(max_iter, 50)) if fast is not None
                           else newton(model, q0, start[None], tol_abs, max(max_iter, 50)))
    if not conv[0] or not drivers_aligned(model, q_drawn, start[None])[0]:
        return None
    path = start + np.linspace(0.0, 1.0, min(n, 2000) + 1)[:, None] * delta
    path[-1] = s0
    # the carry's own settings, not the scene's knobs (a low max_iter or no predictor must not
    # send the start back to the one-jump assembly); it stops at its first failed step
    q, residual, _, _ = solve_positions(model, path, tol=model.scene.solver.tol,
                                        max_iter=max(max_iter, 50), predictor="first",
                                        jacobian="analytic", q_start=q_drawn[0],
                                        stop_on_failure=True)
    if not (np.isfinite(q).all() and (residual <= tol_abs).all()):
        return None  # a step without assembly on the way (or one that did not converge)
    slope = None
    if model.n_drivers == 1:
        slope = ((q[-1] - q[-2]) / (path[-1, 0] - path[-2, 0]))[:, None]
    return q[-1], slope


def _converging_at_cap(model: Model, fast, guess: np.ndarray, s_row: np.ndarray, iterations: int,
                       residual: float, converged: bool, max_iter: int) -> bool:
    """Return whether a Newton run used all ``max_iter`` iterations while converging.

    Converging: its residual fell to a thousandth of the guess's or less. Such a step is
    not_converged (the cap stopped it); a run that reached the cap wandering (far from any root,
    e.g. after a gap) is treated like one that stalled: damped least squares takes over."""
    if converged or iterations < max_iter or not np.isfinite(residual):
        return False
    F = fast.phi(guess, s_row) if fast is not None else model.phi(
        model.positions(guess[None]), s_row[None])[0]
    return bool(F.size and residual <= 1e-3 * float(np.abs(F).max()))


def _velocity_one(model, X, s, s_dot, J=None):
    """Return qdot (n_q,) at one step (for the predictor)."""
    if J is None:
        J = model.jacobian(X, s)
    rhs = -model.phi_t(X, s, s_dot)
    return _lin_solve(J, rhs)[0]


def aim_drivers(model: Model, q: np.ndarray, s_row: np.ndarray) -> np.ndarray:
    """Return a guess q (n_q,) with each angle driver's head point placed along its direction."""
    X = model.positions(q[None])[0]
    for j in np.flatnonzero(model.drv_angle):
        a, b = model.drv_a[j], model.drv_b[j]
        if model.fixed[b] or not np.all(np.isfinite(X[[a, b]])):
            continue
        L = np.hypot(*(X[b] - X[a]))
        X[b] = X[a] + L * np.array([np.cos(s_row[j]), np.sin(s_row[j])])
    return model.q_of(X[None])[0]


class _Step:
    """One step's Phi, Phi_q and driver check on Python floats (sequential continuation).

    The rows are :mod:`linkpipe.model.equations`' own, evaluated on floats: numpy's per-call
    overhead would dominate a single step of a few rows (``tests/test_kernels.py`` checks that
    they equal ``Model.phi`` / ``Model.jacobian`` to the last bit). Built once per model.
    """

    def __init__(self, model: Model):
        md = self.model = model
        self.n, self.m = md.n_q, md.n_rows
        self.nc = md.n_constraints
        self.rows = md.rows
        self.x0 = md.start_position.reshape(-1).tolist()
        self.qpos = [int(2 * p + c) for p in md.moving for c in (0, 1)]
        self.col = [-1] * (2 * md.n_points)  # point coordinate -> column of q (-1: fixed)
        for k, pc in enumerate(self.qpos):
            self.col[pc] = k
        self.drv = [(bool(md.drv_angle[j]), 2 * int(md.drv_a[j]), 2 * int(md.drv_b[j]),
                     int(md.drv_axis[j])) for j in range(md.n_drivers)]
        self.angle = np.flatnonzero(md.drv_angle)

    def _xy(self, q):
        X = self.points(q)
        return lambda p: (X[2 * p], X[2 * p + 1])

    def jac(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi_q (m, n) at q (n,) and s (nd,), as :meth:`Model.jacobian` computes it."""
        n, col = self.n, self.col
        J = [0.0] * (self.m * n)
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        for r, p, gx, gy in eq.jacobian_terms(self.rows, self._xy(q), cs, sn):
            c = col[2 * p]
            if c >= 0:
                J[r * n + c] += gx
            c = col[2 * p + 1]
            if c >= 0:
                J[r * n + c] += gy
        return np.array(J, dtype=float).reshape(self.m, n)

    def points(self, q) -> list:
        X = list(self.x0)
        for k, v in zip(self.qpos, q.tolist()):
            X[k] = v
        return X

    def phi(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi (m,) at q (n,) and s (nd,), as :meth:`Model.phi` computes it."""
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        return np.array(list(eq.phi_rows(self.rows, self._xy(q), s.tolist(), cs, sn)), dtype=float)

    def aligned(self, q: np.ndarray, s: np.ndarray) -> bool:
        """:func:`drivers_aligned` at one step."""
        if not len(self.angle):
            return True
        X = self.points(q)
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        for j, (ang, a, b, _) in enumerate(self.drv):
            if ang and not (X[b] - X[a]) * cs[j] + (X[b + 1] - X[a + 1]) * sn[j] > 0:
                return False
        return True

    def phi_s(self, q: np.ndarray, s: np.ndarray) -> list:
        """:meth:`Model.phi_s` at one step, as a list (nd,)."""
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        return list(eq.phi_s_rows(self.rows, self._xy(q), cs, sn))

    def fd_jac(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi_q (m, n) by central differences, as :func:`fd_jacobian` computes it."""
        h = np.cbrt(np.finfo(float).eps) * self.model.size
        cols = []
        for k in range(self.n):
            dq = np.zeros(self.n)
            dq[k] = h
            cols.append((self.phi(q + dq, s) - self.phi(q - dq, s)) / (2 * h))
        return np.stack(cols, axis=1) if cols else np.zeros((self.m, 0))

    def newton(self, q: np.ndarray, s: np.ndarray, tol_abs: float, max_iter: int,
               jacobian: str = "analytic"):
        """:func:`newton` at one step; same returns, shapes (1, n), (1,)."""
        jac = self.jac if jacobian == "analytic" else self.fd_jac
        q = np.array(q, dtype=float).reshape(-1)
        best = prev = np.inf
        stall = 0
        it_done = 0
        res = np.inf
        step_cap = 0.5 * self.model.size
        for it in range(max_iter + 1):
            F = self.phi(q, s)
            r = float(np.abs(F).max()) if F.shape[0] else 0.0
            res = r
            progress = (r < best) or (r < 0.5 * prev)
            stall = 0 if progress else stall + 1
            best = min(best, r) if r == r else best  # np.fmin: NaN does not replace a number
            prev = r
            done = not (r > tol_abs)
            bad = not np.isfinite(r) or stall >= NEWTON_STALL
            if it == max_iter or done or bad:
                break
            dq = _lin_solve(jac(q, s)[None], -F[None])[0]
            big = np.abs(dq).max()
            if big > step_cap:
                dq = dq * (step_cap / big)
            q = q + dq
            it_done += 1
        conv = res <= tol_abs
        return (q[None], np.array([res]), np.array([it_done], dtype=np.int32),
                np.array([conv]))


def _step_kernels(model: Model) -> _Step:
    """Return the model's one-step kernels (built once per model, kept beside it)."""
    cache = model.__dict__.get("_linkpipe_step")
    if cache is None:
        cache = _Step(model)
        object.__setattr__(model, "_linkpipe_step", cache)
    return cache


def _cond_inverse(J: np.ndarray):
    """Return (1-norm condition as :func:`jacobian_condition`, inverse or None) of square J (n, n)."""
    try:
        inv = np.linalg.inv(J)
    except np.linalg.LinAlgError:
        return (np.nan if np.isnan(J).any() else np.inf), None
    c = float(np.abs(J).sum(axis=0).max() * np.abs(inv).sum(axis=0).max())
    if c != c and not np.isnan(J).any():
        c = np.inf
    return c, inv


def drivers_aligned(model: Model, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Return (S,) True where every angle driver's vector points along (not against) its angle."""
    ang = model.drv_angle
    if not ang.any():
        return np.ones(q.shape[0], dtype=bool)
    X = model.positions(q)
    d = X[:, model.drv_b[ang]] - X[:, model.drv_a[ang]]
    dot = d[..., 0] * np.cos(s[:, ang]) + d[..., 1] * np.sin(s[:, ang])
    return (dot > 0).all(axis=1)


def solve_positions(model: Model, s: np.ndarray, tol: float | None = None,
                    max_iter: int | None = None, predictor: str | None = None,
                    jacobian: str | None = None, q_start: np.ndarray | None = None,
                    start_slope: np.ndarray | None = None, stop_on_failure: bool = False,
                    subdivide: int = SUBDIVIDE):
    """Solve every step's positions in sweep order with branch-keeping continuation.

    ``s`` (S, nd) driver values in internal units. Returns q (S, n_q) with NaN rows at failed
    steps, residual (S,), iterations (S,), status (S,) int8 (OK / NO_ASSEMBLY / NOT_CONVERGED).
    ``predictor`` is "none", "first" (q + dq/ds * ds) or "second" (adds the curvature term).
    ``q_start`` (n_q,): continue from this assembled configuration instead of assembling the
    scene's start (the vectorised general path re-runs single intervals of a sweep this way),
    with ``start_slope`` (n_q, nd) as the first predictor's dq/ds (see :func:`start_state`).
    ``stop_on_failure``: return at the first step that fails (the rest stay NaN, status 0).
    ``subdivide``: how many levels of ``SUBSTEPS`` sub-steps a step that fails right after an
    assembled one is retried in before it counts as failed.

    After a step without assembly the next one starts by damped least squares from the last
    assembled shape (a gap in the assembly range); after a not_converged step (``max_iter``
    reached on a step that has a root) the sweep predicts on from the root that told the two
    failures apart, with the slope from before: a low cap costs steps, and the step it stopped
    is reported as not_converged, never finished by other iterations.
    """
    sc = model.scene.solver
    tol = sc.tol if tol is None else tol
    max_iter = sc.max_iter if max_iter is None else max_iter
    predictor = sc.predictor if predictor is None else predictor
    jacobian = sc.jacobian if jacobian is None else jacobian
    tol_abs = tol * model.size
    S = s.shape[0]
    nq = model.n_q
    q = np.full((S, nq), np.nan)
    residual = np.full(S, np.nan)
    iterations = np.zeros(S, dtype=np.int32)
    status = np.zeros(S, dtype=np.int8)

    if q_start is None:
        q_start, start_slope = start_state(model, s[0], tol_abs, max_iter)
    last_q = q_start
    last_s = s[0]
    # dq/ds along the sweep (n_q, nd); without a predictor the start slope is not used either
    # (a singular start is then left by trying either side, below)
    last_dq = start_slope if predictor != "none" else None
    last_d2q = None
    rcond = model.scene.solver.singular_rcond
    square = model.n_rows == nq
    # one-step kernels: the same Newton, Phi and checks with less overhead per step
    # (the finite-difference Jacobian knob changes Newton's iteration matrix only: the condition
    # and the slopes below use the analytic one either way)
    fast = _step_kernels(model) if nq else None
    last_sign = 0.0  # sign of det(Phi_q) at the last regular step: the assembly mode
    gap = False  # a failed step since the last assembled one
    mode_pending = False  # a failed step since the last regular one: its mode to be kept
    gap_shape = None  # least-squares shape of the last failed step
    for i in range(S):
        ds = s[i] - last_s
        guess = last_q.copy()
        if predictor != "none" and last_dq is not None:
            guess += last_dq @ ds
            if predictor == "second" and last_d2q is not None:
                guess += 0.5 * np.einsum("qij,i,j->q", last_d2q, ds, ds)
        if last_dq is None:
            guess = aim_drivers(model, guess, s[i])
        it_lm = 0
        if gap and nq:
            # after a failed step most steps fail too: damped least squares, which stops as soon
            # as the residual stops falling, decides first (Newton only polishes a root it finds).
            # It starts from the last assembled shape and, failing that, from the previous
            # step's least-squares shape, which moves on through the gap and may become a root
            # where the sweep re-enters the range (either can sit in a local minimum alone)
            q_lm, r_lm, it_lm = _lm_root(model, guess, s[i], tol_abs)
            if not r_lm <= 10 * tol_abs and gap_shape is not None:
                q2, r2, it2 = _lm_root(model, aim_drivers(model, gap_shape, s[i]), s[i], tol_abs)
                it_lm += it2
                if r2 < r_lm or not np.all(np.isfinite(q_lm)):
                    q_lm, r_lm = q2, r2
            if np.all(np.isfinite(q_lm)):
                gap_shape = q_lm
            if not r_lm <= 10 * tol_abs:
                residual[i], iterations[i], status[i] = r_lm, it_lm, NO_ASSEMBLY
                continue
            guess = q_lm
        conv = np.zeros(1, dtype=bool)
        iterations[i] = it_lm
        if last_dq is None and not gap and nq and np.any(s[i] != last_s):
            # leaving a singular shape without a slope (a start at a dead centre or change
            # point): which side Newton takes from it is up to rounding, so start on either side
            # of it instead, the side nearer the start configuration as written first
            Jg = model.jacobian(model.positions(last_q[None]), s[i][None])
            if not jacobian_condition(Jg)[0] * rcond < 1.0:
                v, roots = _null_line_roots(model, last_q[None], s[i])
                written = model.q_of(model.start_position[None])[0]
                for t in sorted(roots, key=lambda t: np.abs(last_q + t * v - written).max()):
                    qc, res, itc, convc = newton(model, (last_q + t * v)[None], s[i][None], tol_abs,
                                                 max_iter, jacobian)
                    iterations[i] += itc[0]
                    residual[i] = res[0]
                    if convc[0] and drivers_aligned(model, qc, s[i][None])[0]:
                        qi, conv = qc, convc
                        break
        capped = False  # Newton reached max_iter while converging (see _converging_at_cap)
        if not conv[0]:
            if fast is not None:
                qi, res, it, conv = fast.newton(guess, s[i], tol_abs, max_iter, jacobian)
            else:
                qi, res, it, conv = newton(model, guess[None], s[i][None], tol_abs, max_iter, jacobian)
            residual[i] = res[0]
            iterations[i] += it[0]
            capped = _converging_at_cap(model, fast, guess, s[i], it[0], res[0], conv[0], max_iter)
            if conv[0] and not (fast.aligned(qi[0], s[i]) if fast is not None
                                else drivers_aligned(model, qi, s[i][None])[0]):
                # the angle constraint's other root (vector pointing backwards): not this step's
                # mechanism; retry with the driven point aimed along the driven direction
                qi, res, it2, conv = newton(model, aim_drivers(model, guess, s[i])[None],
                                            s[i][None], tol_abs, max_iter, jacobian)
                iterations[i] += it2[0]
                residual[i] = res[0]
                conv = conv & drivers_aligned(model, qi, s[i][None])
                capped = _converging_at_cap(model, fast, aim_drivers(model, guess, s[i]), s[i],
                                            it2[0], res[0], conv[0], max_iter)
        lm_residual = None
        if not conv[0] and nq and not capped:
            # Newton gave up (it stalled, failed, or wandered to the cap): slow or wandering at
            # a singular root, or no root at all. Damped least squares from the same guess tells
            # which, and reaches a singular root. A Newton run that reached max_iter while
            # converging is not rescued this way: the step is not_converged, as max_iter says.
            q_lm, lm_residual, it_lm = _lm_root(model, guess, s[i], tol_abs)
            iterations[i] += it_lm
            if lm_residual <= tol_abs and drivers_aligned(model, q_lm[None], s[i][None])[0]:
                qi, conv, residual[i] = q_lm[None], np.ones(1, dtype=bool), lm_residual
        if not conv[0] and nq and not gap and subdivide > 0 and i > 0:
            # failing from an assembled step, the step may just be too long for the continuation
            # (a dyad that moves fast there): retry it in sub-steps (each Newton run capped at
            # max_iter too) before calling it a failure
            sub = last_s + np.linspace(0.0, 1.0, SUBSTEPS + 1)[:, None] * (s[i] - last_s)
            sub[-1] = s[i]
            qs, rs, its, _ = solve_positions(model, sub, tol, max_iter, predictor, jacobian,
                                             q_start=last_q, start_slope=last_dq,
                                             stop_on_failure=True, subdivide=subdivide - 1)
            iterations[i] += int(its.sum())
            if np.isfinite(qs[-1]).all() and rs[-1] <= tol_abs:
                qi, conv, residual[i] = qs[-1][None], np.ones(1, dtype=bool), rs[-1]
                lm_residual, capped = None, False
        if conv[0]:
            X = None if fast is not None else model.positions(qi)
            J = fast.jac(qi[0], s[i])[None] if fast is not None else model.jacobian(X, s[i][None])
            inv = None
            if fast is not None and square:
                cond, inv = _cond_inverse(J[0])
            else:
                cond = jacobian_condition(J)[0]
            if not cond * rcond < 1e-3:
                # within 1000 of the singular threshold: at a double root Newton stops at tol on
                # a slow (linear) approach, with the Jacobian less singular than at the root;
                # iterate on to rounding level before deciding
                qi, residual[i], extra = _polish(model, qi, s[i], max_iter)
                iterations[i] += extra
                X = model.positions(qi)
                J = model.jacobian(X, s[i][None])
                cond, inv = jacobian_condition(J)[0], None
            regular = bool(cond * rcond < 1.0)  # as derivatives() decides
            if square and regular and mode_pending and last_sign:
                # re-entering after a gap: no path connects the two sides, so keep the assembly
                # mode (sign of det Phi_q) of the last regular step, if it exists here
                if np.linalg.slogdet(J[0])[0] != last_sign:
                    def same_mode(qq, si=s[i]):
                        Jq = model.jacobian(model.positions(qq), si[None])
                        return bool(np.linalg.slogdet(Jq[0])[0] == last_sign
                                    and jacobian_condition(Jq)[0] * rcond < 1.0)

                    alt, extra = _mirror_root(model, qi, s[i], tol_abs, max_iter, jacobian,
                                              same_mode, guesses=(guess,))
                    iterations[i] += extra
                    if alt is not None:
                        qi, X = alt, model.positions(alt)
                        J = model.jacobian(X, s[i][None])
                        inv = None
                        residual[i] = float(np.abs(model.phi(X, s[i][None])).max())
            gap, gap_shape = False, None
            if cond * rcond < 1e-4:
                # well clear of a limit (condition below 100 at the default rcond): the mode is
                # settled. A re-entry on or next to the limit
                # (its two modes about to meet) leaves the check to the steps after it
                mode_pending = False
            if square and regular:
                last_sign = np.linalg.slogdet(J[0])[0]
            q[i] = qi[0]
            # influence coefficients dq/ds_j, one column per driver
            if inv is not None:
                # Phi_q dq_j = -Phi_t with unit rate of driver j: only driver row j is non-zero
                ps = fast.phi_s(qi[0], s[i])
                dq = inv[:, fast.nc:] * -np.array(ps)[None, :]
            else:
                if X is None:
                    X = model.positions(qi)
                cols = []
                for j in range(model.n_drivers):
                    e = np.zeros((1, model.n_drivers))
                    e[0, j] = 1.0
                    cols.append(_velocity_one(model, X, s[i][None], e, J))
                dq = np.stack(cols, axis=1)
            if regular and np.all(np.isfinite(dq)) and np.abs(dq).max() < 1e8 * model.size:
                if predictor == "second":
                    # curvature along the sweep: gamma with unit driver rate, zero acceleration
                    if X is None:
                        X = model.positions(qi)
                    d2 = np.zeros((nq, model.n_drivers, model.n_drivers))
                    for j in range(model.n_drivers):
                        e = np.zeros((1, model.n_drivers))
                        e[0, j] = 1.0
                        V = model.velocities(dq[:, j][None])
                        g = model.gamma(X, V, s[i][None], e, np.zeros_like(e))
                        d2[:, j, j] = _lin_solve(J, g)[0]
                    last_d2q = d2
                last_dq = dq
            # else a singular step (change point, dead centre): its tangent is undefined, so keep
            # the slope from before it; predicting across with that slope keeps the branch
            last_q, last_s = qi[0], s[i]
        else:
            root = None
            if lm_residual is None:
                tries = (guess, qi, last_q) if capped else (guess,)
                status[i], root = _classify_failure(model, tries, s[i], tol_abs)
            else:
                status[i] = NOT_CONVERGED if lm_residual <= 10 * tol_abs else NO_ASSEMBLY
            if stop_on_failure:
                break
            if status[i] == NOT_CONVERGED and capped:
                # a root exists, the cap stopped Newton: the step stays not_converged (NaN), and
                # the sweep goes on predicting from that root (found to tell the two failures
                # apart) with the slope from before, not by a least-squares restart
                if root is not None:
                    last_q, last_s = root, s[i]
                continue
            gap = mode_pending = True
            if lm_residual is not None and np.all(np.isfinite(q_lm)):
                gap_shape = q_lm
            last_dq, last_d2q = None, None  # after a gap, restart from the last assembled shape
    return q, residual, iterations, status


def derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool):
    """Return velocities and (optionally) accelerations for all steps by linear solves.

    Marks steps whose Jacobian is rank-deficient SINGULAR (their derivatives NaN). Returns a
    dict with velocity, acceleration (or None), condition, velocity_residual,
    acceleration_residual, status, jacobian_inverse.
    """
    S = X.shape[0]
    nq, m = model.n_q, model.n_rows
    status = status.copy()
    ok = status == OK
    condition = np.full(S, np.nan)
    Jinv = np.full((S, nq, m), np.nan)
    idx = np.flatnonzero(ok)
    if len(idx):
        J = model.jacobian(X[idx], s[idx])
        if m == nq:
            try:
                inv = np.linalg.inv(J)
                n1 = np.abs(J).sum(axis=1).max(axis=1)
                ni = np.abs(inv).sum(axis=1).max(axis=1)
                cond = n1 * ni
            except np.linalg.LinAlgError:
                inv, cond = _pinv_cond(J)
        else:
            inv, cond = _pinv_cond(J)
        condition[idx] = cond
        Jinv[idx] = inv
        sing = ~(cond * model.scene.solver.singular_rcond < 1.0)
        status[idx[sing]] = SINGULAR
        Jinv[idx[sing]] = np.nan
    good = status == OK
    nan_rows = ~good
    V = np.full((S, model.n_points, 2), np.nan)
    A = None
    qd = np.einsum("sij,sj->si", Jinv, -model.phi_t(X, s, s_dot))
    V = model.velocities(qd)
    V[nan_rows] = np.nan
    V[:, model.fixed] = 0.0
    vres = np.full(S, np.nan)
    if good.any():
        Jg = model.jacobian(X[good], s[good])
        vres[good] = np.abs(np.einsum("sij,sj->si", Jg, qd[good]) + model.phi_t(X[good], s[good], s_dot[good])).max(axis=1)
    ares = None
    if need_acceleration:
        Vz = np.where(np.isfinite(V), V, 0.0)
        g = model.gamma(X, Vz, s, s_dot, s_ddot)
        qdd = np.einsum("sij,sj->si", Jinv, g)
        A = model.velocities(qdd)
        A[nan_rows] = np.nan
        A[:, model.fixed] = 0.0
        ares = np.full(S, np.nan)
        if good.any():
            ares[good] = np.abs(np.einsum("sij,sj->si", Jg, qdd[good]) - g[good]).max(axis=1)
    return dict(velocity=V, acceleration=A, condition=condition, velocity_residual=vres,
                acceleration_residual=ares, status=status, jacobian_inverse=Jinv)


def _pinv_cond(J):
    """Return the pseudo-inverse and the condition sigma_1/sigma_n of stacks (S, m, n)."""
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    n = J.shape[2]
    cond = sv[:, 0] / np.where(sv[:, n - 1] > 0, sv[:, n - 1], np.finfo(float).tiny)
    cut = sv > (1e-13 * sv[:, :1])
    inv_sv = np.where(cut, 1.0 / np.where(cut, sv, 1.0), 0.0)
    inv = np.einsum("sji,sj,skj->sik", Vt, inv_sv, U)
    return inv, cond


def fd_derivatives(X: np.ndarray, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray,
                   status: np.ndarray, need_acceleration: bool):
    """Return velocities and accelerations (S, n_points, 2) by finite differences along the sweep.

    The shortcut many scripts take (the accuracy ladder compares it with the linear solves):
    dX/ds by second-order differences over the first driver's values (``np.gradient``),
    then V = dX/ds * s_dot and A = d2X/ds2 * s_dot^2 + dX/ds * s_ddot. Steps next to a failed
    step are NaN.
    """
    S = X.shape[0]
    V = np.full_like(X, np.nan)
    A = np.full_like(X, np.nan) if need_acceleration else None
    if S < 3:
        return V, A
    x = s[:, 0]
    dX = np.gradient(X, x, axis=0, edge_order=2)
    V = dX * s_dot[:, 0, None, None]
    if need_acceleration:
        d2X = np.gradient(dX, x, axis=0, edge_order=2)
        A = d2X * s_dot[:, 0, None, None] ** 2 + dX * s_ddot[:, 0, None, None]
    bad = status != OK
    near = bad | np.r_[bad[1:], False] | np.r_[False, bad[:-1]]
    V[near] = np.nan
    if A is not None:
        A[near] = np.nan
    return V, A


def link_angles_unwrapped(model: Model, X: np.ndarray) -> np.ndarray:
    """Return link angles (S, n_links) in radians, unwrapped along the sweep across NaN gaps."""
    ang = model.link_angles(X)
    out = np.full_like(ang, np.nan)
    for j in range(ang.shape[1]):
        col = ang[:, j]
        fin = np.isfinite(col)
        if fin.any():
            out[fin, j] = np.unwrap(col[fin])
    return out


def link_rates(model: Model, X, V, A=None):
    """Return angular velocity (S, n_links) and, with A, angular acceleration of every link."""
    d = X[:, model.link_b] - X[:, model.link_a]
    dv = V[:, model.link_b] - V[:, model.link_a]
    n2 = np.einsum("slj,slj->sl", d, d)
    w = (d[..., 0] * dv[..., 1] - d[..., 1] * dv[..., 0]) / n2
    if A is None:
        return w, None
    da = A[:, model.link_b] - A[:, model.link_a]
    al = (d[..., 0] * da[..., 1] - d[..., 1] * da[..., 0]) / n2 - 2 * w * np.einsum("slj,slj->sl", d, dv) / n2
    return w, al
