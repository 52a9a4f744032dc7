"""Scenes: TOML -> frozen :class:`Scene` dataclasses, every check that needs only the text.

:mod:`.tables` the dataclasses; :mod:`.keys` the keys of every table and how one table is read;
:mod:`.parse` the reader (with :mod:`.geometry`, :mod:`.motion` and :mod:`.springs` for its
table readers).
"""
from .parse import load_scene, parse_scene
from .tables import (EFFECTS, KINEMATIC_ORDERS, SOLVER_CHOICES, Driver, Input, Link, Load, Mass,
                     Outputs, Point, Scene, Slider, Solver, Spring, TorsionSpring)

__all__ = ["load_scene", "parse_scene", "Scene", "Point", "Link", "Slider", "Input", "Driver",
           "Solver", "Spring", "TorsionSpring", "Mass", "Load", "Outputs", "EFFECTS", "KINEMATIC_ORDERS",
           "SOLVER_CHOICES"]
