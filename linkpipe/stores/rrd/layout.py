"""The embedded blueprint: the mechanism (y up, every arrow in view) beside the plots."""
from __future__ import annotations

import numpy as np
import rerun.blueprint as rrb

from . import style
from .forces import force_arrows, force_legend
from .geometry import arrow_legend, arrow_scales, bounds, point_index
from .mechanism import path_of
from .series import PLOTTED, SOLVER
from ...output_units import entry_units


def view_bounds(result) -> tuple[np.ndarray, np.ndarray]:
    """Return the 2D view's (lower, upper) corners: every position and arrow tip, padded 8 %."""
    drawn = [result.position.reshape(-1, 2)]
    k = point_index(result, result.scene.outputs.vectors)
    for quantity, scale in arrow_scales(result).items():    # arrow tips too
        drawn.append((result.position[:, k] + scale * getattr(result, quantity)[:, k]).reshape(-1, 2))
    arrows, scale = force_arrows(result)
    for _, _, origins, vectors in arrows:
        drawn.append((origins + scale * vectors).reshape(-1, 2))
    corners = np.concatenate([np.stack(bounds(result, d)) for d in drawn])  # no (S * n, 2) copy
    lo, hi = bounds(result, corners)
    pad = 0.08 * max(float(np.max(hi - lo)), 1e-9)
    return lo - pad, hi + pad


def mechanism_title(result) -> str:
    """The 2D view's name: the scene, y up, and the scale and colour of every kind of arrow."""
    name = f"{result.scene.name} (y up)"
    forces = force_legend(result)    # first: a long title is cut at the view's width
    if forces:
        name += f"; {forces}"
    scales = arrow_scales(result)
    if result.scene.outputs.vectors and scales:
        name += "; arrows: " + ", ".join(
            f"{q} ({style.VECTOR_COLOR_NAMES[q]}) {arrow_legend(result, q)}" for q in scales)
    return name


def blueprint(result) -> rrb.Blueprint:
    """Return the default layout: the mechanism (y up) beside the plots and solver series."""
    lo, hi = view_bounds(result)
    mechanism = rrb.Spatial2DView(
        origin="/", contents="mechanism/**", name=mechanism_title(result),
        visual_bounds=rrb.VisualBounds2D(x_range=[lo[0], hi[0]], y_range=[-hi[1], -lo[1]]))
    variables = {v.name: v for v in result.variables()}
    labels = {c.name: list(c.data) for c in result.coordinates()}
    plots = []
    for name in PLOTTED:
        if name not in variables:
            continue
        var = variables[name]
        units = entry_units(var) if len(var.dims) == 2 else [var.units]
        if len(set(units)) == 1:
            plots.append(rrb.TimeSeriesView(origin=f"plots/{name}", name=f"{name} [{units[0]}]"))
            continue
        # entries in different units (a torque beside a force): one view per unit, each on
        # its own scale
        for unit in dict.fromkeys(units):
            entries = [path_of("plots", name, label)
                       for label, u in zip(labels[var.dims[1]], units) if u == unit]
            plots.append(rrb.TimeSeriesView(origin=f"plots/{name}", name=f"{name} [{unit}]",
                                            contents=entries))
    if result.measurements:
        plots += [rrb.TimeSeriesView(origin=path_of("plots", "measurements", name),
                                     name=f"{name}: computed and measured [{unit}]")
                  for name, unit in zip(result.measurements["names"],
                                        result.measurements["units"])]
    length = variables["residual"].units
    solver = [rrb.TimeSeriesView(origin="solver", name=f"log10 residual [{length}]",
                                 contents=["solver/log10_residual", "solver/log10_tolerance"])]
    solver += [rrb.TimeSeriesView(origin=f"solver/{name}", name=f"{name} [{variables[name].units}]")
               for name in SOLVER]
    return rrb.Blueprint(
        rrb.Horizontal(mechanism, rrb.Vertical(*plots, rrb.Tabs(*solver)), column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="step", state="collapsed"),
    )
