"""Reading the spring tables: ``[[springs]]`` of every kind and ``[[torsion_springs]]``."""
from __future__ import annotations

from .keys import _Table, _show, _suggest
from .tables import GROUND, SPRING_KINDS, Spring, TorsionSpring

#: the keys only a gas spring has, and the keys it must not have
GAS_KEYS = ("force_extended", "extended_length", "dead_length", "gamma", "compressed_length")
NOT_GAS_KEYS = ("k", "free_length", "preload")


class SpringTables:
    """The ``[[springs]]`` and ``[[torsion_springs]]`` readers of :class:`~.parse._Parser`."""

    def spring_tables(self) -> tuple[Spring, ...]:
        springs = []
        for table in self.entries("springs"):
            between = table.strings("between", what="point")
            if len(between) != 2:
                raise table.error("between", f"expected two different points, got "
                                  f"{len(between)}", f"write e.g. {table.example('between')}")
            for name in between:
                self.point(table, "between", name)
            self._spring_spans_two_bodies(table, between)
            kind = table.string("kind", SPRING_KINDS[0])
            if kind not in SPRING_KINDS:
                raise table.error("kind", f"unknown spring kind {_show(kind)}",
                                  _suggest(kind, SPRING_KINDS))
            damping = table.number("damping", 0.0)
            if damping < 0:
                raise table.error("damping", f"must be >= 0, got {damping:g}",
                                  "write e.g. damping = 0.0")
            law = _gas_law(table) if kind == "gas" else _elastic_law(table, kind)
            springs.append(Spring(table.data["name"], between, damping=damping, kind=kind, **law))
        return tuple(springs)

    def _spring_spans_two_bodies(self, table: _Table, between: list) -> None:
        """A spring's ends must be on different bodies (or one on ground): between two ground
        points, or two points of one link, its length never changes and it does no work (a
        mistyped point name, most likely)."""
        a, b = between
        fix = "name the point on the other body (or ground) it pulls or pushes"
        if a == b:
            raise table.error("between", f'both ends are point "{a}"', fix)
        if self.points[a].fixed and self.points[b].fixed:
            raise table.error("between", f'"{a}" and "{b}" are both fixed (ground): the '
                              "spring's length never changes, so it does no work", fix)
        for link in self.links.values():
            if a in link.points and b in link.points:
                raise table.error("between", f'"{a}" and "{b}" are both points of link '
                                  f'"{link.name}": the spring\'s length never changes, so it does '
                                  "no work", fix)

    def torsion_spring_tables(self) -> tuple[TorsionSpring, ...]:
        out = []
        for table in self.entries("torsion_springs"):
            raw = table.value("links")
            if isinstance(raw, list) and len(raw) == 2 and raw[0] == raw[1] and isinstance(raw[0], str):
                raise table.error("links", f'a torsion spring between link "{raw[0]}" and itself '
                                  "(its angle would always be 0)",
                                  f'name two different links, or "{GROUND}" second')
            links = table.strings("links", what="link")
            if len(links) != 2:
                raise table.error("links", f"expected two links, got {len(links)}",
                                  f'write e.g. {table.example("links")} (the second may be '
                                  f'"{GROUND}")')
            if links[0] == GROUND:
                raise table.error("links", f'"{GROUND}" may only be the second link',
                                  f'write links = ["{links[1]}", "{GROUND}"] and negate '
                                  "free_angle (the angle is first minus second)")
            for name in links:
                if name == GROUND and GROUND in self.links:
                    raise table.error("links", f'"{GROUND}" is ambiguous: a link is named '
                                      f'"{GROUND}" too', "rename that link")
                if name != GROUND and name not in self.links:
                    raise table.error("links", f'unknown link "{name}"',
                                      _suggest(name, [*self.links, GROUND]))
            k = table.number("k")
            if k < 0:
                raise table.error("k", f"negative stiffness k = {k:g}",
                                  "use k >= 0 (torque per radian)")
            out.append(TorsionSpring(table.data["name"], links, k, table.number("free_angle")))
        return tuple(out)


def _elastic_law(table: _Table, kind: str) -> dict:
    """k and free_length (or preload) of a linear, tension-only or compression-only spring."""
    for key in GAS_KEYS:
        if table.has(key):
            raise table.error(key, f'only a gas spring has {key} (this one is kind = "{kind}")',
                              f'write kind = "gas" (with force_extended, extended_length, '
                              f"dead_length), or remove {key}")
    k = table.number("k")
    if k < 0:
        raise table.error("k", f"negative stiffness k = {k:g}",
                          "use k >= 0 (the force is tension when stretched)")
    table.one_of("free_length", "preload")
    free_length = table.number("free_length", None)
    if free_length is not None and free_length < 0:
        raise table.error("free_length", f"must be >= 0, got {free_length:g}",
                          "write the spring's unstretched length")
    return {"k": k, "free_length": free_length, "preload": table.number("preload", None)}


def _gas_law(table: _Table) -> dict:
    """force_extended F1, extended_length L1, dead_length d (< L1) and gamma (> 0)."""
    for key in NOT_GAS_KEYS:
        if table.has(key):
            raise table.error(key, f"a gas spring has no {key}: its force follows from "
                              "force_extended, extended_length, dead_length and gamma",
                              f"remove {key}")
    for key in GAS_KEYS[:3]:
        if not table.has(key):
            raise table.error(key, "missing: a gas spring needs force_extended, "
                              "extended_length and dead_length", f"add {table.example(key)}")
    force = table.number("force_extended")
    if force <= 0:
        raise table.error("force_extended", f"must be positive (the strut's push at its "
                          f"extended length), got {force:g}", "write e.g. force_extended = 450.0")
    extended = table.number("extended_length", geometric=True)
    if extended <= 0:
        raise table.error("extended_length", f"must be positive, got {extended:g}",
                          "write the strut's length fully extended, e.g. extended_length = 0.50")
    dead = table.number("dead_length", geometric=True)
    if dead >= extended:
        raise table.error("dead_length", f"dead_length = {dead:g} is not below extended_length "
                          f"= {extended:g}: the gas volume (length - dead_length) would be "
                          "zero or negative at full extension",
                          "use a dead_length below extended_length (the length at which the "
                          "gas volume would be zero; it may be negative)")
    gamma = table.number("gamma", 1.0)
    if gamma <= 0:
        raise table.error("gamma", f"must be positive, got {gamma:g}",
                          "write gamma = 1.0 (isothermal) or 1.4 (adiabatic)")
    compressed = table.number("compressed_length", None, geometric=True)
    if compressed is not None and compressed >= extended:
        raise table.error("compressed_length", f"compressed_length = {compressed:g} is not below "
                          f"extended_length = {extended:g}: the strut would have no stroke",
                          "give the strut's shortest length, below extended_length (its longest)")
    if compressed is not None and compressed <= dead:
        raise table.error("compressed_length", f"compressed_length = {compressed:g} is not above "
                          f"dead_length = {dead:g}: the gas volume would be gone before the "
                          "strut is fully compressed",
                          "give the strut's shortest length, above dead_length")
    return {"k": 0.0, "force_extended": force, "extended_length": extended,
            "dead_length": dead, "gamma": gamma, "compressed_length": compressed}
