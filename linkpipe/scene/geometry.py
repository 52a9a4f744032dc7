"""Reading the geometry tables: points, links (lengths, local coordinates), sliders."""
from __future__ import annotations

import math

import numpy as np

from . import sides
from .keys import _Table, _show, _suggest, _type_name
from .tables import Link, Point, Slider


#: the shortest length a scene may give: its reciprocal and square stay inside double precision
MIN_LENGTH = 1e-100
#: a link's first two points must be farther apart than this part of the drawing's extent
#: (they span the link's frame; nearer, every other point's local coordinates are noise)
FRAME_RTOL = 1e-9


def drawing_extent(X0):
    """The drawing's extent: its largest |coordinate|; X0 (P, 2) -> float, (V, P, 2) -> (V,)."""
    return np.abs(X0).max(axis=(-2, -1))


def frame_too_close(apart, extent):
    """True where a link's first two points, ``apart`` from each other, are too close to span
    its frame in a drawing of ``extent`` (floats or arrays; at the same place is a separate
    error: :meth:`GeometryTables.link_tables`)."""
    return (0 < apart) & (apart <= FRAME_RTOL * extent)


class GeometryTables:
    """The ``[points]``, ``[[links]]`` and ``[[sliders]]`` readers of :class:`~.parse._Parser`."""

    def _check_frame(self, table, names) -> None:
        """The first two points of a link must be apart (relative to the drawing's extent)."""
        pa, pb = self.points[names[0]], self.points[names[1]]
        extent = drawing_extent(np.array([[p.x, p.y] for p in self.points.values()]))
        apart = float(np.hypot(pb.x - pa.x, pb.y - pa.y))
        if frame_too_close(apart, extent):
            raise table.error("points", f'points "{names[0]}" and "{names[1]}" are {apart:g} '
                              f"apart, {apart / extent:.1g} of the drawing's extent: too close "
                              "to span the link's frame",
                              "move one of them in [points], or list two points farther apart "
                              "first")

    def point_table(self) -> None:
        raw = self.top("points")
        if not raw and isinstance(self.top("study"), dict):
            raise self.error("study", None, "this is a study file (a [study] table, no [points]): "
                             "its scene is the base it names",
                             "run it with python -m linkpipe study FILE (check it with "
                             "python -m linkpipe check FILE)")
        if not raw:
            raise self.error("points", None, "no points: the scene needs a [points] table",
                             "add [points] with e.g. A = { x = 0.0, y = 0.0, fixed = true }")
        for name, value in raw.items():
            if not name.strip():
                raise self.error("points", f'"{name}"', "a point name is empty",
                                 "name it, e.g. A = { x = 0.0, y = 0.0 }")
            if not isinstance(value, dict):
                raise self.error("points", name, f"expected a table {{ x = ..., y = ... }}, "
                                 f"got {_type_name(value)} ({_show(value)})",
                                 f"write e.g. {name} = {{ x = 0.0, y = 0.0 }}")
            table = _Table(self.path, f"points.{name}", value, "point")
            self.points[name] = Point(name, table.number("x", geometric=True),
                                      table.number("y", geometric=True),
                                      table.boolean("fixed", False))


    def link_tables(self) -> None:
        for table in self.entries("links"):
            names = table.strings("points", what="point")
            if len(names) < 2:
                raise table.error("points", f"a link needs at least two points, got "
                                  f"{len(names)}", 'write e.g. points = ["A", "B"]')
            for name in names:
                self.point(table, "points", name)
            self._check_frame(table, names)
            pa, pb = self.points[names[0]], self.points[names[1]]
            if (pa.x, pa.y) == (pb.x, pb.y):  # further points may coincide (a tracer on a pin)
                raise table.error("points", f'points "{names[0]}" and "{names[1]}" are at the '
                                  f"same place ({pa.x:g}, {pa.y:g}): the first two points of a "
                                  "link span its frame", "move one of them in [points] (x, y "
                                  "are the start configuration), or list another point second")
            length, distances = self.link_lengths(table, names)
            local = self.link_local(table, names)
            local.update(self.local_from_distances(table, names, length, distances, local))
            side = dict(table.data.get("side", {})) if distances else {}
            link = Link(table.data["name"], names, length, local, distances, side)
            self.links[link.name] = link
        if not self.links:
            raise self.error("links", None, "no links: the scene needs at least one [[links]]",
                             'add [[links]] with name = "..." and points = ["A", "B"]')

    def link_lengths(self, table: _Table, names):
        """``lengths``: the first two points' distance (or None) and the further points'
        distances ``{(earlier point, later point): d}`` (a pair given once, either way round)."""
        if not table.has("lengths"):
            return None, {}
        if not isinstance(table.data["lengths"], dict):
            raise table.wrong_type("lengths", "a table")
        sub = _Table(self.path, f"{table.label}.lengths", table.data["lengths"], "links",
                     examples={key: "3.5" for key in table.data["lengths"]})
        order = {n: i for i, n in enumerate(names)}
        length, distances = None, {}
        for key in sub.data:
            pair = self._pair_of(sub, key, names)
            pair = tuple(sorted(pair, key=order.get))
            if pair in distances or (pair == tuple(names[:2]) and length is not None):
                raise sub.error(key, f'the distance of "{pair[0]}" and "{pair[1]}" is given '
                                "twice", f'keep one of "{pair[0]}-{pair[1]}" and '
                                f'"{pair[1]}-{pair[0]}"')
            d = sub.number(key, geometric=True)
            if d <= MIN_LENGTH:
                raise sub.error(key, f"must be positive (above {MIN_LENGTH:g}), got {d:g}",
                                f'write the distance of "{pair[0]}" and "{pair[1]}"')
            if pair == tuple(names[:2]):
                length = d
                self._check_fixed_length(sub, key, pair, d)
            else:
                distances[pair] = (key, d)
        return length, distances

    def _pair_of(self, sub: _Table, key: str, names) -> tuple[str, str]:
        """The two points a ``lengths`` key "X-Y" names, both on the link."""
        for cut in range(1, len(key)):  # point names may hold "-": find the split that fits
            if key[cut] == "-" and key[:cut] in names and key[cut + 1:] in names:
                if key[:cut] == key[cut + 1:]:
                    break
                return key[:cut], key[cut + 1:]
        raise sub.error(key, f'"{key}" is not two points of this link joined by "-"',
                        f'write "<point>-<point>" with points of {list(names)}, e.g. '
                        f'"{names[0]}-{names[1]}"')

    def _check_fixed_length(self, sub, key, pair, length) -> None:
        pa, pb = self.points[pair[0]], self.points[pair[1]]
        if pa.fixed and pb.fixed:  # nothing moves to meet this length: it must hold as drawn
            drawn = math.hypot(pb.x - pa.x, pb.y - pa.y)
            if abs(drawn - length) > 1e-9 * max(drawn, length):
                raise sub.error(key, f'"{pair[0]}" and "{pair[1]}" are both fixed, {drawn:g} '
                                f"apart, but the length says {length:g}",
                                "move the fixed points, or correct (or drop) the length")

    def local_from_distances(self, table: _Table, names, length, distances, local) -> dict:
        """Local coordinates of the further points given by two distances to points placed
        before them (:mod:`.sides`), once, at load."""
        return sides.place(self, table, names, length, distances, local)


    def link_local(self, table: _Table, names) -> dict[str, tuple[float, float]]:
        """``local = { P = [u, v] }`` for points of the link after the first two."""
        if not table.has("local"):
            return {}
        if not isinstance(table.data["local"], dict):
            raise table.wrong_type("local", "a table")
        sub = _Table(self.path, f"{table.label}.local", table.data["local"], "links",
                     examples={key: "[1.5, 0.8]" for key in table.data["local"]})
        local = {}
        for name in sub.data:
            if name in names[:2]:
                raise sub.error(name, f'"{name}" is one of the first two points, which span '
                                "the link's frame", f'give local coordinates only for points '
                                f'after them ("{names[0]}" is [0, 0], "{names[1]}" is on the '
                                "u axis; set their distance with lengths)")
            if name not in names:
                if name not in self.points:
                    raise sub.error(name, f'unknown point "{name}"',
                                    _suggest(name, names[2:] or self.points))
                raise sub.error(name, f'point "{name}" is not a point of {table.label}',
                                f'add "{name}" to its points')
            local[name] = sub.pair(name)
        return local

    def slider_tables(self) -> tuple[Slider, ...]:
        sliders = []
        for table in self.entries("sliders"):
            point = self.point(table, "point", table.string("point"))
            along = table.value("along")
            if isinstance(along, dict):
                sub = table.sub("along")
                sliders.append(Slider(table.data["name"], point, through=sub.pair("through"),
                                      direction=sub.pair("direction", nonzero=True)))
                continue
            if (not isinstance(along, list) or len(along) != 2
                    or not all(isinstance(v, str) for v in along)):
                raise table.error("along", "expected { through = [x, y], direction = [dx, dy] } "
                                  f"or two point names, got {_type_name(along)} ({_show(along)})",
                                  f'write e.g. {table.example("along")} or along = ["D", "E"]')
            a, b = along
            for name in along:
                self.point(table, "along", name)
            if a == b:
                raise table.error("along", f'the line needs two different points, got "{a}" '
                                  "twice", "name two points of one moving link")
            if point in along:
                raise table.error("along", f'the slider point "{point}" cannot be one of the '
                                  "points its line goes through",
                                  "name two other points of the link that carries the guide")
            if not any(a in link.points and b in link.points for link in self.links.values()):
                def on(p):
                    found = [f'"{n}"' for n, link in self.links.items() if p in link.points]
                    return "links " + ", ".join(found) if found else "no link"
                on_a, on_b = on(a), on(b)
                raise table.error("along", f'"{a}" and "{b}" are not on one common link '
                                  f'("{a}" is on {on_a}, "{b}" on {on_b})',
                                  "name two points of the same link, or write "
                                  "{ through = [x, y], direction = [dx, dy] } for a fixed guide")
            sliders.append(Slider(table.data["name"], point, line_points=(a, b)))
        return tuple(sliders)

