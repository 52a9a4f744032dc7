"""Reading ``[[friction]]`` (version 3): friction at pins, at sliders and in actuators. No maths
here: the laws are :mod:`linkpipe.forces.friction`'s."""
from __future__ import annotations

from .keys import _Table, _suggest
from .tables import Friction

#: what each kind of entry names, and the keys only it may have
KIND_KEYS = {"pins": ("joints", "mu", "pin_radius", "viscous"),
             "slider": ("slider", "mu", "viscous"),
             "driver": ("driver", "coulomb", "viscous", "stribeck")}


class FrictionTables:
    """The ``[[friction]]`` reader of :class:`~.parse._Parser`."""

    def friction_tables(self, drivers, sliders) -> tuple[Friction, ...]:
        out = []
        for table in self.entries("friction"):
            kind = {"joints": "pins", "slider": "slider", "driver": "driver"}[
                table.exactly_one(("joints", "slider", "driver"))]
            for key in table.data:
                if key != "name" and key not in KIND_KEYS[kind]:
                    raise table.error(key, f"a friction at {_WHAT[kind]} has no {key}",
                                      f"remove {key} (its keys: "
                                      f"{', '.join(KIND_KEYS[kind])})")
            viscous = _not_negative(table, "viscous")
            name = table.data["name"]
            if kind == "pins":
                out.append(Friction(name, kind, joints=self._joints(table),
                                    mu=_not_negative(table, "mu", required=True),
                                    pin_radius=_positive(table, "pin_radius"), viscous=viscous))
            elif kind == "slider":
                names = [s.name for s in sliders]
                slider = table.string("slider")
                if slider not in names:
                    raise table.error("slider", f'unknown slider "{slider}"',
                                      _suggest(slider, names) or "declare it with [[sliders]]")
                out.append(Friction(name, kind, slider=slider,
                                    mu=_not_negative(table, "mu", required=True), viscous=viscous))
            else:
                names = [d.name for d in drivers]
                driver = table.string("driver")
                if driver not in names:
                    raise table.error("driver", f'unknown driver "{driver}"',
                                      _suggest(driver, names) or "declare it with [[drivers]]")
                coulomb = _not_negative(table, "coulomb")
                peak = velocity = None
                if table.has("stribeck"):
                    sub = table.sub("stribeck")
                    sub.check_keys()
                    peak, velocity = _not_negative(sub, "peak", required=True), _positive(sub, "velocity")
                    if peak < coulomb:
                        raise sub.error("peak", f"the breakaway peak {peak:g} is below coulomb "
                                        f"= {coulomb:g}", "give a peak >= coulomb (the force "
                                        "at the start of motion), or leave stribeck out")
                out.append(Friction(name, kind, driver=driver, coulomb=coulomb, viscous=viscous,
                                    stribeck_peak=peak, stribeck_velocity=velocity))
        return tuple(out)

    def _joints(self, table: _Table) -> tuple[str, ...]:
        """The pins' point names: each must join two bodies (two links, or a link and ground)."""
        joints = table.strings("joints", what="point")
        if not joints:
            raise table.error("joints", "is empty", f"name the pins, e.g. {table.example('joints')}")
        for name in joints:
            self.point(table, "joints", name)
            moving = [ln.name for ln in self.links.values()
                      if name in ln.points and not all(self.points[p].fixed for p in ln.points)]
            bodies = len(moving) + int(self.points[name].fixed)
            if bodies < 2:
                on = f'only link "{moving[0]}"' if moving else "no moving link"
                raise table.error("joints", f'point "{name}" is not a joint: {on} meets there',
                                  "name points where two links (or a link and ground) turn "
                                  "against each other")
        return joints


_WHAT = {"pins": "pins (joints)", "slider": "a slider", "driver": "an actuator (driver)"}


def _not_negative(table: _Table, key: str, required: bool = False) -> float:
    value = table.number(key) if required else table.number(key, 0.0)
    if value < 0:
        raise table.error(key, f"must be >= 0, got {value:g}",
                          f"write e.g. {table.example(key)} (a friction only opposes motion)")
    return value


def _positive(table: _Table, key: str) -> float:
    value = table.number(key, geometric=True)
    if value <= 0:
        raise table.error(key, f"must be positive, got {value:g}", f"write e.g. {table.example(key)}")
    return value
