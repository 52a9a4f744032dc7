"""The plotted series: ``plots/<variable>/<label>``, ``plots/measurements/<name>/computed`` and
``.../measured``, and ``solver/**``, each in a colour of its own."""
from __future__ import annotations

import numpy as np
import rerun as rr

from . import style
from .mechanism import path_of
from ...output_units import entry_units
from ...status import OUT_OF_STROKE

#: per-step series plotted under ``plots/<name>/<label>`` (variable name -> its second dim)
PLOTTED = ("input_force", "spring_force", "torsion_spring_torque", "link_angle",
           "friction_force", "stroke_margin")
SOLVER = ("residual", "iterations")


def series_of(result) -> list[tuple[str, str, np.ndarray, list[int]]]:
    """Return [(entity, name, values (S,), colour)] of every plotted series. Within a plot each
    series has its own colour (:func:`.style.colour` of its column: a link's angle is drawn in
    the link's colour); the residual and the tolerance beside it differ too."""
    variables = {v.name: v for v in result.variables()}
    labels = {c.name: c.data for c in result.coordinates()}
    series = []
    for name in PLOTTED:
        var = variables.get(name)
        if var is None or var.dims[:1] != ("step",) or len(var.dims) != 2:
            continue
        for j, (label, unit) in enumerate(zip(labels[var.dims[1]], entry_units(var))):
            series.append((path_of("plots", name, label), f"{label} [{unit}]", var.data[:, j],
                           style.colour(j)))
    for name in SOLVER:
        var = variables[name]
        series.append((f"solver/{name}", f"{name} [{var.units}]", var.data, style.colour(0)))
    if result.measurements:  # computed beside measured, one plot per measurement
        m = result.measurements
        for k, name in enumerate(m["names"]):
            unit = m["units"][k]
            series.append((path_of("plots", "measurements", name, "computed"), f"computed [{unit}]",
                           m["measured"][:, k] + m["residual"][:, k], style.colour(0)))
            series.append((path_of("plots", "measurements", name, "measured"), f"measured [{unit}]",
                           m["measured"][:, k], style.colour(1)))
    log_res, log_tol = log10_residual(result)
    length = variables["residual"].units
    series.append(("solver/log10_residual", f"log10 residual [{length}]", log_res, style.colour(0)))
    series.append(("solver/log10_tolerance", f"log10 tolerance [{length}]",
                   np.full(result.n_steps, log_tol), style.colour(3)))
    return series


def log_series(stream, send, result) -> None:
    for entity, title, values, colour in series_of(result):
        values = np.asarray(values, dtype=float)
        finite = np.isfinite(values)
        # a series NaN at every step (every step failed) is logged too; +-inf (e.g. a failed
        # step's residual) would wreck the axis
        if not finite.all():
            values = np.where(finite, values, np.nan)
        stream.log(entity, rr.SeriesLines(names=title, colors=[colour]), static=True)
        # every step, NaN included: the viewer breaks the line at a NaN, whereas a step left
        # out would be bridged by a straight segment that looks like data
        send(entity, rr.Scalars.columns(scalars=values))


def log_out_of_stroke(stream, send, result) -> None:
    """``plots/stroke_margin/out_of_stroke``: a red marker on the stroke-margin plot at each
    step outside a stroke (its most negative margin), none elsewhere."""
    if result.stroke_margin is None:
        return
    outside = result.status == OUT_OF_STROKE
    with np.errstate(invalid="ignore"):
        worst = np.nanmin(np.where(np.isfinite(result.stroke_margin), result.stroke_margin, np.nan),
                          axis=1, initial=np.inf)
    values = np.where(outside & np.isfinite(worst), worst, np.nan)
    entity = path_of("plots", "stroke_margin", "out_of_stroke")
    stream.log(entity, rr.SeriesPoints(names="out of stroke", colors=[[230, 30, 30]],
                                       markers="cross", marker_sizes=4.0), static=True)
    send(entity, rr.Scalars.columns(scalars=values))


def log10_residual(result) -> tuple[np.ndarray, float]:
    """Return (log10 of the residual (S,), log10 of the solver's tolerance), lengths in scene units.

    The viewer labels no axis below ~1e-13, so the raw ``solver/residual`` of a solved sweep
    (rounding level, ~1e-16 of the size) plots as unlabelled noise; its log10 beside the
    tolerance's (``tol`` x the mechanism's size, what Newton stops at, floored at what float64
    resolves at the drawing's distance from the origin: ``Model.tolerance``) reads at a glance. A
    residual of exactly 0 is drawn one decade below rounding level (log10(eps x size) - 1);
    NaN (a step without assembly) stays NaN and is not drawn.
    """
    size = result.model.size
    floor = float(np.log10(np.finfo(float).eps * size)) - 1.0
    res = np.asarray(result.residual, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.log10(res)
    out[res == 0] = floor
    return out, float(np.log10(result.model.tolerance()))
