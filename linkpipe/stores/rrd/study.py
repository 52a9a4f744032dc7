"""Write a study's recording ``<name>_study.rrd`` (or an optimisation's
``<name>_optimize.rrd``) from a :class:`linkpipe.study.view.StudyView`.

Entities: ``study/vs/<parameter>/<metric>`` each metric against each parameter (one 2D
scatter per pair, both axes scaled to the unit square, y up, the ranges written at the corners;
each point coloured by the objective (``view.objective``, the first metric: yellow lowest,
through green and blue to purple highest, by its rank among the variants; drawn lowest last,
on top), red where some step failed; ``best`` the best variant ringed, ``pareto`` the Pareto
set in orange, ``envelope`` the lowest value of the metric in each of 40 slices of the
parameter's range: the trend a grid's stripes hide), one tab per metric with a view per
parameter; ``study/progress/population_best`` an optimisation's best per generation (on the
``generation`` timeline; ``.../after_polish`` the best, one generation after the last),
``study/pareto/<a>/<b>`` every variant in grey
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
BEST_COLOUR, PARETO_COLOUR, ENVELOPE_COLOUR = [255, 255, 255], [255, 140, 0], [200, 200, 200]
INFEASIBLE_COLOUR = [70, 70, 70]
#: viridis at five stops, from the highest objective (purple) to the lowest (yellow)
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]],
                    dtype=float)
#: slices of a parameter's range the envelope takes its lowest value in
N_SLICES = 40


def objective_colours(objective: np.ndarray, failed: np.ndarray, infeasible=None) -> np.ndarray:
    """(V, 3) uint8: yellow for the lowest objective to purple for the highest, by rank among
    the feasible (an outlier does not wash the others out); red where a step failed, dark
    grey where a constraint is broken, grey where not finite."""
    out = np.tile(np.array(GREY, float), (len(objective), 1))
    dim = np.zeros(len(objective), bool) if infeasible is None else np.asarray(infeasible)
    finite = np.isfinite(objective) & ~dim
    if finite.any():
        rank = np.empty(int(finite.sum()))
        rank[np.argsort(objective[finite], kind="stable")] = np.arange(finite.sum())
        t = 1.0 - rank / max(1, finite.sum() - 1)  # 1: the lowest
        pos = t * (len(_VIRIDIS) - 1)
        i = np.minimum(pos.astype(int), len(_VIRIDIS) - 2)
        f = (pos - i)[:, None]
        out[finite] = _VIRIDIS[i] * (1 - f) + _VIRIDIS[i + 1] * f
    out[dim] = INFEASIBLE_COLOUR
    out[failed] = FAILED_COLOUR
    return out.astype(np.uint8)


def envelope(x: np.ndarray, y: np.ndarray, slices: int = N_SLICES) -> np.ndarray:
    """(n, 2): the lowest y in each of ``slices`` equal slices of x's range (x at the slice's
    lowest point), in order of x; empty slices left out."""
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return np.zeros((0, 2))
    x, y = x[ok], y[ok]
    span = np.ptp(x)
    k = np.zeros(len(x), int) if span == 0 else np.minimum((x - x.min()) / span * slices, slices - 1).astype(int)
    order = np.lexsort((y, k))
    first = np.r_[True, k[order][1:] != k[order][:-1]]
    pick = order[first]
    return np.stack([x[pick], y[pick]], axis=1)


def _unit(x: np.ndarray, span=None) -> tuple[np.ndarray, float, float]:
    """x scaled to [0, 1] over ``span`` (lo, hi), default its finite range (a constant column
    sits at 0.5)."""
    finite = np.isfinite(x)
    if not finite.any():
        return np.full(x.shape, np.nan), np.nan, np.nan
    lo, hi = span or (float(x[finite].min()), float(x[finite].max()))
    return ((x - lo) / (hi - lo) if hi > lo else np.where(finite, 0.5, np.nan)), lo, hi


#: a positive metric spanning more than this ratio is drawn on a log scale (an optimisation's
#: first generation can be 10,000 times its best, a 4-parameter grid's worst 760 times its
#: best: on a linear scale every good variant is one line along the bottom)
LOG_RATIO = 100.0


def _log_scale(y: np.ndarray) -> bool:
    finite = y[np.isfinite(y)]
    return bool(len(finite) and finite.min() > 0 and finite.max() > LOG_RATIO * finite.min())


def _scatter(stream, entity: str, x, y, colours, xlabel: str, ylabel: str,
             spans=(None, None), order=None) -> np.ndarray:
    """Points (x, y) scaled to the unit square over ``spans`` (default: their ranges; drawn
    y up: the view's y points down; y on a log scale where positive over more than
    ``LOG_RATIO``), in ``order`` (the last on top; default as given), with a frame and the
    ranges at its corners; returns the drawn (V, 2) positions (by variant)."""
    y = np.asarray(y, float)
    log = spans[1] is None and _log_scale(y)
    (ux, x0, x1), (uy, y0, y1) = (_unit(np.asarray(x, float), spans[0]),
                                  _unit(np.log10(y) if log else y, spans[1]))
    if log:
        y0, y1 = 10.0 ** y0, 10.0 ** y1
    drawn = np.stack([ux, 1.0 - uy], axis=1)
    order = np.arange(len(drawn)) if order is None else order
    ok = order[np.isfinite(drawn[order]).all(axis=1)]
    stream.log(f"{entity}/variants", rr.Points2D(drawn[ok], colors=colours[ok],
                                                 radii=rr.components.Radius.ui_points(2.5)),
               static=True)
    stream.log(f"{entity}/frame", rr.LineStrips2D([[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]],
                                                  colors=[GREY], radii=0.002), static=True)
    stream.log(f"{entity}/axes", rr.Points2D(
        [[0, 1.06], [1, 1.06], [-0.12, 1], [-0.12, 0], [0.5, 1.13], [0.25, -0.08]],
        labels=[f"{x0:.4g}", f"{x1:.4g}", f"{y0:.4g}", f"{y1:.4g}", xlabel,
                f"{ylabel} ({'log, ' if log else ''}up)"],
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
    failed = view.status != 0
    shown = ~failed if view.infeasible is None else ~failed & ~view.infeasible
    if view.objective is not None:
        colours = objective_colours(np.asarray(view.metrics[view.objective], float), failed,
                                    view.infeasible)
        # drawn worst first: the infeasible and failed under all, the lowest objective on top
        key = np.where(shown, np.nan_to_num(view.metrics[view.objective], nan=np.inf), np.inf)
        order = np.argsort(-key, kind="stable")
    else:
        colours = np.where(failed[:, None], FAILED_COLOUR, OK_COLOUR).astype(np.uint8)
        order = np.arange(len(failed))
    best = view.best[0][0] if view.best else None
    front = view.pareto[1]
    for p, x in view.parameters.items():
        for m, y in view.metrics.items():
            entity = path_of("study", "vs", p, m)
            drawn = _scatter(stream, entity, x, y, colours, view.label(p), view.label(m),
                             order=order)
            line = envelope(drawn[shown, 0], -drawn[shown, 1])  # the lowest: highest drawn y
            if len(line) > 1:
                stream.log(f"{entity}/envelope", rr.LineStrips2D(
                    [np.stack([line[:, 0], -line[:, 1]], axis=1)], colors=[ENVELOPE_COLOUR],
                    radii=rr.components.Radius.ui_points(1.0)), static=True)
            if len(front):
                pts = drawn[front]
                pts = pts[np.isfinite(pts).all(axis=1)]
                stream.log(f"{entity}/pareto", rr.Points2D(
                    pts, colors=[PARETO_COLOUR], radii=rr.components.Radius.ui_points(3.5)),
                    static=True)
            if best is not None and np.isfinite(drawn[best]).all():
                stream.log(f"{entity}/best", rr.Points2D(
                    [drawn[best]], colors=[BEST_COLOUR], radii=rr.components.Radius.ui_points(6.0)),
                    static=True)
    if view.progress is not None:
        for g, value in enumerate(view.progress):
            if np.isfinite(value):
                stream.set_time("generation", sequence=g)
                stream.log("study/progress/population_best", rr.Scalars(float(value)))
        if best is not None:  # the polish's result, one generation after the last
            stream.set_time("generation", sequence=len(view.progress))
            stream.log("study/progress/after_polish",
                       rr.Scalars(float(view.metrics[view.objective][best])))
        stream.reset_time()
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
    row = "variant" if view.kind == "study" else "evaluation"
    lines = [f"| rank | {row} | " + " | ".join(map(view.label, view.parameters)) + " | "
             + " | ".join(map(view.label, view.metrics)) + " |",
             "|---" * (2 + len(view.parameters) + len(view.metrics)) + "|"]
    for rank, (v, _) in enumerate(view.best, 1):
        lines.append(f"| {rank} | {v} | " + " | ".join(f"{x[v]:.6g}" for x in view.parameters.values())
                     + " | " + " | ".join(f"{y[v]:.6g}" for y in view.metrics.values()) + " |")
    if view.objective is not None:
        lines += ["", f"Colours: {view.objective}, yellow the lowest through green and blue to "
                  "purple the highest (by rank); red: a step failed"
                  + ("; dark grey: a constraint broken" if view.infeasible is not None else "")
                  + ". White ring: the best"
                  + ("; orange: the Pareto set" if len(view.pareto[1]) else "")
                  + "; grey line: the lowest value in each slice of the parameter (of the variants that "
                  "finish" + (" and meet the constraints)." if view.infeasible is not None else ").")]
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


#: each scatter's view: the unit square and its labels, nothing cut
SCATTER_BOUNDS = rrb.VisualBounds2D(x_range=[-0.2, 1.1], y_range=[-0.16, 1.24])


def blueprint(view) -> rrb.Blueprint:
    """Tabs: one per metric (the objective first), each a grid of that metric against each
    parameter (titled by the parameter); the Pareto set; an optimisation's progress; each
    metric's spread; the best variant."""
    P = len(view.parameters)
    columns = P if P <= 3 else 2 if P == 4 else -(-P // 2) if P <= 8 else 4
    tabs = [rrb.Grid(*[rrb.Spatial2DView(origin=path_of("study", "vs", p, m), name=view.label(p),
                                         visual_bounds=SCATTER_BOUNDS)
                       for p in view.parameters],
                     grid_columns=columns, name=f"{m} vs parameters")
            for m in view.metrics]
    (a, b), _ = view.pareto
    if a:
        tabs.append(rrb.Spatial2DView(
            origin=path_of("study", "pareto", a, b),
            name=f"Pareto set: {a} and {b} (lower is better; framed on the set)",
            visual_bounds=rrb.VisualBounds2D(x_range=[-0.25, 1.1], y_range=[-0.2, 1.25])))
    if view.progress is not None:
        tabs.append(rrb.TimeSeriesView(origin="study/progress", name=f"best {view.objective} "
                                       "per generation (the polish after)"))
    if any(len(h[0]) for h in view.spread.values()):
        tabs.append(rrb.Grid(*[rrb.BarChartView(origin=path_of("study", "spread", m),
                                                name=f"{m}: variants per bin")
                               for m, h in view.spread.items() if len(h[0])],
                             name="spread of each metric"))
    if view.best:
        v = view.best[0][0]
        tabs.append(rrb.Horizontal(
            rrb.Spatial2DView(origin="/", contents="mechanism/**",
                              name=f"best variant {v} (y up), runners-up thin" if view.kind == "study"
                              else f"best (evaluation {v}, y up)"),
            rrb.Vertical(rrb.TimeSeriesView(origin="plots/input_force", name="best variant's input force"),
                         rrb.TextDocumentView(origin="study/best", name="best variants")),
            name=f"best variant {v}" if view.kind == "study" else f"best (evaluation {v})"))
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(timeline="step", state="collapsed"))
