"""Stage 1: solve a mechanism over its whole sweep (positions, velocities, accelerations).

Positions: Newton-Raphson with the analytic Jacobian from a predicted start (the previous
step's position plus its velocity times the driver increment), so the solver stays on the
assembly branch it starts on. Velocities ``Phi_q qd = -Phi_t`` and accelerations
``Phi_q qdd = gamma`` are linear solves over all steps at once. A step that cannot be solved
gets NaN and a status; the sweep goes on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .errors import SceneError
from .model import Model, driver_scale, driver_values

OK, NO_ASSEMBLY, SINGULAR, NOT_CONVERGED = 0, 1, 2, 3
STATUS_NAMES = ("ok", "no_assembly", "singular", "not_converged")



@dataclass
class Kinematics:
    """Stage-1 arrays, step axis first. Derivative arrays are None when not computed.

    driver_value (S, n_drivers) scene units; s, s_dot, s_ddot (S, n_drivers) internal units
    (rad, rad/s, rad/s^2 for angle drivers); position/velocity/acceleration (S, n_points, 2);
    status (S,) int8; residual (S,) constraint norm (max abs, lengths); iterations (S,) int;
    condition (S,) 1-norm condition estimate of the square (or SVD for redundant) Jacobian;
    velocity_residual, acceleration_residual (S,) norms of the linear equations' residuals.
    """

    driver_value: np.ndarray
    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray
    position: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    condition: np.ndarray
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    velocity_residual: np.ndarray | None = None
    acceleration_residual: np.ndarray | None = None
    jacobian_inverse: np.ndarray | None = None  # (S, n_q, n_rows): pseudo-inverse where used

    @property
    def n_steps(self) -> int:
        return self.position.shape[0]


def driver_motion(model: Model):
    """Return driver values in scene units and (s, s_dot, s_ddot) in internal units, each (S, nd)."""
    scene = model.scene
    value = driver_values(scene)
    scale = driver_scale(scene)
    rate = np.array([d.rate for d in scene.drivers], dtype=float) * scale
    acc = np.array([d.acceleration for d in scene.drivers], dtype=float) * scale
    S = value.shape[0]
    return value, value * scale, np.broadcast_to(rate, (S, len(rate))).copy(), np.broadcast_to(acc, (S, len(acc))).copy()


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
    their residual (max abs of Phi) is below ``tol_abs``; converged ones are frozen.
    """
    q = np.array(q, dtype=float)
    S = q.shape[0]
    iters = np.zeros(S, dtype=np.int32)
    res = np.full(S, np.inf)
    active = np.arange(S)
    step_cap = 0.5 * model.size
    for it in range(max_iter + 1):
        X = model.positions(q[active])
        F = model.phi(X, s[active])
        r = np.abs(F).max(axis=1) if F.shape[1] else np.zeros(len(active))
        res[active] = r
        done = ~(r > tol_abs)  # NaN counts as not done
        bad = ~np.isfinite(r)
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


def _classify_failure(model: Model, q_guess: np.ndarray, s_row: np.ndarray, tol_abs: float) -> int:
    """Tell no_assembly (least-squares minimum of Phi above tolerance) from not_converged."""
    if not np.all(np.isfinite(q_guess)):
        return NO_ASSEMBLY

    def fun(qq):
        return model.phi(model.positions(qq[None]), s_row[None])[0]

    def jac(qq):
        return model.jacobian(model.positions(qq[None]), s_row[None])[0]

    try:
        sol = least_squares(fun, q_guess, jac=jac, method="trf", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, max_nfev=200)
    except Exception:  # noqa: BLE001 - a classification helper must not kill the sweep
        return NO_ASSEMBLY
    solvable = np.abs(sol.fun).max() <= 10 * tol_abs and drivers_aligned(model, sol.x[None], s_row[None])[0]
    return NOT_CONVERGED if solvable else NO_ASSEMBLY


def assemble_start(model: Model, s0: np.ndarray, tol_abs: float, max_iter: int) -> np.ndarray:
    """Assemble the first step from the start configuration as written; SceneError if impossible."""
    q0 = model.q_of(model.start_position[None])
    q, res, _, conv = newton(model, q0, s0[None], tol_abs, max(max_iter, 50))
    if conv[0]:
        return q[0]
    # Newton may wander from a poor guess: a least-squares solve tells whether a solution exists.
    def fun(qq):
        return model.phi(model.positions(qq[None]), s0[None])[0]

    def jac(qq):
        return model.jacobian(model.positions(qq[None]), s0[None])[0]

    sol = least_squares(fun, q0[0], jac=jac, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=500)
    if np.abs(sol.fun).max() <= tol_abs:
        qq, res2, _, conv2 = newton(model, sol.x[None], s0[None], tol_abs, max_iter)
        if conv2[0]:
            return qq[0]
    worst = float(np.abs(sol.fun).max())
    raise SceneError(model.scene.path, "points", None,
                     f"the start configuration cannot be assembled at the first driver value "
                     f"(smallest constraint residual {worst:.3g} in scene length units, "
                     f"tolerance {tol_abs:.3g})",
                     "check the link lengths, the `local` coordinates and the drivers' `from`; "
                     "the points' x, y must be close to an assembled position")


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
                    jacobian: str | None = None):
    """Solve every step's positions in sweep order with branch-keeping continuation.

    ``s`` (S, nd) driver values in internal units. Returns q (S, n_q) with NaN rows at failed
    steps, residual (S,), iterations (S,), status (S,) int8 (OK / NO_ASSEMBLY / NOT_CONVERGED).
    ``predictor`` is "none", "first" (q + dq/ds * ds) or "second" (adds the curvature term).
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

    q_start = assemble_start(model, s[0], tol_abs, max_iter)
    unit = np.ones((1, model.n_drivers))  # derivative along the sweep direction, per unit of s
    last_q = q_start
    last_s = s[0]
    last_dq = None  # dq/ds along the sweep (n_q, nd)
    last_d2q = None
    for i in range(S):
        ds = s[i] - last_s
        guess = last_q.copy()
        if predictor != "none" and last_dq is not None:
            guess += last_dq @ ds
            if predictor == "second" and last_d2q is not None:
                guess += 0.5 * np.einsum("qij,i,j->q", last_d2q, ds, ds)
        if last_dq is None:
            guess = aim_drivers(model, guess, s[i])
        qi, res, it, conv = newton(model, guess[None], s[i][None], tol_abs, max_iter, jacobian)
        residual[i] = res[0]
        iterations[i] = it[0]
        if conv[0] and not drivers_aligned(model, qi, s[i][None])[0]:
            # the angle constraint's other root (vector pointing backwards): not this step's
            # mechanism; retry with the driven point aimed along the driven direction
            qi, res, it2, conv = newton(model, aim_drivers(model, guess, s[i])[None], s[i][None],
                                        tol_abs, max_iter, jacobian)
            iterations[i] += it2[0]
            residual[i] = res[0]
            conv = conv & drivers_aligned(model, qi, s[i][None])
        if conv[0]:
            q[i] = qi[0]
            X = model.positions(qi)
            J = model.jacobian(X, s[i][None])
            # influence coefficients dq/ds_j, one column per driver
            cols = []
            for j in range(model.n_drivers):
                e = np.zeros((1, model.n_drivers))
                e[0, j] = 1.0
                cols.append(_velocity_one(model, X, s[i][None], e, J))
            dq = np.stack(cols, axis=1)
            if np.all(np.isfinite(dq)) and np.abs(dq).max() < 1e8 * model.size:
                if predictor == "second":
                    # curvature along the sweep: gamma with unit driver rate, zero acceleration
                    d2 = np.zeros((nq, model.n_drivers, model.n_drivers))
                    for j in range(model.n_drivers):
                        e = np.zeros((1, model.n_drivers))
                        e[0, j] = 1.0
                        V = model.velocities(dq[:, j][None])
                        g = model.gamma(X, V, s[i][None], e, np.zeros_like(e))
                        d2[:, j, j] = _lin_solve(J, g)[0]
                    last_d2q = d2
                last_dq = dq
            else:
                last_dq, last_d2q = None, None  # a singular step: keep no slope from it
            last_q, last_s = qi[0], s[i]
        else:
            status[i] = _classify_failure(model, guess, s[i], tol_abs)
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
