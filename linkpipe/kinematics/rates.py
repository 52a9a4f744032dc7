"""Velocities, accelerations, condition numbers and the Jacobian's inverse of a solved sweep
(the "jacobian" stage), on the sparse engine or densely; finite-difference derivatives;
link angles and their rates; the drivers' motion."""
from __future__ import annotations

import numpy as np

from ..model import Model, driver_scale, driver_values
from .linalg import condition_and_inverse, is_singular
from .sparse import engine
from .linalg import CHUNK
from ..status import OK, SINGULAR


def derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool,
                velocity: np.ndarray | None = None, acceleration: np.ndarray | None = None,
                need_inverse: bool = True, chunk: int = CHUNK):
    """Velocities, accelerations, condition and Jacobian inverse of a solved sweep, on the
    sparse engine; a dict as :func:`dense_derivatives` returns (the path of a model without an
    engine, which this falls back to).

    Condition ``|J|_1 |J^-1|_1`` and SINGULAR flags as there; velocities and accelerations from
    the inverse (or the given ``velocity``/``acceleration``, e.g. the dyads', NaN where singular).
    ``need_inverse=False`` leaves ``jacobian_inverse`` None (no force stage).
    """
    eng = engine(model)
    if eng is None:
        return dense_derivatives(model, X, s, s_dot, s_ddot, status, need_acceleration)
    S = X.shape[0]
    n, m = model.n_q, model.n_rows
    status = status.copy()
    condition = np.full(S, np.nan)
    Jinv = np.full((S, n, m), np.nan) if need_inverse else None
    V = np.full((S, model.n_points, 2), np.nan)
    A = np.full((S, model.n_points, 2), np.nan) if need_acceleration else None
    vres = np.full(S, np.nan)
    ares = np.full(S, np.nan) if need_acceleration else None
    rcond = model.scene.solver.singular_rcond
    for lo in range(0, S, chunk):
        hi = min(S, lo + chunk)
        idx = lo + np.flatnonzero(status[lo:hi] == OK)
        if not len(idx):
            continue
        Xc, sc_ = X[idx], s[idx]
        q = model.q_of(Xc)
        E = eng.entries(q, sc_)
        invs = eng.inverse(E)  # (n, m, k)
        cond = eng.condition(E, invs)
        condition[idx] = cond
        sing = is_singular(cond, rcond)
        status[idx[sing]] = SINGULAR
        good = ~sing
        gi = idx[good]
        if not len(gi):
            continue
        invg = invs[:, :, good]  # (n, m, g)
        if Jinv is not None:
            Jinv[gi] = np.moveaxis(invg, 2, 0)
        Eg = E[:, good]
        Xg, sg = Xc[good], sc_[good]
        phit = -model.phi_t(Xg, sg, s_dot[gi])  # (g, m)
        if velocity is None:
            qd = np.einsum("imk,km->ik", invg, phit)  # (n, g)
        else:
            qd = model.q_of(velocity[gi]).T
        res = eng.matvec(Eg, list(qd))
        vres[gi] = np.abs(np.stack(res) - phit.T).max(axis=0)
        Vg = model.velocities(qd.T)
        V[gi] = Vg
        if need_acceleration:
            g = model.gamma(Xg, Vg, sg, s_dot[gi], s_ddot[gi])  # (g, m)
            if acceleration is None:
                qdd = np.einsum("imk,km->ik", invg, g)
            else:
                qdd = model.q_of(acceleration[gi]).T
            res = eng.matvec(Eg, list(qdd))
            ares[gi] = np.abs(np.stack(res) - g.T).max(axis=0)
            A[gi] = model.velocities(qdd.T)
    V[:, model.fixed] = 0.0
    if A is not None:
        A[:, model.fixed] = 0.0
    return dict(velocity=V, acceleration=A, condition=condition, velocity_residual=vres,
                acceleration_residual=ares, status=status, jacobian_inverse=Jinv)


def dense_derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool):
    """Return velocities and (optionally) accelerations for all steps by linear solves.

    Marks steps whose Jacobian is rank-deficient SINGULAR (their dense_derivatives NaN). Returns a
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
        cond, inv = condition_and_inverse(J)
        condition[idx] = cond
        Jinv[idx] = inv
        sing = is_singular(cond, model.scene.solver.singular_rcond)
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


def driver_motion(model: Model):
    """Return driver values in scene units and (s, s_dot, s_ddot) in internal units, each (S, nd)."""
    scene = model.scene
    value = driver_values(scene)
    scale = driver_scale(scene)
    rate = np.array([d.rate for d in scene.drivers], dtype=float) * scale
    acc = np.array([d.acceleration for d in scene.drivers], dtype=float) * scale
    S = value.shape[0]
    return value, value * scale, np.broadcast_to(rate, (S, len(rate))).copy(), np.broadcast_to(acc, (S, len(acc))).copy()
