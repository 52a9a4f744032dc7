"""The knobs of the ladder: which solver settings and step counts a scene is measured at."""
from __future__ import annotations

import dataclasses as dc

import numpy as np

from ..kinematics.plan import METHODS
from ..scene import Scene
from ..scene.tables import LogData, TimeSweep
from ..scene.timing import MIN_SMOOTHING_SAMPLES


# The ladder. Step counts are multiples of the scene's own number of intervals.
FULL = dict(
    tol=(1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14),
    max_iter=(1, 2, 3, 5, 25),
    fd_steps=(0.25, 0.5, 1, 2, 4),
    predictor_steps=(1 / 16, 0.25, 1, 4),
    friction_velocity_scale=(1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8),
)


QUICK = dict(
    tol=(1e-2, 1e-4, 1e-8, 1e-12, 1e-14),
    max_iter=(2, 25),
    fd_steps=(1, 2),
    predictor_steps=(0.25, 1),
    friction_velocity_scale=(1e-2, 1e-6),
)


#: friction's regularisation scale that is the exact sign law in float64 (tanh(v / 1e-300) is
#: +-1 for every |v| above 1e-284 and 0 at rest): the reference friction is measured against
EXACT_SIGN_SCALE = 1e-300

#: the reference's settings (extended checks add one Newton refinement step)
REFERENCE_SOLVER = dict(tol=1e-15, max_iter=50, jacobian="analytic", derivatives="linear",
                        predictor="second", method="newton")


def _with_solver(scene: Scene, **changes) -> Scene:
    return dc.replace(scene, solver=dc.replace(scene.solver, **changes))


def _with_steps(scene: Scene, steps: int) -> Scene:
    """Return ``scene`` swept over the same range with ``steps`` steps.

    A ``[time]`` scene keeps its first and last instant (:func:`resampled_instants`: a
    refinement by a whole factor keeps every instant it had, so a finer reference can be read at
    them); its drivers' laws, rates and logs are then evaluated at the new instants. Its
    measurements, sampled at the scene's own steps, are left out (the ladder measures the
    solver, not the fit to a log)."""
    if steps == scene.n_steps:
        return scene
    time = scene.time
    if time is not None:
        instants = resampled_instants(np.asarray(time.instants, dtype=float), steps)
        time = TimeSweep(float(instants[0]), float(instants[-1]), steps, None, None, instants)
    drivers = []
    for d in scene.drivers:
        to = d.to_value if d.step is None else d.from_value + (d.steps - 1) * d.step
        drivers.append(dc.replace(d, steps=steps, step=None, to_value=to))
    return dc.replace(scene, drivers=tuple(drivers), time=time, measurements=())


def resampled_instants(instants: np.ndarray, steps: int) -> np.ndarray:
    """(steps,) instants from the first of ``instants`` (S,) to its last: when ``steps - 1`` is
    a multiple ``k`` of ``S - 1``, each interval cut into ``k`` equal parts (every old instant
    kept exactly, however uneven a log's time stamps); else evenly spaced."""
    S = len(instants)
    if S >= 2 and steps >= 2 and (steps - 1) % (S - 1) == 0:
        k = (steps - 1) // (S - 1)
        parts = instants[:-1, None] + np.diff(instants)[:, None] * (np.arange(k) / k)
        return np.append(parts.ravel(), instants[-1])
    return np.linspace(instants[0], instants[-1], steps)


def _all_orders(scene: Scene) -> Scene:
    """Return ``scene`` asking for velocities and accelerations (so every order is measured)."""
    return dc.replace(scene, outputs=dc.replace(scene.outputs,
                                                kinematics=("velocity", "acceleration")))


KNOBS = ("tol", "max_iter", "jacobian", "linear_algebra", "derivatives", "predictor", "method",
         "log", "friction_velocity_scale")

#: the log knobs (a [time] scene driven by motion laws: each driver replaced by a log of its own
#: law): keep every k-th sample; smoothing lam in units of h^3 (h: the mean sample spacing)
LOG_EVERY = {False: (1, 2, 4, 8, 16), True: (1, 4)}
LOG_SMOOTHING_H3 = {False: (1e-2, 1.0, 1e2), True: (1.0,)}


def settings(scene: Scene, quick: bool = False, knobs=KNOBS) -> list[tuple[str, str, Scene, str]]:
    """Return the ladder's rows as (knob, value, scene variant, timed stage).

    ``knobs``: which of :data:`KNOBS` to include (all by default).
    """
    unknown = set(knobs) - set(KNOBS)
    if unknown:
        raise ValueError(f"unknown knob(s) {sorted(unknown)}; choose from {KNOBS}")
    ladder = QUICK if quick else FULL
    base = _all_orders(scene)
    # the Newton knobs measure the general path (method = "auto" may take closed-form dyads,
    # which have no tolerance, iterations, Jacobian or predictor)
    newton = _with_solver(base, method="newton")
    out = []
    if "tol" in knobs:
        for tol in ladder["tol"]:
            out.append(("tol", f"{tol:.0e}", _with_solver(newton, tol=tol), "positions"))
    if "max_iter" in knobs:
        for n in ladder["max_iter"]:
            out.append(("max_iter", str(n), _with_solver(newton, max_iter=n), "positions"))
    if "jacobian" in knobs:
        for jac in ("analytic", "finite_difference"):
            out.append(("jacobian", jac, _with_solver(newton, jacobian=jac), "positions"))
    if "linear_algebra" in knobs:  # the general path's one-step solves: dense or sparse LU
        for la in ("dense", "sparse"):
            out.append(("linear_algebra", la, _with_solver(newton, linear_algebra=la), "positions"))
    m = scene.n_steps - 1
    if m >= 2 and "derivatives" in knobs:
        out.append(("derivatives", "linear", _with_solver(newton, derivatives="linear"),
                    "derivatives"))
        fd = _with_solver(newton, derivatives="finite_difference")
        for n in _intervals(m, ladder["fd_steps"]):
            out.append(("derivatives", "finite_difference", _with_steps(fd, n + 1),
                        "derivatives"))
    if m >= 2 and "predictor" in knobs:
        for n in _intervals(m, ladder["predictor_steps"]):
            for pred in ("none", "first", "second"):
                out.append(("predictor", pred, _with_steps(_with_solver(newton, predictor=pred),
                                                           n + 1), "kinematics"))
    if "method" in knobs:
        for method in METHODS:  # every [solver] method (kinematics.plan)
            out.append(("method", method, _with_solver(base, method=method), "kinematics"))
    if "log" in knobs:
        out += log_settings(base, quick)
    if "friction_velocity_scale" in knobs and "friction" in scene.effects and scene.friction:
        from ..model import build_model

        size = build_model(scene).size  # the scale is a speed: these fractions of size per s
        for f in ladder["friction_velocity_scale"]:
            out.append(("friction_velocity_scale", f"{f:.0e}",
                        _with_solver(base, friction_velocity_scale=f * size), "forces"))
    return out


def log_settings(scene: Scene, quick: bool = False) -> list[tuple[str, str, Scene, str]]:
    """Rows measuring what driving from a log costs against the known motion law: for a
    ``[time]`` scene whose drivers follow laws (or rates), each driver replaced by a log
    sampled from its own law at every k-th instant (the last one kept), through the
    interpolating spline (``log_every``) or a smoothing one (``log_smoothing``, lam in seconds^3);
    the instants, and so the reference, stay the scene's. Empty for any other scene."""
    if scene.time is None or not all(d.timed in ("law", "rate") for d in scene.drivers):
        return []

    from ..model.drive import driver_motion

    law = driver_motion(scene).value  # (S, nd) in scene units
    t = np.asarray(scene.time.instants, dtype=float)
    S = len(t)

    def variant(k: int, smoothing: float) -> Scene:
        idx = np.unique(np.r_[np.arange(0, S, k), S - 1])
        columns = {d.name: law[idx, j].copy() for j, d in enumerate(scene.drivers)}
        log = LogData("law_samples", "(sampled from the motion laws)", "(in memory)", "t",
                      t[idx], columns, ("t", *columns))
        drivers = tuple(dc.replace(d, timed="log", log=("law_samples", d.name), scale=1.0,
                                   smoothing=smoothing, law=None) for d in scene.drivers)
        return dc.replace(scene, drivers=drivers, logs=tuple(scene.logs) + (log,))

    out = [("log_every", str(k), variant(k, 0.0), "kinematics") for k in LOG_EVERY[quick]
           if (S - 1) // k >= 3]
    h = float(np.mean(np.diff(t))) if S > 1 else 1.0
    if S >= MIN_SMOOTHING_SAMPLES:  # the smoothing spline's fewest samples
        out += [("log_smoothing", f"{f * h ** 3:.2e}", variant(1, f * h ** 3), "kinematics")
                for f in LOG_SMOOTHING_H3[quick]]
    return out


def _intervals(m: int, factors) -> list[int]:
    """Return the distinct interval counts ``round(m * f)`` (at least 2), in order."""
    seen = []
    for f in factors:
        n = max(2, int(round(m * f)))
        if n not in seen:
            seen.append(n)
    return seen
