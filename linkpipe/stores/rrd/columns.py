"""Whole-sweep columns for ``send_columns``: the timelines of every row, and Arrow arrays built
from numpy buffers where rerun's own conversion would walk the steps in Python."""
from __future__ import annotations

import math

import numpy as np
import rerun as rr


def sender(stream: rr.RecordingStream, result):
    """Return ``send(entity, columns, rows=None)``: ``stream.send_columns`` on the timelines of
    the contract (``step``, and ``time`` when the sweep has instants) and, for a one-driver
    sweep, the driver's value (:func:`driver_timeline`), at the steps ``rows`` (all if None)."""
    steps = (np.arange(result.n_steps) if result.step_numbers is None
             else np.asarray(result.step_numbers))
    # nanoseconds rounded to the nearest (rerun truncates float seconds: 1 ns short at times)
    nanoseconds = (None if result.time is None else
                   np.round(np.asarray(result.time, float) * 1e9).astype("timedelta64[ns]"))
    by_value = driver_timelines(result)

    def index_at(rows) -> list:
        index = [rr.TimeColumn("step", sequence=steps[rows])]
        if nanoseconds is not None:
            index.append(rr.TimeColumn("time", duration=nanoseconds[rows]))
        for name, values in by_value:
            index.append(rr.TimeColumn(name, sequence=values[rows]))
        return index

    every = index_at(slice(None))  # built once: most entities go out at every step (a
    # TimeColumn holds its Arrow array, read and not changed by send_columns)

    def send(entity: str, columns, rows: np.ndarray | None = None) -> None:
        index = every if rows is None else index_at(rows)
        stream.send_columns(entity, indexes=index, columns=columns)

    return send


def driver_timelines(result) -> list[tuple[str, np.ndarray]]:
    """[(name, values (S,) int64)]: a timeline per driver whose value is finite at every step
    and only rises or only falls (:func:`driver_timeline`), so that every plot can be read
    against any driver's value (a sweep of two drivers has two)."""
    return [t for t in (_timeline(result, j) for j in range(len(result.driver_names)))
            if t is not None]


def driver_timeline(result) -> tuple[str, np.ndarray] | None:
    """Return (name, values (S,) int64) of a timeline that is the driver's value, for a sweep
    with one driver whose value is finite at every step and only rises or only falls; None
    otherwise.

    Picked in the time panel, it puts every plot against the crank's angle or the cylinder's
    length instead of the step. Rerun's timelines count in integers, so the value is counted
    in the driver's own unit when every value is a whole number of it (``"crank [degree]"``),
    else in a decimal fraction of it fine enough that neighbouring steps are 10 to 100 counts
    apart: 100,000 steps over 360 degrees give ``"crank [0.0001 degree]"`` (3600000 at 360).
    """
    if len(result.driver_names) != 1:
        return None
    return _timeline(result, 0)


def _timeline(result, j: int) -> tuple[str, np.ndarray] | None:
    """:func:`driver_timeline` of driver ``j``."""
    if result.n_steps < 2:
        return None
    value = np.asarray(result.driver_value[:, j], dtype=float)
    if not np.isfinite(value).all():
        return None
    step = np.diff(value)
    if not ((step > 0).all() or (step < 0).all()):
        return None
    if (value == np.round(value)).all():   # whole numbers already: no finer count needed
        digits = 0
    else:
        digits = max(0, math.ceil(-math.log10(float(np.abs(step).min()))) + 1)
    if digits > 15 or float(np.abs(value).max()) * 10.0 ** digits >= 2 ** 62:
        return None
    ints = np.round(value * 10.0 ** digits).astype(np.int64)
    if not (np.diff(ints) != 0).all():
        return None
    unit = result.driver_units()[j]
    count = unit if digits == 0 else f"{10.0 ** -digits:.{digits}f} {unit}"
    return f"{result.driver_names[j]} [{count}]", ints


def labels_arrow(names, ok: np.ndarray):
    """Return the labels ``names[p]`` of every finite (step, point) of ``ok`` (S, P), row-major,
    as one Arrow string array built from its buffers (not from 100k's of Python strings)."""
    import pyarrow as pa

    enc = [str(n).encode() for n in names]
    lens = np.array([len(b) for b in enc], dtype=np.int64)
    blob = np.frombuffer(b"".join(enc), dtype=np.uint8)
    pidx = np.broadcast_to(np.arange(len(enc)), ok.shape)[ok]
    L = lens[pidx]
    offsets = np.zeros(len(pidx) + 1, dtype=np.int64)
    np.cumsum(L, out=offsets[1:])
    if offsets[-1] >= 2**31:
        return np.broadcast_to(np.array(names, dtype=str), ok.shape)[ok]
    if ok.all():
        data = np.tile(blob, ok.shape[0])
    else:
        starts = np.r_[0, np.cumsum(lens)[:-1]]
        data = blob[np.repeat(starts[pidx] - offsets[:-1], L) + np.arange(offsets[-1])]
    return pa.StringArray.from_buffers(len(pidx), pa.py_buffer(offsets.astype(np.int32)),
                                       pa.py_buffer(np.ascontiguousarray(data)))


def strips_arrow(strips: np.ndarray):
    """Return strips (N, k, 2) as the Arrow array of LineStrip2D components, built whole.

    rerun's own conversion walks the N strips in Python to find their offsets; with N the
    number of steps (100k and more) that dominated writing a recording.
    """
    import pyarrow as pa
    from rerun.components import LineStrip2DBatch
    from rerun.encodings.vec2d import Vec2DBatch

    n, k = strips.shape[:2]
    inner = Vec2DBatch(np.asarray(strips, dtype=np.float32).reshape(-1, 2)).as_arrow_array()
    offsets = pa.array(np.arange(0, (n + 1) * k, k, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, inner, type=LineStrip2DBatch._ARROW_DATATYPE)
