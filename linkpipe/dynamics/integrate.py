"""Integrating the drivers' equations of motion over [dynamics] with scipy's adaptive solvers.

The state is ``y = (s, sd, W_drivers, W_other)``: the drivers' values and rates (internal
units) and two running works, the drivers' forces' ``integral F . sd dt`` and that of every effect
with no stored energy (damping, loads), so that ``energy_error`` compares like with like at
every instant. ``solve_ivp`` (DOP853, explicit 8th order, or Radau IIA, implicit 5th order for
stiff springs) chooses its steps to ``rtol``; the motion is read off its dense output at the
output instants.

An event ends the integration: where the mechanism cannot be assembled (or is singular) at a
stage's driver values the right-hand side is NaN, the step is rejected and retried 5x shorter,
so the solver closes in on the last instant the motion exists until its step falls below the
spacing of floating-point numbers there (scipy's "step size too small"): the event's time is
then known to about 1e-15 s x t, well inside ``rtol``. A stroke limit (a driver's ``stroke``,
once scenes have it) is a terminal event function located by scipy's root finder.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .equations import MotionEquations, NoAssembly
from .forcing import Forcing


@dataclass(frozen=True)
class Trajectory:
    """The integrated motion at the output instants ``t`` (S,): ``s``, ``sd`` (S, nd) internal
    units (NaN after an event), the works ``work_drivers`` and ``work_other`` (S,), ``solved``
    (S,) bool; ``end`` the time the integration reached, ``event`` what ended it early ("" at
    [dynamics] to), ``steps``, ``evaluations`` the solver's accepted steps and right-hand-side
    evaluations, ``method``, ``rtol``."""

    t: np.ndarray
    s: np.ndarray
    sd: np.ndarray
    work_drivers: np.ndarray
    work_other: np.ndarray
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
                                                    eqs.nonconservative_power(st)[0]]])

    sc = scales(scene, model)
    # the works are carried along but steer no step (atol huge): the motion's accuracy is
    # what rtol controls; they are as accurate as the steps the motion takes
    atol = np.concatenate([rtol * sc, rtol * sc, [1e300, 1e300]])
    y0 = np.concatenate([s0, sd0, [0.0, 0.0]])
    instants = np.asarray(dyn.instants, float)
    options = {"jac": finite_jacobian(rhs, nd, atol / rtol)} if method == "Radau" else {}
    sol = solve_ivp(rhs, (0.0, dyn.to), y0, method=method, rtol=rtol, atol=atol,
                    dense_output=True, **options)
    end = float(sol.t[-1])
    event = ""
    if sol.status == -1:
        at = ", ".join(f"{d.name} {v:.9g} {'deg' if d.kind == 'angle' else 'length units'}"
                       for d, v in zip(scene.drivers, sol.y[:nd, -1] / scale))
        event = (f"out of assembly (no assembled, non-singular position beyond it; {at})"
                 if at_event(failed, end) else f"the integrator stopped: {sol.message}")
    solved = instants <= end * (1 + 1e-15) if event else np.ones(len(instants), bool)
    Y = np.full((len(instants), len(y0)), np.nan)
    if solved.any():
        Y[solved] = sol.sol(np.minimum(instants[solved], end)).T
    Y[0] = y0  # the start exactly as given
    return Trajectory(instants, Y[:, :nd], Y[:, nd:2 * nd], Y[:, 2 * nd], Y[:, 2 * nd + 1],
                      solved, end, event, len(sol.t) - 1, int(sol.nfev), method, rtol)


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
    ``scale`` (2 nd + 2,): the states' scales; the step is sqrt(eps) times the larger of it and
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
