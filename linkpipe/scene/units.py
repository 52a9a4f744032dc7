"""Driver rates written with a unit, gravity checked against the scene's length unit, and the
scene's units checked for consistency (force = mass x length / time^2).

linkpipe does no unit conversion of the scene as a whole (``[scene].units`` is metadata); a
driver's ``rate`` and ``acceleration`` alone may carry a unit, because a speed is so often
quoted in one (``"120 rpm"``, ``"12.57 rad/s"``, ``"720 deg/s"``, ``"50 mm/s"``): the string is
turned here into the number v1 means (degrees per second for an angle; the scene's length unit
per second for a length), once, at load. A small table of factors, no units library.
"""
from __future__ import annotations

import math
import re

#: an angle rate's units in degrees per second (rate) or per second squared (acceleration)
ANGLE_RATE = {"deg/s": 1.0, "rad/s": 180.0 / math.pi, "rpm": 6.0, "rev/min": 6.0, "rev/s": 360.0}
ANGLE_ACCELERATION = {"deg/s^2": 1.0, "rad/s^2": 180.0 / math.pi, "rev/s^2": 360.0}
#: lengths in metres, for a length rate's unit against the scene's ``units.length``
LENGTH_M = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "km": 1e3, "in": 0.0254, "ft": 0.3048}
#: standard gravity in each length unit per s^2
STANDARD_GRAVITY_M = 9.80665

_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z/^²2\s]+?)\s*$")


def _normal(unit: str) -> str:
    """'deg / s²' -> 'deg/s^2'; 'mm/s2' -> 'mm/s^2'."""
    unit = unit.replace(" ", "").replace("²", "^2")
    return unit[:-1] + "^2" if unit.endswith("/s2") else unit


def accepted(kind: str, order: int) -> list[str]:
    """The units a driver of ``kind`` ("angle" or a length kind) accepts for its rate (order 1)
    or acceleration (order 2)."""
    if kind == "angle":
        return list(ANGLE_RATE if order == 1 else ANGLE_ACCELERATION)
    suffix = "/s" if order == 1 else "/s^2"
    return [u + suffix for u in LENGTH_M]


def convert(text: str, kind: str, order: int, length_unit: str | None) -> float:
    """Return the value of ``text`` ("<number> <unit>") in the driver's own units per second
    (order 1) or per second squared (order 2). Raises ValueError with the reason (the caller
    names the file, table and key)."""
    match = _QUANTITY.match(text)
    if not match:
        raise ValueError(f'"{text}" is not a number with a unit')
    value, unit = float(match.group(1)), _normal(match.group(2))
    if kind == "angle":
        table = ANGLE_RATE if order == 1 else ANGLE_ACCELERATION
        if unit not in table:
            raise ValueError(f'unit "{match.group(2).strip()}" does not fit an angle driver')
        return value * table[unit]
    suffix = "/s" if order == 1 else "/s^2"
    if not unit.endswith(suffix) or unit[:-len(suffix)] not in LENGTH_M:
        raise ValueError(f'unit "{match.group(2).strip()}" does not fit a {kind} driver '
                         f"(a length per second{'' if order == 1 else ' squared'})")
    if length_unit not in LENGTH_M:
        raise ValueError(f"[scene].units.length is {_quote(length_unit)}, not a length unit "
                         "linkpipe can convert to")
    return value * LENGTH_M[unit[:-len(suffix)]] / LENGTH_M[length_unit]


def _quote(unit) -> str:
    return "not given" if unit is None else f'"{unit}"'


#: masses in kilograms, times in seconds and forces in newtons, for the consistency check
MASS_KG = {"kg": 1.0, "g": 1e-3, "t": 1e3, "tonne": 1e3, "Mg": 1e3, "lb": 0.45359237,
           "lbm": 0.45359237, "slug": 14.593902937206364, "lbf*s^2/in": 175.12683524647636}
TIME_S = {"s": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0}
FORCE_N = {"N": 1.0, "mN": 1e-3, "kN": 1e3, "MN": 1e6, "lbf": 4.4482216152605,
           "kgf": 9.80665, "kip": 4448.2216152605}


def consistency_warning(units: dict) -> str:
    """A warning when the scene's declared mass, length, time and force units (all known to
    the tables above) are not one consistent system: linkpipe computes m a and weights in the
    scene's own numbers, so their forces come out in mass x length / time^2 whatever
    ``force`` says (kg, mm, s and "N": m a in mN, labelled N). "" when consistent or unknown."""
    try:
        mass, length = MASS_KG[units["mass"]], LENGTH_M[units["length"]]
        time, force = TIME_S[units.get("time", "s")], FORCE_N[units["force"]]
    except KeyError:
        return ""
    implied = mass * length / time ** 2  # newtons per unit of m a in these units
    if abs(implied / force - 1) <= 1e-3:
        return ""
    u = {k: units.get(k, "s") for k in ("mass", "length", "time", "force")}
    combo = f"{u['mass']}*{u['length']}/{u['time']}^2"
    fits = [name for name, n in FORCE_N.items() if abs(implied / n - 1) <= 1e-3]
    masses = [name for name, kg in MASS_KG.items()
              if abs(kg * length / time ** 2 / force - 1) <= 1e-3]
    fix = " or ".join([f'force = "{f}"' for f in fits[:1]] + [f'mass = "{m}"' for m in masses[:1]])
    return (f"[scene].units: {combo} is {implied / force:.6g} {u['force']}, not 1 "
            f"{u['force']}: masses times accelerations (inertia, weights) come out in {combo} "
            f"while springs and loads are in the numbers as written, labelled {u['force']}"
            + (f"; declare {fix} for one consistent system" if fix else ""))


def gravity_warning(g: tuple[float, float], length_unit: str | None) -> str:
    """A warning when |g| is standard gravity in another length unit than the scene's (9.81 in
    a millimetre scene is 1000x too weak), else ""."""
    magnitude = math.hypot(*g)
    if length_unit not in LENGTH_M or magnitude == 0:
        return ""
    expected = STANDARD_GRAVITY_M / LENGTH_M[length_unit]
    if abs(magnitude / expected - 1) <= 0.05:
        return ""
    for unit, metres in LENGTH_M.items():
        if abs(magnitude / (STANDARD_GRAVITY_M / metres) - 1) <= 0.05:
            return (f"[gravity] g has magnitude {magnitude:g}, standard gravity in {unit}/s^2, but "
                    f'[scene].units.length is "{length_unit}": in {length_unit}/s^2 it is '
                    f"{expected:.6g} (the weights come out {magnitude / expected:.3g} times "
                    f"Earth's)")
    return ""


#: a log column's units (``[[logs]] units``): quantity and SI value of one unit (radians for
#: angles, pascals for pressures); each of them also per s and per s^2 (``"mm/s"``, ``"deg/s^2"``)
COLUMN_UNITS = {
    **{u: ("length", m) for u, m in (("m", 1.0), ("cm", 1e-2), ("mm", 1e-3), ("um", 1e-6),
                                      ("µm", 1e-6), ("km", 1e3), ("in", 0.0254), ("ft", 0.3048))},
    "deg": ("angle", math.pi / 180.0), "rad": ("angle", 1.0), "rev": ("angle", 2.0 * math.pi),
    "s": ("time", 1.0), "ms": ("time", 1e-3), "min": ("time", 60.0),
    "N": ("force", 1.0), "kN": ("force", 1e3), "mN": ("force", 1e-3),
    "lbf": ("force", FORCE_N["lbf"]),
    "Pa": ("pressure", 1.0), "kPa": ("pressure", 1e3), "MPa": ("pressure", 1e6),
    "bar": ("pressure", 1e5), "psi": ("pressure", 6894.757293168361),
}
#: rates written as one word
COLUMN_RATES = {"rpm": ("angle", 1, 2.0 * math.pi / 60.0)}


def column_unit(text: str) -> tuple[str, int, float]:
    """``(quantity, order, SI value)`` of a log column's unit: "mm" -> ("length", 0, 1e-3),
    "deg/s" -> ("angle", 1, pi/180), "bar" -> ("pressure", 0, 1e5). ValueError naming the
    known units otherwise."""
    unit = _normal(str(text))
    if unit in COLUMN_RATES:
        return COLUMN_RATES[unit]
    base, order = unit, 0
    for suffix, n in (("/s^2", 2), ("/s", 1)):
        if unit.endswith(suffix) and unit[:-len(suffix)] in COLUMN_UNITS:
            base, order = unit[:-len(suffix)], n
            break
    if base not in COLUMN_UNITS or (order and COLUMN_UNITS[base][0] == "time"):
        known = ", ".join(list(COLUMN_UNITS)[:-1])
        raise ValueError(f'unknown unit "{text}" (known: {known}, psi, rpm; each of them per s '
                         'and per s^2, e.g. "mm/s", "deg/s^2")')
    quantity, si = COLUMN_UNITS[base]
    return quantity, order, si


def scene_unit_si(quantity: str, order: int, scene_units: dict, angle: str = "deg") -> float:
    """The SI value of one scene unit of ``quantity`` per time^``order`` (the scene's
    ``[scene].units``; angles in ``angle``, "deg" or "rad"; a pressure in force per length^2).
    ValueError naming the ``[scene].units`` key it needs but does not have or know."""
    def need(key: str, table: dict) -> float:
        unit = scene_units.get(key, "s" if key == "time" else None)
        if unit not in table:
            raise ValueError(f"[scene].units.{key} is {_quote(unit)}, not a unit linkpipe can "
                             f"convert to (known: {', '.join(table)})")
        return table[unit]

    if quantity == "length":
        base = need("length", LENGTH_M)
    elif quantity == "angle":
        base = math.pi / 180.0 if angle == "deg" else 1.0
    elif quantity == "time":
        base = need("time", TIME_S)
    elif quantity == "force":
        base = need("force", FORCE_N)
    else:  # pressure: the scene's force per its length squared
        base = need("force", FORCE_N) / need("length", LENGTH_M) ** 2
    return base / need("time", TIME_S) ** order if order else base
