"""The numbers of a scene's force tables as arrays, optionally one row per step.

A scene's own constants have no step axis (``ForceConstants.of``). A study that varies only
these numbers (and anchor points no constraint uses) solves stage 1 once and puts its variants
on one long step axis (variant, step): each constant then has a leading step axis, one row per
(variant, step), and every effect broadcasts it like the positions (``linkpipe.study.vector``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def start_assembled(model) -> np.ndarray:
    """The start configuration a spring's start length is measured on (n_points, 2): the
    drawing assembled at its own driver values where it assembles there (its points may be a
    guess), else the drawing."""
    from ..kinematics.drawing import assembled_drawing

    X = assembled_drawing(model)
    return model.start_position if X is None else X


@dataclass(frozen=True)
class ForceConstants:
    """``spring_k``, ``spring_free_length`` (NaN where the scene gives none: the start length),
    ``spring_preload`` (NaN where none), ``spring_damping``: (n_springs,) or (S, n_springs);
    ``mass``, ``inertia``: (n_masses,) or (S, n_masses); ``gravity`` (2,) or (S, 2) (zeros when
    the scene has none); ``load_force`` (n_loads, 2) or (S, n_loads, 2) (zeros for a couple);
    ``load_torque`` (n_loads,) or (S, n_loads); a gas spring's ``gas_force_extended``,
    ``gas_extended_length``, ``gas_dead_length``, ``gas_gamma`` (n_springs,) or (S, n_springs),
    NaN for the other kinds; ``torsion_k`` and ``torsion_free_angle`` (degrees)
    (n_torsion_springs,) or (S, n_torsion_springs);
    ``start_position`` (n_points, 2) or
    (S, n_points, 2), the drawn positions; ``start_assembled`` the same shape, the drawing
    assembled at its own driver values (:func:`linkpipe.kinematics.drawing.assembled_drawing`;
    the drawing itself where it does not assemble there): a spring's start length, at which
    its ``preload`` holds; ``size`` the
    mechanism's length scale, a float or (S,) (the leverage an input must have); ``pivots``
    True where the mechanism's own fixed points differ row by row (a study's variants that move
    them: the Jacobian is read off the positions, :func:`linkpipe.kinematics.rates.entries_at`);
    ``model_rows`` the model's rows with their constants per step where a study's variants differ in
    link lengths (:class:`linkpipe.model.equations.Rows` of (S,) arrays; None: the model's own)."""

    spring_k: np.ndarray
    spring_free_length: np.ndarray
    spring_preload: np.ndarray
    spring_damping: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray
    load_force: np.ndarray
    load_torque: np.ndarray
    gas_force_extended: np.ndarray
    gas_extended_length: np.ndarray
    gas_dead_length: np.ndarray
    gas_gamma: np.ndarray
    torsion_k: np.ndarray
    torsion_free_angle: np.ndarray
    start_position: np.ndarray
    start_assembled: np.ndarray
    size: float | np.ndarray
    pivots: bool = False
    model_rows: object = None

    @classmethod
    def of(cls, model) -> "ForceConstants":
        """The scene's own constants (no step axis)."""
        sc = model.scene

        def col(values):
            return np.array([np.nan if x is None else x for x in values], dtype=float)

        return cls(
            spring_k=col(sp.k for sp in sc.springs),
            spring_free_length=col(sp.free_length for sp in sc.springs),
            spring_preload=col(sp.preload for sp in sc.springs),
            spring_damping=col(sp.damping for sp in sc.springs),
            mass=col(m.mass for m in sc.masses), inertia=col(m.inertia for m in sc.masses),
            gravity=np.asarray(sc.gravity if sc.gravity is not None else (0.0, 0.0), dtype=float),
            load_force=np.array([ld.force if ld.point is not None else (0.0, 0.0)
                                 for ld in sc.loads], dtype=float).reshape(-1, 2),
            load_torque=col(ld.torque if ld.point is None else 0.0 for ld in sc.loads),
            **{f"gas_{key}": col(getattr(sp, key) if sp.kind == "gas" else None
                                 for sp in sc.springs)
               for key in ("force_extended", "extended_length", "dead_length", "gamma")},
            torsion_k=col(t.k for t in sc.torsion_springs),
            torsion_free_angle=col(t.free_angle for t in sc.torsion_springs),
            start_position=model.start_position, start_assembled=start_assembled(model),
            size=model.size)

    #: each field's number of axes without a step axis
    BASE_NDIM = {"spring_k": 1, "spring_free_length": 1, "spring_preload": 1,
                 "spring_damping": 1, "mass": 1, "inertia": 1, "gravity": 1, "load_force": 2,
                 "load_torque": 1, "gas_force_extended": 1, "gas_extended_length": 1,
                 "gas_dead_length": 1, "gas_gamma": 1, "torsion_k": 1, "torsion_free_angle": 1,
                 "start_position": 2, "start_assembled": 2,
                 "size": 0}

    def rows(self, steps: slice) -> "ForceConstants":
        """The constants at a slice of the steps (fields without a step axis as they are)."""
        return ForceConstants(pivots=self.pivots,
                              model_rows=None if self.model_rows is None else self.model_rows.take(steps),
                              **{
            name: value[steps] if np.ndim(value) == base + 1 else value
            for name, base in self.BASE_NDIM.items() for value in (getattr(self, name),)})
