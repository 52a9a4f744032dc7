"""How the positions of a sweep are found: the one place that chooses the method.

``[solver] method`` names a :class:`Method` of :data:`METHODS`: "auto" takes the closed-form
dyads where the scene decomposes and every dyad stays clear of its singular shape (checked
segment by segment: :func:`.dyads.branch_check`), else the general path (coarse continuation
+ batched Newton); "dyads" requires the fast path and keeps its own branches; "newton" is the
general path. A :class:`Plan` holds that choice for one sweep and switches itself from the
dyads to Newton where auto must leave them (:attr:`Plan.used`): the pipeline's stage 1
(:class:`linkpipe.stage1.Stage1`), studies and the benchmarks' kernel (:func:`solve_sweep`)
all ask a Plan for positions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..model import Model
from ..status import NO_ASSEMBLY, NO_INPUT, OK
from . import compiled
from .branches import refine_branches, set_branches
from .decompose import decompose
from .dyads import branch_check, solve_chain
from .sparse import no_engine_reason
from .start import OutOfReach, start_state, sweep_reach
from .vectorised import max_abs_phi, solve_newton


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
    #: the dyads' own links' directions (S, n_links) and (angular velocity, acceleration or
    #: None), from their pass (:func:`.dyads.solve_chain` with ``links``), or None; exact at
    #: ok steps only (the others are recomputed from the final arrays: linkpipe.stage1)
    link_angle: np.ndarray | None = None
    link_rates: tuple | None = None
    #: {angle driver: (cos, sin) (S,)}, numpy's, where the dyads computed them (else None)
    trig: dict | None = None

    def rows(self, rows: slice) -> "Sweep":
        """The steps ``rows`` of this sweep (positions and statuses; a general path's)."""
        return Sweep(*(getattr(self, f)[rows] for f in
                       ("position", "residual", "iterations", "status")), self.method, self.note)


@dataclass(frozen=True)
class Method:
    """One ``[solver] method``: whether it tries the closed-form dyads, and whether it
    requires them (``forced``: the dyads or a SceneError, their own branches kept, no branch
    check, so no switch to Newton)."""

    dyads: bool
    forced: bool = False

    @property
    def branch_checked(self) -> bool:
        """The dyads are taken where :func:`.dyads.branch_check` finds that they follow
        Newton's branch, else the general path (auto: a sweep begun on the dyads may leave
        them)."""
        return self.dyads and not self.forced


#: ``[solver] method`` -> how the positions are found; the scene's choices
#: (``linkpipe.scene.tables``) are these keys
METHODS = {"auto": Method(dyads=True), "newton": Method(dyads=False),
           "dyads": Method(dyads=True, forced=True)}

#: why auto leaves the dyads for Newton when a step fails the branch check
DYADS_LEFT = ("auto: a dyad passes near its singular configuration or cannot be assembled at "
              "some step; general Newton path")


def dyad_plan(model: Model, s, forced: bool):
    """``(chain, "", start)``: the scene's dyads with their branches set at the first step of
    ``s`` (its first two steps: (2, nd) at least), or ``(None, note, start)`` with the reason
    the path does not apply (auto then runs Newton from ``start``, the assembled first step or
    None); ``forced`` (method = "dyads") raises SceneError where the scene does not decompose."""
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
               carry: dict | None = None, links: bool = False,
               compiled: bool = False) -> Sweep | None:
    """The dyads' Sweep of the steps ``s`` (S, nd), or None where auto must leave them for
    Newton (a step fails :func:`branch_check`). ``carry``: kept across the segments of one
    sweep (:func:`solve_chain`), so that segments give the whole sweep's rows and checks;
    ``links``: the links' directions and rates from the same pass; ``compiled``: by the
    compiled loop (the same numbers: :func:`solve_chain`)."""
    tol_abs = model.tolerance()
    sw = solve_chain(chain, s, s_dot, s_ddot, order=order, gaps=not forced,
                     max_abs_phi=max_abs_phi(model), carry=carry, links=links,
                     compiled=compiled)
    if not (forced or branch_check(chain, sw)):
        return None
    bad = sw.ok & ~(sw.residual <= 10 * tol_abs)  # a redundant constraint not met
    for arr in (sw.position, sw.velocity, sw.acceleration):
        if arr is not None and bad.any():
            arr[np.ix_(bad, model.moving)] = np.nan
    status = np.where(sw.ok & ~bad, OK, NO_ASSEMBLY).astype(np.int8)
    return Sweep(sw.position, sw.residual, np.zeros(s.shape[0], dtype=np.int32), status,
                 "dyads", chain.describe(), sw.velocity, sw.acceleration, sw.link_angle,
                 sw.link_rates, sw.trig)


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


class Plan:
    """How the positions of one sweep of driver values ``s`` (S, nd, internal units) are
    found: :data:`METHODS` [``[solver] method``], the steps solved (those that have every
    driver value, from the first the drawing reaches: the first ``unreached`` are no_assembly,
    ``reach_note`` says why) and, on the dyads, their branches set at the first solvable steps
    and carried from segment to segment (:meth:`restart` starts again from the first step).

    :meth:`positions` gives the Sweep of any steps; where auto must leave the dyads it solves
    the positions of the whole sweep by the general path itself and says so in :attr:`used`
    (the steps given before are then not those of the sweep's own path: start again from the
    first segment)."""

    def __init__(self, model: Model, s: np.ndarray):
        self.model, self.s = model, s
        self.method = METHODS[model.scene.solver.method]
        self.compiled = compiled.wanted(len(s))  # the dyads' compiled loop on a long sweep
        self.present = np.isfinite(s).all(axis=1)  # False where a logged value is missing
        self.solvable, self.unreached, self.reach_note = self.present, 0, ""
        try:
            self._choose()
        except OutOfReach:
            self.unreached, self.reach_note = sweep_reach(model)
            self.solvable = self.present & (np.arange(len(s)) >= self.unreached)
            self._choose()
        self.restart()

    def _choose(self) -> None:
        """The dyads and their branches at the first solvable steps, or the general path."""
        model = self.model
        self.newton: Sweep | None = None
        self.chain, self.note, self.start = None, "", None
        first = np.flatnonzero(self.solvable)[:2]
        if not len(first):
            self.newton = self._unreached(_where_present(model, self.s, self.solvable))
        elif self.method.dyads:
            self.chain, self.note, self.start = dyad_plan(model, self.s[first],
                                                          self.method.forced)
        if self.chain is None and self.newton is None:
            self._use_newton()

    def restart(self) -> None:
        """Segments from the first step again (the dyads' margins carried from one to the next)."""
        self.chain_carry: dict = {}

    @property
    def used(self) -> str:
        """The path the positions come from: "dyads" or "newton"."""
        return "dyads" if self.chain is not None else "newton"

    def _use_newton(self) -> None:
        """The general path's positions of the whole sweep; segments then slice them."""
        note = self.note or (DYADS_LEFT if self.chain is not None else "")
        self.chain = None
        if self.solvable.all():
            self.newton = solve_with_newton(self.model, self.s, note, self.start)
        else:
            self.newton = self._unreached(_where_present(self.model, self.s, self.solvable,
                                                         note, self.start))

    def _unreached(self, sweep: Sweep, lo: int = 0) -> Sweep:
        """``sweep`` (of steps ``lo`` ..) with the steps out of the drawing's reach that have
        every driver value no_assembly (they were left out of the solve, as no_input)."""
        n = min(self.unreached - lo, len(sweep.status))
        if n > 0:
            sweep.status[:n] = np.where(self.present[lo:lo + n], NO_ASSEMBLY, sweep.status[:n])
        return sweep

    def positions(self, rows: slice, s_dot: np.ndarray, s_ddot: np.ndarray,
                  order: int, links: bool = False) -> Sweep:
        """The Sweep of steps ``rows`` (``s_dot``, ``s_ddot``: the drivers' rates of those
        rows; ``order``: the highest derivative the dyads compute on the way; ``links``: the
        dyads give the links' directions and rates from the same pass too). Where auto leaves
        the dyads here, :attr:`used` turns to "newton" and the general path's rows come."""
        if self.chain is not None:
            sweep = self._dyad_rows(rows, s_dot, s_ddot, order, links)
            if sweep is not None:
                return sweep
            self._use_newton()
            self.restart()
        return self.newton.rows(rows)

    def _dyad_rows(self, rows: slice, sd, sdd, order: int, links: bool) -> Sweep | None:
        model, chain, forced = self.model, self.chain, self.method.forced
        present, s = self.solvable[rows], self.s[rows]
        if present.all():
            return dyad_sweep(model, chain, s, sd, sdd, order, forced, self.chain_carry, links,
                              self.compiled)
        idx = np.flatnonzero(present)
        sub = (dyad_sweep(model, chain, s[idx], sd[idx], sdd[idx], order, forced,
                          self.chain_carry, compiled=self.compiled) if len(idx) else None)
        if sub is None and len(idx):
            return None
        if sub is None:  # no step of these solved: every one out of reach or without a value
            return self._unreached(_where_present(model, s, present), rows.start)
        return self._unreached(_scattered(model, sub, idx, len(present)), rows.start)


def solve_sweep(model: Model, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray,
                order: int = 0) -> Sweep:
    """The positions of a whole sweep by the scene's ``[solver] method`` (a :class:`Plan`
    over one segment): driver values and rates ``s``, ``s_dot``, ``s_ddot`` (S, n_drivers) in
    internal units; ``order`` the highest derivative the scene needs (the dyads compute them
    on the way). The benchmarks' kernel: stage 1's positions without the rest of stage 1."""
    return Plan(model, s).positions(slice(0, s.shape[0]), s_dot, s_ddot, order)


def _scattered(model, sub: Sweep, idx: np.ndarray, S: int) -> Sweep:
    """A Sweep of S steps with ``sub``'s rows at ``idx`` (steps that have every driver value);
    the others no_input, every moving quantity NaN."""
    X = np.full((S, model.n_points, 2), np.nan)
    X[:, model.fixed] = model.start_position[model.fixed]
    full = dict(position=X, residual=np.full(S, np.nan), iterations=np.zeros(S, np.int32),
                status=np.full(S, NO_INPUT, np.int8))
    for key in ("position", "residual", "iterations", "status"):
        full[key][idx] = getattr(sub, key)
    for key in ("velocity", "acceleration"):
        if getattr(sub, key) is not None:
            full[key] = np.full((S, model.n_points, 2), np.nan)
            full[key][idx] = getattr(sub, key)
    return Sweep(**full, method=sub.method, note=sub.note)


def _where_present(model, s, present, note: str = "", start=None) -> Sweep:
    """The general path on the steps that have every driver value (the others: status
    no_input, every moving quantity NaN). The continuation runs from one present step to the
    next, so a missing sample leaves its neighbours' solutions as they would be without it."""
    S, idx = s.shape[0], np.flatnonzero(present)
    if not len(idx):
        X = np.full((S, model.n_points, 2), np.nan)
        X[:, model.fixed] = model.start_position[model.fixed]
        return Sweep(X, np.full(S, np.nan), np.zeros(S, np.int32),
                     np.full(S, NO_INPUT, np.int8), method="none",
                     note="no step has every driver value")
    return _scattered(model, solve_with_newton(model, s[idx], note, start), idx, S)
