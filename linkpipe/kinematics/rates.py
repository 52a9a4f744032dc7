"""Velocities, accelerations, condition numbers and the Jacobian's inverse of a solved sweep
(the "jacobian" stage), on the sparse engine or densely; finite-difference derivatives (the
links' angles and rates: :mod:`.angles`)."""
from __future__ import annotations

import functools

import numpy as np

from ..model import Model
from .linalg import (CHUNK, ESTIMATE_FROM, EXACT_WITHIN, SINGULAR_AT, condition_and_inverse,
                     estimated_condition, is_singular)
from . import block_kernel
from .affine import entries_at
from .sparse import engine
from .sparse_lu import uses_sparse
from ..status import OK, SINGULAR
from ..workers import for_chunks


def derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool,
                velocity: np.ndarray | None = None, acceleration: np.ndarray | None = None,
                need_influence: bool = True, chunk: int = CHUNK, dense: bool = False,
                fixed_per_row: bool = False, rows=None, residuals: bool = False,
                need_velocity: bool = True, compiled: bool = False, trig: dict | None = None):
    """Velocities, accelerations, condition and influence coefficients of a solved sweep: the
    one place they are solved, from one factorisation of each ok step's Jacobian.

    The factorisation is the sparse engine's (:class:`.sparse.Engine`: its block-triangular
    inverse up to ESTIMATE_FROM unknowns, its block solves beyond) or, for a model without an
    engine (or ``dense=True``, the accuracy ladder's independent check), the dense inverse
    (pseudo-inverse under redundant constraints). Per step: the condition ``|J|_1 |J^-1|_1``
    (sigma_1/sigma_n when redundant; estimated beyond ESTIMATE_FROM unknowns, exact near the
    threshold) flags SINGULAR steps (their derivatives NaN); ``qd = J^-1 (-Phi_t)``,
    ``qdd = J^-1 gamma`` (or the given ``velocity`` / ``acceleration`` (S, P, 2), e.g. the
    dyads', completed in place: NaN at every step not ok, zero at fixed points, so a sweep's
    rates are not held twice); with ``residuals`` (the scene's ``[solver] rate_residuals``)
    each step's rates put back into their linear equations, ``|J qd + Phi_t|`` and
    ``|J qdd - gamma|`` (max over rows), else no such re-check: that the engine's solves and
    the dyads' closed forms meet those equations to rounding is what ``tests/test_fast_path.py``
    and ``tests/test_kernels.py`` prove; with ``need_influence`` the influence coefficients
    ``dq/ds = -J^-1 Phi_s`` over the driver rows (what the force stage needs of the inverse).

    ``need_velocity`` False (a scene of positions only): no rates, only the condition (and
    the influence coefficients); velocity is then NaN at every moving point.

    ``fixed_per_row``: the fixed points of X differ row by row (a study's variants that move
    pivots): the engine's entries are read off the model's terms at X itself
    (:func:`entries_at`) instead of its affine map of the drawing. ``rows``: the model's rows
    with per-row constants (:class:`linkpipe.model.equations.Rows`; a study's variants of other
    link lengths), read at X's rows the same way.

    ``compiled``: the caller's :func:`.compiled.wanted` for the whole sweep (this call may be
    one segment of it): the exact condition without an inverse then comes from the compiled
    loop (:func:`.block_kernel.condition`, the entries made in it), where the engine's blocks
    are all 1x1 or 2x2; the same numbers to the bit, only sooner. ``trig``: {driver: (cos,
    sin) (S,)} of s's angle drivers, numpy's, where the caller has them (the dyads'), for that
    loop (else it takes numpy's cos and sin itself).

    Returns a dict: velocity, acceleration (or None), condition, velocity_residual,
    acceleration_residual (None without ``residuals``), status, influence (S, n_q, n_drivers) NaN where not ok, or None.
    """
    rcond = model.scene.solver.singular_rcond
    eng = None if dense else engine(model)
    # the inverse is formed only where a solve uses it: rates to solve, or influence
    # coefficients; else the exact condition comes from its column sums alone
    uses_inverse = (need_influence or (need_velocity and velocity is None)
                    or (need_acceleration and acceleration is None))
    factorise = (_dense_factors if eng is None else
                 _engine_factors(eng, model.n_q <= ESTIMATE_FROM, rcond,
                                 fixed_per_row or rows is not None, uses_inverse, compiled))
    S = X.shape[0]
    status = status.copy()
    condition = np.full(S, np.nan)
    influence = np.full((S, model.n_q, model.n_drivers), np.nan) if need_influence else None
    V = velocity if velocity is not None else np.full((S, model.n_points, 2), np.nan)
    A = (acceleration if acceleration is not None else np.full((S, model.n_points, 2), np.nan)
         ) if need_acceleration else None
    residuals = residuals and need_velocity
    vres = np.full(S, np.nan) if residuals else None
    ares = np.full(S, np.nan) if residuals and need_acceleration else None

    def work(lo: int, hi: int) -> None:  # rows lo .. hi - 1 of every output
        at = lo + np.flatnonzero(status[lo:hi] == OK)  # the chunk's ok steps
        if not len(at):
            return
        ok_rows = slice(lo, hi) if len(at) == hi - lo else at  # every step ok: views, not copies
        Xc, sc_ = X[ok_rows], s[ok_rows]
        rows_c = None if rows is None else rows.take(ok_rows)
        trig_c = trig and {j: (c[ok_rows], sn[ok_rows]) for j, (c, sn) in trig.items()}
        cond, regular_steps = factorise(model, Xc, sc_, rows_c, trig_c)
        condition[ok_rows] = cond
        sing = is_singular(cond, rcond)
        status[at[sing]] = SINGULAR
        good = ~sing
        if not good.any():
            return
        every = good.all()
        gi = ok_rows if every else at[good]
        solve, driver_columns, times_jacobian = regular_steps(good)
        Xg, sg = (Xc, sc_) if every else (Xc[good], sc_[good])
        rows_g = None if rows_c is None else rows_c if every else rows_c.take(good)
        if influence is not None:
            influence[gi] = driver_columns(model.phi_s(Xg, sg, rows_g))
        solve_v = need_velocity and velocity is None
        solve_a = need_acceleration and acceleration is None
        if not (solve_v or solve_a or residuals):
            return  # the given rates, not re-checked (see above)
        phit = -model.phi_t(Xg, sg, s_dot[gi], rows_g) if solve_v or residuals else None  # (g, m)
        # coordinates first, steps last (n, g): the engine's contiguous layout
        qd = solve(phit) if solve_v else model.q_of(velocity[gi]).T
        if residuals:
            vres[gi] = np.abs(times_jacobian(qd) - phit.T).max(axis=0)
        Vg = model.velocities(qd.T)
        if solve_v:
            V[gi] = Vg
        if solve_a or (residuals and need_acceleration):
            g = model.gamma(Xg, Vg, sg, s_dot[gi], s_ddot[gi], rows_g)  # (g, m)
            qdd = solve(g) if solve_a else model.q_of(acceleration[gi]).T
            if residuals:
                ares[gi] = np.abs(times_jacobian(qdd) - g.T).max(axis=0)
            if solve_a:
                A[gi] = model.velocities(qdd.T)

    for_chunks(work, S, chunk)  # chunks on the workers' threads: rows do not depend on them
    # every ok step's rates are written (given: the dyads' buffers hold zero at fixed points;
    # solved: model.velocities), so only the steps not ok need their fixed points zeroed: a
    # whole (S, P, 2) column write touches every cache line of the array (measured 10 ms per
    # array at 360k steps)
    bad = np.flatnonzero(status != OK)
    fixed = np.flatnonzero(model.fixed)
    for given, out, written in ((velocity, V, need_velocity), (acceleration, A, True)):
        if out is None:
            continue
        if given is not None:
            out[bad] = np.nan
        out[np.ix_(bad, fixed) if written else (slice(None), fixed)] = 0.0
    return dict(velocity=V, acceleration=A, condition=condition, velocity_residual=vres,
                acceleration_residual=ares, status=status, influence=influence)


def dense_derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool):
    """:func:`derivatives` on dense Jacobians (the independent check of the accuracy ladder),
    in chunks of steps whose (chunk, m, n) Jacobians and inverses stay small
    (:func:`dense_chunk`)."""
    return derivatives(model, X, s, s_dot, s_ddot, status, need_acceleration, dense=True,
                       chunk=dense_chunk(model))


#: doubles per dense (chunk, m, n) stack of Jacobians (32 MB): large mechanisms' dense work goes
#: in chunks of steps small enough for this, never as one (steps, m, n) array
DENSE_CHUNK_ENTRIES = 4_000_000


def dense_chunk(model: Model) -> int:
    """Steps per chunk of dense Jacobian work: CHUNK, or fewer where n_rows x n_q is large."""
    return max(1, min(CHUNK, DENSE_CHUNK_ENTRIES // max(1, model.n_rows * model.n_q)))


def _engine_factors(eng, with_inverse: bool, rcond: float, fixed_per_row: bool = False,
                    uses_inverse: bool = True, compiled: bool = False):
    """The sparse engine's factorisation of a chunk of k steps: (condition (k,),
    ``regular_steps(rows (k,) bool)`` -> the g picked steps' ``solve(b (g, m)) -> J^-1 b``
    (n, g), ``driver_columns(phi_s (g, nd)) -> -J^-1 Phi_s`` over the driver rows (g, n, nd)
    and ``times_jacobian(x (n, g)) -> J x`` (m, g)).

    ``with_inverse`` (small Jacobians): the inverse by one block solve per unit right-hand side,
    the cheaper way to their exact condition. Otherwise no inverse: block solves, and the
    condition estimated from a few of them (:func:`.linalg.estimate_inverse_norm1`), taken
    exactly where the estimate comes within POLISH_FROM of the singular threshold, so a step's
    status never rests on an estimate. ``fixed_per_row``: as :func:`derivatives` says.
    ``uses_inverse`` False (small Jacobians whose solves are not wanted): the exact condition
    from the inverse's column sums (:meth:`.sparse.Engine.inverse_column_sums`), no inverse;
    ``solve`` then takes block solves. ``compiled`` (with ``uses_inverse`` False): that exact
    condition from the compiled loop (:func:`.block_kernel.condition`, given the chunk's
    ``trig`` where :func:`derivatives` has it) where the engine's blocks allow it; its entries
    are made in the loop, and here only if a solve or a product wants them."""
    rows_d = slice(eng.model.n_constraints, eng.model.n_rows)
    kernel = compiled and with_inverse and not uses_inverse and block_kernel.supported(eng)

    def factorise(model: Model, X, s, rows=None, trig=None):
        E = entries_at(eng, X, s, rows) if fixed_per_row else None
        if kernel:
            inv, cond = None, block_kernel.condition(eng, E, X, s, trig)
        else:
            E = eng.entries_of(X, s) if E is None else E
            if with_inverse:
                inv = eng.inverse(E) if uses_inverse else None  # (n, m, k)
                cond = eng.condition(E, inv)
            else:
                inv = None
                cond = engine_condition(eng, E, rcond)

        def regular_steps(rows):
            @functools.cache
            def entries():  # the picked steps' entries, made on the first solve or product
                E_ = eng.entries_of(X, s) if E is None else E
                return E_ if rows.all() else E_[:, rows]

            def times_jacobian(x):
                return np.stack(eng.matvec(entries(), list(x)))

            if inv is not None:
                invg = inv if rows.all() else inv[:, :, rows]
                return (lambda b: np.einsum("imk,km->ik", invg, b),
                        lambda phi_s: -np.moveaxis(invg[:, rows_d, :], 2, 0) * phi_s[:, None, :],
                        times_jacobian)

            def driver_columns(phi_s):
                cols = []
                for j in range(phi_s.shape[1]):
                    b = [0.0] * model.n_rows
                    b[rows_d.start + j] = -phi_s[:, j]
                    cols.append(np.stack(eng.solve(entries(), b), axis=1))
                return np.stack(cols, axis=2)

            return (lambda b: np.stack(eng.solve(entries(), list(b.T))), driver_columns,
                    times_jacobian)

        return cond, regular_steps

    return factorise


def engine_condition(eng, E: np.ndarray, rcond: float, threshold: float = SINGULAR_AT,
                     within: float = EXACT_WITHIN) -> np.ndarray:
    """The condition (S,) of the engine's Jacobians, entries E (nnz, S), without the inverse:
    :func:`.linalg.estimated_condition` on the engine's block solves, exact (the inverse) at
    the steps near the thresholds. Large mechanisms (:func:`.sparse_lu.uses_sparse`) invert
    each diagonal block larger than 2x2 once for the estimate's dozen solves."""
    inv = eng.block_inverses(E) if uses_sparse(eng.model) else None
    return estimated_condition(eng.norm1(E), lambda b: eng.solve(E, b, inv),
                               lambda b: eng.solve_transpose(E, b, inv),
                               lambda near: eng.condition(E[:, near]), eng.model.n_q, E.shape[1],
                               rcond, threshold, within)


def _dense_factors(model: Model, X, s, rows=None, trig=None):
    """The dense factorisation of a chunk, as :func:`_engine_factors` returns it."""
    J = model.jacobian(X, s, rows)
    cond, inv = condition_and_inverse(J)  # inv (k, n, m)

    def regular_steps(rows):
        invg, Jg = inv[rows], J[rows]
        return (lambda b: np.einsum("sij,sj->is", invg, b),
                lambda phi_s: -invg[:, :, model.driver_rows] * phi_s[:, None, :],
                lambda x: np.einsum("sij,js->is", Jg, x))

    return cond, regular_steps


def fd_derivatives(X: np.ndarray, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray,
                   status: np.ndarray, need_acceleration: bool, time: np.ndarray | None = None):
    """Return velocities and accelerations (S, n_points, 2) by finite differences along the sweep.

    The shortcut many scripts take (the accuracy ladder compares it with the linear solves):
    dX/ds by second-order differences over the first driver's values (``np.gradient``),
    then V = dX/ds * s_dot and A = d2X/ds2 * s_dot^2 + dX/ds * s_ddot; with ``time`` (a
    [time] sweep, whose drivers may turn back or move on other laws) by differences in time:
    V = dX/dt, A = d2X/dt2. Steps next to a failed step are NaN.
    """
    if time is not None:
        ones = np.ones((len(time), 1))
        return fd_derivatives(X, time[:, None], ones, 0 * ones, status, need_acceleration)
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
