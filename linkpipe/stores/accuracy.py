"""Write an accuracy ladder (:class:`linkpipe.accuracy.Ladder`): ``<name>_accuracy.h5`` and ``.rrd``.

HDF5, netCDF-4 layout like ``<name>.h5``: a ``row`` dimension whose coordinate variable holds
the row labels (``tol=1e-12``, ``predictor=none,steps=46``...), a ``quantity`` dimension
(position, velocity, acceleration[, input_force]); one variable per column (``knob``,
``value``, ``seconds``, ``seconds_solve``, ``error (row, quantity)``, ``relative_error``,
``iterations_mean``, ...), each with ``units``. Readable by ``h5py`` and by
``xarray.open_dataset(path, engine="h5netcdf")``.

Rerun: one time-series view per quantity, the row's whole-solve time on the x axis (duration
timeline ``solve_seconds``; ``stage_seconds`` is the time of the knob's stage) and
``log10(relative error)`` on the y axis (Rerun 0.41 plots have no log scale), one point
series per knob (``errors/<quantity>/<knob>``), the Pareto front as a line
(``errors/<quantity>/pareto_front``), and the table as a Markdown document (``table``).
"""
from __future__ import annotations

import math
import os
import uuid

import h5py
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from . import atomic_path, hdf5

APPLICATION_ID = "linkpipe_accuracy"
FLOOR = 1e-17  # relative errors below this are drawn at log10 = -17

_KNOB_COLORS = {
    "tol": [31, 119, 180], "max_iter": [255, 127, 14], "jacobian": [44, 160, 44],
    "derivatives": [214, 39, 40], "predictor": [148, 103, 189], "method": [23, 190, 207],
}
_KNOB_MARKERS = {"tol": "circle", "max_iter": "diamond", "jacobian": "square",
                 "derivatives": "cross", "predictor": "up", "method": "asterisk"}


# ------------------------------------------------------------------------------ HDF5
def write_h5(ladder, path: str | os.PathLike) -> None:
    """Write ``ladder`` to ``path`` atomically, one row per setting (netCDF-4 layout)."""
    coords, data = ladder.variables()
    hdf5.write_layout(path, ladder.attributes(), coords, data)


def read_h5(path: str | os.PathLike) -> dict:
    """Return every variable of an accuracy file as numpy arrays (strings as ``str``)."""
    out = {}
    with h5py.File(path, "r") as f:
        for name, ds in f.items():
            arr = ds[()]
            if arr.dtype.kind in "OS":
                arr = np.array([x.decode() if isinstance(x, bytes) else str(x)
                                for x in np.ravel(arr)], dtype=str).reshape(arr.shape)
            out[name] = arr
    return out


# ------------------------------------------------------------------------------ Rerun
def _log10(values) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    return np.log10(np.maximum(v, FLOOR))


def write_rrd(ladder, path: str | os.PathLike, table_markdown: str = "") -> None:
    """Write the error-vs-time recording of ``ladder`` to ``path`` atomically."""
    name = ladder.scene.name
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"{name}-accuracy-{uuid.uuid4().hex}")
    with atomic_path(path) as tmp:
        stream.set_sinks(rr.FileSink(tmp), default_blueprint=blueprint(ladder))
        with stream:
            stream.send_recording_name(f"{name} accuracy")
            log_ladder(stream, ladder, table_markdown)


def log_ladder(stream: rr.RecordingStream, ladder, table_markdown: str = "") -> None:
    """Log one point series per knob and quantity, the Pareto fronts, and the table."""
    rows = [r for r in ladder.rows if r.available and np.isfinite(r.seconds_solve)]
    for q in ladder.quantities:
        for knob in dict.fromkeys(r.knob for r in rows):
            sel = [r for r in rows if r.knob == knob and np.isfinite(r.relative_error[q])]
            if not sel:
                continue
            entity = f"errors/{q}/{knob}"
            stream.log(entity, rr.SeriesPoints(
                names=knob, colors=_KNOB_COLORS.get(knob, [200, 200, 200]),
                markers=_KNOB_MARKERS.get(knob, "circle"), marker_sizes=4.0), static=True)
            _send(stream, entity, sel, [r.relative_error[q] for r in sel])
        front = sorted(ladder.front(q), key=lambda r: r.seconds_solve)
        front = [r for r in front if np.isfinite(r.relative_error[q])]
        if front:
            entity = f"errors/{q}/pareto_front"
            stream.log(entity, rr.SeriesLines(names="Pareto front", colors=[120, 120, 120],
                                               widths=1.0), static=True)
            _send(stream, entity, front, [r.relative_error[q] for r in front])
    if table_markdown:
        stream.log("table", rr.TextDocument(table_markdown, media_type=rr.MediaType.MARKDOWN),
                   static=True)


def _send(stream, entity: str, rows, errors) -> None:
    order = np.argsort([r.seconds_solve for r in rows], kind="stable")
    solve = np.array([rows[i].seconds_solve for i in order], dtype=float)
    stage = np.array([rows[i].seconds if math.isfinite(rows[i].seconds) else rows[i].seconds_solve
                      for i in order], dtype=float)
    values = _log10([errors[i] for i in order])
    stream.send_columns(entity, indexes=[rr.TimeColumn("solve_seconds", duration=solve),
                                         rr.TimeColumn("stage_seconds", duration=stage)],
                        columns=rr.Scalars.columns(scalars=values))


def blueprint(ladder) -> rrb.Blueprint:
    """Return the layout: one error-vs-time plot per quantity beside the table.

    The x axis (whole-solve seconds) spans 0 to the slowest row, the y axis the same decades
    in every plot, so the plots compare at a glance.
    """
    times = [r.seconds_solve for r in ladder.rows if r.available and np.isfinite(r.seconds_solve)]
    errors = [e for r in ladder.rows for e in r.relative_error.values() if np.isfinite(e)]
    t_max = 1.08 * max(times) if times else 1.0
    top = math.ceil(float(np.max(_log10(errors)))) + 0.5 if errors else 0.5
    axis_x = rrb.TimeAxis(view_range=rrb.TimeRange(
        start=rrb.TimeRangeBoundary.absolute(seconds=0.0),
        end=rrb.TimeRangeBoundary.absolute(seconds=t_max)))
    plots = [
        rrb.TimeSeriesView(
            origin=f"errors/{q}",
            name=f"{q}: log10 relative error vs solve seconds",
            axis_x=axis_x,
            axis_y=rrb.ScalarAxis(range=(math.log10(FLOOR) - 0.5, top)),
            plot_legend=rrb.PlotLegend(corner="RightTop", visible=True),
        )
        for q in ladder.quantities
    ]
    grid = rrb.Grid(*plots, grid_columns=2)
    return rrb.Blueprint(
        rrb.Horizontal(grid, rrb.TextDocumentView(origin="table", name="table"),
                       column_shares=[1, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="solve_seconds", state="collapsed"),
    )
