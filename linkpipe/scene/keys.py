"""The keys every table may hold and how one table of the TOML is read and checked
(types, units, did-you-mean hints for unknown keys)."""
from __future__ import annotations

import math

from ..errors import SceneError, did_you_mean


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
    "time": "table",
    "dynamics": "table",
    "logs": "array",
    "measurements": "array",
    "fit": "table",
    "study": "table",
    "optimize": "table",
    "solver": "table",
    "analysis": "table",
    "gravity": "table",
    "springs": "array",
    "torsion_springs": "array",
    "masses": "array",
    "loads": "array",
    "outputs": "table",
    "friction": "array",
}

#: The allowed keys of every kind of table, each with an example value for hints. These dicts
#: are the whole vocabulary: any other key is an error with a "did you mean" hint.
KEYS: dict[str, dict[str, str]] = {
    "scene": {"name": '"fourbar"', "description": '"Crank-rocker four-bar"',
              "units": '{ length = "m", mass = "kg", time = "s", force = "N" }'},
    "point": {"x": "0.0", "y": "0.0", "fixed": "true"},
    "links": {"name": '"coupler"', "points": '["A", "B"]',
              "lengths": '{ "A-B" = 3.5, "A-P" = 2.0, "B-P" = 1.8 }',
              "local": "{ P = [1.5, 0.8] }", "side": '{ P = "left" }'},
    "sliders": {"name": '"guide"', "point": '"C"',
                "along": "{ through = [0.0, 0.0], direction = [0.0, 1.0] }"},
    "sliders.along": {"through": "[0.0, 0.0]", "direction": "[0.0, 1.0]"},
    "drivers": {"name": '"crank"', "angle": '["O2", "A"]', "coordinate": '"P.y"',
                "distance": '["C1", "C2"]', "relative_to": '["B", "A"]',
                "from": "0.0", "to": "360.0", "steps": "361", "step": "1.0",
                "rate": '0.0 (driver units per second, or with a unit: "120 rpm", "50 mm/s")',
                "acceleration": '0.0 (or with a unit: "30 deg/s^2")', "input": '{ point = "H", direction = [0.0, 1.0] }',
                "law": '"cycloidal"', "log": '"run3.boom_len"', "scale": "0.001",
                "smoothing": "0.0", "stroke": "[1.10, 1.70] (shortest, longest)",
                "offset": "0.0 (a log driver's zero, in driver units)",
                "start_rate": "0.0 (driver units per second)",
                "force": "0.033 (its actuator's generalized force: a torque for an angle)",
                "force_law": '{ law = "cycloidal", from = 0.0, to = 50.0, duration = 0.5 }',
                "force_log": '"run3.p_cap"'},
    "drivers.force_law": {"law": '"cycloidal"', "from": "0.0", "to": "50.0",
                          "duration": "0.5 (s; default [dynamics] to)"},
    "dynamics": {"to": "2.0", "output_step": "0.001", "rtol": "1e-9",
                 "method": '"DOP853" (or "Radau" for stiff springs)'},
    "time": {"from": "0.0", "to": "4.0", "steps": "4001", "step": "0.001", "log": '"run3"'},
    "logs": {"name": '"run3"', "file": '"logs/run3.csv"', "time": '"t"',
             "time_scale": "0.001 (a time column in ms)", "skip_rows": "1 (a units row)",
             "format": '"csv" (delimited text) or "parquet"', "delimiter": '"\\t"',
             "units": '{ stroke = "mm", p_cap = "bar", wheel = "deg" }',
             "lag": "0.004 (s: the log's stamps are late by lag)"},
    "fit": {"parameters": '["springs.cable.k", "masses.boom.mass"]',
            "per_log": '["drivers.crank.offset"]', "loss": '"soft_l1"', "f_scale": "3.0",
            "bounds": '{ "springs.cable.k" = [0.0, 1e5] }'},
    "study": {"base": '"../basketball_goal.toml" (study files only)', "samples": "1000",
              "seed": "1", "batch_size": "1000",
              "parameters": '{ "springs.left.k" = { from = 2.0, to = 6.0, steps = 9 } }',
              "metrics": '{ peak = "max(abs(input_force.crank))" }'},
    "optimize": {"minimize": '"peak_handle" (a [study.metrics] name, or two: a Pareto set)',
                 "parameters": '{ "springs.left.k" = [0.0, 5000.0] }',
                 "tie": '{ "springs.right.k" = "springs.left.k" }',
                 "constraints": '["hold_open <= 0"]', "seed": "1",
                 "population": "60", "generations": "300", "tol": "1e-4"},
    "measurements": {"name": '"cylinder_force"', "log": '"run3.p_force"', "scale": "1.0",
                     "offset": "0.0",
                     "of": '"input_force.boom_cylinder"', "sigma": "50.0",
                     "alarm": "3.0 (follow: a residual beyond 3 sigma is an alarm)"},
    "drivers.input": {"point": '"H"', "direction": "[0.0, 1.0]", "link": '"handle"'},
    "solver": {"tol": "1e-12", "max_iter": "25", "jacobian": '"analytic"',
               "derivatives": '"linear"', "predictor": '"first"', "method": '"auto"',
               "singular_rcond": "1e-6", "linear_algebra": '"auto"',
               "rate_residuals": "true",
               "friction_velocity_scale": "1e-6 (length units per second)"},
    "analysis": {"effects": '["springs", "gravity"]'},
    "gravity": {"g": "[0.0, -9.81]"},
    "springs": {"name": '"left"', "between": '["S1", "S2"]', "k": "4.0",
                "free_length": "0.5", "preload": "10.0", "damping": "0.0",
                "kind": '"linear"', "force_extended": "450.0", "extended_length": "0.50",
                "dead_length": "0.20", "gamma": "1.0", "compressed_length": "0.30"},
    "torsion_springs": {"name": '"hinge"', "links": '["boom", "arm"]', "k": "2.5",
                        "free_angle": "30.0"},
    "masses": {"link": '"coupler"', "mass": "1.0", "center": '"G" (or [u, v] in the link frame)',
               "inertia": "0.0"},
    "loads": {"name": '"cut"', "point": '"C"', "force": "[0.0, 500.0]", "link": '"rocker"',
              "torque": "-2.0"},
    "outputs": {"kinematics": '["velocity", "acceleration"]', "trace": '["P"]',
                "vectors": '["P"]'},
    "friction": {"name": '"pins"', "joints": '["A", "B"]', "slider": '"guide"',
                 "driver": '"boom_cylinder"', "mu": "0.12", "pin_radius": "0.008",
                 "viscous": "0.0", "coulomb": "800.0",
                 "stribeck": "{ peak = 1200.0, velocity = 0.01 }"},
    "friction.stribeck": {"peak": "1200.0", "velocity": "0.01"},
}

#: What each effect needs in the file: effect -> the tables that must be present (a tuple
#: among them: one of those tables).
EFFECT_NEEDS = {
    "springs": (("springs", "torsion_springs"),),
    "gravity": ("gravity", "masses"),
    "inertia": ("masses",),
    "loads": ("loads",),
    "damping": ("springs",),
    "friction": ("friction",),
}

_REQUIRED = object()  # default of a key that must be given


#: the largest magnitude of a coordinate or length: its square, and products of two, stay far
#: inside double precision (1e308); any unit system for a real machine fits (nm to light years)
MAX_MAGNITUDE = 1e100

_TYPE_NAMES = ((bool, "a boolean"), (int, "an integer"), (float, "a float"), (str, "a string"),
               (list, "an array"), (dict, "a table"))  # bool before int: a bool is an int


def _type_name(value) -> str:
    """Name a TOML value's type as a user reads it: "a string", "a boolean", ..."""
    return next((name for kind, name in _TYPE_NAMES if isinstance(value, kind)), "a date/time")


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


#: words users write for a key, and the key they mean (a closest-spelling hint would miss them)
SYNONYMS = {"rpm": "rate", "speed": "rate", "omega": "rate", "velocity": "rate",
            "angular_velocity": "rate", "angular_speed": "rate", "alpha": "acceleration",
            "angular_acceleration": "acceleration", "accel": "acceleration"}

#: a length driver's (distance, coordinate) examples in place of the angle's degrees
LENGTH_DRIVER_EXAMPLES = {"from": "1.2", "to": "1.65", "steps": "46", "step": "0.01"}

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
                meant = SYNONYMS.get(str(key).lower())
                hint = (f'did you mean "{meant}"? ({self.example(meant)})'
                        if meant in self.examples else _suggest(key, self.examples))
                raise self.error(key, "unknown key", hint)

    def error(self, key: str | None, message: str, hint: str = "") -> SceneError:
        return SceneError(self.path, self.label, key, message, hint)

    def example(self, key: str) -> str:
        return f"{key} = {self.examples[key]}"

    def as_given(self, key: str) -> str:
        """``key = <the value the file gives>``, for a message about keys given together."""
        return f"{key} = {_show(self.data[key])}"

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

    def too_large(self, key: str, value) -> SceneError:
        return self.error(key, f"{_show(value)} is beyond {MAX_MAGNITUDE:g}: coordinates and "
                          "lengths are squared, which overflows double precision",
                          "choose a length unit that brings the mechanism's size nearer 1")

    def number(self, key: str, default=_REQUIRED, geometric: bool = False) -> float | None:
        """A finite number (an integer is accepted) as a float; ``geometric``: a coordinate or
        length, whose magnitude must stay within :data:`MAX_MAGNITUDE` (it gets squared)."""
        if not self._present(key, default):
            return default
        value = self.data[key]
        if not _is_number(value):
            raise self.wrong_type(key, "a number")
        if not math.isfinite(value):
            raise self.error(key, f"must be a finite number, got {_show(value)}",
                             f"write e.g. {self.example(key)}")
        if geometric and abs(value) > MAX_MAGNITUDE:
            raise self.too_large(key, value)
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

    def pair(self, key: str, default=_REQUIRED, nonzero: bool = False, geometric: bool = True):
        """Two finite numbers ``[a, b]`` as a tuple of floats; ``nonzero``: not ``[0, 0]``;
        ``geometric`` (coordinates, directions): magnitudes within :data:`MAX_MAGNITUDE`."""
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
        if geometric and max(abs(result[0]), abs(result[1])) > MAX_MAGNITUDE:
            raise self.too_large(key, value)
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

    def exactly_one(self, keys: tuple[str, ...]) -> str:
        """Which one of several exclusive keys is given; raise when none or more than one is."""
        given = [k for k in keys if self.has(k)]
        listed = ", ".join(keys[:-1]) + f" or {keys[-1]}"
        if len(given) > 1:
            raise self.error(given[1], f"give one of {listed}, not both {' and '.join(given)}",
                             f"keep one of {' or '.join(self.as_given(k) for k in given)}")
        if not given:
            raise self.error(keys[0], f"missing: give {listed}",
                             "add " + " or ".join(self.example(k) for k in keys))
        return given[0]

    def one_of(self, first: str, second: str) -> str:
        """Which of two exclusive keys is given; raise when neither or both are."""
        if self.has(first) and self.has(second):
            raise self.error(second, f"give {first} or {second}, not both",
                             f"keep one of {self.as_given(first)} or {self.as_given(second)}")
        if not (self.has(first) or self.has(second)):
            raise self.error(first, f"missing: give {first} or {second}",
                             f"add {self.example(first)} or {self.example(second)}")
        return first if self.has(first) else second


