"""Write a :class:`~linkpipe.result.Result` as a Rerun recording (``.rrd``), rerun-sdk 0.41.

Entity paths and timelines follow ``docs/output-format.md``. Everything that changes per
step goes out columnar with ``send_columns`` (one call per entity, never one per step);
geometry that does not change is logged once as static. Steps where a point is NaN (failed
assembly) log an empty batch for the entities that need it, which clears them at that step.

The 2D view of Rerun has +y pointing down; a static ``Transform3D`` on ``mechanism`` flips
it so the mechanism appears y-up. The logged data are the scene's own coordinates.

Modules: :mod:`.mechanism` (points, links and plates, actuators, guides, springs, traces,
velocity and acceleration arrows), :mod:`.forces` (force arrows, one row per kind),
:mod:`.series` (plots and solver series), :mod:`.columns` (timelines, the driver's value as
one, Arrow arrays), :mod:`.geometry` (sizes, scales, plate outlines), :mod:`.layout`
(blueprint), :mod:`.style` (colours).
"""
from __future__ import annotations

import contextlib
import uuid

import numpy as np
import rerun as rr

from .. import atomic_path
from . import forces, mechanism, series
from .columns import driver_timeline, sender
from .forces import FORCE_FRACTION, KINDS, force_arrows, force_legend
from .geometry import ARROW_FRACTION, arrow_legend, arrow_scales, mechanism_size, outline
from .layout import blueprint, mechanism_title, view_bounds
from .mechanism import path_of
from .series import PLOTTED, SOLVER, log10_residual

__all__ = ["write", "log_result", "blueprint", "path_of", "arrow_scales", "arrow_legend",
           "mechanism_size", "force_arrows", "force_legend", "driver_timeline", "outline",
           "log10_residual", "view_bounds", "mechanism_title", "KINDS", "PLOTTED", "SOLVER",
           "ARROW_FRACTION", "FORCE_FRACTION", "APPLICATION_ID"]

APPLICATION_ID = "linkpipe"


#: the most steps a recording keeps; past it a uniform stride (the HDF5 keeps every step)
MAX_STEPS = 100_000


def stride_of(n_steps: int, max_steps: int | None = MAX_STEPS) -> int:
    """The stride a recording of ``n_steps`` keeps (1: every step; ``max_steps`` 0/None: no cap)."""
    if not max_steps or n_steps <= max_steps:
        return 1
    return -(-n_steps // max_steps)


def write(result, path, spawn: bool = False, connect: str | None = None,
          max_steps: int | None = MAX_STEPS) -> None:
    """Write the recording of ``result`` to ``path`` (``None``: no file) and optionally stream it.

    ``spawn=True`` starts a Rerun viewer and streams to it; ``connect`` streams to a running
    viewer at that address (``rerun+http://host:port/proxy``). The file is written to a
    temporary name and renamed into place when complete. A sweep longer than ``max_steps`` is
    recorded at a uniform stride of steps (:func:`stride_of`), said in a static ``info`` text
    entity; the step timeline keeps the sweep's own step numbers.
    """
    if path is None and not spawn and not connect:
        return
    stride = stride_of(result.n_steps, max_steps)
    info = None
    if stride > 1:
        rows = np.arange(0, result.n_steps, stride)
        info = (f"This recording keeps every {stride}th step ({len(rows):,} of "
                f"{result.n_steps:,}, --rrd-max-steps {max_steps:,}); the .h5 keeps every step.")
        result = result.strided(rows)
    scene = result.scene
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}-{uuid.uuid4().hex}")
    # generous on purpose: the recording holds float32 copies of the arrays plus labels, and
    # Rerun's file writer does not fail cleanly on a full disk (it can hang flushing): twice
    # the arrays' bytes, the force arrows' float32 origins and vectors, and 256 KiB
    n_bytes = 2 * sum(v.data.nbytes for v in result.variables()) + (256 << 10)
    n_bytes += sum(8 * origins.size for *_, origins, _ in force_arrows(result)[0])
    with atomic_path(path, n_bytes) if path is not None else contextlib.nullcontext() as tmp:
        sinks = [rr.FileSink(tmp)] if tmp is not None else []
        if spawn:
            rr.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        if connect:
            sinks.append(rr.GrpcSink(connect))
        stream.set_sinks(*sinks, default_blueprint=blueprint(result))
        with stream:  # on exit: flush, and finalise the file (footer) so it is complete
            stream.send_recording_name(scene.name)
            if info:
                stream.log("info", rr.TextDocument(info), static=True)
            log_result(stream, result)
    if spawn or connect:
        stream.disconnect()


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
    series.log_series(stream, send, result)
