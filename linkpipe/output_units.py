"""The units of what linkpipe writes, from a scene's ``units`` (free text): each variable's,
each driver's, measurement's, parameter's and metric's entry, and the one "shared unit, else
mixed" rule. Pure functions of the scene; :class:`linkpipe.result.Result` and the stores use
them."""
from __future__ import annotations

from .scene import Scene


def common_unit(units: list[str]) -> str:
    """The one unit of a variable whose entries (drivers, measurements) share it, else
    ``"mixed"`` (each entry's own unit then goes in an attribute beside it)."""
    return units[0] if len(set(units)) == 1 else "mixed"


def driver_units_of(scene: Scene) -> list[str]:
    """Each driver's value unit: degree for an angle, the scene's length for a distance."""
    L = units_of(scene)["length"]
    return ["degree" if d.kind == "angle" else L for d in scene.drivers]


def input_force_units(drivers, units: dict) -> list[str]:
    """Each driver's input force unit: a generalized force, force*length for an angle driver
    (a torque), force for a length driver or for any driver with an ``input`` point (the force
    along its direction). ``units``: the scene's (:func:`units_of`)."""
    force_unit, length_unit = units["force"], units["length"]
    return [f"{force_unit}*{length_unit}" if d.kind == "angle" and d.input is None else force_unit
            for d in drivers]


def measured_units(scene: Scene) -> list[str]:
    """Each ``[[measurements]]`` entry's unit: that of the stored entry its ``of`` names (a
    driver's own unit where drivers differ). ``tests/test_measurements.py`` proves it equal to
    the unit :meth:`Result.variables` writes for every measurable variable."""
    return [entry_unit(scene, m.of[0], m.of[1]) for m in scene.measurements]


def entry_unit(scene: Scene, variable: str, label: str | None = None) -> str:
    """The unit of one stored entry, ``variable`` at ``label`` (a driver's, point's, spring's
    name); "" for a variable this table does not know."""
    u = units_of(scene)
    L, T, F = u["length"], u["time"], u["force"]
    names = [d.name for d in scene.drivers]
    per_driver = {"driver_value": driver_units_of(scene),
                  "input_force": input_force_units(scene.drivers, u)}
    per_driver["input_force_lagrange"] = per_driver["input_force"]
    per_driver["driver_velocity"] = [f"{d}/{T}" for d in per_driver["driver_value"]]
    per_driver["driver_acceleration"] = [f"{d}/{T}^2" for d in per_driver["driver_value"]]
    whole = {"position": L, "velocity": f"{L}/{T}", "acceleration": f"{L}/{T}^2",
             "link_angle": "rad", "link_angular_velocity": f"rad/{T}",
             "link_angular_acceleration": f"rad/{T}^2",
             "spring_length": L, "spring_extension": L, "spring_energy": f"{F}*{L}",
             "torsion_spring_angle": "rad", "torsion_spring_torque": f"{F}*{L}",
             "torsion_spring_energy": f"{F}*{L}", "link_force": F, "spring_force": F,
             "slider_force": F, "joint_force": F, "ground_reaction": F,
             "spring_damping_force": F, "gravity_energy": f"{F}*{L}",
             "power": f"{F}*{L}/{T}", "residual": L, "condition": "1", "iterations": "1"}
    if variable in per_driver and label in names:
        return per_driver[variable][names.index(label)]
    frictions = [fr.name for fr in scene.friction]
    if variable == "friction_force" and label in frictions:  # a torque at pins, else a force
        return friction_units(scene, u)[frictions.index(label)]
    if variable == "friction_power":
        return f"{F}*{L}/{T}"
    return whole.get(variable, "")


def parameter_unit(scene: Scene, path: tuple) -> str:
    """The unit of the number at ``path`` in the scene's TOML data (a fitted or studied
    parameter: ``("springs", 0, "k")``, ``("points", "S1", "y")``), from the scene's units;
    "1" for a pure number, "" where the key has no fixed unit."""
    u = units_of(scene)
    L, T, F, M = u["length"], u["time"], u["force"], u["mass"]
    keys = [p for p in path if isinstance(p, str)]
    table, key = keys[0], keys[-1]
    if table == "drivers" and isinstance(path[1], int):
        d = driver_units_of(scene)[path[1]] if path[1] < len(scene.drivers) else ""
        return {"from": d, "to": d, "step": d, "rate": f"{d}/{T}",
                "acceleration": f"{d}/{T}^2", "offset": d}.get(key, "")
    if table == "measurements" and isinstance(path[1], int):
        m = measured_units(scene)[path[1]] if path[1] < len(scene.measurements) else ""
        return {"offset": m, "sigma": m}.get(key, "")
    if table == "logs":
        return {"lag": "s", "time_scale": "s"}.get(key, "")
    if table == "torsion_springs":
        return {"k": f"{F}*{L}/rad", "free_angle": "degree"}.get(key, "")
    if (table == "points" or "lengths" in keys or "local" in keys or "sides" in keys
            or "through" in keys):
        return L
    return {"k": f"{F}/{L}", "free_length": L, "extended_length": L, "dead_length": L,
            "preload": F, "force_extended": F, "force": F, "gamma": "1", "damping": f"{F}*{T}/{L}",
            "mass": M, "inertia": f"{M}*{L}^2", "center": L, "torque": f"{F}*{L}",
            "g": f"{L}/{T}^2", "direction": "1"}.get(key, "")


def parameter_units(scene: Scene, parameters) -> list[str]:
    """The unit of each fitted or studied parameter (objects with a ``path``)."""
    return [parameter_unit(scene, p.path) for p in parameters]


def entry_units(var) -> list[str]:
    """The unit of each entry along a :class:`~linkpipe.result.Variable`'s second dimension: its ``<dimension>_units``
    attribute (``driver_units``, ``measurement_units``) where the entries may differ, else the
    variable's one unit for every entry."""
    per = var.attrs.get(f"{var.dims[1]}_units") if len(var.dims) > 1 else None
    return per.split(",") if per else [var.units] * var.data.shape[1]


def friction_units(scene: Scene, units: dict) -> list[str]:
    """Each ``[[friction]]`` entry's ``friction_force`` unit: a torque for pins and for an angle
    driver's seal, else a force."""
    torque = f"{units['force']}*{units['length']}"
    angles = {d.name for d in scene.drivers if d.kind == "angle"}
    return [torque if fr.kind == "pins" or fr.driver in angles else units["force"]
            for fr in scene.friction]


def units_of(scene: Scene) -> dict[str, str]:
    """Unit strings of a scene (free text), with neutral defaults: length, time, force, mass."""
    u = dict(scene.units)
    return {"length": u.get("length", "length"), "time": u.get("time", "s"),
            "force": u.get("force", "force"), "mass": u.get("mass", "mass")}
