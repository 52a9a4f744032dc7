"""Stage 1 of many variants of one mechanism that differ in where its fixed points (pivots) are
drawn, on one long (variant, step) row axis: the closed-form dyads with the pivots as per-row
columns, then the derivative stage on the same rows (a study's geometry variants:
:mod:`linkpipe.study.pivots`).

Moving a pivot leaves every constant of the model's rows (link lengths, local coordinates,
guides) as it is when the scene gives them or derives them from other points (the study
checks it), so each variant's equations are the model's with its own fixed points, and those
are read from the positions X (S, n_points, 2) row by row everywhere except in the sparse
engine's affine map, whose entries then take the coefficients each variant's own engine has
(:func:`.affine.entries_at`, read off :meth:`Model.jacobian_terms` at probe configurations).
Variants that also differ in link lengths (or local coordinates) carry their own constants
the same way: the model's rows with per-row arrays (:class:`linkpipe.model.equations.Rows`,
built by the model's own code, :func:`linkpipe.model.rows.variant_rows`), read by every
equation, the engine's coefficients and the dyads' constants (:func:`.decompose.chain_at`)
row by row.

A variant is solved here only where its own run (``linkpipe.solve``) would take the same path
with the same branches (:func:`solve_pivot_variants` returns which): its drawing is assembled
at the first driver value directly (no carry), every step assembles, no dyad comes near its
singular shape (:func:`.dyads.branch_check` per variant), and its start, Newton's from the
drawing, lies on the base scene's branches: each two-root dyad's point at the first step is
closer to its drawn place (|dx| + |dy|) than the distance between the dyad's two roots over
``BRANCH_MARGIN`` (the margin :func:`.dyads.branch_check` asks of a step's move), and not on
its singular shape; and that start is the one its own run assembles: Newton from each
drawing, by the one loop with the own run's tolerance and limit, for all variants at once
(:func:`own_starts`), converges to the chain's first step (a drawing far from its solved start
may lead Newton to the mirror assembly, or nowhere: the nearness test alone let such variants
through); and its own sparse engine has the base's pattern of entries and coefficients
(:func:`.affine.same_pattern`), so that its Jacobian entries are its own to the last bit. The
others are left to their own runs.
"""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..status import NO_ASSEMBLY, OK
from .affine import same_pattern
from .branches import BRANCH_MARGIN, branch_value
from .decompose import DyadChain
from .dyads import solve_chain
from .angles import link_angles_unwrapped, link_rates
from .rates import derivatives
from .sparse import engine
from .start import carry_steps
from .linalg import lin_solve
from .newton import iterate
from .vectorised import max_abs_phi


def solve_pivot_variants(model: Model, chain: DyadChain, pivots: np.ndarray, sizes: np.ndarray,
                         s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray, order: int,
                         need_influence: bool, rows=None):
    """Stage 1 of V variants whose drawings ``pivots`` (V, n_points, 2) differ in their fixed
    points, of length scales ``sizes`` (V,); the sweep ``s``, ``s_dot``, ``s_ddot`` (S, nd) in
    internal units; ``chain`` the base scene's dyads with its branches set. Variants that also
    differ in link lengths (or local coordinates) give ``rows``, their model's rows with (V,)
    arrays where they differ (:func:`linkpipe.model.rows.variant_rows`), and ``chain`` with
    their dyads' (V,) constants (:func:`.decompose.chain_at`; which variants decompose alike
    is the caller's to check).

    Returns ``(usable (V,) bool, arrays)``: which variants' own runs take these dyads with these
    branches (module doc), and on the V x S rows (variant, step): s, s_dot, s_ddot (R, nd),
    position, residual, status, link_angle, the derivative stage's dict, link rates and
    ``rows`` (the model's rows at the R rows, or None)."""
    V, S = pivots.shape[0], s.shape[0]
    sc = model.scene.solver
    sR, sdR, sddR = (np.tile(a, (V, 1)) for a in (s, s_dot, s_ddot))
    fixed_rows = np.repeat(pivots, S, axis=0)
    variant_of_row = np.repeat(np.arange(V), S)
    rows_R = None if rows is None else rows.take(variant_of_row)
    sw = solve_chain(chain.take(variant_of_row), sR, sdR, sddR, order=order, gaps=True,
                     max_abs_phi=max_abs_phi(model), fixed_position=fixed_rows, period=S,
                     rows=rows_R)
    size_rows = np.repeat(sizes, S)
    usable = sw.ok.reshape(V, S).all(axis=1) & (sw.gap.reshape(V, S) > 0).all(axis=1)
    usable &= carry_steps(model, pivots, s[0], sizes)[1] <= 1.0
    usable &= _on_base_branches(chain, sw.position[::S], pivots, s[0], sizes)
    # and the start its own run assembles is the chain's first step: Newton from each drawing
    converged, starts = own_starts(model, rows, pivots, s[0], sizes)
    usable &= converged & (np.abs(starts - sw.position[::S]).max(axis=(1, 2))
                           <= START_MATCH * sizes)
    eng = engine(model)
    if eng is not None:  # the variant's own engine: the same entries and coefficient pattern
        usable &= same_pattern(eng, pivots, rows)
    bad = sw.ok & ~(sw.residual <= 10 * model.tolerance(size=size_rows))  # a redundant row not met
    for arr in (sw.position, sw.velocity, sw.acceleration):
        if arr is not None and bad.any():
            arr[np.ix_(bad, model.moving)] = np.nan
    status = np.where(sw.ok & ~bad, OK, NO_ASSEMBLY).astype(np.int8)
    X = sw.position
    Xz = X if np.isfinite(X).all() else np.where(np.isfinite(X), X, 0.0)
    der = derivatives(model, Xz, sR, sdR, sddR, status, order >= 2, velocity=sw.velocity,
                      acceleration=sw.acceleration, need_influence=need_influence,
                      fixed_per_row=True, rows=rows_R, need_velocity=order >= 1,
                      residuals=sc.rate_residuals)
    velocity = der["velocity"] if order >= 1 else None
    acceleration = der["acceleration"] if order >= 2 else None
    rates = link_rates(model, X, velocity, acceleration) if order >= 1 else (None, None)
    return usable, dict(s=sR, s_dot=sdR, s_ddot=sddR, position=X, residual=sw.residual,
                        status=status, link_angle=link_angles_unwrapped(model, X, period=S, s=sR,
                                                                    drawings=pivots),
                        der=der, velocity=velocity, acceleration=acceleration, link_rates=rates,
                        rows=rows_R)


#: a variant's own start and the chain's first step are the same root when they agree to this
#: part of the size (the other roots, mirror images, lie a fraction of the size away; both
#: meet the tolerance, 1e-12 of the size by default)
START_MATCH = 1e-6


def own_starts(model: Model, rows, drawn: np.ndarray, s0: np.ndarray, sizes: np.ndarray):
    """``(converged (V,), X (V, n_points, 2))``: the start each variant's own run assembles at
    the first driver value ``s0`` (nd,) directly from its drawing ``drawn`` (V, n_points, 2):
    the first attempt of :func:`.start.start_state` (Newton by the one loop,
    :func:`.newton.iterate`, with its tolerance and its iteration limit), for all V at once on
    columns, each with its own rows (``rows``: (V,) arrays where they differ, or None) and size.
    A variant that does not converge here (its own run then goes on to least squares, or
    refuses the scene) is left to its own run by the caller."""
    V = drawn.shape[0]
    sc = model.scene.solver
    s_rows = np.tile(s0, (V, 1))

    def positions(qT):
        X = drawn.copy()
        X[:, model.moving] = qT.T.reshape(V, -1, 2)
        return X

    def residual(qT):
        return model.phi(positions(qT), s_rows, rows).T

    def correction(qT, F):
        return lin_solve(model.jacobian(positions(qT), s_rows, rows), -F.T).T

    qT = np.ascontiguousarray(model.q_of(drawn).T)
    with np.errstate(all="ignore"):
        qT, _, _, converged = iterate(residual, correction, qT, model.tolerance(size=sizes),
                                      max(sc.max_iter, 50), sizes)
    return converged, positions(qT)


def _on_base_branches(chain: DyadChain, X: np.ndarray, drawn: np.ndarray, s0: np.ndarray,
                      sizes: np.ndarray) -> np.ndarray:
    """(V,) True where each variant's first step X (V, P, 2), solved on the chain's branches,
    is the start its own run assembles from its drawing ``drawn`` (V, P, 2) (module doc)."""
    ok = np.ones(X.shape[0], dtype=bool)
    for st in chain.steps:
        val = branch_value(st, X, s0)
        if val is None:
            continue
        p = st.targets[0]
        move = np.abs(X[:, p, 0] - drawn[:, p, 0]) + np.abs(X[:, p, 1] - drawn[:, p, 1])
        ok &= (val * st.sign > 1e-9 * sizes) & ((2 * val) ** 2 > (BRANCH_MARGIN * move) ** 2)
    return ok
