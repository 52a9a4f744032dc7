"""Write a study's recording ``<name>_study.rrd`` from a :class:`linkpipe.study.view.StudyView`.

Entities: ``study/vs/<parameter>/<metric>`` each metric against each parameter (one 2D
scatter per pair, both axes scaled to the unit square, y up, the ranges written at the corners;
green: every step ok, red: some step failed), ``study/pareto/<a>/<b>`` every variant in grey
and the Pareto set of the first two metrics as a line (the square framed on the set: from its
lowest values to its highest plus its own range again), and the best variant (by the first
metric) as a whole recording of its own sweep under ``mechanism/**`` and ``plots/**`` on the
``step`` timeline, with the next best variants' links under
``mechanism/runners_up/variant <v>``.
``study/best`` is a text table of the best variants and their parameter values;
``study/spread/<metric>`` each metric's histogram over the variants (a bar chart on the
metric's own values: how tolerances spread it).
"""
from __future__ import annotations

import uuid

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from .. import atomic_path
from . import APPLICATION_ID, log_result, style
from .mechanism import path_of

OK_COLOUR, FAILED_COLOUR, GREY = [60, 180, 90], [220, 60, 50], [150, 150, 150]


def _unit(x: np.ndarray, span=None) -> tuple[np.ndarray, float, float]:
    """x scaled to [0, 1] over ``span`` (lo, hi), default its finite range (a constant column
    sits at 0.5)."""
    finite = np.isfinite(x)
    if not finite.any():
        return np.full(x.shape, np.nan), np.nan, np.nan
    lo, hi = span or (float(x[finite].min()), float(x[finite].max()))
    return ((x - lo) / (hi - lo) if hi > lo else np.where(finite, 0.5, np.nan)), lo, hi


def _scatter(stream, entity: str, x, y, colours, xlabel: str, ylabel: str,
             spans=(None, None)) -> np.ndarray:
    """Points (x, y) scaled to the unit square over ``spans`` (default: their ranges; drawn
    y up: the view's y points down), with a frame and the ranges at its corners; returns the
    drawn (V, 2) positions."""
    (ux, x0, x1), (uy, y0, y1) = (_unit(np.asarray(x, float), spans[0]),
                                  _unit(np.asarray(y, float), spans[1]))
    drawn = np.stack([ux, 1.0 - uy], axis=1)
    ok = np.isfinite(drawn).all(axis=1)
    stream.log(f"{entity}/variants", rr.Points2D(drawn[ok], colors=colours[ok],
                                                 radii=rr.components.Radius.ui_points(2.5)),
               static=True)
    stream.log(f"{entity}/frame", rr.LineStrips2D([[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]],
                                                  colors=[GREY], radii=0.002), static=True)
    stream.log(f"{entity}/axes", rr.Points2D(
        [[0, 1.07], [1, 1.07], [-0.12, 1], [-0.12, 0], [0.5, 1.18], [0.25, -0.1]],
        labels=[f"{x0:.4g}", f"{x1:.4g}", f"{y0:.4g}", f"{y1:.4g}", xlabel, f"{ylabel} (up)"],
        radii=0.0, show_labels=True, colors=[GREY]), static=True)
    return drawn


def _near(x: np.ndarray, front: np.ndarray) -> tuple[float, float] | None:
    """The span that frames the Pareto set: from its lowest value to its highest plus its
    own range again (the variants far beyond lie outside the view)."""
    if not len(front):
        return None
    lo, hi = float(x[front].min()), float(x[front].max())
    return (lo, hi + (hi - lo)) if hi > lo else None


def write(view, path) -> None:
    """Write the recording of a study's view to ``path`` (temporary name, then rename)."""
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"{view.name}-study-{uuid.uuid4().hex}")
    n_bytes = 64 * sum(len(v) for v in view.metrics.values()) * max(1, len(view.parameters)) \
        + (1 << 20)
    with atomic_path(path, n_bytes) as tmp:
        stream.set_sinks(rr.FileSink(tmp), default_blueprint=blueprint(view))
        with stream:
            stream.send_recording_name(f"{view.name} study")
            log_view(stream, view)


def log_view(stream, view) -> None:
    colours = np.where((view.status == 0)[:, None], OK_COLOUR, FAILED_COLOUR).astype(np.uint8)
    for p, x in view.parameters.items():
        for m, y in view.metrics.items():
            _scatter(stream, path_of("study", "vs", p, m), x, y, colours, view.label(p),
                     view.label(m))
    (a, b), front = view.pareto
    if a:
        entity = path_of("study", "pareto", a, b)
        grey = np.tile(np.array(GREY, np.uint8), (len(view.status), 1))
        pts = _scatter(stream, entity, view.metrics[a], view.metrics[b], grey, view.label(a),
                       view.label(b),
                       (_near(view.metrics[a], front), _near(view.metrics[b], front)))[front]
        stream.log(f"{entity}/front", rr.LineStrips2D([pts], colors=[style.colour(1)], radii=0.004),
                   static=True)
        stream.log(f"{entity}/front_points", rr.Points2D(
            pts, colors=[style.colour(1)], radii=0.012, labels=[f"variant {v}" for v in front],
            show_labels=len(front) <= 12), static=True)
    for m, (counts, centres, widths) in view.spread.items():
        if len(counts):
            stream.log(path_of("study", "spread", m), rr.BarChart(
                counts, abscissa=centres, widths=widths.astype(np.float32),
                color=style.colour(0)), static=True)
    lines = ["| rank | variant | " + " | ".join(map(view.label, view.parameters)) + " | "
             + " | ".join(map(view.label, view.metrics)) + " |",
             "|---" * (2 + len(view.parameters) + len(view.metrics)) + "|"]
    for rank, (v, _) in enumerate(view.best, 1):
        lines.append(f"| {rank} | {v} | " + " | ".join(f"{x[v]:.6g}" for x in view.parameters.values())
                     + " | " + " | ".join(f"{y[v]:.6g}" for y in view.metrics.values()) + " |")
    stream.log("study/best", rr.TextDocument("\n".join(lines), media_type="text/markdown"),
               static=True)
    if view.best:
        log_result(stream, view.best[0][1])
        _runners_up(stream, view.best[1:])


def _runners_up(stream, best) -> None:
    """The next best variants' links (first two points of each link) on the step timeline."""
    for rank, (v, result) in enumerate(best, 2):
        X = result.position
        index = {n: i for i, n in enumerate(result.point_names)}
        pairs = [(index[l.points[0]], index[l.points[1]]) for l in result.scene.links]
        strips = np.stack([np.stack([X[:, a], X[:, b]], axis=1) for a, b in pairs], axis=1)
        entity = path_of("mechanism", "runners_up", f"variant {v}")
        stream.log(entity, rr.LineStrips2D.from_fields(colors=[style.colour(rank)],
                                                       radii=rr.components.Radius.ui_points(1.5)),
                   static=True)
        for s in range(X.shape[0]):
            if np.isfinite(strips[s]).all():
                stream.set_time("step", sequence=s)
                stream.log(entity, rr.LineStrips2D(strips[s].astype(np.float32)))


def blueprint(view) -> rrb.Blueprint:
    """Tabs: metrics against each parameter (a grid), the Pareto set, each metric's spread,
    the best variant."""
    scatter = [rrb.Spatial2DView(origin=path_of("study", "vs", p, m), name=f"{m} vs {p}")
               for p in view.parameters for m in view.metrics]
    tabs = [rrb.Grid(*scatter, name="metrics vs parameters")]
    (a, b), _ = view.pareto
    if a:
        tabs.append(rrb.Spatial2DView(
            origin=path_of("study", "pareto", a, b),
            name=f"Pareto set: {a} and {b} (lower is better; framed on the set)",
            visual_bounds=rrb.VisualBounds2D(x_range=[-0.25, 1.1], y_range=[-0.2, 1.25])))
    tabs.append(rrb.Grid(*[rrb.BarChartView(origin=path_of("study", "spread", m),
                                            name=f"{m}: variants per bin")
                           for m, h in view.spread.items() if len(h[0])],
                         name="spread of each metric"))
    if view.best:
        v = view.best[0][0]
        tabs.append(rrb.Horizontal(
            rrb.Spatial2DView(origin="/", contents="mechanism/**",
                              name=f"best variant {v} (y up), runners-up thin"),
            rrb.Vertical(rrb.TimeSeriesView(origin="plots/input_force", name="best variant's input force"),
                         rrb.TextDocumentView(origin="study/best", name="best variants")),
            name=f"best variant {v}"))
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(timeline="step", state="collapsed"))
