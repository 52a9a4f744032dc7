"""Force arrows: ``mechanism/forces/<kind>/<name>``, every force where it acts, one scale.

Only a run with a force stage draws them (a kinematics-only scene computes no force, so none is
drawn), and only the kinds it computed. Each kind is one row of :data:`KINDS`: the variable of
``result.forces`` whose presence calls for it, its colour, and a function that returns, for each
named item, where its forces act and what they are at every step (force units, the stored
values; the recording multiplies them by the one scale):

* ``input`` (red): each driver's ``input_force``. With ``input``, at the input point along its
  direction (turning with ``input.link``). Without: a ``distance`` driver's axial force on its
  two pins (pushing them apart when positive); a ``coordinate`` driver's force at its point along
  its axis; an ``angle`` driver's torque as the equivalent force at the head ``b`` of the driven
  vector ``a -> b``, perpendicular to it, torque / |ab| (the force at ``b`` that turns the link
  about ``a`` with that torque); with ``relative_to`` ``c -> d`` on a moving second body, also
  the reaction on it, ``input/<driver>/reaction``: minus the torque, at ``d``, perpendicular
  to ``c -> d``.
* ``loads`` (orange): each force load at its point (couples are not arrows).
* ``weights`` (violet): each mass's weight ``m g`` at its centre, per link.
* ``springs`` (yellow): each two-point spring's force (``spring_force``, damping included) on
  its two ends; a tension pulls them together.
* ``reactions`` (cyan): ``ground_reaction``, the force the ground exerts at each fixed point.
* ``friction`` (blue): a seal's friction on its cylinder's two pins, a slider's on its point
  along the guide, opposing the motion (:func:`friction_arrows`); a pin's is a couple, drawn as
  an arc arrow around its pin, ``mechanism/forces/friction/<entry>/<joint>``
  (:func:`pin_couples`).

The scale makes the longest arrow of the sweep at most :data:`FORCE_FRACTION` of the mechanism's
size, rounded so that one length unit stands for 1, 2, 2.5 or 5 times a power of ten force
units; the 2D view's title says it (``forces 1 m = 250 N``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Callable

import numpy as np
import rerun as rr

from ...cache import derived
from . import style
from .geometry import finite_rows, mechanism_size
from .mechanism import path_of, send_strips

#: the longest force arrow of a sweep, at most this fraction of the mechanism's size
FORCE_FRACTION = 0.3
#: an item's label is drawn when its arrows are this long (fraction of the size) at 80 % of
#: the steps or more
LABEL_FRACTION = 0.06


@dataclass(frozen=True)
class ForceKind:
    """One kind of force arrow: drawn when ``result.forces`` holds ``variable``."""

    name: str
    variable: str
    colour: tuple[int, int, int]
    colour_name: str
    arrows: Callable  # result -> [(item (a name, or a tuple of path parts), origins (S, k, 2),
    #                              forces (S, k, 2))]
    tag: str          # the arrows' drawn label: "<tag> <item>" ("R O2"), or the item alone
    legend: str = ""  # what the legend calls the kind ("ground reactions")
    outward: bool = False  # drawn from its point outward: an arrow pointing into the bodies
    #                        ends at its point instead of starting there (:func:`placed`)


def _points(result) -> tuple[np.ndarray, dict[str, int]]:
    return result.position, {n: i for i, n in enumerate(result.point_names)}


def _unit(d: np.ndarray) -> np.ndarray:
    """Rows of d (S, 2) divided by their length (NaN where it is 0)."""
    length = np.hypot(d[:, 0], d[:, 1])
    return d / np.where(length > 0, length, np.nan)[:, None]


def _perp(d: np.ndarray) -> np.ndarray:
    """Rows of d (S, 2) turned a quarter turn counter-clockwise."""
    return np.stack([-d[:, 1], d[:, 0]], axis=1)


def input_direction(result, driver_input) -> np.ndarray:
    """Unit direction (S, 2) an input pushes along: global, or with ``link`` in that link's frame
    (u from its first point to its second, v a quarter turn CCW); the same rule as
    :func:`linkpipe.forces.virtual_work.input_direction`, evaluated on the stored positions."""
    n = np.asarray(driver_input.direction, dtype=float)
    n = n / np.hypot(*n)
    if driver_input.link is None:
        return np.broadcast_to(n, (result.n_steps, 2))
    X, idx = _points(result)
    link = next(ln for ln in result.scene.links if ln.name == driver_input.link)
    e = _unit(X[:, idx[link.points[1]]] - X[:, idx[link.points[0]]])
    return np.stack([n[0] * e[:, 0] - n[1] * e[:, 1], n[0] * e[:, 1] + n[1] * e[:, 0]], axis=1)


def input_arrows(result) -> list:
    X, idx = _points(result)
    F = result.forces["input_force"][1]
    out = []
    for j, driver in enumerate(result.scene.drivers):
        f = F[:, j, None]
        if driver.input is not None:
            at, force = [X[:, idx[driver.input.point]]], [f * input_direction(result, driver.input)]
        elif driver.kind == "coordinate":
            axis = np.eye(2)[driver.axis]
            at, force = [X[:, idx[driver.points[0]]]], [f * axis]
        elif driver.kind == "distance":
            a, b = X[:, idx[driver.points[0]]], X[:, idx[driver.points[1]]]
            u = _unit(b - a)
            at, force = [a, b], [-(f * u), f * u]
        else:  # a torque: the force at b, perpendicular to a -> b, that turns it about a
            a, b = X[:, idx[driver.points[0]]], X[:, idx[driver.points[1]]]
            at, force = [b], [_torque_as_force(f, b - a)]
            if driver.relative_to is not None and (driver.bodies or ("", ""))[1] != "ground":
                # the motor's reaction on the second body: an entity of its own beneath the
                # driver's, so that each label sits at its own arrow
                c, d = X[:, idx[driver.relative_to[0]]], X[:, idx[driver.relative_to[1]]]
                out.append(((driver.name, "reaction"), d[:, None], _torque_as_force(-f, d - c)[:, None]))
        out.append((driver.name, np.stack(at, axis=1), np.stack(force, axis=1)))
    return out


def _torque_as_force(torque: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """The force (S, 2) at the end of ``arm`` (S, 2) with moment ``torque`` (S, 1) about its start."""
    length = np.hypot(arm[:, 0], arm[:, 1])[:, None]
    return (torque / np.where(length > 0, length, np.nan)) * _perp(_unit(arm))


def load_arrows(result) -> list:
    if "loads" not in result.scene.effects:
        return []
    X, idx = _points(result)
    return [(load.name, X[:, idx[load.point]][:, None],
             np.broadcast_to(np.asarray(load.force, float), (result.n_steps, 1, 2)))
            for load in result.scene.loads if load.point is not None and load.force is not None]


def weight_arrows(result) -> list:
    g = np.asarray(result.scene.gravity, dtype=float)
    centres: dict[str, list] = {}
    for mass in result.scene.masses:
        centres.setdefault(mass.link, []).append((mass_centre(result, mass), mass.mass * g))
    return [(link, np.stack([c for c, _ in items], axis=1),
             np.broadcast_to(np.stack([w for _, w in items]), (result.n_steps, len(items), 2)))
            for link, items in centres.items()]


def mass_centre(result, mass) -> np.ndarray:
    """A mass's centre (S, 2): its point, or local (u, v) along the link's first two points."""
    X, idx = _points(result)
    if isinstance(mass.center, str):
        return X[:, idx[mass.center]]
    link = next(ln for ln in result.scene.links if ln.name == mass.link)
    a = X[:, idx[link.points[0]]]
    e = _unit(X[:, idx[link.points[1]]] - a)
    u, v = mass.center
    return a + u * e + v * _perp(e)


def spring_arrows(result) -> list:
    X, idx = _points(result)
    T = result.forces["spring_force"][1]
    out = []
    for k, spring in enumerate(result.scene.springs):
        a, b = X[:, idx[spring.between[0]]], X[:, idx[spring.between[1]]]
        pull = T[:, k, None] * _unit(b - a)   # on a, towards b when in tension
        out.append((spring.name, np.stack([a, b], axis=1), np.stack([pull, -pull], axis=1)))
    return out


def reaction_arrows(result) -> list:
    X, idx = _points(result)
    R = result.forces["ground_reaction"][1]
    return [(name, X[:, idx[name]][:, None], R[:, k][:, None])
            for k, name in enumerate(result.force_coords["fixed_point"])]


def friction_arrows(result) -> list:
    """Seal friction on a cylinder's two pins (pulling them together while it extends) and a
    slider's friction on its point along the guide, each opposing the motion (pins' friction is
    a couple: plotted, not drawn)."""
    X, idx = _points(result)
    mag = result.forces["friction_force"][1]
    out = []
    for e, fr in enumerate(result.scene.friction):
        if fr.kind == "driver":
            j = [d.name for d in result.scene.drivers].index(fr.driver)
            driver = result.scene.drivers[j]
            if driver.kind != "distance" or result.driver_velocity is None:
                continue
            f = (mag[:, e] * np.sign(result.driver_velocity[:, j]))[:, None]
            a, b = X[:, idx[driver.points[0]]], X[:, idx[driver.points[1]]]
            u = _unit(b - a)
            out.append((fr.name, np.stack([a, b], axis=1), np.stack([f * u, -(f * u)], axis=1)))
        elif fr.kind == "slider" and result.velocity is not None:
            sl = next(x for x in result.scene.sliders if x.name == fr.slider)
            p = idx[sl.point]
            if sl.moving:
                d, e2 = idx[sl.line_points[0]], idx[sl.line_points[1]]
                t, rel = _unit(X[:, e2] - X[:, d]), result.velocity[:, p] - result.velocity[:, d]
            else:
                t = np.broadcast_to(np.asarray(sl.direction, float) / np.hypot(*sl.direction),
                                    (result.n_steps, 2))
                rel = result.velocity[:, p]
            sign = np.sign(rel[:, 0] * t[:, 0] + rel[:, 1] * t[:, 1])
            out.append((fr.name, X[:, p][:, None], (-(mag[:, e] * sign)[:, None] * t)[:, None]))
    return out
def _kind(name, variable, arrows, tag, legend, outward=False) -> ForceKind:
    """A kind in its own saturated hue (:data:`.style.ARROW_HUES`, never a link's)."""
    return ForceKind(name, variable, tuple(style.arrow_colour(name)), style.ARROW_HUE_NAMES[name],
                     arrows, tag, legend, outward)


#: the kinds of force arrows, drawn in this order; a new kind is one row (the loads are the
#: scene's own constants: drawn whenever forces are computed, i.e. ``input_force`` is there)
KINDS = (
    _kind("input", "input_force", input_arrows, "", "input force"),
    _kind("loads", "input_force", load_arrows, "", "loads"),
    _kind("weights", "gravity_energy", weight_arrows, "W", "weights"),
    _kind("springs", "spring_force", spring_arrows, "", "spring forces"),
    _kind("reactions", "ground_reaction", reaction_arrows, "R", "ground reactions", True),
    _kind("friction", "friction_force", friction_arrows, "f", "friction"),
)


def force_arrows(result) -> list[tuple[ForceKind, str, np.ndarray, np.ndarray]]:
    """Return [(kind, item, origins (S, k, 2), forces (S, k, 2))] of every force to draw (force
    units), with the scale (length per force unit, 0 if there is nothing to draw); built once."""
    return derived(result, "rrd_force_arrows", _force_arrows)


def _force_arrows(result):
    forces = result.forces or {}
    arrows = [(kind, item, origins, vectors) for kind in KINDS if kind.variable in forces
              for item, origins, vectors in kind.arrows(result)]
    largest = 0.0
    for *_, vectors in arrows:   # over finite arrows: an overflowed step (inf) is not drawn
        with np.errstate(invalid="ignore", over="ignore"):
            norm = np.hypot(vectors[..., 0], vectors[..., 1])
        norm = norm[np.isfinite(norm)]
        if norm.size:
            largest = max(largest, float(norm.max()))
    if not largest > 0:
        return [], 0.0
    return arrows, 1.0 / nice_ceiling(largest / (FORCE_FRACTION * mechanism_size(result)))


def nice_ceiling(x: float) -> float:
    """The smallest of 1, 2, 2.5, 5 times a power of ten that is >= x (> 0)."""
    power = 10.0 ** math.floor(math.log10(x))
    for step in (1.0, 2.0, 2.5, 5.0, 10.0):
        if step * power >= x * (1 - 1e-12):
            return step * power
    return 10.0 * power


def force_legend(result) -> str:
    """``"forces 1 m = 250 N (input red, reactions cyan)"``: the scale and the kinds drawn."""
    arrows, scale = force_arrows(result)
    if not scale:
        return ""
    units = result.units()
    kinds = dict.fromkeys(kind for kind, *_ in arrows)
    return (f"forces 1 {units['length']} = {1 / scale:,.10g} {units['force']} ("
            + ", ".join(f"{k.name} {k.colour_name}" for k in kinds) + ")")


#: a force whose arrow would be shorter than this fraction of the mechanism's size (but not
#: zero) is drawn at this length, its value labelled: a 2.7 lbf spring force at 1 ft = 100 lbf
#: would otherwise be an invisible dot
MIN_FRACTION = 0.04


def drawn_arrows(result) -> list[tuple[ForceKind, str, np.ndarray, np.ndarray, np.ndarray]]:
    """Return [(kind, item, origins (S, k, 2), vectors (S, k, 2), short (S, k))]: every force
    arrow as drawn (length units): the force times the scale, at least :data:`MIN_FRACTION` of
    the size where it is not zero (``short``: drawn longer than its scale, its value labelled);
    a kind drawn ``outward`` (the ground reactions) that points towards the bodies at its point
    (:func:`towards_neighbours`) ends at its point instead of starting there, so that it lies
    outside them (a pole's foot: the reaction no longer runs up the pole). Built once."""
    return derived(result, "rrd_drawn_arrows", _drawn_arrows)


def _drawn_arrows(result):
    arrows, scale = force_arrows(result)
    if not scale:
        return []
    least = MIN_FRACTION * mechanism_size(result)
    out = []
    for kind, item, origins, vectors in arrows:
        v = vectors * scale
        with np.errstate(invalid="ignore", over="ignore"):
            length = np.hypot(v[..., 0], v[..., 1])
            short = (length > 0) & (length < least)
            if short.any():
                v = np.where(short[..., None], v * (least / np.where(short, length, 1.0))[..., None], v)
            if kind.outward:
                towards = towards_neighbours(result, item)[:, None, :]      # (S, 1, 2)
                inward = np.einsum("skc,skc->sk", v, np.broadcast_to(towards, v.shape)) > 0
                origins = np.where(inward[..., None], origins - v, origins)
        out.append((kind, item, origins, v, short))
    return out


def towards_neighbours(result, name: str) -> np.ndarray:
    """(S, 2): the sum of unit vectors from point ``name`` to its neighbours at each step: the
    other points of the links it is on and, for a fixed point, the other fixed points (the
    ground is one body, drawn or not). An arrow at the point that has a positive component
    along it points into the bodies there."""
    X, idx = _points(result)
    k = idx[name]
    near = {idx[p] for ln in result.scene.links if name in ln.points for p in ln.points}
    if result.scene.points[k].fixed:
        near |= {i for i, p in enumerate(result.scene.points) if p.fixed}
    near.discard(k)
    out = np.zeros((result.n_steps, 2))
    for n in sorted(near):
        with np.errstate(invalid="ignore"):
            u = _unit(X[:, n] - X[:, k])
        out += np.where(np.isfinite(u), u, 0.0)
    return out


def log_forces(stream, send, result) -> None:
    """``mechanism/forces/<kind>/<item>``: each item's arrows (:func:`drawn_arrows`) at every
    step where they are finite (a failed step clears them), each labelled with its item (a
    reaction ``R <point>``, a weight ``W <link>``): drawn where the arrows are long enough to
    carry it (:func:`_labelled`), else on hover. An item drawn at the least length at some
    step carries its value at every step (``S1 2.7 lbf``), drawn. The kinds' colours and the
    scale are in the legend (:mod:`.legend`)."""
    arrows, scale = force_arrows(result)
    if not scale:
        return
    size = mechanism_size(result)
    unit = result.units()["force"]
    drawn = drawn_arrows(result)
    under = _drawn_over(drawn)
    per_kind = {}
    for kind, *_ in drawn:
        per_kind[kind.name] = per_kind.get(kind.name, 0) + 1
    for n_item, ((kind, item, _, forces_), (_, _, origins, vectors, short)) in enumerate(zip(arrows, drawn)):
        parts = item if isinstance(item, tuple) else (item,)
        entity = path_of("mechanism", "forces", kind.name, *parts)
        tag = " ".join(([kind.tag] if kind.tag else []) + [str(p) for p in parts])  # one per item: drawn at the
        # centre of its arrows (a cylinder's or a spring's middle), not once per arrow
        same = [n for n, first in under.items() if first == n_item]
        if same:   # items drawn on top of this one (two springs side by side): one label
            tag = " = ".join([tag] + [_item_tag(*drawn[n][:2]) for n in same])
        valued, named = bool(short.any()), _labelled(forces_, scale, size)
        if n_item in under:    # drawn under an earlier item's arrows: its label says both
            valued = named = False
        if per_kind[kind.name] > style.CROWD:   # a smear of labels: each on hover only
            named = False
        stream.log(entity, rr.Arrows2D.from_fields(
            labels=None if valued else [tag], colors=kind.colour,
            show_labels=(valued or named) and per_kind[kind.name] <= style.CROWD,
            radii=rr.components.Radius.ui_points(2.0), draw_order=45.0), static=True)
        ok = finite_rows(origins) & finite_rows(vectors)          # (S, k)
        values = np.hypot(forces_[..., 0], forces_[..., 1])
        if ok.all():  # no masked copies
            origins, vectors = origins.reshape(-1, 2), vectors.reshape(-1, 2)
            values, short = values.reshape(-1), short.reshape(-1)
        elif ok.any():
            origins, vectors, values, short = origins[ok], vectors[ok], values[ok], short[ok]
        else:
            continue
        extra = {}
        if valued:  # per step (a static label would shadow them): the value where the arrow is
            import pyarrow as pa  # drawn at the least length, else the item's name (or none)

            other = tag if named else ""
            # the first arrow of each step carries it (a spring's two ends: one label)
            first = (np.arange(ok.shape[1])[None, :] == np.argmax(ok, axis=1)[:, None])[ok]
            extra["labels"] = pa.array([(f"{tag} {_value(v)} {unit}" if s else other) if f else ""
                                        for v, s, f in zip(values.tolist(), short.tolist(),
                                                           first.tolist())], type=pa.string())
        send(entity, rr.Arrows2D.columns(
            origins=origins.astype(np.float32),
            vectors=vectors.astype(np.float32), **extra).partition(ok.sum(axis=1)))


def _value(v: float) -> str:
    """A force's value to 3 significant figures, in plain digits between 0.001 and 10^7
    (``14,700``, ``2.67``, ``0.195``), else in exponent form."""
    if not 1e-3 <= abs(v) < 1e7:
        return f"{v:.3g}"
    r = float(f"{v:.3g}")
    return f"{r:,.0f}" if abs(r) >= 100 else f"{r:.3g}"


def _item_tag(kind: ForceKind, item) -> str:
    parts = item if isinstance(item, tuple) else (item,)
    return " ".join(([kind.tag] if kind.tag else []) + [str(p) for p in parts])


def _drawn_over(drawn) -> dict[int, int]:
    """{item: the earlier item of its kind drawn exactly where it is at every step} (two
    springs side by side in the plane): their labels would be drawn on top of each other."""
    out = {}
    for n, (kind, _, origins, vectors, _) in enumerate(drawn):
        for m in range(n):
            k2, _, o2, v2, _ = drawn[m]
            if m in out or k2 is not kind or o2.shape != origins.shape:
                continue
            if (np.allclose(o2, origins, equal_nan=True, rtol=1e-9, atol=0)
                    and np.allclose(v2, vectors, equal_nan=True, rtol=1e-9, atol=0)):
                out[n] = m
                break
    return out


def _labelled(vectors: np.ndarray, scale: float, size: float) -> bool:
    """Whether an item's label is drawn: always for two or more arrows (its label sits at their
    centre, e.g. a cylinder's middle, away from the points' labels); for one arrow, when it is,
    scaled, at least LABEL_FRACTION of the size at 80 % of the steps or more (a shorter one
    would put its label, drawn at the arrow's middle, on its point's own)."""
    if vectors.shape[1] > 1:
        return True
    with np.errstate(invalid="ignore"):
        longest = np.nanmax(np.hypot(vectors[..., 0], vectors[..., 1]), axis=1, initial=0.0)
    return bool(np.mean(longest * scale >= LABEL_FRACTION * size) >= 0.8)


#: a pin friction's couple is drawn as an arc around its pin: this radius (fraction of the
#: mechanism's size), sweeping up to :data:`COUPLE_SWEEP` radians at the sweep's largest torque
COUPLE_RADIUS, COUPLE_SWEEP, COUPLE_LEAST = 0.05, 1.5 * np.pi, 0.2 * np.pi


def pin_couples(result) -> list[tuple[str, str, np.ndarray]]:
    """Return [(entry, joint, arc (S, n, 2))]: every pin friction's couple as an arc with a
    head around its pin, in the sense the couple turns the pin's (first) moving body (against
    its rotation relative to the other body or the ground), sweeping an angle proportional to
    the entry's ``friction_force`` (its torque; an entry on several pins: their sum, drawn at
    each) over the largest of every pin entry's, at least :data:`COUPLE_LEAST`; NaN (not drawn)
    where the torque is zero (at rest) or unknown."""
    if not result.forces or "friction_force" not in result.forces or result.velocity is None:
        return []
    from ...forces.friction import link_angular_velocity  # the one formula for a link's rate
    entries = [(e, fr) for e, fr in enumerate(result.scene.friction) if fr.kind == "pins"]
    if not entries:
        return []
    X, idx = _points(result)
    V = result.velocity
    mag = result.forces["friction_force"][1]
    with np.errstate(invalid="ignore"):
        largest = np.nanmax(np.abs(mag[:, [e for e, _ in entries]]), initial=0.0)
    if not largest > 0:
        return []
    links = result.scene.links
    a = np.array([idx[ln.points[0]] for ln in links])
    b = np.array([idx[ln.points[1]] if len(ln.points) > 1 else idx[ln.points[0]] for ln in links])
    model = SimpleNamespace(link_a=a, link_b=b)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = link_angular_velocity(model, X, V)               # (S, n_links)
    rho = COUPLE_RADIUS * mechanism_size(result)
    out = []
    for e, fr in entries:
        torque = mag[:, e]
        sweep = np.maximum(COUPLE_SWEEP * np.abs(torque) / largest, COUPLE_LEAST)
        for joint in fr.joints:
            on = [li for li, ln in enumerate(links) if joint in ln.points and len(ln.points) > 1]
            if not on:
                continue
            rel = w[:, on[0]] - (w[:, on[1]] if len(on) > 1 else 0.0)
            sense = -np.sign(rel)                            # against the relative rotation
            t = np.linspace(0.0, 1.0, 24)
            phi = 0.5 * np.pi + sense[:, None] * sweep[:, None] * t[None, :]   # (S, n)
            centre = X[:, idx[joint]]
            arc = centre[:, None, :] + rho * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
            end, tangent = arc[:, -1], sense[:, None] * np.stack(
                [-np.sin(phi[:, -1]), np.cos(phi[:, -1])], axis=1)
            back, side = -0.35 * rho * tangent, 0.2 * rho * _perp(tangent)
            head = np.stack([end + back + side, end, end + back - side], axis=1)
            strip = np.concatenate([arc, head], axis=1)      # the arc, then its head
            blank = ~(np.isfinite(torque) & (torque != 0) & (sense != 0))
            out.append((fr.name, joint, np.where(blank[:, None, None], np.nan, strip)))
    return out


def log_pin_couples(stream, send, result) -> None:
    """``mechanism/forces/friction/<entry>/<joint>``: each pin friction's couple as an arc
    arrow around its pin (:func:`pin_couples`), in friction's hue, labelled ``f <entry>``."""
    for name, joint, strip in pin_couples(result):
        send_strips(stream, send, path_of("mechanism", "forces", "friction", name, joint), strip,
                    radii=rr.components.Radius.ui_points(2.0),
                    colors=style.arrow_colour("friction"), labels=[f"f {name}"],
                    show_labels=True, draw_order=46.0)
