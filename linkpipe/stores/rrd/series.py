"""The plotted series: ``plots/<variable>/<label>``, ``plots/measurements/<name>/computed`` and
``.../measured``, and ``solver/**``, each in a colour of its own.

What a person reads: link angles are also plotted in degrees (``plots/link_angle_deg/<link>``,
the view the blueprint shows; a link turning more than a whole turn wrapped to ±180 degrees;
``plots/link_angle/<link>`` keeps the contract's radians, as the
.h5 does); an input force is named for what it is (``force at H``, ``torque of crank``), not
by the driver alone; series of one plot that coincide at every step are one legend entry
(``left = right``: the others stay logged, out of the view: :func:`coinciding`). Series
names carry no unit: the view's title has it.
"""
from __future__ import annotations

import functools

import numpy as np
import rerun as rr

from . import style
from .mechanism import path_of
from ...cache import derived
from ...output_units import entry_units
from ...status import OUT_OF_STROKE

#: per-step series plotted under ``plots/<name>/<label>`` (variable name -> its second dim)
PLOTTED = ("input_force", "spring_force", "torsion_spring_torque", "link_angle",
           "friction_force", "stroke_margin")
SOLVER = ("residual", "iterations")
#: the measured series' opacity (of 255): drawn over the computed one (the viewer draws
#: ``measured`` after ``computed``), a minute of a noisy log hid the computed line whole
MEASURED_ALPHA = 110
#: link angles in degrees beside the contract's radians (what the blueprint shows)
DEGREES = "link_angle_deg"


def input_force_name(driver, unit: str) -> str:
    """What an input force is: a force along the input at its point, a cylinder's axial force,
    a torque of an angle driver."""
    if driver.input is not None:
        return f"force at {driver.input.point} ({driver.name})"
    if driver.kind == "angle":
        return f"torque of {driver.name}"
    if driver.kind == "distance":
        return f"{driver.name} axial force"
    return f"force of {driver.name}"


def coinciding(result) -> dict[str, list[list[int]]]:
    """{plotted variable: groups of its columns equal at every step (NaN where the other is)},
    each group in column order, only groups of two or more; computed once."""
    return derived(result, "rrd_coinciding", _coinciding)


def _coinciding(result):
    variables = {v.name: v for v in result.variables()}
    out = {}
    for name in PLOTTED:
        var = variables.get(name)
        if var is None or var.dims[:1] != ("step",) or len(var.dims) != 2 or var.data.shape[1] < 2:
            continue
        data = np.asarray(var.data, dtype=float)
        units = entry_units(var)
        groups, seen = [], set()
        for j in range(data.shape[1]):
            if j in seen:
                continue
            group = [j]
            for k in range(j + 1, data.shape[1]):
                if k not in seen and units[k] == units[j] and _same(data[:, j], data[:, k]):
                    group.append(k)
            if len(group) > 1:
                seen.update(group)
                groups.append(group)
        if groups:
            out[name] = groups
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal where either is finite, to a millionth of the larger's range (a curve drawn over
    another one at any plot's resolution); NaN at the same steps."""
    fa, fb = np.isfinite(a), np.isfinite(b)
    if not (fa == fb).all() or not fa.any():
        return False
    span = max(float(np.ptp(a[fa])), float(np.ptp(b[fb])), float(np.abs(a[fa]).max()), 1e-300)
    return bool(np.abs(a[fa] - b[fb]).max() <= 1e-6 * span)


def hidden(result) -> set[str]:
    """The entities of series that coincide with an earlier one of their plot (left out of the
    views; the earlier one's name says both)."""
    labels = {c.name: list(c.data) for c in result.coordinates()}
    variables = {v.name: v for v in result.variables()}
    out = set()
    for name, groups in coinciding(result).items():
        names = labels[variables[name].dims[1]]
        for group in groups:
            out |= {path_of("plots", name, names[k]) for k in group[1:]}
            if name == "link_angle":
                out |= {path_of("plots", DEGREES, names[k]) for k in group[1:]}
    return out


def series_of(result) -> list[tuple[str, str, np.ndarray, list[int]]]:
    """Return [(entity, name, values (S,), colour)] of every plotted series. Within a plot each
    series has its own colour (:func:`.style.colour` of its column; a link's angle is drawn in
    the link's colour); the residual and the tolerance beside it differ too."""
    variables = {v.name: v for v in result.variables()}
    labels = {c.name: c.data for c in result.coordinates()}
    together = coinciding(result)
    drivers = {d.name: d for d in result.scene.drivers}
    series = []
    for name in PLOTTED:
        var = variables.get(name)
        if var is None or var.dims[:1] != ("step",) or len(var.dims) != 2:
            continue
        names = [str(x) for x in labels[var.dims[1]]]
        if name == "input_force":
            shown = [input_force_name(drivers[n], u) if n in drivers else n
                     for n, u in zip(names, entry_units(var))]
        else:
            shown = list(names)
        for group in together.get(name, []):
            shown[group[0]] = " = ".join(shown[k] for k in group) + " (coincide)"
        for j, label in enumerate(names):
            colour = style.link_colour(j) if name == "link_angle" else style.colour(j)
            series.append((path_of("plots", name, label), shown[j], var.data[:, j], colour))
            if name == "link_angle":
                degrees, wrapped = wrapped_degrees(var.data[:, j])
                series.append((path_of("plots", DEGREES, label),
                               shown[j] + (" (wrapped to ±180)" if wrapped else ""),
                               degrees, colour))
    for name in SOLVER:
        var = variables[name]
        series.append((f"solver/{name}", name, var.data, style.colour(0)))
    if result.measurements:  # computed beside measured, one plot per measurement
        m = result.measurements
        for k, name in enumerate(m["names"]):
            series.append((path_of("plots", "measurements", name, "computed"), "computed",
                           m["measured"][:, k] + m["residual"][:, k], style.colour(0)))
            series.append((path_of("plots", "measurements", name, "measured"), "measured",
                           m["measured"][:, k], style.colour(1) + [MEASURED_ALPHA]))
    log_res, log_tol = log10_residual(result)
    series.append(("solver/log10_residual", "log10 residual", log_res, style.colour(0)))
    series.append(("solver/log10_tolerance", "log10 tolerance",
                   np.full(result.n_steps, log_tol), style.colour(3)))
    return series


def wrapped_degrees(angle: np.ndarray) -> tuple[np.ndarray, bool]:
    """(S,) radians -> (degrees (S,), wrapped): a link that turns more than a whole turn over
    the sweep (a crank run for a minute: 40,000 degrees) is wrapped into [-180, 180), else it
    flattens every other link's angle on the plot's scale; others are kept as they are."""
    degrees = np.degrees(np.asarray(angle, dtype=float))
    finite = degrees[np.isfinite(degrees)]
    if not len(finite) or np.ptp(finite) <= 360.0:
        return degrees, False
    return (degrees + 180.0) % 360.0 - 180.0, True


@functools.lru_cache(maxsize=4096)
def series_style(title: str, colour: tuple) -> rr.SeriesLines:
    """A plotted series' static style (its name and colour), built once per name and colour:
    follow logs every series' style with each block, and its stream skips an archetype that
    is the very object it last sent to that entity without encoding it again."""
    return rr.SeriesLines(names=title, colors=[list(colour)])


def log_series(stream, send, result) -> None:
    for entity, title, values, colour in series_of(result):
        values = np.asarray(values, dtype=float)
        finite = np.isfinite(values)
        # a series NaN at every step (every step failed) is logged too; +-inf (e.g. a failed
        # step's residual) would wreck the axis
        if not finite.all():
            values = np.where(finite, values, np.nan)
        stream.log(entity, series_style(title, tuple(colour)), static=True)
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
