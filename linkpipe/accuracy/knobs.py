"""The knobs of the ladder: which solver settings and step counts a scene is measured at."""
from __future__ import annotations

import dataclasses as dc


from ..scene import Scene


# The ladder. Step counts are multiples of the scene's own number of intervals.
FULL = dict(
    tol=(1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14),
    max_iter=(1, 2, 3, 5, 25),
    fd_steps=(0.25, 0.5, 1, 2, 4),
    predictor_steps=(1 / 16, 0.25, 1, 4),
)


QUICK = dict(
    tol=(1e-2, 1e-4, 1e-8, 1e-12, 1e-14),
    max_iter=(2, 25),
    fd_steps=(1, 2),
    predictor_steps=(0.25, 1),
)


#: the reference's settings (extended checks add one Newton refinement step)
REFERENCE_SOLVER = dict(tol=1e-15, max_iter=50, jacobian="analytic", derivatives="linear",
                        predictor="second", method="newton")


def _with_solver(scene: Scene, **changes) -> Scene:
    return dc.replace(scene, solver=dc.replace(scene.solver, **changes))


def _with_steps(scene: Scene, steps: int) -> Scene:
    """Return ``scene`` swept over the same range with ``steps`` steps."""
    drivers = []
    for d in scene.drivers:
        to = d.to_value if d.step is None else d.from_value + (d.steps - 1) * d.step
        drivers.append(dc.replace(d, steps=steps, step=None, to_value=to))
    return dc.replace(scene, drivers=tuple(drivers))


def _all_orders(scene: Scene) -> Scene:
    """Return ``scene`` asking for velocities and accelerations (so every order is measured)."""
    return dc.replace(scene, outputs=dc.replace(scene.outputs,
                                                kinematics=("velocity", "acceleration")))


KNOBS = ("tol", "max_iter", "jacobian", "derivatives", "predictor", "method")


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
        for method in ("auto", "newton", "dyads"):
            out.append(("method", method, _with_solver(base, method=method), "kinematics"))
    return out


def _intervals(m: int, factors) -> list[int]:
    """Return the distinct interval counts ``round(m * f)`` (at least 2), in order."""
    seen = []
    for f in factors:
        n = max(2, int(round(m * f)))
        if n not in seen:
            seen.append(n)
    return seen
