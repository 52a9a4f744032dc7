"""Integrating the drivers' equations of motion over [dynamics] with scipy's adaptive solvers.

The state is ``y = (s, sd, W_drivers, W_other, W_friction)``: the drivers' values and rates
(internal units) and three running works, the drivers' forces' ``integral F . sd dt``, that of
every effect with no stored energy (damping, loads) and friction's (the actuators' seals'), so
that ``energy_error`` compares like with like at every instant. ``solve_ivp`` (DOP853, explicit 8th order, or Radau IIA, implicit 5th order for
stiff springs) chooses its steps to ``rtol``; the motion is read off its dense output at the
output instants.

An event ends the integration: where the mechanism cannot be assembled (or is singular) at a
stage's driver values the right-hand side is NaN, the step is rejected and retried 5x shorter,
so the solver closes in on the last instant the motion exists until its step falls below the
spacing of floating-point numbers there (scipy's "step size too small"): the event's time is
then known to about 1e-15 s x t, well inside ``rtol``. A stroke limit (a driver's ``stroke``,
a gas spring's ``compressed_length`` / ``extended_length``) is a terminal event function of
the state, its margin (:func:`linkpipe.stroke.margins`) plus the tolerance beyond which a step
counts as out of stroke (:func:`linkpipe.stroke.allowance`), whose zero scipy locates on the
step's dense output (Brent's method to a few ulps: the event's time to the motion's own
accuracy, ``rtol``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .. import stroke
from ..output_units import units_of
from .equations import MotionEquations, NoAssembly
from .forcing import Forcing


@dataclass(frozen=True)
class Trajectory:
    """The integrated motion at the output instants ``t`` (S,): ``s``, ``sd`` (S, nd) internal
    units (NaN after an event), the works ``work_drivers``, ``work_other`` and
    ``work_friction`` (S,: friction's, at most zero), ``solved``
    (S,) bool; ``end`` the time the integration reached, ``event`` what ended it early ("" at
    [dynamics] to), ``steps``, ``evaluations`` the solver's accepted steps and right-hand-side
    evaluations, ``method``, ``rtol``."""

    t: np.ndarray
    s: np.ndarray
    sd: np.ndarray
    work_drivers: np.ndarray
    work_other: np.ndarray
    work_friction: np.ndarray
    solved: np.ndarray
    end: float
    event: str
    steps: int
    evaluations: int
    method: str
    rtol: float


def scales(scene, model) -> np.ndarray:
    """(nd,) each driver value's scale: 1 rad for an angle, the mechanism's size for a length;
    the absolute tolerances are ``rtol`` times these (rates: per second)."""
    return np.array([1.0 if d.kind == "angle" else model.size for d in scene.drivers])


def integrate(scene, eqs: MotionEquations, rtol: float | None = None,
              method: str | None = None) -> Trajectory:
    """Integrate ``scene``'s [dynamics] from its drivers' ``from`` and ``start_rate`` (``rtol``,
    ``method``: the scene's unless given: the accuracy ladder's rungs)."""
    dyn = scene.dynamics
    rtol = dyn.rtol if rtol is None else rtol
    method = dyn.method if method is None else method
    model = eqs.model
    scale = np.array([np.pi / 180 if d.kind == "angle" else 1.0 for d in scene.drivers])
    s0 = np.array([d.from_value for d in scene.drivers]) * scale
    sd0 = np.array([d.start_rate for d in scene.drivers]) * scale
    nd = len(s0)
    eqs.start(s0)
    forcing = Forcing(scene)
    failed = []

    def rhs(t, y):
        try:
            st = eqs.state(y[:nd], y[nd:2 * nd])
        except NoAssembly:
            failed.append(t)
            return np.full_like(y, np.nan)
        F = forcing.at(t)
        sdd = eqs.accelerations(st, F[None])[0]
        return np.concatenate([y[nd:2 * nd], sdd, [F @ y[nd:2 * nd],
                                                    eqs.nonconservative_power(st)[0],
                                                    eqs.friction_power(st)[0]]])

    sc = scales(scene, model)
    # the works are carried along but steer no step (atol huge): the motion's accuracy is
    # what rtol controls; they are as accurate as the steps the motion takes
    atol = np.concatenate([rtol * sc, rtol * sc, [1e300] * 3])
    y0 = np.concatenate([s0, sd0, [0.0] * 3])
    instants = np.asarray(dyn.instants, float)
    strokes = StrokeEvents(scene, eqs, scale)
    outside = strokes.outside(y0)
    if outside is not None:  # out of stroke at the start: nothing to integrate
        Y = np.full((len(instants), len(y0)), np.nan)
        Y[0] = y0
        return Trajectory(instants, Y[:, :nd], Y[:, nd:2 * nd], Y[:, 2 * nd],
                          Y[:, 2 * nd + 1], Y[:, 2 * nd + 2], instants <= 0.0, 0.0,
                          strokes.describe(outside, y0, "at the start"), 0, 0, method, rtol)
    options = {"jac": finite_jacobian(rhs, nd, atol / rtol)} if method == "Radau" else {}
    sol = solve_ivp(rhs, (0.0, dyn.to), y0, method=method, rtol=rtol, atol=atol,
                    dense_output=True, events=strokes.functions or None, **options)
    end = float(sol.t[-1])
    event = ""
    if sol.status == -1:
        at = ", ".join(f"{d.name} {v:.9g} {'deg' if d.kind == 'angle' else 'length units'}"
                       for d, v in zip(scene.drivers, sol.y[:nd, -1] / scale))
        event = (f"out of assembly (no assembled, non-singular position beyond it; {at})"
                 if at_event(failed, end) else f"the integrator stopped: {sol.message}")
    elif sol.status == 1:  # a terminal event: a stroke's end
        c = next(c for c, times in enumerate(sol.t_events) if len(times))
        end = float(sol.t_events[c][0])
        event = strokes.describe(c, sol.y_events[c][0])
    solved = instants <= end * (1 + 1e-15) if event else np.ones(len(instants), bool)
    Y = np.full((len(instants), len(y0)), np.nan)
    if solved.any():
        Y[solved] = sol.sol(np.minimum(instants[solved], end)).T
    Y[0] = y0  # the start exactly as given
    return Trajectory(instants, Y[:, :nd], Y[:, nd:2 * nd], Y[:, 2 * nd], Y[:, 2 * nd + 1],
                      Y[:, 2 * nd + 2], solved, end, event, len(sol.t) - 1, int(sol.nfev), method, rtol)


class StrokeEvents:
    """The stroke limits of a scene as terminal event functions of the state ``y`` (solve_ivp's
    ``events``): stroke c's margin (scene units: degrees for an angle driver) plus its
    allowance, falling through zero where the motion leaves the stroke. A gas spring's margin
    needs the positions at ``y`` (Newton from the last solved position); the margins of one
    ``y`` are computed once for all the functions."""

    def __init__(self, scene, eqs: MotionEquations, scale: np.ndarray):
        self.scene, self.eqs, self.scale = scene, eqs, scale
        self.labels = stroke.names(scene)
        self.n_drivers = sum(d.stroke is not None for d in scene.drivers)
        self.allowed = (stroke.allowance(eqs.model, (1, len(self.labels)))[0]
                        if self.labels else np.zeros(0))
        self._last = (None, None)
        self.functions = [self._function(c) for c in range(len(self.labels))]

    def _function(self, c: int):
        def g(t, y):
            return self.values(y)[c]
        g.terminal, g.direction = True, -1
        return g

    def positions(self, y: np.ndarray) -> np.ndarray:
        """X (1, P, 2) at ``y`` (the drawing where no stroke needs the positions)."""
        if len(self.labels) == self.n_drivers:
            return self.eqs.model.start_position[None]
        return self.eqs.positions(y[:len(self.scale)])

    def values(self, y: np.ndarray) -> np.ndarray:
        """(n_strokes,) margin + allowance at state ``y`` (NaN where it cannot be assembled)."""
        key = y[:len(self.scale)].tobytes()
        if self._last[0] != key:
            try:
                X = self.positions(y)
                g = stroke.margins(self.scene, (y[:len(self.scale)] / self.scale)[None], X)[0]
                g = g + self.allowed
            except NoAssembly:
                g = np.full(len(self.labels), np.nan)
            self._last = (key, g)
        return self._last[1]

    def outside(self, y: np.ndarray) -> int | None:
        """The first stroke that ``y`` is outside, or None."""
        if not self.labels:
            return None
        below = np.flatnonzero(self.values(y) < 0)
        return int(below[0]) if len(below) else None

    def describe(self, c: int, y: np.ndarray, when: str = "") -> str:
        """The summary's words on stroke ``c`` ended at state ``y``."""
        label = self.labels[c]
        value = y[:len(self.scale)] / self.scale
        length = units_of(self.scene)["length"] or "length units"
        if c < self.n_drivers:
            j = next(j for j, d in enumerate(self.scene.drivers) if d.name == label)
            d = self.scene.drivers[j]
            v, (lo, hi), unit = value[j], d.stroke, "deg" if d.is_angle else length
            what = f"driver {label}"
        else:
            sp = next(s for s in self.scene.springs if s.name == label)
            a, b = (self.scene.point_names.index(p) for p in sp.between)
            X = self.positions(y)[0]
            v, unit = float(np.hypot(*(X[b] - X[a]))), length
            lo = sp.compressed_length if sp.compressed_length is not None else -np.inf
            hi, what = sp.extended_length, f"gas spring {label}"
        end, bound = ("shortest", lo) if v - lo < hi - v else ("longest", hi)
        return (f"out of stroke{' ' + when if when else ''}: {what} at the {end} end of its "
                f"stroke ({bound:.9g} {unit}; {v:.9g} {unit} there)")


#: how far past the last instant reached a failed evaluation shows the event that stopped the
#: solver (its last attempts are ~1e-15 x t long; a failure farther on was a rejected trial)
EVENT_WINDOW = 1e-9


def at_event(failures, end: float) -> bool:
    """Whether one of the times ``failures`` at which the mechanism could not be evaluated lies
    just past ``end`` (within EVENT_WINDOW of it, relative): the event the solver closed in on."""
    return any(end <= t <= end + EVENT_WINDOW * max(abs(end), 1e-3) for t in failures)


def finite_jacobian(rhs, nd: int, scale: np.ndarray):
    """Radau's Jacobian of ``rhs`` by forward differences over the motion's 2 nd states (the
    works' columns are zero: nothing depends on them), each column taken backward where the
    forward step leaves the assembled region, and zero where neither exists (a state at an
    event: the step's Newton iterations then fail and the step shrinks, as for DOP853).
    ``scale`` (2 nd + 3,): the states' scales; the step is sqrt(eps) times the larger of it and
    |y|."""
    def jac(t, y):
        f0 = rhs(t, y)
        J = np.zeros((len(y), len(y)))
        for j in range(2 * nd):
            h = np.sqrt(np.finfo(float).eps) * max(abs(y[j]), scale[j])
            for step in (h, -h):
                y1 = y.copy()
                y1[j] += step
                col = (rhs(t, y1) - f0) / step
                if np.isfinite(col).all():
                    J[:, j] = col
                    break
        return J

    return jac
