"""The model's constraint rows built from a scene: each link's distance and local-coordinate
rows (side-length plates placed by :mod:`linkpipe.scene.sides`), sliders, drivers; and the rows
of a study's variants built at once by the same code (:func:`variant_rows`). Read by
:func:`linkpipe.model.build.build_model`."""
from __future__ import annotations

import dataclasses
import math
import numpy as np

from ..errors import SceneError
from ..scene import Scene, sides
from ..scene.geometry import MIN_LENGTH, drawing_extent, frame_too_close
from . import equations as eq

_R90 = np.array([[0.0, -1.0], [1.0, 0.0]])  # d_perp = _R90 @ d


def link_rows(scene: Scene, index: dict, X0: np.ndarray, fixed: np.ndarray,
               lengths: dict | None = None, distances: dict | None = None,
               reach: list | None = None, fits: list | None = None):
    """Each link's distance row (between its first two points, unless both are fixed) and two
    local rows per further point; returns (dist, loc) as dicts of lists.

    Variants (:func:`variant_rows`): ``lengths`` {link name: L (V,)} (a frame's length),
    ``distances`` {(link name, key): d (V,)} (a side length of ``lengths`` that places a
    further point: :mod:`linkpipe.scene.sides`) and X0 (V, n_points, 2) (each variant's
    drawing) give V variants' own numbers in place of the scene's; their rows' numbers are
    then arrays. A link whose side-length points depend on a varied number is placed again by
    :func:`linkpipe.scene.sides.placement` (the code that placed the scene's at load).
    ``reach``: a list that collects each further point's distance from the frame's first
    point over the frame's length instead of refusing a far one here; ``fits``: a list that
    collects where each placed triangle passes the scene's checks (:func:`sides.fits`)."""
    dist = {k: [] for k in ("a", "b", "len", "link")}
    loc = {k: [] for k in ("a", "b", "p", "u", "v", "len", "link")}
    lengths, distances = lengths or {}, distances or {}
    per_variant_drawing = X0.ndim == 3

    def xy(i):
        return X0[..., i, 0], X0[..., i, 1]

    for li, link in enumerate(scene.links):
        ia, ib = index[link.points[0]], index[link.points[1]]
        if all(fixed[index[p]] for p in link.points):
            continue  # a drawn piece of ground: no unknowns, no rows
        (ax, ay), (bx, by) = xy(ia), xy(ib)
        L0 = eq._number(np.hypot(bx - ax, by - ay))
        L = (lengths[link.name] if link.name in lengths
             else float(link.length) if link.length is not None else L0)
        if not fixed[ia] or not fixed[ib]:
            for key, val in zip(("a", "b", "len", "link"), (ia, ib, L, li)):
                dist[key].append(val)
        local = link.local
        if link.distances and (link.name in lengths or per_variant_drawing
                               or any(name == link.name for name, _ in distances)):
            local = _placed_again(link, xy, index, lengths.get(link.name, link.length),
                                  distances, fits)
        for pname in link.points[2:]:
            ip = index[pname]
            if fixed[ip] and fixed[ia] and fixed[ib]:
                continue
            u, v = local[pname] if pname in local else sides.drawn_local(ax, ay, bx, by, *xy(ip))
            if reach is None:
                _check_reach(scene, link, pname, float(np.hypot(u, v)) / L)
            else:
                reach.append(np.hypot(u, v) / L)
            for key, val in zip(("a", "b", "p", "u", "v", "len", "link"), (ia, ib, ip, u, v, L, li)):
                loc[key].append(val)
    return dist, loc


def _placed_again(link, xy, index: dict, length, distances: dict, fits: list | None) -> dict:
    """The local coordinates {point: (u, v)} of a link's further points that its side lengths
    place, placed again with variants' frame ``length``, side lengths ``distances`` {(link,
    key): (V,)} and drawing (``xy``: a point index -> its drawn (x, y))."""
    given = {pair: (key, distances.get((link.name, key), d))
             for pair, (key, d) in link.distances.items()}
    by_point = sides.given_by_point(link.points, given)
    explicit = {p: uv for p, uv in link.local.items() if p not in by_point}
    drawn = {p: xy(index[p]) for p in link.points}
    placed, triangles = sides.placement(link.points, length, drawn, by_point, explicit, link.side)
    if fits is not None:
        fits.append(sides.fits(triangles))
    return {p: placed[p] for p in triangles} | explicit


def variant_rows(model, lengths: dict | None = None, distances: dict | None = None,
                 drawn: np.ndarray | None = None):
    """The rows of V variants of the model's scene that differ in link lengths (``lengths``
    {link name: (V,)}, the distance of each link's first two points), in the side lengths that
    place further points of a plate (``distances`` {(link name, key): (V,)}, ``key`` as
    ``lengths`` writes it) and in their drawings (``drawn`` (V, n_points, 2): lengths and local
    coordinates the scene takes from the drawing, the side a point is drawn on), built by the
    code that builds the model's own (:func:`link_rows`, :func:`slider_rows`,
    :func:`driver_rows`, :func:`linkpipe.scene.sides.placement`): ``(rows, ok)`` with rows an
    :class:`equations.Rows` whose varied numbers are (V,) arrays, and ok (V,) True where a
    variant passes the model's and the placement's checks (no further point out of its
    frame's reach, every plate's triangle closes, the frame and reference points apart)."""
    scene = model.scene
    index = {n: i for i, n in enumerate(model.point_names)}
    X0 = model.start_position if drawn is None else drawn
    reach: list = []
    fits: list = []
    dist, loc = link_rows(scene, index, X0, model.fixed, lengths, distances, reach, fits)
    n_variants = max([len(x) for x in (lengths or {}).values()]
                     + [len(x) for x in (distances or {}).values()]
                     + [X0.shape[0] if X0.ndim == 3 else 1])
    ok = np.ones(n_variants, dtype=bool)
    for given in list((lengths or {}).values()) + list((distances or {}).values()):
        ok &= np.asarray(given) > MIN_LENGTH  # the scene's own rule: a length is positive
    for value in reach:
        ok &= ~_too_far(scene, value)
    for value in fits:
        ok &= value
    arrays = {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    arrays.update(dist_len=dist["len"], loc_u=loc["u"], loc_v=loc["v"], loc_len=loc["len"])
    if drawn is not None:  # a moving guide's length and a relative angle's scale as drawn
        apart: list = []
        arrays["smov_len"] = slider_rows(scene, index, X0)[3]["len"]
        arrays["drv_len"] = driver_rows(scene, index, X0, apart)["len"]
        for value in apart:
            ok &= value
        extent = drawing_extent(X0)
        for link in scene.links:  # the frame checks of the scene's links, on each drawing
            a, b = X0[:, index[link.points[0]]], X0[:, index[link.points[1]]]
            ok &= ~frame_too_close(np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]), extent)
            ok &= (a != b).any(axis=1)
    return eq.rows_of(**arrays), ok


def _too_far(scene: Scene, reach):
    """True where a further point ``reach`` times its frame's length from the frame's first
    point makes every step singular (the Jacobian's condition grows as reach^2)."""
    return reach * math.sqrt(scene.solver.singular_rcond) >= 1.0


def _check_reach(scene: Scene, link, pname: str, reach: float) -> None:
    """A further point far beyond the frame's second point makes every step singular."""
    if not _too_far(scene, reach):  # reach^2 rcond < 1, unsquared
        return
    # the Jacobian's condition grows as reach^2: every step would count as singular
    raise SceneError(
        scene.path, f'links "{link.name}"', "local" if pname in link.local else "points",
        f'point "{pname}" is {reach:.3g} times farther from "{link.points[0]}" than '
        f'the link\'s second point "{link.points[1]}": a frame that short cannot hold '
        f"it (the constraint Jacobian's condition grows as the square of that ratio, "
        f"about {reach * reach:.1g} here, and every step would count as singular)",
        f'list a far point second so that the frame is long, e.g. points = '
        f'["{link.points[0]}", "{pname}", ...] (lengths and local refer to the first '
        f"two points)")


def slider_rows(scene: Scene, index: dict, X0: np.ndarray):
    """Fixed guides (point, a point of the line, unit normal) and moving guides (point, the
    guide's two points, their distance)."""
    sfix_p, sfix_c, sfix_n = [], [], []
    smov = {k: [] for k in ("p", "d", "e", "len")}
    for sl in scene.sliders:
        ip = index[sl.point]
        if sl.moving:
            idd, ie = index[sl.line_points[0]], index[sl.line_points[1]]
            d = X0[..., ie, :] - X0[..., idd, :]
            for key, val in zip(("p", "d", "e", "len"),
                                (ip, idd, ie, eq._number(np.hypot(d[..., 0], d[..., 1])))):
                smov[key].append(val)
        else:
            dvec = np.asarray(sl.direction, dtype=float)
            dvec = dvec / np.hypot(*dvec)
            sfix_p.append(ip)
            sfix_c.append(sl.through)
            sfix_n.append(_R90 @ dvec)
    return sfix_p, sfix_c, sfix_n, smov


def driver_rows(scene: Scene, index: dict, X0: np.ndarray, apart: list | None = None) -> dict:
    """Per driver (dict of lists): its kind, (tail) point, head point, axis, the reference
    vector's points of a relative angle and the row's length scale (-1 / 0.0 where unused).
    X0 (n_points, 2), or (V, n_points, 2) for V variants' drawings (:func:`variant_rows`);
    ``apart``: a list that collects where a relative angle's reference points are drawn apart
    instead of refusing them here."""
    out = {k: [] for k in ("kind", "a", "b", "axis", "c", "d", "len")}
    for dr in scene.drivers:
        kind = eq.KIND_OF[dr.kind]
        c = d = -1
        scale = 0.0
        if dr.relative_to is not None:
            kind = eq.RELATIVE
            c, d = index[dr.relative_to[0]], index[dr.relative_to[1]]
            ref = X0[..., d, :] - X0[..., c, :]
            scale = eq._number(np.hypot(ref[..., 0], ref[..., 1]))
            if apart is not None:
                apart.append(scale > 0)
            elif not scale > 0:
                raise SceneError(scene.path, f'drivers "{dr.name}"', "relative_to",
                                 f'"{dr.relative_to[0]}" and "{dr.relative_to[1]}" are drawn at '
                                 "the same place: they give no direction to measure from",
                                 "name two distinct points of the reference link")
        elif kind == eq.DISTANCE:
            scale = max(abs(dr.from_value), abs(dr.to_value))
        values = (kind, index[dr.points[0]], index[dr.points[1]] if len(dr.points) > 1 else -1,
                  -1 if dr.axis is None else int(dr.axis), c, d, scale)
        for key, val in zip(out, values):
            out[key].append(val)
    return out
