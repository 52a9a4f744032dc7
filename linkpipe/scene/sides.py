"""A link's further points given by two side lengths, turned into local coordinates at load.

``lengths = { "A-B" = 0.23, "A-P" = 0.65, "B-P" = 0.45 }``: point P at 0.65 from A and 0.45
from B, the way a drawing dimensions a plate. Each further point given so needs exactly two
distances to points listed before it on the link (the frame points, or earlier further
points); it lies on the side of the directed line from the first of them to the second where
the start configuration draws it, unless ``side = { P = "left" | "right" }`` says which
("left": counter-clockwise of that line). The result is P's ``local`` (u, v) in the link's
frame (u from its first point towards its second, v a quarter turn counter-clockwise): the
model never sees a distance.
"""
from __future__ import annotations

import math

from .keys import _Table

SIDES = {"left": 1.0, "right": -1.0}


def place(parser, table: _Table, names, length, distances: dict, local: dict) -> dict:
    """Return {point: (u, v)} for the points ``distances`` {(earlier, later): (key, d)} place."""
    side = _sides(parser, table, names, distances)
    if not distances:
        return {}
    pts = parser.points
    a, b = names[0], names[1]
    ax, ay = pts[a].x, pts[a].y
    dx, dy = pts[b].x - ax, pts[b].y - ay
    drawn = math.hypot(dx, dy)
    ex, ey = dx / drawn, dy / drawn
    placed = {a: (0.0, 0.0), b: (drawn if length is None else length, 0.0)}
    by_point: dict = {}
    for (p, q), (key, d) in distances.items():
        by_point.setdefault(q, []).append((p, key, d))
    rank = {n: i for i, n in enumerate(names)}
    for given in by_point.values():  # measured from the earlier point first, whatever the key order
        given.sort(key=lambda item: rank[item[0]])
    out = {}
    for name in names[2:]:
        given = by_point.get(name, [])
        if not given:
            if name in local:
                placed[name] = local[name]
            else:  # from the drawing, as the model takes it
                rx, ry = pts[name].x - ax, pts[name].y - ay
                placed[name] = (rx * ex + ry * ey, -rx * ey + ry * ex)
            continue
        keys = [key for _, key, _ in given]
        if name in local:
            raise table.error("local", f'"{name}" is given by local coordinates and by the '
                              f"distances {', '.join(keys)}", "keep one of them")
        if len(given) != 2:
            what = "only one distance" if len(given) == 1 else f"{len(given)} distances"
            raise table.error("lengths", f'"{name}" has {what} ({", ".join(keys)}): a point of '
                              "a plate needs two distances, to two points listed before it",
                              f'give e.g. "{names[0]}-{name}" and "{names[1]}-{name}"')
        placed[name] = out[name] = _apex(parser, table, name, given, placed, side.get(name))
    return out


def _apex(parser, table, name, given, placed, side):
    """Local (u, v) of ``name`` at distances d1, d2 from two placed points (a triangle)."""
    (p1, k1, d1), (p2, k2, d2) = given
    (x1, y1), (x2, y2) = placed[p1], placed[p2]
    bx, by = x2 - x1, y2 - y1
    base = math.hypot(bx, by)
    if base == 0.0:
        raise table.error("lengths", f'"{p1}" and "{p2}" are at one place: {k1} and {k2} do '
                          f'not fix "{name}"', f'measure "{name}" from two points apart')
    along = (d1 * d1 - d2 * d2 + base * base) / (2 * base)
    h2 = d1 * d1 - along * along
    if h2 < -1e-12 * max(d1, d2, base) ** 2:
        raise table.error("lengths", f'the triangle "{p1}", "{p2}", "{name}" cannot close: '
                          f"{k1} = {d1:g} and {k2} = {d2:g} with {p1} and {p2} {base:g} apart "
                          f"(each side must be at most the sum of the other two)",
                          "correct one of the distances")
    h = math.sqrt(max(h2, 0.0))
    sign = SIDES[side] if side is not None else _drawn_side(parser, table, name, p1, p2, h)
    ux, uy = bx / base, by / base
    return (x1 + along * ux - sign * h * uy, y1 + along * uy + sign * h * ux)


def _drawn_side(parser, table, name, p1, p2, h) -> float:
    """+1 where the drawing has ``name`` left of the line p1 -> p2, -1 right of it."""
    pts = parser.points
    bx, by = pts[p2].x - pts[p1].x, pts[p2].y - pts[p1].y
    rx, ry = pts[name].x - pts[p1].x, pts[name].y - pts[p1].y
    cross = bx * ry - by * rx
    # on the line to 1e-9 of the lengths involved: the drawing does not tell the side
    if abs(cross) <= 1e-9 * math.hypot(bx, by) * math.hypot(rx, ry) and h > 0.0:
        raise table.error("lengths", f'"{name}" is drawn on the line "{p1}"-"{p2}": its side '
                          "cannot be read from the drawing",
                          f'say which with side = {{ {name} = "left" }} (or "right", seen '
                          f'from "{p1}" towards "{p2}")')
    return 1.0 if cross >= 0.0 else -1.0


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
