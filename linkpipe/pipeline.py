""":func:`solve`: a scene's whole sweep as one segment of the spine (:mod:`.spine`: stage 1,
then forces -> status -> Result), its measurements compared; what a run checks before any work
(the memory estimate, degrees of freedom, the start: :func:`preflight`)."""
from __future__ import annotations

import contextlib
import time as _time

import numpy as np
from threadpoolctl import threadpool_limits

from . import kinematics as kin
from .model import build_model
from .result import Result
from .spine import Stages, finish, finished
from .stage1 import Kinematics, mobility_of
from .errors import MemoryRefused
from .scene import Scene, load_scene


#: what a run needs beside its stored arrays: the interpreter and libraries (~0.25 GB measured
#: with numpy, scipy, pandas, h5py and rerun loaded), a recording of at most --rrd-max-steps
#: rows, and one chunk's working set
FIXED_BYTES = 600 * 2**20
#: the stored arrays times this: the transients of the stages around them (each stage's own
#: work goes in chunks of steps; measured peaks: benchmarks/bench_logs.py prints both)
TRANSIENT_FACTOR = 1.3


def bytes_per_step(scene: Scene) -> int:
    """The bytes a run keeps per step, from the scene's counts alone (before any work): every
    array the Result stores (docs/output-format.md) and what stage 1 hands to the force stage
    (driver values in internal units, influence coefficients), 8 bytes a number."""
    stages = Stages.of(scene)
    P, L, nd = len(scene.points), len(scene.links), max(1, len(scene.drivers))
    n_q = 2 * sum(not p.fixed for p in scene.points)
    rates = (2 * P + L + 1) * (int(stages.velocity) + int(stages.acceleration))
    numbers = 2 * P + L + 6 + 6 * nd + rates  # positions, angles, residuals, driver values
    if stages.forces:
        joints = sum(len(link.points) for link in scene.links)
        fixed = sum(p.fixed for p in scene.points)
        numbers += (n_q * nd + 2 * nd + len(scene.effects) + L + 2 * joints + 2 * fixed
                    + 5 * len(scene.springs) + 3 * len(scene.torsion_springs)
                    + len(scene.sliders) + 1)
    return 8 * (numbers + 2 * len(scene.measurements))


def whole_sweep_bytes_per_step(scene: Scene) -> int:
    """The bytes per step a run in segments (:mod:`linkpipe.segments`) keeps for the whole
    sweep: the drivers' motion in scene and internal units, the time axis, and the general
    path's positions with their residuals, iterations and statuses (the dyads need none, but
    the path is known only once solved: an upper bound)."""
    nd, P = max(1, len(scene.drivers)), len(scene.points)
    n_q = 2 * sum(not p.fixed for p in scene.points)
    return 8 * (6 * nd + 2) + 1 + 8 * (2 * P + n_q + 1) + 5


def memory_needed(scene: Scene, segment: int | None = None, recorded_steps: int = 0) -> int:
    """An upper bound of a run's peak memory in bytes (checked against measured peaks in
    benchmarks/bench_memory.py): the whole sweep's arrays, or with ``segment`` (steps) a run in
    segments: one segment's arrays, what stays whole, and the ``recorded_steps`` rows it keeps
    for its recording (the fixed part holds a recording of up to the default 100,000 rows of a
    small scene; more rows, or larger ones, count here)."""
    if segment is None or segment >= scene.n_steps:
        return int(scene.n_steps * bytes_per_step(scene) * TRANSIENT_FACTOR) + FIXED_BYTES
    return int(segment * bytes_per_step(scene) * TRANSIENT_FACTOR
               + scene.n_steps * whole_sweep_bytes_per_step(scene)
               + recorded_steps * bytes_per_step(scene)) + FIXED_BYTES


def available_memory() -> int | None:
    """Return the memory the kernel says is available (bytes), or None where it does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(scene: Scene, segment: int | None = None, recorded_steps: int = 0) -> None:
    """MemoryRefused (a SceneError) when the sweep would need more memory than is available
    (before any work: a run that the kernel kills half-way writes nothing). What the steps
    need is compared with the memory still free: the fixed part of the estimate (libraries,
    the recording) is held already or bounded, and no number of steps could remove it."""
    need = memory_needed(scene, segment, recorded_steps)
    avail = available_memory()
    if avail is not None and need - FIXED_BYTES > avail:
        first = scene.drivers[0] if scene.drivers else None
        driver = first.name if first else ""
        key = "step" if first is not None and first.step is not None else "steps"
        raise MemoryRefused(scene.path, f'drivers "{driver}"', key,
                         f"{scene.n_steps:,} steps of {len(scene.points)} points need about "
                         f"{need / 2**30:.1f} GiB of memory; {avail / 2**30:.1f} GiB is available",
                         ("use a larger step" if key == "step" else "use fewer steps")
                         + ", or split the sweep into several scenes")


def preflight(scene: Scene, segment: int | None = None, recorded_steps: int = 0):
    """Check what can be checked before solving; return (model, mobility).

    The scene's memory need (of a run in segments of ``segment`` steps keeping
    ``recorded_steps`` rows for its recording: :func:`memory_needed`), its degrees of freedom
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


#: BLAS threads while a scene is solved: its solves are many small systems (stacks of 2x2 to
#: few-hundred-square blocks), where a multi-threaded BLAS only adds overhead (measured:
#: benchmarks/bench_threads.py; docs/performance.md)
DEFAULT_THREADS = 1


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
    """The spine over one segment (:func:`linkpipe.spine.finished`), or :func:`finish` on a
    reused stage 1 (measurements compared there)."""
    tell = progress if callable(progress) else (lambda stage: None)
    seconds: dict[str, float] = {}
    t0 = _time.perf_counter()
    if kinematics is None:  # a reused stage 1 was checked when it was solved
        check_memory(scene)
    model = build_model(scene)
    seconds["model"] = _time.perf_counter() - t0
    if kinematics is None:
        result = next(finished(scene, model, max(1, scene.n_steps), seconds, tell, wanted))
    else:
        result = finish(scene, model, kinematics, wanted=wanted, reused=True, seconds=seconds,
                        tell=tell)
    return result
