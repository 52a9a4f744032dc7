"""Read a scene TOML file into frozen, typed objects (no maths here).

The contract is ``docs/scene-format.md``. Every check that needs only the text lives in this
package; checks that need the constraint Jacobian (degrees of freedom, assembly of the start
configuration) live in :mod:`linkpipe.model` and raise the same :class:`SceneError`.
"""
from __future__ import annotations

import stat
import tomllib
from pathlib import Path

from ..errors import SceneError
from .keys import KEYS, TABLES, UNIT_KEYS, _Table, _show, _suggest, _type_name
from .tables import Link, Point, Scene
from .geometry import GeometryTables
from .motion import EffectTables, MotionTables
from .springs import SpringTables
from .friction import FrictionTables
from . import units
from .timing import MeasurementTables, TimeTables
from .dynamics import DynamicsTables


class _Parser(GeometryTables, MotionTables, EffectTables, SpringTables, TimeTables,
              MeasurementTables, FrictionTables, DynamicsTables):
    """Read one scene; the table readers run in dependency order (names before their users)."""

    def __init__(self, data: dict, text: str, path: str):
        self.data, self.text, self.path = data, text, path
        self.points: dict[str, Point] = {}
        self.links: dict[str, Link] = {}
        self.time = None
        self.dynamics = None
        self.logs = {}


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
            by_link = [r.get("link") for r in self.top(name) or [] if isinstance(r, dict)]
            if (not named and isinstance(raw.get("link"), str)
                    and by_link.count(raw["link"]) == 1):  # [[masses]]: known by its link,
                table.label = f'{name} "{raw["link"]}"'  # as [fit] addresses it
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
        self.units = scene["units"]
        self.point_table()
        self.link_tables()
        sliders = self.slider_tables()
        if self.top("fit") is not None:
            self.table("fit")  # its keys; linkpipe.fit reads and checks the values
        if self.top("study") is not None:
            self.table("study")  # its keys; linkpipe.study reads and checks the values
        if self.top("optimize") is not None:
            self.table("optimize")  # its keys; linkpipe.study.optimize reads the values
        self.logs = self.log_tables()
        self.dynamics = self.dynamics_table()
        self.time = self.time_table(self.logs)
        drivers = self.driver_tables()
        solver = self.solver_table()
        gravity = self.gravity_table()
        springs = self.spring_tables()
        torsion_springs = self.torsion_spring_tables()
        masses = self.mass_tables()
        loads = self.load_tables()
        friction = self.friction_tables(drivers, sliders)
        effects = self.analysis_table()
        outputs = self.output_table()
        return Scene(path=self.path, text=self.text, **scene,
                     points=tuple(self.points.values()), links=tuple(self.links.values()),
                     sliders=sliders, drivers=drivers, solver=solver, effects=effects,
                     gravity=gravity, springs=springs, masses=masses, loads=loads,
                     outputs=outputs, torsion_springs=torsion_springs, time=self.time,
                     logs=tuple(self.logs.values()), friction=friction, dynamics=self.dynamics,
                     warnings=self.warnings(gravity, effects, drivers),
                     measurements=self.measurement_tables(drivers, springs, torsion_springs,
                                                          sliders, effects, friction))


    def warnings(self, gravity, effects, drivers=()) -> tuple[str, ...]:
        """What is legal but probably not meant (printed in the summary, stored in the .h5)."""
        out = []
        for d in drivers:  # held while others move, yet with a velocity: statics meant?
            if (self.time is None and d.steps > 1 and d.from_value == d.to_value
                    and (d.rate != 0 or d.acceleration != 0)):
                unit = "deg" if d.kind == "angle" else self.units.get("length", "length units")
                out.append(f'{self.path}: [drivers "{d.name}"] is held (from = to = '
                           f"{d.from_value:g} {unit}) with rate = {d.rate:g} {unit}/s, "
                           f"acceleration = {d.acceleration:g} {unit}/s^2: its value stays while "
                           "its velocity and "
                           "acceleration are those at every step (the contract's instantaneous "
                           "state); give rate = 0 for a driver that does not move")
        if self.dynamics is not None:  # the drivers' forces are generalized forces
            out += [f'{self.path}: [drivers "{d.name}"] input is not used with [dynamics]: its '
                    "force is the driver's own generalized force (a torque for an angle, an "
                    "axial force for a distance or coordinate); remove input, or give force in "
                    "those terms" for d in drivers if d.input is not None]
        moving = [d for d in drivers if d.from_value != d.to_value]
        if self.dynamics is None and self.time is None and drivers and drivers[0].steps > 1 and not moving:
            out.append(f"{self.path}: every driver is held (from = to): the sweep is "
                       f"{drivers[0].steps} identical steps; use steps = 1 for a single "
                       "position, or give a driver from != to to sweep")
        # from, from + s, ... never reached to: the single step at from
        swept = ([("[time]", self.time, "instant")] if self.time is not None else
                 [(f'[drivers "{d.name}"]', d, "position") for d in moving])
        for table, sw, single in swept:
            if sw.step is not None and sw.steps == 1 and sw.to_value != sw.from_value:
                out.append(f"{self.path}: {table} step = {sw.step:g} oversteps to = "
                           f"{sw.to_value:g} from from = {sw.from_value:g}: the sweep is the "
                           f"single {single} at from; use a step no larger than |to - from| = "
                           f"{abs(sw.to_value - sw.from_value):g} to sweep")
        if gravity is not None and "gravity" in effects:
            note = units.gravity_warning(gravity, self.units.get("length"))
            if note:
                out.append(f"{self.path}: {note}")
        if {"gravity", "inertia"} & set(effects):  # masses meet forces: one unit system
            note = units.consistency_warning(self.units)
            if note:
                out.append(f"{self.path}: {note}")
        return tuple(out)

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
                if "," in value:  # the outputs list several entries' units comma-separated
                    raise self.error("scene.units", key, f"{_show(value)} holds a comma, which "
                                     "the outputs use between entries' units (driver_units, "
                                     "measurement_units)", f'write it without one, e.g. '
                                     f'{key} = "{" ".join(value.replace(",", " ").split()) or "m"}"')
                units[key] = value
        return {"name": name, "description": table.string("description", ""), "units": units}


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
