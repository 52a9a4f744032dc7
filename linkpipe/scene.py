"""Read a scene TOML file into frozen, typed objects (no maths here).

The contract is ``docs/scene-format.md``. Every check that needs only the text lives here;
checks that need the constraint Jacobian (degrees of freedom, assembly of the start
configuration) live in :mod:`linkpipe.model` and raise the same :class:`SceneError`.
"""
from __future__ import annotations

import math  # isfinite, floor and hypot (a fixed link's drawn length) only: no maths here
import stat
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from .errors import SceneError, did_you_mean

EFFECTS = ("springs", "gravity", "inertia", "damping", "loads")
KINEMATIC_ORDERS = ("velocity", "acceleration")


@dataclass(frozen=True)
class Point:
    name: str
    x: float
    y: float
    fixed: bool = False


@dataclass(frozen=True)
class Link:
    """A rigid body. ``points[0]``, ``points[1]`` span its frame.

    ``length``: the exact distance of the first two points from ``lengths``, or None (take it
    from the start configuration). ``local``: explicit local coordinates ``{name: (u, v)}`` of
    further points (others are taken from the start configuration).
    """

    name: str
    points: tuple[str, ...]
    length: float | None = None
    local: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class Slider:
    """A point on a line: fixed (``through`` + ``direction``) or through two points of a link."""

    name: str
    point: str
    through: tuple[float, float] | None = None
    direction: tuple[float, float] | None = None
    line_points: tuple[str, str] | None = None  # along = ["D", "E"]

    @property
    def moving(self) -> bool:
        return self.line_points is not None


@dataclass(frozen=True)
class Input:
    point: str
    direction: tuple[float, float]


@dataclass(frozen=True)
class Driver:
    """One driven coordinate.

    ``kind`` is ``"angle"`` (``points`` = (a, b): direction of a->b, degrees from +x, CCW) or
    ``"coordinate"`` (``points`` = (p,), ``axis`` 0 for x, 1 for y). ``steps`` is the resolved
    number of steps; ``step`` is the step size when the scene gave ``step`` (values are then
    ``from + i*step``), else None (values ``from + i*(to-from)/(steps-1)``).
    ``rate`` and ``acceleration`` in driver units per s and s^2 (degrees for angles).
    """

    name: str
    kind: str
    points: tuple[str, ...]
    axis: int | None
    from_value: float
    to_value: float
    steps: int
    step: float | None = None
    rate: float = 0.0
    acceleration: float = 0.0
    input: Input | None = None


#: Choices of the [solver] knobs that trade accuracy for speed (first = default).
SOLVER_CHOICES = {
    "jacobian": ("analytic", "finite_difference"),
    "derivatives": ("linear", "finite_difference"),
    "predictor": ("first", "second", "none"),
    "method": ("auto", "newton", "dyads"),
}


@dataclass(frozen=True)
class Solver:
    """Settings of stage 1. ``tol`` is relative to the mechanism's size.

    ``jacobian``: analytic or finite-difference Newton Jacobian. ``derivatives``: velocities and
    accelerations by linear solves or by finite differences of positions along the sweep.
    ``predictor``: start guess of each step (none / first order / second order).
    ``method``: ``auto`` (closed-form dyads where the scene decomposes, else Newton),
    ``newton`` (always the general path) or ``dyads`` (require the fast path).
    ``singular_rcond``: 1/condition below which a step's Jacobian counts as singular. At a
    change point or assembly limit even a fully converged solution has a smallest singular value
    of about sqrt(machine eps) ~ 1e-8 (the root is double), so values much below 1e-6 stop
    flagging exact singular configurations.
    """

    tol: float = 1e-12
    max_iter: int = 25
    jacobian: str = "analytic"
    derivatives: str = "linear"
    predictor: str = "first"
    method: str = "auto"
    singular_rcond: float = 1e-6


@dataclass(frozen=True)
class Spring:
    name: str
    between: tuple[str, str]
    k: float
    free_length: float | None = None
    preload: float | None = None
    damping: float = 0.0


@dataclass(frozen=True)
class Mass:
    link: str
    mass: float
    center: str | tuple[float, float]
    inertia: float = 0.0


@dataclass(frozen=True)
class Load:
    """A constant force at a point (global frame) or a couple on a link (CCW positive)."""

    name: str
    point: str | None = None
    force: tuple[float, float] | None = None
    link: str | None = None
    torque: float | None = None


@dataclass(frozen=True)
class Outputs:
    kinematics: tuple[str, ...] = ()
    trace: tuple[str, ...] = ()
    vectors: tuple[str, ...] = ()


@dataclass(frozen=True)
class Scene:
    """A whole checked scene. ``text`` is the TOML source, ``path`` where it came from."""

    path: str
    text: str
    name: str
    description: str
    units: dict[str, str]
    points: tuple[Point, ...]
    links: tuple[Link, ...]
    sliders: tuple[Slider, ...]
    drivers: tuple[Driver, ...]
    solver: Solver
    effects: tuple[str, ...] = ()
    gravity: tuple[float, float] | None = None
    springs: tuple[Spring, ...] = ()
    masses: tuple[Mass, ...] = ()
    loads: tuple[Load, ...] = ()
    outputs: Outputs = Outputs()

    @property
    def point_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.points)

    @property
    def n_steps(self) -> int:
        return self.drivers[0].steps if self.drivers else 1

    @property
    def present_but_off(self) -> tuple[str, ...]:
        """Effect tables present in the file but not named in ``effects`` (validated, unused)."""
        present = {
            "springs": bool(self.springs),
            "gravity": self.gravity is not None,
            "inertia": bool(self.masses),
            "loads": bool(self.loads),
            "damping": any(s.damping for s in self.springs),
        }
        return tuple(e for e in EFFECTS if present[e] and e not in self.effects)


# --------------------------------------------------------------------------------------------
# The loader.
#
# Messages name tables as written: ``scene``, ``points.A``, ``links "coupler"``,
# ``links "coupler".lengths``, ``drivers "crank".input``, ``masses[1]``. An entry of an array of
# tables is named by its ``name`` once that name has been read; before that (a missing or bad
# ``name``), and for ``[[masses]]``, which have no name, by its 1-based index: ``links[2]``.
# --------------------------------------------------------------------------------------------

#: Top-level tables: name -> "table" (``[name]``) or "array" (``[[name]]``).
TABLES = {
    "scene": "table",
    "points": "table",
    "links": "array",
    "sliders": "array",
    "drivers": "array",
    "solver": "table",
    "analysis": "table",
    "gravity": "table",
    "springs": "array",
    "masses": "array",
    "loads": "array",
    "outputs": "table",
}

#: The allowed keys of every kind of table, each with an example value for hints. These dicts
#: are the whole vocabulary: any other key is an error with a "did you mean" hint.
KEYS: dict[str, dict[str, str]] = {
    "scene": {"name": '"fourbar"', "description": '"Crank-rocker four-bar"',
              "units": '{ length = "m", mass = "kg", time = "s", force = "N" }'},
    "point": {"x": "0.0", "y": "0.0", "fixed": "true"},
    "links": {"name": '"coupler"', "points": '["A", "B"]', "lengths": '{ "A-B" = 3.5 }',
              "local": "{ P = [1.5, 0.8] }"},
    "sliders": {"name": '"guide"', "point": '"C"',
                "along": "{ through = [0.0, 0.0], direction = [0.0, 1.0] }"},
    "sliders.along": {"through": "[0.0, 0.0]", "direction": "[0.0, 1.0]"},
    "drivers": {"name": '"crank"', "angle": '["O2", "A"]', "coordinate": '"P.y"',
                "from": "0.0", "to": "360.0", "steps": "361", "step": "1.0", "rate": "0.0",
                "acceleration": "0.0", "input": '{ point = "H", direction = [0.0, 1.0] }'},
    "drivers.input": {"point": '"H"', "direction": "[0.0, 1.0]"},
    "solver": {"tol": "1e-12", "max_iter": "25", "jacobian": '"analytic"',
               "derivatives": '"linear"', "predictor": '"first"', "method": '"auto"',
               "singular_rcond": "1e-6"},
    "analysis": {"effects": '["springs", "gravity"]'},
    "gravity": {"g": "[0.0, -9.81]"},
    "springs": {"name": '"left"', "between": '["S1", "S2"]', "k": "4.0",
                "free_length": "0.5", "preload": "10.0", "damping": "0.0"},
    "masses": {"link": '"coupler"', "mass": "1.0", "center": '"G" (or [u, v] in the link frame)',
               "inertia": "0.0"},
    "loads": {"name": '"cut"', "point": '"C"', "force": "[0.0, 500.0]", "link": '"rocker"',
              "torque": "-2.0"},
    "outputs": {"kinematics": '["velocity", "acceleration"]', "trace": '["P"]',
                "vectors": '["P"]'},
}

#: What each effect needs in the file: effect -> the tables that must be present.
EFFECT_NEEDS = {
    "springs": ("springs",),
    "gravity": ("gravity", "masses"),
    "inertia": ("masses",),
    "loads": ("loads",),
    "damping": ("springs",),
}

_REQUIRED = object()  # default of a key that must be given


def _type_name(value) -> str:
    """Name a TOML value's type as a user reads it: "a string", "a boolean", ..."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a float"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return "a date/time"


def _show(value) -> str:
    """Show a value briefly, TOML-like, for a message."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return f'"{value}"'
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


#: the keys of ``[scene].units`` (their values are free text, recorded in the outputs)
UNIT_KEYS = ("length", "mass", "time", "force")


def _suggest(word: str, choices) -> str:
    """A "did you mean" hint that also catches a wrong case ("p" for "P")."""
    same = [c for c in choices if str(c).lower() == str(word).lower()]
    return f'did you mean "{same[0]}"?' if same else did_you_mean(word, choices)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _table_ref(name: str) -> str:
    return f"[[{name}]]" if TABLES[name] == "array" else f"[{name}]"


class _Table:
    """One TOML table being read: its label for messages and typed, checked getters.

    ``kind`` selects the allowed keys in :data:`KEYS` (unknown keys raise at once); a table whose
    keys are names (``local``) passes ``examples`` instead and checks its keys itself.
    """

    def __init__(self, path: str, label: str, data: dict, kind: str, examples=None,
                 check: bool = True):
        self.path, self.label, self.data, self.kind = path, label, data, kind
        self.examples = KEYS[kind] if examples is None else examples
        if check and examples is None:
            self.check_keys()

    def check_keys(self) -> None:
        """Raise on the first key that is not in the vocabulary, with a "did you mean"."""
        for key in self.data:
            if key not in self.examples:
                raise self.error(key, "unknown key",
                                 _suggest(key, self.examples))

    def error(self, key: str | None, message: str, hint: str = "") -> SceneError:
        return SceneError(self.path, self.label, key, message, hint)

    def example(self, key: str) -> str:
        return f"{key} = {self.examples[key]}"

    def has(self, key: str) -> bool:
        return key in self.data

    def value(self, key: str):
        """The raw value of a required key of several possible types."""
        self._present(key, _REQUIRED)
        return self.data[key]

    def _present(self, key: str, default) -> bool:
        """Whether ``key`` is given; raise when it is missing and required."""
        if key in self.data:
            return True
        if default is _REQUIRED:
            raise self.error(key, "missing", f"add {self.example(key)}")
        return False

    def wrong_type(self, key: str, expected: str) -> SceneError:
        value = self.data[key]
        return self.error(key, f"expected {expected}, got {_type_name(value)} ({_show(value)})",
                          f"write e.g. {self.example(key)}")

    def number(self, key: str, default=_REQUIRED) -> float | None:
        """A finite number (an integer is accepted) as a float."""
        if not self._present(key, default):
            return default
        value = self.data[key]
        if not _is_number(value):
            raise self.wrong_type(key, "a number")
        if not math.isfinite(value):
            raise self.error(key, f"must be a finite number, got {_show(value)}",
                             f"write e.g. {self.example(key)}")
        return float(value)

    def integer(self, key: str, default=_REQUIRED) -> int | None:
        if not self._present(key, default):
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.wrong_type(key, "an integer")
        return value

    def boolean(self, key: str, default) -> bool:
        if not self._present(key, default):
            return default
        if not isinstance(self.data[key], bool):
            raise self.wrong_type(key, "true or false")
        return self.data[key]

    def string(self, key: str, default=_REQUIRED) -> str | None:
        if not self._present(key, default):
            return default
        if not isinstance(self.data[key], str):
            raise self.wrong_type(key, "a string")
        return self.data[key]

    def name(self, key: str = "name") -> str:
        """A required, non-empty name."""
        value = self.string(key)
        if not value.strip():
            raise self.error(key, "is empty", f"write e.g. {self.example(key)}")
        return value

    def pair(self, key: str, default=_REQUIRED, nonzero: bool = False):
        """Two finite numbers ``[a, b]`` as a tuple of floats; ``nonzero``: not ``[0, 0]``."""
        if not self._present(key, default):
            return default
        value = self.data[key]
        if (not isinstance(value, list) or len(value) != 2
                or not all(_is_number(v) for v in value)):
            raise self.wrong_type(key, "two numbers [a, b]")
        if not all(math.isfinite(v) for v in value):
            raise self.error(key, f"must hold finite numbers, got {_show(value)}",
                             f"write e.g. {self.example(key)}")
        result = (float(value[0]), float(value[1]))
        if nonzero and result == (0.0, 0.0):
            raise self.error(key, "is zero: a direction needs a non-zero vector",
                             f"write e.g. {self.example(key)}")
        return result

    def strings(self, key: str, default=_REQUIRED, what: str = "name") -> tuple[str, ...]:
        """An array of strings (``what`` names one of them), each listed once."""
        if not self._present(key, default):
            return tuple(default)
        value = self.data[key]
        if not isinstance(value, list):
            raise self.wrong_type(key, f"an array of {what}s")
        seen = set()
        for i, item in enumerate(value, 1):
            if not isinstance(item, str):
                raise self.error(key, f"element {i} is {_type_name(item)} ({_show(item)}), "
                                 f"expected a {what} (a string)",
                                 f"write e.g. {self.example(key)}")
            if item in seen:
                raise self.error(key, f'{what} "{item}" appears twice', "list each one once")
            seen.add(item)
        return tuple(value)

    def sub(self, key: str) -> _Table:
        """The inline table at ``key``, checked against the keys of ``<kind>.<key>``."""
        if not isinstance(self.data[key], dict):
            raise self.wrong_type(key, "a table")
        return _Table(self.path, f"{self.label}.{key}", self.data[key], f"{self.kind}.{key}")

    def one_of(self, first: str, second: str) -> str:
        """Which of two exclusive keys is given; raise when neither or both are."""
        if self.has(first) and self.has(second):
            raise self.error(second, f"give {first} or {second}, not both",
                             f"keep one of {self.example(first)} or {self.example(second)}")
        if not (self.has(first) or self.has(second)):
            raise self.error(first, f"missing: give {first} or {second}",
                             f"add {self.example(first)} or {self.example(second)}")
        return first if self.has(first) else second


class _Parser:
    """Read one scene; the table readers run in dependency order (names before their users)."""

    def __init__(self, data: dict, text: str, path: str):
        self.data, self.text, self.path = data, text, path
        self.points: dict[str, Point] = {}
        self.links: dict[str, Link] = {}

    def error(self, table: str, key: str | None, message: str, hint: str = "") -> SceneError:
        return SceneError(self.path, table, key, message, hint)

    # -- the shape of the file ----------------------------------------------------------------

    def top(self, name: str):
        """The raw value of a top-level table: a dict, a list of dicts, or None when absent."""
        value = self.data.get(name)
        if value is None:
            return None
        if TABLES[name] == "table":
            if not isinstance(value, dict):
                raise self.error(name, None, f"expected a table [{name}], got "
                                 f"{_type_name(value)}", f"write [{name}] on a line of its own")
        elif not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(name, None, f"expected an array of tables [[{name}]], got "
                             f"{_type_name(value)}",
                             f"write [[{name}]] (double brackets) before each entry")
        return value

    def table(self, name: str) -> _Table:
        """A top-level single table (empty when absent)."""
        return _Table(self.path, name, self.top(name) or {}, name)

    def entries(self, name: str) -> list[_Table]:
        """The entries of an array of tables, labelled by their names, which must be unique."""
        tables, first_at = [], {}
        named = "name" in KEYS[name]
        for i, raw in enumerate(self.top(name) or [], 1):
            table = _Table(self.path, f"{name}[{i}]", raw, name, check=False)
            if named and "name" in raw:
                entry_name = table.name()
                if entry_name in first_at:
                    raise table.error("name", f'"{entry_name}" is used twice '
                                      f"({first_at[entry_name]} and {name}[{i}])",
                                      f"give each of the [[{name}]] its own name")
                first_at[entry_name] = f"{name}[{i}]"
                table.label = f'{name} "{entry_name}"'
            table.check_keys()
            if named and "name" not in raw:
                table.name()  # "missing", once a misspelt name key has had its hint
            tables.append(table)
        return tables

    # -- name look-ups ------------------------------------------------------------------------

    def point(self, table: _Table, key: str, name: str) -> str:
        if name not in self.points:
            raise table.error(key, f'unknown point "{name}"',
                              _suggest(name, self.points) or "declare it in [points]")
        return name

    def link(self, table: _Table, key: str, name: str) -> Link:
        if name not in self.links:
            raise table.error(key, f'unknown link "{name}"',
                              _suggest(name, self.links) or "declare it with [[links]]")
        return self.links[name]

    # -- the tables ---------------------------------------------------------------------------

    def parse(self) -> Scene:
        for name in self.data:
            if name not in TABLES:
                raise self.error(name, None, "unknown table", _suggest(name, TABLES))
        scene = self.scene_table()
        self.point_table()
        self.link_tables()
        sliders = self.slider_tables()
        drivers = self.driver_tables()
        solver = self.solver_table()
        gravity = self.gravity_table()
        springs = self.spring_tables()
        masses = self.mass_tables()
        loads = self.load_tables()
        effects = self.analysis_table()
        outputs = self.output_table()
        return Scene(path=self.path, text=self.text, **scene,
                     points=tuple(self.points.values()), links=tuple(self.links.values()),
                     sliders=sliders, drivers=drivers, solver=solver, effects=effects,
                     gravity=gravity, springs=springs, masses=masses, loads=loads,
                     outputs=outputs)

    def scene_table(self) -> dict:
        table = self.table("scene")
        stem = "scene" if self.path == "<string>" else Path(self.path).stem
        name = table.string("name", stem)
        if not name.strip() or any(c in name for c in "/\\") or name in (".", ".."):
            raise table.error("name", f"{_show(name)} cannot be a file name (outputs are "
                              "<name>.h5 and <name>.rrd)", f"write e.g. {table.example('name')}")
        units = {}
        if table.has("units"):
            if not isinstance(table.data["units"], dict):
                raise table.wrong_type("units", "a table of strings")
            for key, value in table.data["units"].items():
                if key not in UNIT_KEYS:  # they name the outputs' units: a typo must not pass
                    raise self.error("scene.units", key, f"unknown unit key {_show(key)}: "
                                     + _suggest(key, UNIT_KEYS),
                                     "the keys are " + ", ".join(UNIT_KEYS))
                if not isinstance(value, str):
                    raise self.error("scene.units", key, f"expected a string, got "
                                     f"{_type_name(value)} ({_show(value)})",
                                     f'units are free text: write e.g. {key} = "m"')
                units[key] = value
        return {"name": name, "description": table.string("description", ""), "units": units}

    def point_table(self) -> None:
        raw = self.top("points")
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
            self.points[name] = Point(name, table.number("x"), table.number("y"),
                                      table.boolean("fixed", False))

    def link_tables(self) -> None:
        for table in self.entries("links"):
            names = table.strings("points", what="point")
            if len(names) < 2:
                raise table.error("points", f"a link needs at least two points, got "
                                  f"{len(names)}", 'write e.g. points = ["A", "B"]')
            for name in names:
                self.point(table, "points", name)
            for i, a in enumerate(names):
                for b in names[i + 1:]:
                    pa, pb = self.points[a], self.points[b]
                    if (pa.x, pa.y) == (pb.x, pb.y):
                        raise table.error("points", f'points "{a}" and "{b}" are at the same '
                                          f"place ({pa.x:g}, {pa.y:g}) on one link",
                                          "move one of them in [points] (x, y are the start "
                                          "configuration)")
            link = Link(table.data["name"], names, self.link_length(table, names),
                        self.link_local(table, names))
            self.links[link.name] = link
        if not self.links:
            raise self.error("links", None, "no links: the scene needs at least one [[links]]",
                             'add [[links]] with name = "..." and points = ["A", "B"]')

    def link_length(self, table: _Table, names) -> float | None:
        """``lengths = { "A-B" = d }``: only the first two points' distance may be given."""
        if not table.has("lengths"):
            return None
        a, b = names[0], names[1]
        if not isinstance(table.data["lengths"], dict):
            raise table.wrong_type("lengths", "a table")
        sub = _Table(self.path, f"{table.label}.lengths", table.data["lengths"], "links",
                     examples={key: "3.5" for key in table.data["lengths"]})
        length = None
        for key in sub.data:
            if key not in (f"{a}-{b}", f"{b}-{a}"):
                raise sub.error(key, f'only the distance of the first two points, "{a}-{b}", '
                                "may be given",
                                "further points are held by `local`: write "
                                f'local = {{ P = [u, v] }} for a point P after "{a}", "{b}"')
            length = sub.number(key)
            if length <= 0:
                raise sub.error(key, f"must be positive, got {length:g}",
                                f'write the distance of "{a}" and "{b}"')
            pa, pb = self.points[a], self.points[b]
            if pa.fixed and pb.fixed:  # nothing moves to meet this length: it must hold as drawn
                drawn = math.hypot(pb.x - pa.x, pb.y - pa.y)
                if abs(drawn - length) > 1e-9 * max(drawn, length):
                    raise sub.error(key, f'"{a}" and "{b}" are both fixed, {drawn:g} apart, but '
                                    f"the length says {length:g}",
                                    "move the fixed points, or correct (or drop) the length")
        return length

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

    def driver_tables(self) -> tuple[Driver, ...]:
        tables = self.entries("drivers")
        if not tables:
            raise self.error("drivers", None, "no drivers: the scene needs at least one "
                             "[[drivers]]", 'add [[drivers]] with name, angle = ["O2", "A"] '
                             '(or coordinate = "P.y"), from, to and steps')
        drivers = [self.driver(table) for table in tables]
        first = drivers[0]
        for table, driver in zip(tables[1:], drivers[1:]):
            if driver.steps != first.steps:
                raise table.error("step" if table.has("step") else "steps",
                                  f'gives {driver.steps} steps but drivers "{first.name}" '
                                  f"gives {first.steps}",
                                  "all drivers advance together: make their step counts equal")
        return tuple(drivers)

    def driver(self, table: _Table) -> Driver:
        if table.one_of("angle", "coordinate") == "angle":
            kind, axis = "angle", None
            points = table.strings("angle", what="point")
            if len(points) != 2:
                raise table.error("angle", f"expected two point names, got {len(points)}",
                                  f"write e.g. {table.example('angle')}")
            for name in points:
                self.point(table, "angle", name)
            if all(self.points[p].fixed for p in points):
                raise table.error("angle", f'"{points[0]}" and "{points[1]}" are both fixed: '
                                  "their direction cannot be driven",
                                  "drive the direction from a point to a moving point")
        else:
            kind = "coordinate"
            text = table.string("coordinate")
            name, dot, axis_name = text.rpartition(".")
            if not dot or axis_name not in ("x", "y"):
                raise table.error("coordinate", f"{_show(text)} is not a point coordinate",
                                  'write "<point>.x" or "<point>.y", e.g. coordinate = "P.y"')
            self.point(table, "coordinate", name)
            if self.points[name].fixed:
                raise table.error("coordinate", f'point "{name}" is fixed: its coordinate '
                                  "cannot be driven", "drive a moving point")
            points, axis = (name,), "xy".index(axis_name)
        start, stop = table.number("from"), table.number("to")
        steps, step = self.driver_steps(table, start, stop)
        driver_input = None
        if table.has("input"):
            sub = table.sub("input")
            driver_input = Input(self.point(sub, "point", sub.string("point")),
                                 sub.pair("direction", nonzero=True))
            if self.points[driver_input.point].fixed:
                raise sub.error("point", f'point "{driver_input.point}" is fixed: it never moves, '
                                "so an actuator there does no work (every step would be "
                                "no_leverage)", "name the moving point the actuator pushes")
        return Driver(table.data["name"], kind, tuple(points), axis, start, stop, steps, step,
                      rate=table.number("rate", 0.0),
                      acceleration=table.number("acceleration", 0.0), input=driver_input)

    @staticmethod
    def driver_steps(table: _Table, start: float, stop: float) -> tuple[int, float | None]:
        """Resolve ``steps`` or ``step`` into the step count (and the step, when given)."""
        span = f"from = {start:g}, to = {stop:g}"
        if table.one_of("steps", "step") == "steps":
            steps = table.integer("steps")
            if steps < 1:
                raise table.error("steps", f"steps = {steps} gives no steps",
                                  "use steps >= 1 (steps = 1 is a single position)")
            if steps == 1 and start != stop:
                raise table.error("steps", f"steps = 1 with {span} gives no steps: a single "
                                  "position never reaches to",
                                  "use steps >= 2 to sweep, or to = from for a single position")
            if steps > 1 and start == stop:
                raise table.error("steps", f"{span} with steps = {steps} gives no motion",
                                  "use steps = 1 for a single position, or change from/to")
            return steps, None
        step = table.number("step")
        if start == stop:
            raise table.error("step", f"{span} gives no motion",
                              "use steps = 1 for a single position, or change from/to")
        if step == 0 or (step > 0) != (stop > start):
            better = abs(step) if step else abs(stop - start) / 10
            raise table.error("step", f"step = {step:g} with {span} gives no steps",
                              "use a non-zero step with the sign of to - from, e.g. step = "
                              f"{better if stop > start else -better:g}")
        # from, from + s, ... up to and including `to` when it lands within 1e-9*|s| of it
        steps = math.floor((stop - start) / step + 1e-9) + 1
        if steps == 1:
            raise table.error("step", f"step = {step:g} with {span} gives no steps: it "
                              "oversteps to, leaving a single position",
                              f"use a step no larger than |to - from| = {abs(stop - start):g}")
        return steps, step

    def solver_table(self) -> Solver:
        table = self.table("solver")
        tol = table.number("tol", Solver.tol)
        if tol <= 0:
            raise table.error("tol", f"must be positive, got {tol:g}", "write e.g. tol = 1e-12")
        max_iter = table.integer("max_iter", Solver.max_iter)
        if max_iter < 1:
            raise table.error("max_iter", f"must be at least 1, got {max_iter}",
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
        return Solver(tol, max_iter, singular_rcond=rcond, **choices)

    def gravity_table(self) -> tuple[float, float] | None:
        return self.table("gravity").pair("g") if self.top("gravity") is not None else None

    def spring_tables(self) -> tuple[Spring, ...]:
        springs = []
        for table in self.entries("springs"):
            between = table.strings("between", what="point")
            if len(between) != 2:
                raise table.error("between", f"expected two different points, got "
                                  f"{len(between)}", f"write e.g. {table.example('between')}")
            for name in between:
                self.point(table, "between", name)
            k = table.number("k")
            if k < 0:
                raise table.error("k", f"negative stiffness k = {k:g}",
                                  "use k >= 0 (the force is tension when stretched)")
            table.one_of("free_length", "preload")
            free_length = table.number("free_length", None)
            if free_length is not None and free_length < 0:
                raise table.error("free_length", f"must be >= 0, got {free_length:g}",
                                  "write the spring's unstretched length")
            damping = table.number("damping", 0.0)
            if damping < 0:
                raise table.error("damping", f"must be >= 0, got {damping:g}",
                                  "write e.g. damping = 0.0")
            springs.append(Spring(table.data["name"], between, k, free_length,
                                  table.number("preload", None), damping))
        return tuple(springs)

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
                                  force=table.pair("force")))
            else:
                loads.append(Load(table.data["name"],
                                  link=self.link(table, "link", table.string("link")).name,
                                  torque=table.number("torque")))
        return tuple(loads)

    def analysis_table(self) -> tuple[str, ...]:
        table = self.table("analysis")
        effects = table.strings("effects", (), what="effect")
        for effect in effects:
            if effect not in EFFECTS:
                raise table.error("effects", f'unknown effect "{effect}"',
                                  _suggest(effect, EFFECTS))
            for needed in EFFECT_NEEDS[effect]:
                if not self.top(needed):
                    ref = _table_ref(needed)
                    raise table.error("effects", f'effect "{effect}" is on but the scene has '
                                      f"no {ref}", f'add {ref} or remove "{effect}" from effects')
        return effects

    def output_table(self) -> Outputs:
        table = self.table("outputs")
        kinematics = table.strings("kinematics", (), what="kinematic order")
        for order in kinematics:
            if order not in KINEMATIC_ORDERS:
                raise table.error("kinematics", f'unknown kinematic order "{order}"',
                                  _suggest(order, KINEMATIC_ORDERS))
        lists = {key: table.strings(key, (), what="point") for key in ("trace", "vectors")}
        for key, names in lists.items():
            for name in names:
                self.point(table, key, name)
        return Outputs(kinematics, lists["trace"], lists["vectors"])


def parse_scene(text: str, path: str = "<string>") -> Scene:
    """Parse and check a scene's TOML text; raise :class:`SceneError` on the first problem."""
    path = str(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "", None, f"not valid TOML: {exc}",
                         "fix the syntax there (strings need quotes, tables are [name], "
                         "arrays of tables [[name]], each key once)") from None
    return _Parser(data, text, path).parse()


#: a scene file larger than this is not a scene (a log, an image, a device): refused unread
MAX_SCENE_BYTES = 16 * 2**20


def _read_regular_file(path: Path) -> bytes:
    """Return the bytes of a regular file; a FIFO, a device or a socket is refused without
    being opened (reading one would block or never end), and so is a file over 16 MiB."""
    info = path.stat()  # FileNotFoundError / PermissionError propagate
    if stat.S_ISDIR(info.st_mode):
        raise IsADirectoryError(path)
    if not stat.S_ISREG(info.st_mode):
        raise SceneError(str(path), "", None, "is not a regular file (a pipe, device or socket)",
                         "give the path of a .toml file")
    if info.st_size > MAX_SCENE_BYTES:
        raise SceneError(str(path), "", None, f"is {info.st_size / 2**20:.0f} MiB, not a scene",
                         "give the path of a .toml scene file")
    return path.read_bytes()


def load_scene(path) -> Scene:
    """Read and check the scene file at ``path``; raise :class:`SceneError` on any problem."""
    path = str(path)
    try:
        raw = _read_regular_file(Path(path))
    except FileNotFoundError:
        raise SceneError(path, "", None, "no such scene file",
                         "check the path (scenes live in configs/*.toml)") from None
    except IsADirectoryError:
        raise SceneError(path, "", None, "is a directory, not a scene file",
                         "give the path of a .toml file") from None
    except OSError as exc:
        raise SceneError(path, "", None, f"cannot read the file ({exc.strerror})",
                         "check the path and its permissions") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(path, "", None, f"not UTF-8 text (byte {exc.start})",
                         "save the scene as UTF-8") from None
    return parse_scene(text, path)
