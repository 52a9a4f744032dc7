"""A link's further points given by two side lengths, turned into local coordinates at load.

``lengths = { "A-B" = 0.23, "A-P" = 0.65, "B-P" = 0.45 }``: point P at 0.65 from A and 0.45
from B, the way a drawing dimensions a plate. Each further point given so needs exactly two
distances to points listed before it on the link (the frame points, or earlier further
points); it lies on the side of the directed line from the first of them to the second where
the start configuration draws it, unless ``side = { P = "left" | "right" }`` says which
("left": counter-clockwise of that line). The result is P's ``local`` (u, v) in the link's
frame (u from its first point towards its second, v a quarter turn counter-clockwise): the
model never sees a distance.

The geometry (:func:`drawn_local`, :func:`placement`) is written once, elementwise: on floats
for one scene (:func:`place`, at load) and on (V,) arrays for V variants of it (a study's
side distances, frame lengths or drawn points: :func:`linkpipe.model.rows.variant_rows`).
The checks a scene must pass (:func:`fits`, :func:`place`'s errors) read its results; only
:func:`place` raises.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .keys import _Table

SIDES = {"left": 1.0, "right": -1.0}
#: a triangle closes when h^2 >= -CLOSE_RTOL * (its longest side)^2 (rounding of an exact one)
CLOSE_RTOL = 1e-12
#: a point drawn within this part of |p1 p2| |p1 P| of the line p1 -> p2 is drawn on it
ON_LINE_RTOL = 1e-9


class Triangle(NamedTuple):
    """One further point placed by two distances ``d1``, ``d2`` from earlier points ``p1``,
    ``p2`` (keys ``k1``, ``k2``): the base |p1 p2| of its triangle in the link's frame, the
    squared height ``h2`` and whether its drawn side was unreadable (``on_line``: drawn on
    the line p1 -> p2 with no ``side`` given); floats, or (V,) arrays for V variants."""

    p1: str
    k1: str
    d1: object
    p2: str
    k2: str
    d2: object
    base: object
    h2: object
    on_line: object


def _plain(x):
    """A float for one scene, the array for variants."""
    return float(x) if np.ndim(x) == 0 else x


def drawn_local(ax, ay, bx, by, px, py):
    """(u, v) of a point drawn at (px, py) in the frame of a link whose first two points are
    drawn at (ax, ay), (bx, by): u along a -> b, v a quarter turn counter-clockwise (floats,
    or arrays elementwise). The model takes every further point's local coordinates that the
    scene does not give from here (:func:`linkpipe.model.rows.link_rows`)."""
    dx, dy = bx - ax, by - ay
    drawn = np.hypot(dx, dy)
    ex, ey = dx / drawn, dy / drawn
    rx, ry = px - ax, py - ay
    return _plain(rx * ex + ry * ey), _plain(-rx * ey + ry * ex)


def triangle_apex(x1, y1, x2, y2, d1, d2, sign):
    """``(u, v, base, h2)``: the point at distances d1, d2 from (x1, y1), (x2, y2) on side
    ``sign`` (+1 left of the line 1 -> 2), the base |12| and the squared height (h2 < 0: the
    triangle cannot close; the height is then taken as 0). Floats or arrays elementwise."""
    bx, by = x2 - x1, y2 - y1
    base = np.hypot(bx, by)
    with np.errstate(divide="ignore", invalid="ignore"):
        along = (d1 * d1 - d2 * d2 + base * base) / (2 * base)
        h2 = d1 * d1 - along * along
        h = np.sqrt(np.maximum(h2, 0.0))
        ux, uy = bx / base, by / base
        u, v = x1 + along * ux - sign * h * uy, y1 + along * uy + sign * h * ux
    return _plain(u), _plain(v), _plain(base), _plain(h2)


def drawn_side(x1, y1, x2, y2, px, py):
    """``(sign, on_line)``: +1 where the drawing has (px, py) left of the line 1 -> 2, -1
    right of it; on_line where it is on the line to ON_LINE_RTOL of the lengths involved."""
    bx, by = x2 - x1, y2 - y1
    rx, ry = px - x1, py - y1
    cross = bx * ry - by * rx
    on_line = np.abs(cross) <= ON_LINE_RTOL * np.hypot(bx, by) * np.hypot(rx, ry)
    sign = np.where(cross >= 0.0, 1.0, -1.0)
    return _plain(sign), (bool(on_line) if np.ndim(on_line) == 0 else on_line)


def given_by_point(names, distances: dict) -> dict:
    """{later point: [(earlier point, key, d), (earlier, key, d)]} of ``distances``
    {(earlier, later): (key, d)}, each list from the earlier point first in the link's order."""
    by_point: dict = {}
    for (p, q), (key, d) in distances.items():
        by_point.setdefault(q, []).append((p, key, d))
    rank = {n: i for i, n in enumerate(names)}
    for given in by_point.values():  # measured from the earlier point first, whatever the key order
        given.sort(key=lambda item: rank[item[0]])
    return by_point


def placement(names, length, drawn: dict, by_point: dict, local: dict, side: dict):
    """The one placement of a link's points in its frame: ``(placed, triangles)``, placed
    {point: (u, v)} for every point of the link and triangles {point: :class:`Triangle`} for
    those placed by two distances.

    ``names``: the link's points (the first two span the frame); ``length``: the frame's
    length (None: as drawn); ``drawn`` {point: (x, y)}: the drawing; ``by_point``:
    :func:`given_by_point`; ``local``: the points given by local coordinates; ``side``
    {point: "left" | "right"}. Numbers are floats (one scene) or (V,) arrays (V variants:
    a length, a distance or a drawn coordinate each)."""
    a, b = names[0], names[1]
    ax, ay = drawn[a]
    bx, by = drawn[b]
    placed = {a: (0.0, 0.0), b: (_plain(np.hypot(bx - ax, by - ay)) if length is None
                                 else length, 0.0)}
    triangles = {}
    for name in names[2:]:
        given = by_point.get(name)
        if not given:
            placed[name] = (local[name] if name in local  # else from the drawing, as the model takes it
                            else drawn_local(ax, ay, bx, by, *drawn[name]))
            continue
        (p1, k1, d1), (p2, k2, d2) = given
        if name in side:
            sign, on_line = SIDES[side[name]], False
        else:
            sign, on_line = drawn_side(*drawn[p1], *drawn[p2], *drawn[name])
        u, v, base, h2 = triangle_apex(*placed[p1], *placed[p2], d1, d2, sign)
        placed[name] = (u, v)
        triangles[name] = Triangle(p1, k1, d1, p2, k2, d2, base, h2, on_line)
    return placed, triangles


def apart(t: Triangle):
    """True where the triangle's two known points are apart (they fix the point)."""
    return t.base != 0.0


def closes(t: Triangle):
    """True where the triangle closes: each side at most the sum of the other two, to
    rounding (h^2 >= -CLOSE_RTOL times the longest side squared)."""
    longest = np.maximum(np.maximum(t.d1, t.d2), t.base)
    return np.logical_not(t.h2 < -CLOSE_RTOL * (longest * longest))


def side_readable(t: Triangle):
    """False where the point is off the line p1 -> p2 but drawn on it (side not given)."""
    return np.logical_not(t.on_line & (t.h2 > 0.0))


def fits(triangles: dict):
    """True (or (V,) True) where every triangle of a placement passes the scene's checks."""
    ok = True
    for t in triangles.values():
        ok = ok & apart(t) & closes(t) & side_readable(t)
    return ok


def place(parser, table: _Table, names, length, distances: dict, local: dict) -> dict:
    """Return {point: (u, v)} for the points ``distances`` {(earlier, later): (key, d)} place
    (every misuse a scene error naming the key)."""
    side = _sides(parser, table, names, distances)
    if not distances:
        return {}
    by_point = given_by_point(names, distances)
    for name in names[2:]:
        _check_given(table, names, name, by_point.get(name, []), local)
    drawn = {n: (parser.points[n].x, parser.points[n].y) for n in names}
    placed, triangles = placement(names, length, drawn, by_point, local, side)
    for name, t in triangles.items():
        _check_triangle(table, name, t)
    return {name: placed[name] for name in triangles}


def _check_given(table, names, name, given, local) -> None:
    """A point given by distances has exactly two and no local coordinates."""
    if not given:
        return
    keys = [key for _, key, _ in given]
    if name in local:
        raise table.error("local", f'"{name}" is given by local coordinates and by the '
                          f"distances {', '.join(keys)}", "keep one of them")
    if len(given) != 2:
        what = "only one distance" if len(given) == 1 else f"{len(given)} distances"
        raise table.error("lengths", f'"{name}" has {what} ({", ".join(keys)}): a point of '
                          "a plate needs two distances, to two points listed before it",
                          f'give e.g. "{names[0]}-{name}" and "{names[1]}-{name}"')


def _check_triangle(table, name, t: Triangle) -> None:
    """The scene errors of one placed point (:func:`apart`, :func:`closes`,
    :func:`side_readable`)."""
    if not apart(t):
        raise table.error("lengths", f'"{t.p1}" and "{t.p2}" are at one place: {t.k1} and '
                          f'{t.k2} do not fix "{name}"', f'measure "{name}" from two points apart')
    if not closes(t):
        raise table.error("lengths", f'the triangle "{t.p1}", "{t.p2}", "{name}" cannot close: '
                          f"{t.k1} = {t.d1:g} and {t.k2} = {t.d2:g} with {t.p1} and {t.p2} "
                          f"{t.base:g} apart (each side must be at most the sum of the other "
                          "two)", "correct one of the distances")
    if not side_readable(t):
        raise table.error("lengths", f'"{name}" is drawn on the line "{t.p1}"-"{t.p2}": its '
                          "side cannot be read from the drawing",
                          f'say which with side = {{ {name} = "left" }} (or "right", seen '
                          f'from "{t.p1}" towards "{t.p2}")')


def _sides(parser, table: _Table, names, distances) -> dict:
    """``side = { P = "left" }``, checked: only for points given by distances."""
    if not table.has("side"):
        return {}
    if not isinstance(table.data["side"], dict):
        raise table.wrong_type("side", "a table")
    by_distance = {q for (_, q) in distances}
    out = {}
    for name, value in table.data["side"].items():
        if name not in by_distance:
            raise table.error("side", f'"{name}" is not a point given by two distances in '
                              "lengths: side says which of the two places such a point takes",
                              "remove it, or give the point by two distances")
        if value not in SIDES:
            raise table.error("side", f'side of "{name}" must be "left" or "right", got '
                              f"{value!r}", f'write side = {{ {name} = "left" }}')
        out[name] = value
    return out
