"""Write a :class:`~linkpipe.result.Result` as a Rerun recording (``.rrd``), rerun-sdk 0.41.

Entity paths and timelines follow ``docs/output-format.md``. Everything that changes per
step goes out columnar with ``send_columns`` (one call per entity, never one per step);
geometry that does not change is logged once as static. Steps where a point is NaN (failed
assembly) log an empty batch for the entities that need it, which clears them at that step.

The 2D view of Rerun has +y pointing down; a static ``Transform3D`` on ``mechanism`` flips
it so the mechanism appears y-up. The logged data are the scene's own coordinates.
"""
from __future__ import annotations

import contextlib
import math
import uuid

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from . import atomic_path
from .rrd_forces import KIND_COLORS, force_arrows, force_legend, force_scale
from ..cache import derived

APPLICATION_ID = "linkpipe"
#: per-step series plotted under ``plots/<name>/<label>`` (variable name -> its second dim)
PLOTTED = ("input_force", "spring_force", "torsion_spring_torque", "link_angle")
SOLVER = ("residual", "iterations")
#: longest velocity / acceleration arrow, as a fraction of the mechanism's size
ARROW_FRACTION = 0.25

_PALETTE = np.array([[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40],
                     [148, 103, 189], [140, 86, 75], [227, 119, 194], [23, 190, 207],
                     [188, 189, 34], [127, 127, 127]], dtype=np.uint8)
_POINT = [235, 235, 235]
_GROUND = [110, 110, 110]
_GUIDE = [150, 150, 150]
_TRACE = [200, 200, 200, 150]
_SPRING = [240, 200, 40]
_VECTOR_COLORS = {"velocity": [0, 150, 70], "acceleration": [200, 30, 120]}


def write(result, path, spawn: bool = False, connect: str | None = None) -> None:
    """Write the recording of ``result`` to ``path`` (``None``: no file) and optionally stream it.

    ``spawn=True`` starts a Rerun viewer and streams to it; ``connect`` streams to a running
    viewer at that address (``rerun+http://host:port/proxy``). The file is written to a
    temporary name and renamed into place when complete.
    """
    if path is None and not spawn and not connect:
        return
    scene = result.scene
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}-{uuid.uuid4().hex}")
    # generous on purpose: the recording holds float32 copies of the arrays plus labels, and
    # Rerun's file writer does not fail cleanly on a full disk (it can hang flushing): twice
    # the arrays' bytes and 256 KiB
    n_bytes = 2 * sum(v.data.nbytes for v in result.variables()) + (256 << 10)
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
            log_result(stream, result)
    if spawn or connect:
        stream.disconnect()


# ------------------------------------------------------------------------------ geometry
def _bounds(result, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the (lower, upper) corners of the finite rows of ``points`` (N, 2)."""
    # NaN rows (failed steps) drop out of nanmin/nanmax; no masked copy of (S * P, 2) points
    with np.errstate(invalid="ignore"):
        finite = _finite_rows(points)
    if not finite.any():
        points = np.array([[p.x, p.y] for p in result.scene.points], dtype=float)
        return points.min(axis=0), points.max(axis=0)
    if finite.all():  # per coordinate: numpy's reductions over a length-2 axis are slow
        x, y = points[:, 0], points[:, 1]
        return np.array([x.min(), y.min()]), np.array([x.max(), y.max()])
    return np.nanmin(points, axis=0), np.nanmax(points, axis=0)


def _finite_rows(a: np.ndarray) -> np.ndarray:
    """Return ``np.isfinite(a).all(axis=-1)``: a NaN or inf survives the row's sum."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.isfinite(a.sum(axis=-1)) if a.shape[-1] > 2 else np.isfinite(a[..., 0] + a[..., -1])


def mechanism_size(result) -> float:
    """Return the diagonal of the bounding box of every position of the sweep (1 if none)."""
    return derived(result, "rrd_mechanism_size", _mechanism_size)  # asked for several times


def _mechanism_size(result) -> float:
    lo, hi = _bounds(result, result.position.reshape(-1, 2))
    return float(np.hypot(*(hi - lo))) or 1.0


def arrow_scales(result) -> dict[str, float]:
    """Return the length per unit of each vector quantity: its longest arrow is 25 % of the size."""
    return dict(derived(result, "rrd_arrow_scales", _arrow_scales))  # blueprint and log ask


def _arrow_scales(result) -> dict[str, float]:
    k = _point_index(result, result.scene.outputs.vectors)
    scales = {}
    for name in ("velocity", "acceleration"):
        data = getattr(result, name)
        if data is None or not k:
            continue
        norm = np.linalg.norm(data[:, k], axis=-1)
        vmax = np.nanmax(norm) if np.isfinite(norm).any() else 0.0
        scales[name] = ARROW_FRACTION * mechanism_size(result) / vmax if vmax > 0 else 1.0
    return scales


def arrow_legend(result, quantity: str) -> str:
    """Return ``"1 m = 7.51 m/s"``: what one length unit of ``quantity``'s arrows stands for."""
    unit = {v.name: v.units for v in result.variables()}[quantity]
    return f"1 {result.units()['length']} = {1 / arrow_scales(result)[quantity]:.3g} {unit}"


def _point_index(result, names) -> list[int]:
    index = {n: i for i, n in enumerate(result.point_names)}
    return [index[n] for n in names]


def _runs(path: np.ndarray) -> list[np.ndarray]:
    """Split an (S, 2) path at its non-finite rows into runs of 2 or more points."""
    ok = np.isfinite(path).all(axis=1)
    edges = np.flatnonzero(np.diff(ok.astype(np.int8))) + 1
    return [run for run, good in zip(np.split(path, edges), np.split(ok, edges))
            if good[0] and len(run) >= 2]


# ------------------------------------------------------------------------------ logging
def path_of(*parts) -> str:
    """The entity path of unescaped parts (scene names may hold ``/``, spaces, backslashes):
    Rerun's own escaping (``rr.new_entity_path``), so that distinct names stay distinct."""
    return rr.new_entity_path([str(p) for p in parts])


def log_result(stream: rr.RecordingStream, result) -> None:
    """Log every entity of the contract for ``result`` to ``stream``."""
    steps = np.arange(result.n_steps)
    by_value = driver_timeline(result)

    def send(entity: str, columns, rows: np.ndarray | None = None) -> None:
        rows = slice(None) if rows is None else rows
        index = [rr.TimeColumn("step", sequence=steps[rows])]
        if result.time is not None:
            index.append(rr.TimeColumn("time", duration=np.asarray(result.time, float)[rows]))
        if by_value is not None:
            index.append(rr.TimeColumn(by_value[0], sequence=by_value[1][rows]))
        stream.send_columns(entity, indexes=index, columns=columns)

    stream.log("mechanism", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
    _log_points(stream, send, result)
    _log_links(stream, send, result)
    _log_actuators(stream, send, result)
    _log_guides(stream, send, result)
    _log_springs(stream, send, result)
    _log_traces(stream, result)
    _log_vectors(stream, send, result)
    _log_forces(stream, send, result)
    _log_series(stream, send, result)


def driver_timeline(result):
    """(name, values (S,) int64) of a timeline that is the driver's value, for a one-driver
    sweep whose value only rises or only falls: the plots can then be read against the crank
    angle or the cylinder's length (pick it in the time panel). Rerun's timelines count in
    integers, so the value is written in units fine enough that every step has its own:
    ``"crank [deg/1000]"`` holds 1000 x the angle in degrees. None otherwise."""
    if len(result.driver_names) != 1 or result.n_steps < 2:
        return None
    value = np.asarray(result.driver_value[:, 0], dtype=float)
    step = np.diff(value)
    if not (np.isfinite(value).all() and ((step > 0).all() or (step < 0).all())):
        return None
    per = 10.0 ** max(0, math.ceil(-math.log10(float(np.abs(step).min()))) + 1)
    ints = np.round(value * per).astype(np.int64)
    if not (np.abs(value).max() * per < 2 ** 62 and (np.diff(ints) != 0).all()):
        return None
    unit = result.driver_units()[0]
    return f"{result.driver_names[0]} [{unit}/{per:g}]", ints


def _log_points(stream, send, result) -> None:
    X = result.position
    ok = _finite_rows(X)                                  # (S, P)
    stream.log("mechanism/points", rr.Points2D.from_fields(
        radii=rr.components.Radius.ui_points(4.0), colors=_POINT, show_labels=True,
        draw_order=30.0), static=True)
    if ok.any():
        pos = X.reshape(-1, 2) if ok.all() else X[ok]  # all finite: no masked copy
        send("mechanism/points",
             rr.Points2D.columns(positions=np.asarray(pos, dtype=np.float32),
                                 labels=_labels_arrow(result.point_names, ok))
             .partition(ok.sum(axis=1)))
    fixed = [i for i, p in enumerate(result.scene.points) if p.fixed]
    if fixed:
        ground = np.array([[result.scene.points[i].x, result.scene.points[i].y] for i in fixed])
        stream.log("mechanism/ground", rr.Points2D(
            ground, radii=rr.components.Radius.ui_points(8.0), colors=_GROUND, draw_order=25.0),
            static=True)


def _labels_arrow(names, ok: np.ndarray):
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


def _log_links(stream, send, result) -> None:
    """Each link as a line strip in its own colour: a bar between its two points, a plate as
    its closed outline (the drawing's convex hull, so the outline never crosses itself; points
    inside the plate stay points)."""
    for j, link in enumerate(result.scene.links):
        k = _outline(result, _point_index(result, link.points))
        _send_strips(stream, send, path_of("mechanism", "links", link.name), result.position[:, k],
                     radii=rr.components.Radius.ui_points(2.5),
                     colors=_PALETTE[j % len(_PALETTE)], draw_order=20.0)


def _outline(result, k: list[int]) -> list[int]:
    """Point indices of a link's outline: its two points; a triangle closed; a larger plate's
    convex hull as drawn, counter-clockwise and closed (one drawn in a line: its two extreme
    points)."""
    if len(k) < 4:  # a bar, or a triangle (closed in any order without crossing)
        return k + k[:1] if len(k) == 3 else k
    drawn = np.array([[result.scene.points[i].x, result.scene.points[i].y] for i in k])
    try:
        from scipy.spatial import ConvexHull
        hull = [k[i] for i in ConvexHull(drawn).vertices]
    except Exception:  # scipy's QhullError: every point on one line
        axis = drawn[np.argmax(np.ptp(drawn, axis=0))] - drawn[0]
        along = (drawn - drawn[0]) @ axis
        return [k[int(np.argmin(along))], k[int(np.argmax(along))]]
    return hull + hull[:1]


def _log_actuators(stream, send, result) -> None:
    """Each ``distance`` driver (a cylinder) as a thick grey bar between its pins."""
    for driver in result.scene.drivers:
        if driver.kind == "distance":
            _send_strips(stream, send, path_of("mechanism", "actuators", driver.name),
                         result.position[:, _point_index(result, driver.points)],
                         radii=rr.components.Radius.ui_points(5.0), colors=_GUIDE,
                         draw_order=15.0)


def _send_strips(stream, send, entity: str, strips: np.ndarray, **style) -> None:
    """Log one strip per step from ``strips`` (S, n, 2); steps with a NaN get none (cleared)."""
    ok = _finite_rows(strips.reshape(len(strips), -1))
    stream.log(entity, rr.LineStrips2D.from_fields(**style), static=True)
    if ok.any():
        send(entity, rr.LineStrips2D.columns(strips=_strips_arrow(strips if ok.all() else strips[ok]))
             .partition(ok.astype(int)))


def _strips_arrow(strips: np.ndarray):
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


def _log_guides(stream, send, result) -> None:
    margin = 0.1 * mechanism_size(result)
    for slider in result.scene.sliders:
        (k,) = _point_index(result, [slider.point])
        P = result.position[:, k]
        entity = path_of("mechanism", "guides", slider.name)
        style = dict(radii=rr.components.Radius.ui_points(1.5), colors=_GUIDE, draw_order=5.0)
        if not slider.moving:
            t0 = np.asarray(slider.through, float)
            d = np.asarray(slider.direction, float)
            d = d / np.linalg.norm(d)
            s = (P - t0) @ d
            s = s[np.isfinite(s)]
            lo, hi = (s.min(), s.max()) if len(s) else (0.0, 0.0)
            segment = t0 + np.outer([lo - margin, hi + margin], d)
            stream.log(entity, rr.LineStrips2D([segment], **style), static=True)
            continue
        D, E = (result.position[:, i] for i in _point_index(result, slider.line_points))
        length = np.linalg.norm(E - D, axis=1, keepdims=True)
        d = (E - D) / np.where(length > 0, length, np.nan)
        s = np.stack([np.zeros(len(P)), length[:, 0], np.einsum("ij,ij->i", P - D, d)], axis=1)
        ends = np.stack([s.min(axis=1) - margin, s.max(axis=1) + margin], axis=1)  # (S, 2)
        _send_strips(stream, send, entity, D[:, None, :] + ends[:, :, None] * d[:, None, :], **style)


def _log_springs(stream, send, result) -> None:
    """Log ``mechanism/springs/<spring>`` (an addition to the contract): a line per step."""
    if not result.spring_names:
        return
    for spring in result.scene.springs:
        _send_strips(stream, send, path_of("mechanism", "springs", spring.name),
                     result.position[:, _point_index(result, spring.between)],
                     radii=rr.components.Radius.ui_points(1.0), colors=_SPRING, draw_order=15.0)


def _log_traces(stream, result) -> None:
    for name in result.scene.outputs.trace:
        (k,) = _point_index(result, [name])
        runs = _runs(result.position[:, k])
        if runs:
            stream.log(path_of("mechanism", "trace", name), rr.LineStrips2D(
                runs, radii=rr.components.Radius.ui_points(1.0), colors=_TRACE,
                labels=[f"trace {name}"] * len(runs), show_labels=False, draw_order=10.0),
                static=True)


def _log_vectors(stream, send, result) -> None:
    """Velocity and acceleration arrows, one scale per quantity.

    Each arrow's label names its scale but is not drawn (a velocity and an acceleration at one
    point, often near parallel, would put their labels on top of each other): the viewer shows
    it on hover, and the 2D view's title gives the scales (see :func:`arrow_legend`).
    """
    scales = arrow_scales(result)
    for quantity, scale in scales.items():
        data = getattr(result, quantity)
        for name in result.scene.outputs.vectors:
            (k,) = _point_index(result, [name])
            origins, vectors = result.position[:, k], data[:, k]
            ok = _finite_rows(origins) & _finite_rows(vectors)
            entity = path_of("mechanism", quantity, name)
            stream.log(entity, rr.Arrows2D.from_fields(
                labels=[f"{quantity[0]} {name} ({arrow_legend(result, quantity)})"],
                colors=_VECTOR_COLORS[quantity], show_labels=False,
                radii=rr.components.Radius.ui_points(1.5), draw_order=40.0), static=True)
            if ok.any():
                if not ok.all():
                    origins, vectors = origins[ok], vectors[ok]
                send(entity, rr.Arrows2D.columns(origins=np.asarray(origins, dtype=np.float32),
                                                 vectors=np.asarray(vectors * scale, dtype=np.float32))
                     .partition(ok.astype(int)))


def forces_drawn(result):
    """(arrows, scale) of the recording's force arrows (:mod:`.rrd_forces`), built once."""
    def build(res):
        arrows = force_arrows(res)
        return arrows, force_scale(res, arrows, mechanism_size(res))
    return derived(result, "rrd_force_arrows", build)


def _log_forces(stream, send, result) -> None:
    """``mechanism/forces/<kind>/<name>``: every force where it acts, one scale (title)."""
    arrows, scale = forces_drawn(result)
    if not scale:
        return
    legend = force_legend(result, scale)
    for kind, name, origins, vectors in arrows:
        entity = path_of("mechanism", "forces", kind, name)
        stream.log(entity, rr.Arrows2D.from_fields(
            labels=[f"{kind} {name} ({legend})"], colors=KIND_COLORS[kind], show_labels=False,
            radii=rr.components.Radius.ui_points(2.0), draw_order=45.0), static=True)
        ok = np.isfinite(origins).all(axis=2) & np.isfinite(vectors).all(axis=2)  # (S, k)
        if ok.any():
            send(entity, rr.Arrows2D.columns(
                origins=np.asarray(origins[ok], dtype=np.float32),
                vectors=np.asarray(vectors[ok] * scale, dtype=np.float32)).partition(ok.sum(axis=1)))


def _log_series(stream, send, result) -> None:
    variables = {v.name: v for v in result.variables()}
    labels = {c.name: c.data for c in result.coordinates()}
    series = []
    for name in PLOTTED:
        var = variables.get(name)
        if var is None or var.dims[:1] != ("step",) or len(var.dims) != 2:
            continue
        for j, label in enumerate(labels[var.dims[1]]):  # one colour each within a plot
            series.append((path_of("plots", name, label), f"{label} [{var.units}]", var.data[:, j],
                           _PALETTE[j % len(_PALETTE)]))
    for name in SOLVER:
        var = variables[name]
        series.append((f"solver/{name}", f"{name} [{var.units}]", var.data, _PALETTE[0]))
    if result.measurements:  # computed beside measured, one plot per measurement
        m = result.measurements
        for k, name in enumerate(m["names"]):
            computed = m["measured"][:, k] + m["residual"][:, k]
            unit = m["units"][k]
            series.append((path_of("plots", "measurements", name, "computed"),
                           f"computed [{unit}]", computed, _PALETTE[0]))
            series.append((path_of("plots", "measurements", name, "measured"),
                           f"measured [{unit}]", m["measured"][:, k], _PALETTE[1]))
    log_res, log_tol = log10_residual(result)
    length = variables["residual"].units
    series.append(("solver/log10_residual", f"log10 residual [{length}]", log_res, _PALETTE[0]))
    series.append(("solver/log10_tolerance", f"log10 tolerance [{length}]",
                   np.full(result.n_steps, log_tol), _PALETTE[2]))
    for entity, title, values, colour in series:
        values = np.asarray(values, dtype=float)
        finite = np.isfinite(values)
        if not finite.any():
            continue
        if not finite.all():  # +-inf (e.g. a failed step's residual) would wreck the axis
            values = np.where(finite, values, np.nan)
        stream.log(entity, rr.SeriesLines(names=title, colors=colour), static=True)
        # every step, NaN included: the viewer breaks the line at a NaN, whereas a step left
        # out would be bridged by a straight segment that looks like data
        send(entity, rr.Scalars.columns(scalars=values))


def log10_residual(result) -> tuple[np.ndarray, float]:
    """Return (log10 of the residual (S,), log10 of the solver's tolerance), lengths in scene units.

    The viewer labels no axis below ~1e-13, so the raw ``solver/residual`` of a solved sweep
    (rounding level, ~1e-16 of the size) plots as unlabelled noise; its log10 beside the
    tolerance's (``tol`` x the mechanism's size, what Newton stops at) reads at a glance. A
    residual of exactly 0 is drawn one decade below rounding level (log10(eps x size) - 1);
    NaN (a step without assembly) stays NaN and is not drawn.
    """
    size = result.model.size
    floor = float(np.log10(np.finfo(float).eps * size)) - 1.0
    res = np.asarray(result.residual, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.log10(res)
    out[res == 0] = floor
    return out, float(np.log10(result.scene.solver.tol * size))


# ------------------------------------------------------------------------------ blueprint
def view_bounds(result) -> tuple[np.ndarray, np.ndarray]:
    """Return the 2D view's (lower, upper) corners: every position and arrow tip, padded 8 %."""
    drawn = [result.position.reshape(-1, 2)]
    k = _point_index(result, result.scene.outputs.vectors)
    for quantity, scale in arrow_scales(result).items():    # arrow tips too
        drawn.append((result.position[:, k] + scale * getattr(result, quantity)[:, k]).reshape(-1, 2))
    arrows, fscale = forces_drawn(result)
    for _, _, origins, vectors in arrows if fscale else ():
        drawn.append((origins + fscale * vectors).reshape(-1, 2))
    lo, hi = _bounds(result, np.concatenate(drawn))
    pad = 0.08 * max(float(np.max(hi - lo)), 1e-9)
    return lo - pad, hi + pad


def blueprint(result) -> rrb.Blueprint:
    """Return the default layout: the mechanism (y up) beside the plots and solver series."""
    lo, hi = view_bounds(result)
    name = f"{result.scene.name} (y up)"
    if result.scene.outputs.vectors and arrow_scales(result):
        colour = {"velocity": "green", "acceleration": "magenta"}
        name += "; arrows: " + ", ".join(f"{q} ({colour[q]}) {arrow_legend(result, q)}"
                                         for q in arrow_scales(result))
    arrows, fscale = forces_drawn(result)
    if fscale:
        kinds = dict.fromkeys(kind for kind, *_ in arrows)
        colour = {"input": "red", "loads": "orange", "springs": "yellow", "reactions": "blue"}
        name += (f"; {force_legend(result, fscale)} ("
                 + ", ".join(f"{k} {colour[k]}" for k in kinds) + ")")
    mechanism = rrb.Spatial2DView(
        origin="/", contents="mechanism/**", name=name,
        visual_bounds=rrb.VisualBounds2D(x_range=[lo[0], hi[0]], y_range=[-hi[1], -lo[1]]))
    variables = {v.name: v for v in result.variables()}
    plots = [rrb.TimeSeriesView(origin=f"plots/{name}", name=f"{name} [{variables[name].units}]")
             for name in PLOTTED if name in variables]
    if result.measurements:
        plots += [rrb.TimeSeriesView(origin=path_of("plots", "measurements", name),
                                     name=f"{name}: computed and measured")
                  for name in result.measurements["names"]]
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
