"""Write a :class:`~linkpipe.result.Result` as a Rerun recording (``.rrd``), rerun-sdk 0.41.

Entity paths and timelines follow ``docs/output-format.md``. Everything that changes per
step goes out columnar with ``send_columns`` (one call per entity, never one per step);
geometry that does not change is logged once as static. Steps where a point is NaN (failed
assembly) log an empty batch for the entities that need it, which clears them at that step.

The 2D view of Rerun has +y pointing down; a static ``Transform3D`` on ``mechanism`` flips
it so the mechanism appears y-up. The logged data are the scene's own coordinates.

Modules: :mod:`.mechanism` (points, links and plates, actuators, guides, springs, traces,
velocity and acceleration arrows), :mod:`.forces` (force arrows, one row per kind),
:mod:`.series` (plots and solver series), :mod:`.columns` (timelines, each driver's value as
one, Arrow arrays), :mod:`.geometry` (sizes, scales, plate outlines), :mod:`.legend` (the 2D
view's legend: each arrow kind's colour and scale), :mod:`.layout` (blueprint), :mod:`.style`
(the palette: links muted, each arrow kind one saturated hue).
"""
from __future__ import annotations

import errno
import os
import pathlib
import socket
import sys
import urllib.parse
import uuid

import numpy as np
import rerun as rr

from .. import OutputError, atomic_path
from ...errors import LinkpipeError
from ...result import stride_of
from ...status import NO_ASSEMBLY
from . import forces, legend, mechanism, series
from .columns import driver_timeline, driver_timelines, sender
from .forces import FORCE_FRACTION, KINDS, MIN_FRACTION, drawn_arrows, force_arrows, force_legend
from .geometry import ARROW_FRACTION, arrow_legend, arrow_scales, mechanism_size, outline
from .layout import active_timeline, blueprint, mechanism_bounds, mechanism_title, view_bounds
from .mechanism import path_of
from .series import PLOTTED, SOLVER, log10_residual

__all__ = ["write", "log_result", "blueprint", "path_of", "arrow_scales", "arrow_legend",
           "mechanism_size", "force_arrows", "force_legend", "driver_timeline", "outline",
           "log10_residual", "view_bounds", "mechanism_title", "KINDS", "PLOTTED", "SOLVER",
           "ARROW_FRACTION", "FORCE_FRACTION", "APPLICATION_ID", "MIN_FRACTION", "drawn_arrows",
           "driver_timelines", "active_timeline", "mechanism_bounds"]

APPLICATION_ID = "linkpipe"


#: the most steps a recording keeps; past it a uniform stride (the HDF5 keeps every step)
MAX_STEPS = 100_000
#: the size cap ``--rrd-max-mb`` asks for (none by default: the contract's only default cap is
#: ``MAX_STEPS``; 100,000 steps of a scene with every effect are ~90 MB, which the viewer
#: loads): a sweep whose recording would be larger keeps a uniform stride of steps
MAX_BYTES = 0
#: a bound of any scene's bytes per recorded step (measured: 0.5 kB for a four-bar's
#: kinematics, 0.9 kB with every effect, 0.9 kB for the basketball goal): a sweep whose steps
#: times this fit the cap is recorded whole without measuring its size
MAX_BYTES_PER_STEP = 5_000
#: what a file adds to the bytes recorded into memory: the default blueprint (the layout of
#: the views) and the footer (measured: 70 kB for the crank-rocker with every effect)
FILE_OVERHEAD = 128 * 1024
#: the part of the size cap the plan fills
SIZE_MARGIN = 0.9
#: the samples of steps recorded into memory to measure a recording's fixed and per-step bytes
SAMPLE_STEPS = (250, 1000)


def recorded_bytes(result) -> int:
    """The bytes of ``result``'s recording, recorded into memory (the encoding a file gets)."""
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"size-{uuid.uuid4().hex}")
    memory = stream.memory_recording()
    try:
        log_result(stream, result)
    finally:  # drained even when interrupted: a sink dropped with data warns on stderr
        recorded = memory.drain_as_bytes()
    return len(recorded)


def plan(result, max_steps: int | None = MAX_STEPS, max_bytes: int | None = MAX_BYTES,
         n_steps: int | None = None):
    """Return (stride, why): the uniform stride of steps a recording keeps and, when it is
    more than 1, why ("--rrd-max-steps N" or the size cap). The size of a long sweep's
    recording is measured on two evenly spaced samples of ``result``'s rows
    (:data:`SAMPLE_STEPS`): their difference gives the bytes per step, the rest is fixed; the
    stride keeps the whole recording within ``max_bytes`` (0/None: no size cap). ``n_steps``:
    the sweep's steps where ``result`` holds only some (a sweep streamed in segments plans on
    its first segment: :mod:`linkpipe.segments`); default ``result.n_steps``."""
    n = result.n_steps if n_steps is None else n_steps
    stride, why = stride_of(n, max_steps), f"--rrd-max-steps {max_steps:,}" if max_steps else ""
    if max_bytes and n * MAX_BYTES_PER_STEP > max_bytes:
        m = result.n_steps
        samples = sorted({min(k, m) for k in SAMPLE_STEPS})
        measured = [(len(rows), recorded_bytes(result.strided(rows))) for rows in
                    (np.unique(np.linspace(0, m - 1, k).round().astype(int)) for k in samples)]
        (k0, b0), (k1, b1) = measured[0], measured[-1]
        per_step = max(b1 - b0, 0) / (k1 - k0) if k1 > k0 else b1 / max(k1, 1)
        fixed = max(b0 - per_step * k0, 0.0) + FILE_OVERHEAD
        # 10 % kept free: denser steps compress a little worse than the samples (measured:
        # a recording planned for 1 MB from the samples came out at 1.06 MB)
        room = max(SIZE_MARGIN * max_bytes - fixed, per_step)  # at least one step
        by_size = int(np.ceil(n * per_step / room)) if per_step > 0 else 1
        if by_size > stride:
            stride, why = by_size, f"{max_bytes / 1e6:,.6g} MB at most"
    return stride, why


def write(result, path, spawn: bool = False, connect: str | None = None,
          max_steps: int | None = MAX_STEPS, max_bytes: int | None = MAX_BYTES,
          h5_written: bool = True) -> str | None:
    """Write the recording of ``result`` to ``path`` (``None``: no file) and optionally stream it.

    ``spawn=True`` starts a Rerun viewer and streams to it; ``connect`` streams to a running
    viewer at that address (``rerun+http://host:port/proxy``). The file is written to a
    temporary name and renamed into place when complete. A sweep longer than ``max_steps``, or
    whose recording would exceed ``max_bytes``, is recorded at a uniform stride of steps
    (:func:`plan`), said in a static ``info`` text entity; the step timeline keeps the sweep's
    own step numbers; ``h5_written``: whether the run's .h5 (which keeps every step) exists,
    said in that note. Returns what was kept ("every 4th step (91 of 361; ...)"), or
    None when every step was.
    """
    if path is None and not spawn and not connect:
        return None
    # a sweep solved in segments comes with its rows at the stride :func:`plan` set on its
    # first segment (result.sampled)
    (base, why), stride = result.sampled or (1, ""), 1
    if not result.sampled:
        stride, why = plan(result, max_steps, max_bytes)
    info = kept = None
    if stride * base > 1:
        rows = np.arange(0, result.n_steps, stride)
        kept = (f"every {_ordinal(stride * base)} step ({len(rows):,} of "
                f"{result.totals.n_steps:,}; {why})")
        info = f"This recording keeps {kept}; " + (
            "the .h5 keeps every step." if h5_written else
            "no file of this run keeps every step (it wrote no .h5).")
        result = result.strided(rows)
    ended = integration_end(result)
    if ended is not None:  # nothing was integrated after it: the timeline ends there
        end_note = (f"The motion was integrated to t = {result.time[ended]:.6g} s, where it "
                    f"left its assembly; this recording ends there (the "
                    f"{result.n_steps - ended - 1:,} instants after it are no_assembly"
                    + (" in the .h5)." if h5_written else ")."))
        info = end_note if info is None else f"{info} {end_note}"
        result = result.strided(np.arange(ended + 1))
    scene = result.scene
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}-{uuid.uuid4().hex}")
    # generous on purpose: the recording holds float32 copies of the arrays plus labels, and
    # Rerun's file writer does not fail cleanly on a full disk (it can hang flushing): twice
    # the arrays' bytes, the force arrows' float32 origins and vectors, and 256 KiB
    n_bytes = 2 * sum(v.data.nbytes for v in result.variables()) + (256 << 10)
    n_bytes += sum(8 * origins.size for *_, origins, _ in force_arrows(result)[0])
    def logged(into: rr.RecordingStream) -> None:
        with into:  # on exit: flush, and finalise a file (footer) so it is complete
            into.send_recording_name(scene.name)
            if info:
                into.log("info", rr.TextDocument(info), static=True)
            log_result(into, result)

    if path is not None:
        with atomic_path(path, n_bytes) as tmp:
            stream.set_sinks(rr.FileSink(tmp), default_blueprint=blueprint(result))
            logged(stream)
    if spawn or connect:  # the file first, whatever becomes of the viewer
        _streamed(result, logged, spawn, connect, path)
    return kept


def _streamed(result, logged, spawn: bool, connect: str | None, path) -> None:
    """Log ``result`` once more, to a new viewer (``spawn``) and/or the one at ``connect``; a
    viewer that cannot be reached is an :class:`OutputError` naming it (the file, when one was
    asked for, is written already)."""
    stream = rr.RecordingStream(APPLICATION_ID,
                                recording_id=f"{result.scene.name}-{uuid.uuid4().hex}")
    sinks, where = [], []
    if connect:
        check_listening(connect, path)
        sinks.append(rr.GrpcSink(connect))
        where.append(f"the viewer at {connect}")
    try:
        if spawn:
            where.insert(0, "a new viewer (--spawn)")
            if sys.platform.startswith("linux") and not any(
                    os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")):
                raise RuntimeError("no display to open a viewer on (DISPLAY and WAYLAND_DISPLAY "
                                   "are not set)")
            # a viewer process, listening on 9876: the venv's own viewer where the venv's
            # python runs without its bin/ on PATH (as the README's commands do)
            beside = pathlib.Path(sys.executable).with_name("rerun")
            rr.spawn(connect=False, recording=stream,
                     executable_path=str(beside) if beside.exists() else None)
            sinks.append(rr.GrpcSink())
        stream.set_sinks(*sinks, default_blueprint=blueprint(result))
        logged(stream)
        stream.disconnect()
    except RuntimeError as exc:  # rerun: "gRPC has been unable to connect for 6s"
        kept = f"; {path} is written" if path is not None else ""
        raise OutputError(errno.ECONNREFUSED, f"could not stream to {' and '.join(where)}: "
                          f"{exc}{kept} — start a viewer (rerun) and give its address, or "
                          f"open the .rrd later") from None


def integration_end(result) -> int | None:
    """The last row of a forward-dynamics ``result`` whose integration ended early (its
    mechanism left its assembly: every row after it is ``no_assembly``, its moving points NaN),
    or None (not dynamics, or no such tail). The recording stops there: drawn past it, the
    viewer would play two thirds of the falling lever's second over an empty mechanism."""
    if getattr(result.scene, "dynamics", None) is None or result.time is None:
        return None
    tail = result.status == NO_ASSEMBLY
    if not tail[-1] or tail.all():
        return None
    last = int(np.flatnonzero(~tail)[-1])
    return last if last < result.n_steps - 1 else None


def check_address(address: str) -> None:
    """:class:`LinkpipeError` (exit 2) where ``address`` is not a viewer's address Rerun can
    take: Rerun's own parser decides (``GrpcSink`` parses it; it connects only once set as a
    stream's sink)."""
    try:
        rr.GrpcSink(address)
    except (RuntimeError, ValueError) as exc:
        raise LinkpipeError(f"--connect {address}: {exc}; a viewer listens on "
                            "rerun+http://HOST:PORT/proxy") from None


def check_listening(url: str, path=None) -> None:
    """:class:`OutputError` at once where nothing listens at ``url``'s host and port (rerun's
    own client would retry for 6 s, then fill the terminal with its log lines); ``url`` a
    valid address (:func:`check_address`)."""
    check_address(url)
    parts = urllib.parse.urlsplit(url)
    host, port = parts.hostname or "127.0.0.1", parts.port or 9876
    try:
        socket.create_connection((host, port), timeout=2.0).close()
    except OSError as exc:
        kept = f"; {path} is written" if path is not None else ""
        raise OutputError(errno.ECONNREFUSED, f"--connect {url}: no viewer listens at {host}:"
                          f"{port} ({exc.strerror or exc}){kept} — start one (rerun) and give "
                          "its address, or open the .rrd later") from None


def _ordinal(n: int) -> str:
    """1st, 2nd, 3rd, 4th, ..., 11th, 12th, 13th, ..., 21st, ..."""
    tail = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n:,}{tail}"


def log_result(stream: rr.RecordingStream, result) -> None:
    """Log every entity of the contract (and linkpipe's additions) for ``result`` to ``stream``."""
    send = sender(stream, result)
    stream.log("mechanism", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
    mechanism.log_points(stream, send, result)
    mechanism.log_links(stream, send, result)
    mechanism.log_actuators(stream, send, result)
    mechanism.log_guides(stream, send, result)
    mechanism.log_springs(stream, send, result)
    mechanism.log_traces(stream, result)
    mechanism.log_vectors(stream, send, result)
    forces.log_forces(stream, send, result)
    forces.log_pin_couples(stream, send, result)
    legend.log_legend(stream, result, *mechanism_bounds(result))
    series.log_series(stream, send, result)
    series.log_out_of_stroke(stream, send, result)
