"""The embedded blueprint: the mechanism (y up, every arrow and the legend in view) beside the
plots, read against the quantity that moves the scene.

Laid out for a 1400x900 window and up (1920x1080): the mechanism takes 11 of 20 columns, the
plots the rest, one row each up to :data:`MAX_ROWS` plots (more: two columns, so each keeps the
height its axis numbers need); the solver's series are a second tab beside the plots (collapsed
until asked for). The time panel opens on ``time`` for a timed, logged or dynamics scene
(``[time]``, ``[dynamics]``), on the first driver's value for a sweep (``crank [degree]``), else
on ``time`` or ``step``.
"""
from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ...cache import derived
from .columns import driver_timelines
from .forces import drawn_arrows
from .geometry import arrow_scales, bounds, point_index
from .legend import layout as legend_layout
from .mechanism import path_of
from .series import DEGREES, PLOTTED, SOLVER, hidden
from ...output_units import entry_units

#: the mechanism's share of the window's width (of 20)
COLUMNS = (11, 9)
#: the most plots stacked in one column: at 900 px a sixth of the column (~130 px) shows no
#: number on its y axis (seen on the dump truck with friction's six plots); more go in two
MAX_ROWS = 4
#: the most series a plot's legend lists: the 40-bar chain's 81 link angles' legend covered
#: the plot, Andrews' squeezer's 7 a third of it at 1400x900 (the entries stay on hover);
#: twice as many in a plot that has the column to itself
MAX_LEGEND = 6
#: the plots' x axis: the whole sweep and this fraction of it either side
X_PAD = 0.03


def mechanism_bounds(result) -> tuple[np.ndarray, np.ndarray]:
    """Return the (lower, upper) corners of every position and arrow tip (as drawn), padded 8 %."""
    drawn = [result.position.reshape(-1, 2)]
    k = point_index(result, result.scene.outputs.vectors)
    for quantity, scale in arrow_scales(result).items():    # arrow tips too
        drawn.append((result.position[:, k] + scale * getattr(result, quantity)[:, k]).reshape(-1, 2))
    for _, _, origins, vectors, _ in drawn_arrows(result):
        drawn.append(origins.reshape(-1, 2))
        drawn.append((origins + vectors).reshape(-1, 2))
    corners = np.concatenate([np.stack(bounds(result, d)) for d in drawn])  # no (S * n, 2) copy
    lo, hi = bounds(result, corners)
    pad = 0.08 * max(float(np.max(hi - lo)), 1e-9)
    return lo - pad, hi + pad


def view_bounds(result) -> tuple[np.ndarray, np.ndarray]:
    """Return the 2D view's (lower, upper) corners: :func:`mechanism_bounds` and, above them,
    the legend's band (:mod:`.legend`); computed once."""
    return derived(result, "rrd_view_bounds", _view_bounds)


def _view_bounds(result):
    lo, hi = mechanism_bounds(result)
    placed, band = legend_layout(result, lo, hi)
    if placed:
        right = max(float(o[0] + v[0]) for _, _, o, v in placed)
        right += 0.03 * (right - lo[0])       # the last bar's head clear of the view's edge
        hi = np.array([max(hi[0], right), hi[1] + band])
    return lo, hi


def mechanism_title(result) -> str:
    """The 2D view's name: the scene, y up (the arrows' kinds and scales are in its legend)."""
    return f"{result.scene.name} (y up)"


def active_timeline(result) -> str:
    """The timeline the plots open on: ``time`` for a timed, logged or forward-dynamics scene
    (``[time]`` or ``[dynamics]``: its motion is the answer, the driver's value one of its
    outputs), the first driver's value for a sweep (:func:`.columns.driver_timelines`), else
    ``time`` or ``step``."""
    scene = result.scene
    if result.time is not None and (scene.time is not None
                                    or getattr(scene, "dynamics", None) is not None):
        return "time"
    timelines = driver_timelines(result)
    if timelines:
        return timelines[0][0]
    return "time" if result.time is not None else "step"


def x_range(result, timeline: str):
    """The whole sweep on ``timeline``, for the plots' x axis (else the viewer may open on a
    window around its cursor)."""
    if timeline == "time":
        # the instants that assembled: a dynamics run that ended early (the falling lever's
        # tether running out at 0.33 s of 1 s) is NaN after, and would fill a third of the plot
        t = np.asarray(result.time, dtype=float)
        assembled = np.isfinite(result.position).all(axis=(1, 2))
        t = t[np.isfinite(t) & assembled] if assembled.any() else t[np.isfinite(t)]
        if not len(t):
            return None
        pad = X_PAD * float(t.max() - t.min())
        start = rr.TimeRangeBoundary.absolute(seconds=float(t.min()) - pad)
        end = rr.TimeRangeBoundary.absolute(seconds=float(t.max()) + pad)
    else:
        values = dict(driver_timelines(result)).get(timeline)
        if values is None:
            values = (np.arange(result.n_steps) if result.step_numbers is None
                      else np.asarray(result.step_numbers))
        if not len(values):
            return None
        pad = int(np.ceil(X_PAD * float(values.max() - values.min())))
        start = rr.TimeRangeBoundary.absolute(seq=int(values.min()) - pad)
        end = rr.TimeRangeBoundary.absolute(seq=int(values.max()) + pad)
    return rrb.TimeAxis(view_range=rr.TimeRange(start=start, end=end))


def plot_column(plots: list) -> rrb.Container:
    """The ``plots`` tab: one column of up to :data:`MAX_ROWS` views, else a grid of two
    columns (in reading order, left to right)."""
    if len(plots) <= MAX_ROWS:
        return rrb.Vertical(*plots, name="plots")
    return rrb.Grid(*plots, grid_columns=2, name="plots")


def blueprint(result) -> rrb.Blueprint:
    """Return the default layout: the mechanism (y up) beside the plots; the solver a tab."""
    lo, hi = view_bounds(result)
    mechanism = rrb.Spatial2DView(
        origin="/", contents="mechanism/**", name=mechanism_title(result),
        visual_bounds=rrb.VisualBounds2D(x_range=[lo[0], hi[0]], y_range=[-hi[1], -lo[1]]))
    variables = {v.name: v for v in result.variables()}
    labels = {c.name: list(c.data) for c in result.coordinates()}
    left_out = hidden(result)
    legend = rrb.PlotLegend(corner="LeftTop")
    timeline = active_timeline(result)
    axis = dict(axis_x=x_range(result, timeline))
    plots = []
    for name in PLOTTED:
        if name not in variables:
            continue
        if name == "input_force" and not np.nanmax(np.abs(variables[name].data), initial=0.0):
            continue   # drivers that move freely ([dynamics], no force): a flat 0 says nothing
        var = variables[name]
        units = entry_units(var) if len(var.dims) == 2 else [var.units]
        shown, title = name, name.replace("_", " ")
        if name == "link_angle":   # degrees, beside the drivers' degrees
            shown, units = DEGREES, ["deg"] * len(units)
        for unit in dict.fromkeys(units):
            # entries in different units (a torque beside a force): one view per unit, each on
            # its own scale; a series that coincides with another is left out (its name says so)
            entries = [path_of("plots", shown, label)
                       for label, u in zip(labels[var.dims[1]], units)
                       if u == unit and path_of("plots", name, label) not in left_out]
            plots.append(dict(origin=f"plots/{shown}", name=f"{title} [{unit}]",
                              contents=entries))
    # a legend of more entries than fit covers the curves (hover names them): MAX_LEGEND in a
    # column of several plots, twice that in a plot of its own (Jansen's 7 links: full height)
    room = MAX_LEGEND * (2 if len(plots) + len(result.measurements["names"] if
                                                   result.measurements else []) == 1 else 1)
    plots = [rrb.TimeSeriesView(**view, plot_legend=legend if len(view["contents"]) <= room
                                else rrb.PlotLegend(visible=False), **axis) for view in plots]
    if result.measurements:
        # in a half-width grid cell "cylinder_force: computed and measured [N]" was cut; its
        # legend says computed and measured
        grid = len(plots) + len(result.measurements["names"]) > MAX_ROWS
        plots += [rrb.TimeSeriesView(origin=path_of("plots", "measurements", name),
                                     name=(f"{name} [{unit}]" if grid else
                                           f"{name}: computed and measured [{unit}]"),
                                     plot_legend=legend, **axis)
                  for name, unit in zip(result.measurements["names"],
                                        result.measurements["units"])]
    length = variables["residual"].units
    solver = [rrb.TimeSeriesView(origin="solver", name=f"log10 residual [{length}]",
                                 contents=["solver/log10_residual", "solver/log10_tolerance"],
                                 plot_legend=legend, **axis)]
    solver += [rrb.TimeSeriesView(origin=f"solver/{name}", name=f"{name} [{variables[name].units}]",
                                  plot_legend=rrb.PlotLegend(visible=False), **axis)
               for name in SOLVER]
    right = rrb.Tabs(plot_column(plots), rrb.Vertical(*solver, name="solver"),
                     active_tab=0) if plots else rrb.Vertical(*solver, name="solver")
    return rrb.Blueprint(
        rrb.Horizontal(mechanism, right, column_shares=list(COLUMNS)),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=timeline, state="collapsed"),
    )
