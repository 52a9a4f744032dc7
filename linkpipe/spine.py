"""The spine: one path from a scene to its Results.

Stage 1 gives a sweep's solved motion segment by segment (:meth:`linkpipe.stage1.Stage1.parts`;
a short sweep is one segment); :func:`finish` turns each solved motion into a :class:`Result`:
forces, then every step's status, then the Result. Every producer of results goes through
:func:`finished`/:func:`finish`: :func:`linkpipe.solve` (one segment), ``run``'s streamed
segments (:mod:`linkpipe.segments`), a study's variants on one step axis (:mod:`linkpipe.study`)
and a fit's trials (``solve`` with a reused stage 1). :class:`Stages` says what a scene calls
for.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace

import numpy as np

from . import kinematics as kin
from . import stroke
from .forces import LAGRANGE_VARIABLES, compute_forces
from .errors import SceneError
from .forces.constants import ForceConstants
from .measure import compare
from .output_units import units_of
from .result import Result
from .scene import Scene
from .scene.timing import MEASURED_NEEDS
from .stage1 import RESTART, Kinematics, Stage1
from .stage1 import time_axis as stage1_time_axis
from .status import assign, code_counts
from .status import message as status_message


@dataclass(frozen=True)
class Stages:
    """What a scene calls for: kinematic orders and whether the force stage runs."""

    velocity: bool
    acceleration: bool
    forces: bool

    @classmethod
    def of(cls, scene: Scene) -> "Stages":
        if scene.dynamics is not None:  # the motion is computed: every order, and its forces
            return cls(velocity=True, acceleration=True, forces=True)
        eff = set(scene.effects)
        out = scene.outputs
        vectors = bool(out.vectors)
        measured = {MEASURED_NEEDS.get(m.of[0]) for m in scene.measurements}  # their rates
        acc = ("inertia" in eff or "acceleration" in out.kinematics or vectors
               or "acceleration" in measured)
        vel = (acc or "damping" in eff or "friction" in eff or "velocity" in out.kinematics
               or vectors or "velocity" in measured)
        return cls(velocity=vel, acceleration=acc, forces=bool(eff))

    @property
    def order(self) -> int:
        """The highest time derivative of the positions the scene needs (0, 1 or 2)."""
        return 2 if self.acceleration else 1 if self.velocity else 0

    @property
    def stages(self) -> tuple[str, ...]:
        return ("positions",) + (("velocities",) if self.velocity else ()) + (
            ("accelerations",) if self.acceleration else ()) + (("forces",) if self.forces else ())


def finished(scene: Scene, model, segment: int, seconds: dict, tell=None,
             wanted: frozenset | None = None):
    """Yield the Result of each segment of ``segment`` steps of ``scene``'s sweep, in step
    order (a segment's ``step_numbers`` set; None where it is the whole sweep), or
    :data:`~linkpipe.stage1.RESTART` where the sweep's plan leaves the closed-form dyads for
    Newton after some segments (they then come again from the first step). ``seconds``:
    stage name -> wall seconds, added to; ``tell(stage, done=None)``: told as each stage
    starts and after each segment; ``wanted``: as :func:`finish`'s."""
    tell = tell if callable(tell) else (lambda stage, done=None: None)
    if scene.dynamics is not None:  # another producer of a solved motion: integrated whole
        # imported here, not with the spine: scipy.integrate (and scipy.optimize with it)
        # costs about 0.35 s of every command's start; only a dynamics scene needs it
        from .dynamics import integrated

        motion, forces, time_axis = integrated(scene, model, tell, seconds)
        yield finish(scene, model, motion, seconds=seconds, time_axis=time_axis, forces=forces)
        return
    stage1 = Stage1(scene, model, Stages.of(scene), tell, seconds)
    time, time_note = stage1.time_axis
    S = stage1.n_steps
    for part in stage1.parts(segment):
        if part is RESTART:
            yield RESTART
            continue
        lo, hi, k = part
        whole = (lo, hi) == (0, S)
        yield finish(scene, model, k, wanted=wanted, seconds=seconds, tell=tell,
                     time_axis=(None if time is None else time[lo:hi], time_note),
                     step_numbers=None if whole else np.arange(lo, hi))
        if not whole:
            tell("segment", hi)


def finish(scene: Scene, model, motion: Kinematics, constants: ForceConstants | None = None,
           wanted: frozenset | None = None, *, reused: bool = False, seconds: dict | None = None,
           tell=None, time_axis: tuple | None = None,
           step_numbers: np.ndarray | None = None, forces=None) -> Result:
    """The Result of a solved motion: forces -> status -> Result, the one place it is done.

    ``motion``: the solved motion (:class:`linkpipe.stage1.Kinematics`: stage 1 of a whole
    sweep, of a segment of it, or of a study's variants on one (variant, step) row axis);
    ``constants``: the force tables' numbers and the mechanism's size where they are not the
    scene's (per row: :class:`linkpipe.forces.constants.ForceConstants`); ``wanted``: the names
    of the variables the caller will read (None: every one the scene calls for): the Lagrange
    multipliers and what only they give are solved only when one of them is wanted.
    ``reused``: ``motion`` is a stage 1 reused across calls (a fit's trials): the force stage
    keeps what it may in ``motion.force_cache``. ``seconds``: stage name -> wall seconds, added
    to; ``tell(stage)``: told as the force stage starts. ``time_axis``: (time, note) where
    ``motion`` holds a segment of the sweep, with the segment's ``step_numbers``. ``forces``:
    the force stage's result where the producer of the motion computed it (forward dynamics:
    the applied force in ``input_force`` and ``energy_error`` added); else computed here.

    A step's status is decided once (:func:`linkpipe.status.assign`): the stages' verdicts,
    the residual against the tolerance (of the mechanism's size, per row with ``constants``),
    and whether the stored kinematic arrays (:meth:`Kinematics.stored`) and the forces' arrays
    are finite. A whole sweep's ``[[measurements]]`` are compared with their computed
    counterparts (a scene with measurements is never solved in segments).
    """
    seconds = seconds if seconds is not None else {}
    if forces is None and Stages.of(scene).forces:
        if tell is not None:
            tell("forces")
        t0 = _time.perf_counter()
        lagrange = wanted is None or bool(wanted & LAGRANGE_VARIABLES)
        cache = motion.force_cache if reused and not lagrange and constants is None else None
        forces = compute_forces(model, motion.motion(), units_of(scene), constants,
                                lagrange=lagrange, cache=cache)
        seconds["forces"] = seconds.get("forces", 0.0) + _time.perf_counter() - t0
    size = None if constants is None else constants.size
    margin = stroke.margins(scene, motion.drive.value, motion.sweep.position,
                            None if constants is None else constants.gas_extended_length)
    strokes = stroke.status(model, margin, size)
    status = assign([motion.der["status"]] + ([forces.status] if forces else [])
                    + ([strokes] if strokes is not None else []),
                    motion.sweep.residual, model.tolerance(size=size),
                    forces.defined_arrays() if forces else [], finite=motion.finite)
    result = _result(scene, model, motion, forces, status, seconds, time_axis, step_numbers,
                     margin)
    return _with_measurements(result) if scene.measurements and step_numbers is None else result


def _result(scene: Scene, model, k: Kinematics, forces, status, seconds: dict,
            time_axis: tuple | None, step_numbers: np.ndarray | None,
            stroke_margin: np.ndarray | None = None) -> Result:
    """The Result of a solved stage 1 ``k``, its ``forces`` (or None) and final ``status``
    (S,): step-first arrays of any number of rows (a study's (variant, step) rows too)."""
    stages = Stages.of(scene)
    X, der = k.sweep.position, k.der
    value, drive = k.drive.value, k.drive
    time, time_note = stage1_time_axis(scene, value) if time_axis is None else time_axis
    return Result(
        scene=scene, model=model, mobility=k.mobility, driver_value=value, time=time,
        driver_velocity=drive.rate, driver_acceleration=drive.acceleration,
        time_note=time_note, reach_note=k.reach_note, position=X, link_angle=k.link_angle,
        status=status,
        residual=k.sweep.residual, iterations=k.sweep.iterations, condition=der["condition"],
        velocity=k.velocity, acceleration=k.acceleration,
        link_angular_velocity=k.link_rates[0], link_angular_acceleration=k.link_rates[1],
        velocity_residual=der["velocity_residual"] if stages.velocity else None,
        acceleration_residual=der["acceleration_residual"] if stages.acceleration else None,
        forces=forces.variables if forces else None,
        force_coords=forces.coords if forces else {},
        seconds=seconds, message=status_message(code_counts(status)),
        solver_method_used=k.sweep.method, solver_note=k.sweep.note,
        linear_algebra_used=kin.linear_algebra_used(model) if k.sweep.method == "newton" else "",
        kinematics=k, step_numbers=step_numbers, stroke_margin=stroke_margin)


def _with_measurements(result: Result) -> Result:
    """The result with its measurements beside their computed counterparts (linkpipe.measure);
    a measurement of a quantity the run did not compute is the scene's mistake."""
    try:
        return replace(result, measurements=compare(result))
    except KeyError as missing:
        m = next(m for m in result.scene.measurements if m.of[0] == missing.args[0])
        raise SceneError(result.scene.path, f'measurements "{m.name}"', "of",
                         f'"{m.of[0]}" is not computed by this scene',
                         "turn on what computes it: [analysis] effects for forces, "
                         '[outputs] kinematics = ["velocity", "acceleration"] for rates') from None
