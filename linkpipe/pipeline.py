""":func:`solve`: a scene's whole sweep as the one segment of ``run``'s own path
(:func:`linkpipe.segments.stream`: stage 1, then forces -> status -> Result by the spine,
:mod:`.spine`), its measurements compared; what a run checks before any work (the memory
estimate, degrees of freedom, the start: :func:`preflight`)."""
from __future__ import annotations

import contextlib
import time as _time

import numpy as np
from threadpoolctl import threadpool_limits

from . import kinematics as kin
from .memory import check_memory
from .model import build_model
from .result import Result
from .scene import Scene, load_scene
from .segments import stream
from .spine import finish
from .stage1 import Kinematics, mobility_of
from .workers import DEFAULT_THREADS


def preflight(scene: Scene, segment: int | None = None, recorded_steps: int = 0):
    """Check what can be checked before solving; return (model, mobility).

    The scene's memory need (of a run in segments of ``segment`` steps keeping
    ``recorded_steps`` rows for its recording: :func:`linkpipe.memory.memory_needed`), its degrees of freedom
    against its drivers, and that the start assembles at the first driver value (SceneError
    otherwise): what ``check`` reports."""
    check_memory(scene, segment, recorded_steps)
    model = build_model(scene)
    mob = mobility_of(model)
    kin.sweep_reach(model)  # the start assembles (first steps out of the drawing's reach are data)
    if scene.dynamics is not None:  # its equations of motion hold (a mass for every driver)
        from .dynamics import equations_of

        equations_of(scene, model)
    return model, mob


def solve(scene: Scene | str, progress=None, threads: int | None = DEFAULT_THREADS,
          kinematics: Kinematics | None = None, wanted: frozenset | None = None) -> Result:
    """Run every stage the scene calls for and return the result (failed steps are data).

    ``progress``: an optional callable ``progress(stage_name)`` told as each stage starts
    (the CLI drives a tqdm bar with it on long sweeps). ``threads``: the BLAS thread pool's
    size while solving (threadpoolctl; None leaves the library's own). ``kinematics``: the
    ``Result.kinematics`` of a scene with the same geometry and drivers (only force parameters
    differ): stage 1 is reused, not solved again. ``wanted``: the names of the variables the
    caller will read (None: every one the scene calls for); the Lagrange multipliers and the
    forces only they give are solved only when one of them is wanted (a fit's trials read its
    measurements alone). The Result is built once, by :func:`linkpipe.spine.finish`.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    # overflow and 0/0 are data here, not warnings: such steps are marked (status.assign)
    # threads None: the pools as they are (no threadpoolctl call: finding the libraries costs
    # milliseconds, a study's variant-by-variant path sets the pool once for a whole batch)
    pools = (contextlib.nullcontext() if threads is None
             else threadpool_limits(limits=threads, user_api="blas"))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"), pools:
        return _solve(scene, progress, kinematics, wanted)


def _solve(scene: Scene, progress, kinematics: Kinematics | None = None,
           wanted: frozenset | None = None) -> Result:
    """``run``'s path over one segment (:func:`linkpipe.segments.stream`: the memory check,
    the spine), or :func:`finish` on a reused stage 1 (measurements compared there)."""
    if kinematics is None:
        return stream(scene, progress=progress, threads=None, segment=max(1, scene.n_steps),
                      wanted=wanted)
    tell = progress if callable(progress) else (lambda stage: None)
    seconds: dict[str, float] = {}
    t0 = _time.perf_counter()
    model = build_model(scene)  # a reused stage 1 was checked when it was solved
    seconds["model"] = _time.perf_counter() - t0
    return finish(scene, model, kinematics, wanted=wanted, reused=True, seconds=seconds,
                  tell=tell)
