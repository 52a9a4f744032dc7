"""Stage 1: solve a mechanism over its whole sweep (positions, velocities, accelerations).

The paths (``[solver] method``: "auto" takes the closed-form dyads where the scene decomposes
and every dyad stays clear of its singular shape, else the vectorised Newton path) in pieces:
:func:`dyad_plan` (the dyads and their branches), :func:`dyad_sweep` (their rows of any steps,
carried across segments), :func:`solve_with_newton`; the pipeline composes them over the
whole sweep or in segments (:class:`linkpipe.stage1.Stage1`), :func:`solve_sweep` over a
sweep of driver values alone (the benchmarks' kernel). Modules:
:mod:`.dyads` (closed-form fast path), :mod:`.vectorised` (coarse continuation + batched
Newton), :mod:`.continuation` (step by step), :mod:`.start` (the first step), :mod:`.roots`
(Newton and the rescues), :mod:`.step` (one-step float kernels), :mod:`.linalg` (sparse and
dense solves, condition), :mod:`.rates` (velocities, accelerations, link rates).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..model import Model
from .decompose import decompose
from .branches import refine_branches, set_branches
from .dyads import branch_check, solve_chain
from .sparse import no_engine_reason
from .start import OutOfReach, start_state, steps_out_of_reach, sweep_reach
from .vectorised import max_abs_phi, solve_newton
from ..status import NO_ASSEMBLY, OK


@dataclass(frozen=True)
class Sweep:
    """Stage 1's answer, step axis first: ``position`` (S, n_points, 2) NaN at failed steps;
    ``residual`` (S,) max |Φ| after the solve; ``iterations`` (S,) Newton iterations;
    ``status`` (S,) int8 (ok / no_assembly / not_converged: singular steps are found by the
    derivative stage); ``method`` the path that ran ("dyads" or "newton"); ``note`` why (the
    dyad chain, or why auto chose Newton); ``velocity``, ``acceleration`` (S, n_points, 2)
    where the path computed them (the dyads), else None."""

    position: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    method: str
    note: str
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None


def solve_with_dyads(model: Model, s, s_dot, s_ddot, order: int, forced: bool):
    """The closed-form fast path: ``(Sweep, "", start)``, or ``(None, note, start)`` with the
    reason the path does not apply (auto then runs Newton from ``start``, the assembled first
    step or None); ``forced`` (method = "dyads") raises SceneError where the scene does not
    decompose and keeps the dyads' own branches."""
    chain, note, start = dyad_plan(model, s, forced)
    if chain is None:
        return None, note, start
    sweep = dyad_sweep(model, chain, s, s_dot, s_ddot, order, forced)
    return (sweep, "", start) if sweep is not None else (None, DYADS_LEFT, start)


#: why auto leaves the dyads for Newton when a step fails the branch check
DYADS_LEFT = ("auto: a dyad passes near its singular configuration or cannot be assembled at "
              "some step; general Newton path")


def dyad_plan(model: Model, s, forced: bool):
    """``(chain, "", start)``: the scene's dyads with their branches set at the first step of
    ``s`` (its first two steps: (2, nd) at least), or ``(None, note, start)`` where the path
    does not apply (as :func:`solve_with_dyads`)."""
    sc = model.scene.solver
    chain = decompose(model)
    if not chain.ok:
        if forced:
            raise SceneError(model.scene.path, "solver", "method",
                             f'method = "dyads" but the mechanism does not decompose into '
                             f"closed-form dyads: {chain.reason}",
                             'use method = "auto" (closed-form dyads where the scene '
                             'decomposes, else Newton) or "newton"')
        return None, f"auto: {chain.reason}; general Newton path", None
    if not forced and sc.jacobian != "analytic":
        return None, f"auto: jacobian = {sc.jacobian!r} asks for Newton; general Newton path", None
    return chain, "", start_branches(model, chain, s)


def dyad_sweep(model: Model, chain, s, s_dot, s_ddot, order: int, forced: bool,
               carry: dict | None = None) -> Sweep | None:
    """The dyads' Sweep of the steps ``s`` (S, nd), or None where auto must leave them for
    Newton (a step fails :func:`branch_check`). ``carry``: kept across the segments of one
    sweep (:func:`solve_chain`), so that segments give the whole sweep's rows and checks."""
    tol_abs = model.tolerance()
    sw = solve_chain(chain, s, s_dot, s_ddot, order=order, gaps=not forced,
                     max_abs_phi=max_abs_phi(model), carry=carry)
    if not (forced or branch_check(chain, sw)):
        return None
    bad = sw.ok & ~(sw.residual <= 10 * tol_abs)  # a redundant constraint not met
    for arr in (sw.position, sw.velocity, sw.acceleration):
        if arr is not None and bad.any():
            arr[np.ix_(bad, model.moving)] = np.nan
    status = np.where(sw.ok & ~bad, OK, NO_ASSEMBLY).astype(np.int8)
    return Sweep(sw.position, sw.residual, np.zeros(s.shape[0], dtype=np.int32), status,
                 "dyads", chain.describe(), sw.velocity, sw.acceleration)


def start_branches(model: Model, chain, s: np.ndarray):
    """Assemble the start at s[0] (``start_state``: (q, slope)) and set each dyad's branch of
    ``chain`` from it; return the start."""
    sc = model.scene.solver
    start = start_state(model, s[0], model.tolerance(), sc.max_iter)
    q0, slope0 = start
    X0 = model.positions(q0[None])[0]
    set_branches(chain, X0, s[0])
    if slope0 is not None and s.shape[0] > 1:
        # a start on a dyad's singular shape (a change point) takes that dyad's sign a step
        # along the path the drawing was carried on
        q1 = q0 + slope0 @ (s[1] - s[0])
        refine_branches(chain, X0, s[0], model.positions(q1[None])[0], s[1])
    return start


def solve_with_newton(model: Model, s, note: str = "", start=None) -> Sweep:
    """The general path (coarse continuation + batched Newton; step by step for short
    sweeps): positions only, the derivative stage gives velocities and accelerations."""
    reason = no_engine_reason(model)
    if reason:  # a declared path: the summary and the HDF5 solver_note say it
        note = "; ".join(x for x in (note, f"no sparse engine ({reason}): sequential "
                                           "continuation on every step, dense derivatives") if x)
    out = solve_newton(model, s, start=start, skip=beyond_reach(model, s))
    q = out["q"]
    X = model.positions(np.where(np.isfinite(q), q, 0.0))
    X[~np.isfinite(q).all(axis=1)] = np.nan
    X[:, model.fixed] = model.start_position[model.fixed]
    return Sweep(X, out["residual"], out["iterations"], out["status"], "newton", note)


#: a step is beyond reach when a dyad's circles miss each other so far that the chord between
#: its roots would be imaginary by more than this fraction of the mechanism's size (a miss
#: of ~1e-7 of the size for radii of its order: far above any tolerance Newton meets)
BEYOND_REACH = 1e-3


def beyond_reach(model: Model, s: np.ndarray) -> np.ndarray | None:
    """(S,) bool: the steps of ``s`` (S, nd) that cannot assemble, by the closed-form dyads
    (a dyad whose circles, or circle and line, miss each other by :data:`BEYOND_REACH`; the
    branches do not matter), where the scene decomposes into them; None where it does not.
    The general path skips them inside a gap (:func:`.continuation.solve_positions`): a sweep
    that mostly cannot assemble then costs about what one that can does (issue 34)."""
    chain = decompose(model)
    if not chain.ok or not model.n_q or s.shape[0] < 3:
        return None
    sw = solve_chain(chain, s, order=0, gaps=True)
    return sw.miss < -(BEYOND_REACH * model.size) ** 2


def solve_sweep(model: Model, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray,
                order: int = 0) -> Sweep:
    """Solve a sweep by the scene's ``[solver] method``; driver values and rates ``s``,
    ``s_dot``, ``s_ddot`` (S, n_drivers) in internal units; ``order`` the highest derivative
    the scene needs (the dyads compute them on the way).

    ``auto`` takes the closed-form dyads when the scene decomposes and :func:`branch_check`
    finds that they follow Newton's branch, else the general path, with a note saying why;
    ``newton`` the general path; ``dyads`` requires the fast path.
    """
    return METHODS[model.scene.solver.method](model, s, s_dot, s_ddot, order)


def _auto(model: Model, s, s_dot, s_ddot, order: int = 0, required: bool = False) -> Sweep:
    """The closed-form dyads where they follow Newton's branch, else the general path (with
    the note saying why); ``required``: the dyads or a scene error."""
    sweep, note, start = solve_with_dyads(model, s, s_dot, s_ddot, order, required)
    return sweep if sweep is not None else solve_with_newton(model, s, note, start)


#: ``[solver] method`` -> the function :func:`solve_sweep` runs (model, s, s_dot, s_ddot,
#: order) -> Sweep; the scene's choices (``linkpipe.scene.tables``) are these keys
METHODS = {
    "auto": _auto,
    "dyads": lambda model, s, s_dot, s_ddot, order=0: _auto(model, s, s_dot, s_ddot, order, True),
    "newton": lambda model, s, s_dot, s_ddot, order=0: solve_with_newton(model, s),
}

from .pivots import solve_pivot_variants  # noqa: E402
from .rates import (AngleCarry, dense_chunk, dense_derivatives, derivatives, driver_motion, fd_derivatives,  # noqa: E402
                          link_angles_unwrapped, link_rates)
from .roots import newton  # noqa: E402
from .continuation import solve_positions  # noqa: E402
from .sparse_lu import SPARSE_FROM, linear_algebra_used  # noqa: E402

__all__ = ["solve_sweep", "beyond_reach", "METHODS", "OutOfReach", "steps_out_of_reach", "sweep_reach", "AngleCarry", "dyad_plan", "dyad_sweep", "DYADS_LEFT", "solve_pivot_variants", "start_branches", "Sweep", "solve_with_dyads", "solve_with_newton", "decompose",
           "start_state", "derivatives", "dense_derivatives", "driver_motion", "fd_derivatives",
           "link_angles_unwrapped", "link_rates", "newton", "solve_positions", "linear_algebra_used",
           "dense_chunk", "SPARSE_FROM"]
