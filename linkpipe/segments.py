"""A long sweep solved, written and recorded segment by segment: a run's memory is set by the
size of a segment, not by the length of the sweep (issue 16).

``python -m linkpipe run`` solves a sweep of more than one segment's steps
(:func:`segment_steps`: a power of two from 16,384 to 131,072 steps, as many as
:data:`SEGMENT_BYTES` of the scene's stored arrays allow) in segments: stage 1 of the segment
(:class:`linkpipe.stage1.Stage1`, which carries the dyads' branch margins, the link angles'
unwrapping and the torsion springs' turns across segments), then its forces and statuses, then
every sink (the HDF5 writer, :class:`linkpipe.stores.hdf5.SweepWriter`) takes the segment's
rows, and :class:`Sampled` keeps the rows the recording will hold (a uniform stride of steps
that ``linkpipe.stores.rrd.plan`` sets on the first segment: at most ``--rrd-max-steps`` rows
and ``--rrd-max-mb``) and the whole sweep's :class:`~linkpipe.result.Totals`. What stays
whole: the drivers' motion (a few numbers per step) and, on the general Newton path, the
positions (its coarse continuation spans the sweep).

A segmented run writes the same file as the whole sweep solved at once, to the last bit
(``tests/test_segments.py``; segments of other sizes than ``run``'s agree to rounding). Where
auto's closed-form dyads fail the branch check in a later segment, the whole sweep goes to
the general path (as it does when solved at once) and the sinks start again from the first
step (:data:`RESTART`). Scenes with measurements (their RMS
spans the sweep) or finite-difference derivatives (they read neighbouring steps) are solved
whole: :func:`why_whole`.
"""
from __future__ import annotations

import contextlib
import time as _time
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from .memory import bytes_per_step, check_memory
from .model import build_model
from .result import Result, Totals, combine_flags
from .scene import Scene
from .spine import finished
from .stage1 import RESTART  # what stream's sinks are told where the sweep starts again
from .workers import DEFAULT_THREADS

#: the bytes of stored arrays one segment may hold (its transients come on top: about 1.3 x):
#: 12 MB, 16,384-step segments of the crank-rocker with every rate (A/B, 8 runs of a 360k-step
#: sweep to .h5: 32,768-step segments 0.96x the time of 131,072-step ones, 102 MB peak instead
#: of 126 MB, and 16,384-step ones 0.99x of 32,768 at 91 MB: arrays that small are reused by
#: the allocator instead of mapped afresh, and the writer's last part, written after the
#: solve, is shorter)
SEGMENT_BYTES = 12 * 2**20
#: the fewest and most steps of a segment: powers of two, so that a segment holds whole chunks
#: of every stage whose rows depend on where its chunks start (the derivatives' and the dyads'
#: 8,192, the force stage's 16,384; link rates and the finiteness checks, elementwise, give
#: the same rows in chunks of any size). Each step's numbers are then computed in the
#: same batch as in the whole sweep, so they agree to the last bit (a batched solve's last few
#: steps take a different SIMD path, with other rounding, than the ones before them)
MIN_SEGMENT_STEPS, MAX_SEGMENT_STEPS = 2**14, 2**17


def segment_steps(scene: Scene) -> int:
    """The steps of one segment of ``scene``'s sweep: the largest power of two whose stored
    arrays fit :data:`SEGMENT_BYTES`, within [MIN_SEGMENT_STEPS, MAX_SEGMENT_STEPS]."""
    fit = max(1, SEGMENT_BYTES // bytes_per_step(scene))
    return int(min(MAX_SEGMENT_STEPS, max(MIN_SEGMENT_STEPS, 2 ** int(np.log2(fit)))))


def why_whole(scene: Scene) -> str:
    """Why ``scene``'s sweep is solved whole rather than in segments ("" when it can be)."""
    if scene.dynamics is not None:
        return "dynamics: the motion is integrated over the whole run"
    if scene.measurements:
        return "measurements: their RMS and maximum span the sweep"
    if scene.solver.derivatives == "finite_difference":
        return "finite-difference derivatives read the neighbouring steps"
    return ""


def steps_per_segment(scene: Scene) -> int:
    """The segment size :func:`stream` uses for ``scene``: :func:`segment_steps`, or the whole
    sweep where it is shorter or :func:`why_whole` says so."""
    if why_whole(scene):
        return scene.n_steps
    return min(scene.n_steps, segment_steps(scene))


def segments(scene: Scene, segment: int, seconds: dict, progress=None,
             wanted: frozenset | None = None):
    """Yield the Result of each segment of ``segment`` steps of ``scene``'s sweep, in step
    order (``step_numbers`` set), or :data:`RESTART` where the sweep goes to the general path
    after some segments (the segments then come again from the first step): the spine,
    :func:`linkpipe.spine.finished`, as :func:`linkpipe.solve` takes it over one segment."""
    t0 = _time.perf_counter()
    model = build_model(scene)
    seconds["model"] = seconds.get("model", 0.0) + _time.perf_counter() - t0
    yield from finished(scene, model, segment, seconds, progress, wanted)


class Sampled:
    """The rows of a streamed sweep its recording keeps (every ``stride``-th step: ``plan(first
    segment's Result, n_steps=) -> (stride, why)`` decides on the first segment) and the whole
    sweep's :class:`Totals` and per-sweep flags (the ``*_unique`` variables, which a segment
    without an ok step does not give: the minimum over the segments that give them, as the
    force stage takes them over its chunks)."""

    def __init__(self, n_steps: int, plan):
        self.n_steps, self.plan = n_steps, plan
        self.restart()

    def restart(self) -> None:
        self.parts: list[Result] = []
        self.totals: Totals | None = None
        self.flags: dict = {}
        self.stride, self.why = None, ""

    def add(self, part: Result) -> None:
        if self.stride is None:
            self.stride, self.why = self.plan(part, n_steps=self.n_steps)
        lo = int(part.step_numbers[0])
        self.parts.append(part.strided(np.arange((-lo) % self.stride, part.n_steps, self.stride)))
        totals = Totals.of(part)
        self.totals = totals if self.totals is None else self.totals.merged(totals)
        combine_flags(self.flags, part.forces or {})

    def result(self, seconds: dict) -> Result:
        """The kept rows as one Result, with the whole sweep's totals and flags. Its rows'
        own figures (``n_steps``, ``n_ok``, ``status_counts()``) are the kept rows'; the
        sweep's are ``totals`` (and ``message``)."""
        first = self.parts[0]
        rows = {name: np.concatenate([getattr(p, name) for p in self.parts])
                for name in Result.PER_STEP if getattr(first, name) is not None}
        forces = None
        if first.forces:
            forces = {name: (dims, np.concatenate([p.forces[name][1] for p in self.parts]), unit)
                      for name, (dims, _, unit) in first.forces.items() if dims[:1] == ("step",)}
            forces.update(self.flags)
        return replace(first, **rows, forces=forces, seconds=seconds, message=self.totals.message,
                       step_numbers=np.concatenate([p.step_numbers for p in self.parts]),
                       sweep_totals=self.totals,
                       sampled=(self.stride, self.why) if self.stride > 1 else None)


def stream(scene: Scene, sinks=(), recording=None, progress=None,
           threads: int | None = DEFAULT_THREADS, segment: int | None = None,
           between=None, check: bool = True, wanted: frozenset | None = None) -> Result:
    """Solve ``scene`` in segments (:func:`steps_per_segment`, or ``segment`` steps), handing
    each segment's Result to every sink (``sink.add(part)``; ``sink.restart()`` at
    :data:`RESTART`; ``sink.finish(result)`` at the end, ``sink.stage`` names its seconds);
    return the rows a recording keeps with the whole sweep's totals and seconds
    (:class:`Sampled`). ``recording``: ``plan(first segment, n_steps=) -> (stride, why)``, the
    recording's stride of steps (``linkpipe.stores.rrd.plan`` with the CLI's caps), or None
    for no recording (one row kept).

    A sweep of one segment (short, or solved whole: :func:`why_whole`) is
    :func:`linkpipe.solve`'s Result (solve is this function over one segment): every row, its
    measurements compared. ``between``: called after each segment (the CLI stops there on a
    signal whose exception a finaliser swallowed). ``check``: the memory check first (the CLI
    makes it itself, before its progress bar). ``wanted``: the variables the caller will read
    (:func:`linkpipe.spine.finish`)."""
    segment = segment or steps_per_segment(scene)
    S = scene.n_steps
    seconds: dict[str, float] = {}
    tell = progress if callable(progress) else (lambda stage, done=None: None)
    stages = {sink.stage for sink in sinks}
    whole = segment >= S
    if check:
        check_memory(scene, segment, S if recording is not None and not whole else 0)
    kept = Sampled(S, recording if recording is not None else (lambda part, n_steps: (n_steps, "")))
    pools = (contextlib.nullcontext() if threads is None
             else threadpool_limits(limits=threads, user_api="blas"))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"), pools:
        for part in segments(scene, segment, seconds, tell, wanted):
            if part is RESTART:
                kept.restart()
                for sink in sinks:
                    sink.restart()
                tell("the general path, from the first step", 0)
                continue
            if whole:  # the sweep's own Result, every row (as solve gives it)
                result = replace(part, seconds=dict(seconds))
                _hand(sinks, "add", result, seconds, tell)
                _hand(sinks, "finish", result, seconds, tell)
                return replace(result, seconds=seconds)
            kept.add(part)
            _hand(sinks, "add", part, seconds, tell)
            if between is not None:
                between()
    # the file's seconds_<stage> are the solve's (as a whole sweep's file), the writers' after
    result = kept.result({k: v for k, v in seconds.items() if k not in stages})
    _hand(sinks, "finish", result, seconds, tell)
    return replace(result, seconds=seconds)


def _hand(sinks, method: str, result: Result, seconds: dict, tell) -> None:
    """Call ``method`` of every sink with ``result``, timing it under the sink's stage name."""
    for sink in sinks:
        tell(sink.stage)
        t0 = _time.perf_counter()
        getattr(sink, method)(result)
        seconds[sink.stage] = seconds.get(sink.stage, 0.0) + _time.perf_counter() - t0
