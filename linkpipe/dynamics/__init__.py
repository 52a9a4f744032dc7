"""Forward dynamics: the motion the scene's forces make (``[dynamics]``).

:mod:`.equations` the drivers' equations of motion from the model (Φ, Φq, γ) and the force
effects (mass matrix, generalized forces); :mod:`.forcing` the drivers' own forces over time;
:mod:`.integrate` scipy's adaptive integrators, events; :mod:`.finish` the trajectory made into
a :class:`~linkpipe.result.Result` through the pipeline's own force -> status -> Result path.
The formulation and why: docs/dynamics.md.
"""
from __future__ import annotations

import time as _time

import numpy as np

from ..errors import SceneError
from ..model import build_model
from .equations import MotionEquations, NoAssembly
from .integrate import Trajectory, integrate

__all__ = ["integrated", "equations_of", "integrate", "MotionEquations", "Trajectory"]

#: the reduced mass matrix's condition beyond which the mechanism counts as mass-free
MASS_RCOND = 1e-12


def equations_of(scene, model=None) -> MotionEquations:
    """The scene's equations of motion, checked: a mechanism whose reduced mass matrix is
    singular at the start (a driver moves no mass) is the scene's mistake (SceneError)."""
    model = model if model is not None else build_model(scene)
    eqs = MotionEquations(scene, model)
    scale = np.array([np.pi / 180 if d.kind == "angle" else 1.0 for d in scene.drivers])
    s0 = np.array([d.from_value for d in scene.drivers]) * scale
    eqs.start(s0)
    try:
        st = eqs.state(s0, np.array([d.start_rate for d in scene.drivers]) * scale)
    except NoAssembly:
        raise SceneError(scene.path, f'drivers "{scene.drivers[0].name}"', "from",
                         "the start is singular (the drivers do not fix the mechanism there): "
                         "its motion cannot be integrated from it",
                         "start the drivers a little away from this pose") from None
    Mr = eqs.reduced(st)[0][0]
    sv = np.linalg.svd(Mr, compute_uv=False)
    if not (sv[-1] > MASS_RCOND * max(sv[0], np.finfo(float).tiny)):
        free = [d.name for j, d in enumerate(scene.drivers)
                if not Mr[j, j] > MASS_RCOND * max(sv[0], np.finfo(float).tiny)]
        which = f' (driver{"s" if len(free) > 1 else ""} {", ".join(free)})' if free else ""
        raise SceneError(scene.path, "masses", "mass",
                         f"the mechanism's mass matrix is singular{which}: a driver moves no "
                         "mass, so a force would accelerate it without bound",
                         "give the links the drivers move a [[masses]] entry (mass, and "
                         "inertia for a link turning about its centre)")
    return eqs


def integrated(scene, model, tell=lambda stage: None, seconds: dict | None = None):
    """Integrate ``scene``'s [dynamics]: its solved motion, ``(motion, forces, time_axis)``
    (a :class:`~linkpipe.stage1.Kinematics` of the output instants, the force stage with the
    applied ``input_force`` and ``energy_error``, and ``(time, note)``), which the spine
    finishes into a Result like any other (:func:`linkpipe.spine.finished`)."""
    from ..stage1 import mobility_of
    from .finish import describe, forces_of, kinematics_of

    seconds = {} if seconds is None else seconds
    t0 = _time.perf_counter()
    eqs = equations_of(scene, model)
    seconds["model"] = seconds.get("model", 0.0) + _time.perf_counter() - t0
    tell("integration")
    t0 = _time.perf_counter()
    traj = integrate(scene, eqs)
    seconds["integration"] = _time.perf_counter() - t0
    tell("positions")
    t0 = _time.perf_counter()
    k, F, state = kinematics_of(eqs, traj, mobility_of(model))
    seconds["positions"] = _time.perf_counter() - t0
    tell("forces")
    t0 = _time.perf_counter()
    forces = forces_of(eqs, k, F, state, traj)
    seconds["forces"] = _time.perf_counter() - t0
    return k, forces, (traj.t, describe(traj, forces.variables["energy_error"][1]))
