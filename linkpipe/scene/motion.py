"""Reading the motion and force tables: drivers, solver, gravity, springs, masses, loads,
analysis, outputs."""
from __future__ import annotations

import math

import numpy as np

from . import units
from .keys import EFFECT_NEEDS, LENGTH_DRIVER_EXAMPLES, _Table, _show, _suggest, _table_ref
from .timing import check_not_timed
from .dynamics import check_not_dynamic
from .tables import Driver, EFFECTS, Input, KINEMATIC_ORDERS, Load, Mass, Outputs, SOLVER_CHOICES, Solver


#: the loosest tolerance a scene may ask for: 1 % of the mechanism's size (looser would let a
#: link come out several percent long, every step "ok")
MAX_TOL = 1e-2
#: the most steps a sweep may have (the memory check refuses far fewer on any real machine)
MAX_STEPS = 1e12
#: the most Newton iterations per run (each run also stops when it stalls): bounds the work
MAX_ITER = 1000


class MotionTables:
    """The ``[[drivers]]`` and ``[solver]`` readers of :class:`~.parse._Parser`."""

    def driver_tables(self) -> tuple[Driver, ...]:
        tables = self.entries("drivers")
        if not tables:
            raise self.error("drivers", None, "no drivers: the scene needs at least one "
                             "[[drivers]]", 'add [[drivers]] with name, angle = ["O2", "A"] '
                             '(or coordinate = "P.y"), from, to and steps')
        drivers = [self.driver(table) for table in tables]
        first = drivers[0]
        for table, driver in zip(tables[1:], drivers[1:]):
            if self.time is not None or self.dynamics is not None:
                break  # every driver has the instants of [time]
            if driver.steps != first.steps:
                raise table.error("step" if table.has("step") else "steps",
                                  f'gives {driver.steps} steps but drivers "{first.name}" '
                                  f"gives {first.steps}",
                                  "all drivers advance together: make their step counts equal")
        # every driver held (from = to) over steps > 1 is the contract's sweep of identical
        # steps (from + i (to - from) / (steps - 1)): allowed, with a warning (Parser.warnings)
        return tuple(drivers)

    def driver(self, table: _Table) -> Driver:
        kind = table.exactly_one(("angle", "coordinate", "distance"))
        if kind != "angle":  # a length: its hints in length units, not degrees
            table.examples = {**table.examples, **LENGTH_DRIVER_EXAMPLES}
        relative_to = bodies = None
        axis = None
        if kind == "coordinate":
            points, axis = self.driven_coordinate(table)
        else:
            points = self.point_pair(table, kind)
        if table.has("relative_to"):
            if kind != "angle":
                raise table.error("relative_to", f"relative_to belongs to an angle driver, not "
                                  f"a {kind} driver", "remove relative_to, or drive an angle")
            relative_to = self.point_pair(table, "relative_to")
            bodies = self.motor_bodies(table, points, relative_to)
        elif kind == "angle" and all(self.points[p].fixed for p in points):
            raise table.error("angle", f'"{points[0]}" and "{points[1]}" are both fixed: '
                              "their direction cannot be driven",
                              "drive the direction from a point to a moving point")
        if kind == "distance":
            self.check_distance_bodies(table, points)
        if self.dynamics is not None:
            fields = self.dynamic_driver(table, kind, self.dynamics)
        elif self.time is not None:
            check_not_dynamic(table)
            fields = self.timed_driver(table, kind, self.time, self.logs)
        else:
            check_not_timed(table)
            check_not_dynamic(table)
            start, stop = table.number("from"), table.number("to")
            steps, step = self.driver_steps(table, start, stop)
            fields = dict(from_value=start, to_value=stop, steps=steps, step=step,
                          rate=self.rate(table, "rate", kind, 1),
                          acceleration=self.rate(table, "acceleration", kind, 2))
        if kind == "distance" and fields.get("timed") != "log":
            self.check_distance_values(table, fields)
        return Driver(table.data["name"], kind, tuple(points), axis, **fields,
                      input=self.driver_input(table), relative_to=relative_to, bodies=bodies,
                      stroke=_stroke(table, kind))

    def rate(self, table: _Table, key: str, kind: str, order: int) -> float:
        """A driver's rate (order 1) or acceleration (order 2): a number in driver units per
        second (squared), or a string with a unit (:mod:`.units`), converted here."""
        if not isinstance(table.data.get(key), str):
            return table.number(key, 0.0)
        try:
            return units.convert(table.data[key], kind, order, self.units.get("length"))
        except ValueError as exc:
            listed = ", ".join(f'"{u}"' for u in units.accepted(kind, order))
            raise table.error(key, str(exc), f"write a number ({'degrees' if kind == 'angle' else 'length units'} "
                              f"per second{'' if order == 1 else ' squared'}) or one of the units "
                              f'{listed}, e.g. {key} = "{120 if kind == "angle" else 50} '
                              f'{units.accepted(kind, order)[2 if kind == "angle" else 1]}"') from None

    def driven_coordinate(self, table: _Table) -> tuple[tuple[str], int]:
        text = table.string("coordinate")
        name, dot, axis_name = text.rpartition(".")
        if not dot or axis_name not in ("x", "y"):
            raise table.error("coordinate", f"{_show(text)} is not a point coordinate",
                              'write "<point>.x" or "<point>.y", e.g. coordinate = "P.y"')
        self.point(table, "coordinate", name)
        if self.points[name].fixed:
            raise table.error("coordinate", f'point "{name}" is fixed: its coordinate '
                              "cannot be driven", "drive a moving point")
        return (name,), "xy".index(axis_name)

    def point_pair(self, table: _Table, key: str) -> tuple[str, str]:
        points = table.strings(key, what="point")
        if len(points) != 2:
            raise table.error(key, f"expected two point names, got {len(points)}",
                              f"write e.g. {table.example(key)}")
        for name in points:
            self.point(table, key, name)
        return tuple(points)

    def body_of(self, pair) -> str | None:
        """The link carrying both points of ``pair`` ("ground" when both are fixed), or None."""
        carrying = [ln.name for ln in self.links.values() if set(pair) <= set(ln.points)]
        moving = [n for n in carrying if not all(self.points[p].fixed for p in self.links[n].points)]
        if all(self.points[p].fixed for p in pair):
            return "ground"
        return (moving or carrying or [None])[0]

    def motor_bodies(self, table: _Table, points, relative_to) -> tuple[str, str]:
        """The links a motor between links turns against each other: (driven, reference)."""
        first, second = self.body_of(points), self.body_of(relative_to)
        for key, pair, body in (("angle", points, first), ("relative_to", relative_to, second)):
            if body is None:
                raise table.error(key, f'no link carries both "{pair[0]}" and "{pair[1]}": a '
                                  "motor between links turns one link against another",
                                  "name two points of one link (or two fixed points for ground)")
        if first == second:
            raise table.error("relative_to", f'"{relative_to[0]}" and "{relative_to[1]}" lie on '
                              f'link "{first}" like the driven points: a link\'s angle against '
                              "itself cannot change", "measure against a point pair of the "
                              "other link the motor turns against")
        return first, second

    def check_distance_bodies(self, table: _Table, points) -> None:
        """A linear actuator joins two bodies."""
        a, b = points
        if a == b:
            raise table.error("distance", f'"{a}" is named twice: a cylinder joins two points',
                              f"write e.g. {table.example('distance')}")
        if all(self.points[p].fixed for p in points):
            raise table.error("distance", f'"{a}" and "{b}" are both fixed: their distance '
                              "cannot be driven", "attach the cylinder to a moving point")
        body = next((ln.name for ln in self.links.values() if set(points) <= set(ln.points)), None)
        if body is not None:
            raise table.error("distance", f'"{a}" and "{b}" are both points of link "{body}": '
                              "their distance is fixed by the link",
                              "attach the cylinder's ends to two different bodies")

    def check_distance_values(self, table: _Table, fields: dict) -> None:
        """A cylinder has a positive length at every step: from and to (a law moves between
        them; a rate, from + rate t + acceleration t^2/2, is checked at every instant)."""
        written = ("from",) if fields.get("timed") == "rate" else ("from", "to")  # a rate's
        for key in written:                                  # `to` is its own, checked below
            value = fields[f"{key}_value"]
            if not value > 0:
                raise table.error(key, f"{key} = {value:g}: a cylinder's length must be positive",
                                  "give the pin-to-pin length, e.g. from = 1.2, to = 1.65")
        if fields.get("timed") == "rate":
            t = self.time.instants - self.time.from_value
            length = (fields["from_value"] + fields["rate"] * t
                      + 0.5 * fields["acceleration"] * t * t)
            if not length.min() > 0:
                first = float(self.time.instants[np.argmax(~(length > 0))])
                raise table.error("rate", f"the cylinder's length from + rate t + acceleration "
                                  f"t^2/2 falls to {float(length.min()):g} within [time] "
                                  f"(first not positive at the instant {first:g})",
                                  "a cylinder's length must stay positive: change rate, "
                                  "acceleration or [time]")

    def driver_input(self, table: _Table):
        if not table.has("input"):
            return None
        sub = table.sub("input")
        link = None
        if sub.has("link"):
            link = self.link(sub, "link", sub.string("link")).name
        driver_input = Input(self.point(sub, "point", sub.string("point")),
                             sub.pair("direction", nonzero=True), link)
        if self.points[driver_input.point].fixed:
            raise sub.error("point", f'point "{driver_input.point}" is fixed: it never moves, '
                            "so an actuator there does no work (every step would be "
                            "no_leverage)", "name the moving point the actuator pushes")
        return driver_input

    @staticmethod
    def driver_steps(table: _Table, start: float, stop: float,
                     single: str = "position") -> tuple[int, float | None]:
        """Resolve ``steps`` or ``step`` into the step count (and the step, when given);
        ``single``: what one step is, in the messages (a position; [time]: an instant)."""
        span = f"from = {start:g}, to = {stop:g}"
        if table.one_of("steps", "step") == "steps":
            steps = table.integer("steps")
            if steps < 1:
                raise table.error("steps", f"steps = {steps} gives no steps",
                                  f"use steps >= 1 (steps = 1 is a single {single})")
            if steps == 1 and start != stop:
                raise table.error("steps", f"steps = 1 with {span}: one step is a single "
                                  f"{single}, at from, and never reaches to",
                                  f"use steps >= 2 to sweep, or to = from for a single {single}")
            if steps > 1 and start == stop and single != "position":  # [time]: none passes
                raise table.error("steps", f"{span} with steps = {steps} gives no motion",
                                  f"use steps = 1 for a single {single}, or change from/to")
            return steps, None  # a driver's from = to over steps > 1: held (driver_tables:
                                # while another moves)
        step = table.number("step")
        if start == stop:  # from, from + s, ... up to and including to: from alone
            if step == 0:
                raise table.error("step", f"step = 0 with {span}", "use a non-zero step, or "
                                  "steps = 1 for a single " + single)
            return 1, step
        if step == 0 or (step > 0) != (stop > start):
            better = abs(step) if step else abs(stop - start) / 10
            raise table.error("step", f"step = {step:g} with {span} gives no steps",
                              "use a non-zero step with the sign of to - from, e.g. step = "
                              f"{better if stop > start else -better:g}")
        # from, from + s, ... up to and including `to` when it lands within 1e-9*|s| of it
        count = (stop - start) / step + 1e-9
        if not count < MAX_STEPS:
            raise table.error("step", f"step = {step:g} with {span} gives {count:.3g} steps, "
                              f"more than {MAX_STEPS:.0e}", "use a larger step")
        steps = math.floor(count) + 1  # 1 where the step oversteps to: from alone (a warning)
        return steps, step

    def solver_table(self) -> Solver:
        table = self.table("solver")
        tol = table.number("tol", Solver.tol)
        if not 0 < tol <= MAX_TOL:
            raise table.error("tol", f"must be positive and at most {MAX_TOL:g} (a fraction of the "
                              f"mechanism's size), got {tol:g}", "write e.g. tol = 1e-12")
        max_iter = table.integer("max_iter", Solver.max_iter)
        if not 1 <= max_iter <= MAX_ITER:
            raise table.error("max_iter", f"must be at least 1 and at most {MAX_ITER}, got {max_iter}",
                              "write e.g. max_iter = 25")
        choices = {}
        for key, allowed in SOLVER_CHOICES.items():
            value = table.string(key, allowed[0])
            if value not in allowed:
                raise table.error(key, f"unknown choice {_show(value)}",
                                  _suggest(value, allowed))
            choices[key] = value
        rcond = table.number("singular_rcond", Solver.singular_rcond)
        if not 0 < rcond < 1:
            raise table.error("singular_rcond", f"must be between 0 and 1, got {rcond:g}",
                              "write e.g. singular_rcond = 1e-6")
        scale = table.number("friction_velocity_scale", None)
        if scale is not None and scale <= 0:
            raise table.error("friction_velocity_scale", f"must be positive, got {scale:g}",
                              "write a small speed in length units per second, e.g. "
                              "friction_velocity_scale = 1e-6, or leave it out (1e-6 of the "
                              "mechanism's size per second)")
        return Solver(tol, max_iter, singular_rcond=rcond,
                      rate_residuals=table.boolean("rate_residuals", Solver.rate_residuals),
                      friction_velocity_scale=scale, **choices)



class EffectTables:
    """The ``[gravity]``, ``[[masses]]``, ``[[loads]]``, ``[analysis]`` and ``[outputs]``
    readers of :class:`~.parse._Parser` (springs: :mod:`.springs`)."""

    def gravity_table(self) -> tuple[float, float] | None:
        return self.table("gravity").pair("g", geometric=False) if self.top("gravity") is not None else None

    def mass_tables(self) -> tuple[Mass, ...]:
        masses = []
        for table in self.entries("masses"):
            link = self.link(table, "link", table.string("link"))
            mass = table.number("mass")
            if mass <= 0:
                raise table.error("mass", f"must be positive, got {mass:g}",
                                  f"write e.g. {table.example('mass')}")
            if isinstance(table.value("center"), str):
                center = self.point(table, "center", table.data["center"])
                if center not in link.points:
                    raise table.error("center", f'point "{center}" is not a point of links '
                                      f'"{link.name}"', "use one of its points ("
                                      + ", ".join(f'"{p}"' for p in link.points)
                                      + ") or [u, v] in its frame")
            else:
                center = table.pair("center")
            inertia = table.number("inertia", 0.0)
            if inertia < 0:
                raise table.error("inertia", f"must be >= 0, got {inertia:g}",
                                  "write the moment of inertia about the center of mass")
            masses.append(Mass(link.name, mass, center, inertia))
        return tuple(masses)

    def load_tables(self) -> tuple[Load, ...]:
        loads = []
        for table in self.entries("loads"):
            at_point = table.has("point") or table.has("force")
            on_link = table.has("link") or table.has("torque")
            if at_point and on_link:
                raise table.error("torque" if table.has("torque") else "link",
                                  "a load is a force at a point or a torque on a link, not both",
                                  "split it into two [[loads]]")
            if at_point or not on_link:
                if not at_point:
                    raise table.error("point", "missing: a load needs point + force, or "
                                      "link + torque",
                                      f"add {table.example('point')} and "
                                      f"{table.example('force')}, or {table.example('link')} "
                                      f"and {table.example('torque')}")
                loads.append(Load(table.data["name"],
                                  point=self.point(table, "point", table.string("point")),
                                  force=table.pair("force", geometric=False)))
            else:
                loads.append(Load(table.data["name"],
                                  link=self.link(table, "link", table.string("link")).name,
                                  torque=table.number("torque")))
        return tuple(loads)

    def analysis_table(self) -> tuple[str, ...]:
        table = self.table("analysis")
        effects = _choices(table, "effects", EFFECTS, "effect")
        for effect in effects:
            for needed in EFFECT_NEEDS[effect]:
                options = (needed,) if isinstance(needed, str) else needed
                if not any(self.top(t) for t in options):
                    ref = " or ".join(_table_ref(t) for t in options)
                    raise table.error("effects", f'effect "{effect}" is on but the scene has '
                                      f"no {ref}", f'add {ref} or remove "{effect}" from effects')
        return effects

    def output_table(self) -> Outputs:
        table = self.table("outputs")
        kinematics = _choices(table, "kinematics", KINEMATIC_ORDERS, "kinematic order")
        lists = {key: table.strings(key, (), what="point") for key in ("trace", "vectors")}
        for key, names in lists.items():
            for name in names:
                self.point(table, key, name)
        return Outputs(kinematics, lists["trace"], lists["vectors"])


def _stroke(table: _Table, kind: str) -> tuple[float, float] | None:
    """``stroke = [shortest, longest]`` (driver units: degrees for an angle), or None."""
    if not table.has("stroke"):
        return None
    lo, hi = table.pair("stroke", geometric=kind != "angle")
    if not lo < hi:
        raise table.error("stroke", f"the shortest value {lo:g} is not below the longest {hi:g}",
                          "write stroke = [shortest, longest], e.g. stroke = [1.10, 1.70]")
    if kind == "distance" and lo < 0:
        raise table.error("stroke", f"a length cannot be negative, got {lo:g}",
                          "write the cylinder's shortest and longest pin-to-pin length")
    return (lo, hi)


def _choices(table, key: str, allowed, what: str) -> tuple[str, ...]:
    """The strings of ``key``, each one of ``allowed`` (an error with a hint otherwise)."""
    values = table.strings(key, (), what=what)
    for value in values:
        if value not in allowed:
            raise table.error(key, f'unknown {what} "{value}"', _suggest(value, allowed))
    return values
