"""The memory a run needs, estimated from the scene's counts before any work (:func:`memory_needed`),
and the refusal of a sweep that would not fit (:func:`check_memory`): what ``run``, ``check``,
:func:`linkpipe.solve` and the streamed segments (:mod:`linkpipe.segments`) check first."""
from __future__ import annotations

from .errors import MemoryRefused
from .scene import Scene
from .spine import Stages


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
