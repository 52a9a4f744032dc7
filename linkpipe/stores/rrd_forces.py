"""The recording's force arrows: ``mechanism/forces/<kind>/<name>``, one scale per recording.

Only a scene with a force stage gets them (a kinematics-only scene computes no force, so none is
drawn). Each arrow starts where its force acts, at every step, from the stored variables:

* ``input``: the actuator's force at its ``input`` point along its direction (turning with
  ``input.link``); without ``input``, a cylinder's axial force at both pins (pushing them apart
  when positive), a coordinate driver's force at its point, and a motor's torque as the
  equivalent force at the head of the driven vector (perpendicular to it, torque / length);
* ``loads``: each force load at its point (couples are not arrows);
* ``springs``: each spring's force on its two ends (a tension pulls them together);
* ``reactions``: the force the ground exerts at each fixed point.

The scale makes the longest arrow of the sweep :data:`FORCE_FRACTION` of the mechanism's size;
the 2D view's title says what one length unit stands for (``forces: 1 m = 250 N``).
"""
from __future__ import annotations

import numpy as np

from ..forces.virtual_work import input_direction

#: longest force arrow, as a fraction of the mechanism's size
FORCE_FRACTION = 0.3
KIND_COLORS = {"input": [230, 50, 50], "loads": [255, 150, 20], "springs": [240, 210, 60],
               "reactions": [70, 150, 255]}


def force_arrows(result) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """Return [(kind, name, origins (S, k, 2), forces (S, k, 2))] in force units."""
    forces = result.forces or {}
    if "input_force" not in forces:
        return []
    X = result.position
    idx = {n: i for i, n in enumerate(result.point_names)}
    out = []
    F_in = forces["input_force"][1]
    for j, driver in enumerate(result.scene.drivers):
        out.append(("input", driver.name, *_input_arrows(result, j, driver, F_in[:, j], X, idx)))
    for load in result.scene.loads:
        if load.point is not None and load.force is not None:
            origin = X[:, idx[load.point]][:, None]
            vector = np.broadcast_to(np.asarray(load.force, float), origin.shape).copy()
            vector[~np.isfinite(origin).all(axis=2)] = np.nan
            out.append(("loads", load.name, origin, vector))
    if "spring_force" in forces:
        T = forces["spring_force"][1]
        for k, spring in enumerate(result.scene.springs):
            a, b = X[:, idx[spring.between[0]]], X[:, idx[spring.between[1]]]
            u = _unit(b - a)
            out.append(("springs", spring.name, np.stack([a, b], axis=1),
                        np.stack([T[:, k, None] * u, -T[:, k, None] * u], axis=1)))
    if "ground_reaction" in forces:
        R = forces["ground_reaction"][1]
        for k, name in enumerate(result.force_coords.get("fixed_point", [])):
            out.append(("reactions", name, X[:, idx[name]][:, None], R[:, k][:, None]))
    return out


def _input_arrows(result, j, driver, F, X, idx):
    """Origins and forces (S, k, 2) of driver j's input force F (S,)."""
    if driver.input is not None:
        origin = X[:, idx[driver.input.point]]
        n = input_direction(result.model, driver.input, np.where(np.isfinite(X), X, 0.0))
        return origin[:, None], (F[:, None] * n)[:, None]
    a = X[:, idx[driver.points[0]]]
    if driver.kind == "coordinate":
        axis = np.zeros((1, 2))
        axis[0, driver.axis] = 1.0
        return a[:, None], (F[:, None] * axis)[:, None]
    b = X[:, idx[driver.points[1]]]
    d = b - a
    if driver.kind == "distance":
        u = _unit(d)
        return np.stack([a, b], axis=1), np.stack([-F[:, None] * u, F[:, None] * u], axis=1)
    # a torque tau at b: the force tau / |d| perpendicular to d (counter-clockwise positive)
    length = np.hypot(d[:, 0], d[:, 1])
    perp = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.where(length > 0, length, np.nan)[:, None]
    return b[:, None], (F / np.where(length > 0, length, np.nan))[:, None, None] * perp[:, None]


def _unit(d: np.ndarray) -> np.ndarray:
    length = np.hypot(d[:, 0], d[:, 1])
    return d / np.where(length > 0, length, np.nan)[:, None]


def force_scale(result, arrows, size: float) -> float:
    """Length units per force unit: the sweep's longest arrow is FORCE_FRACTION of ``size``."""
    biggest = 0.0
    for _, _, _, vectors in arrows:
        norm = np.hypot(vectors[..., 0], vectors[..., 1])
        if np.isfinite(norm).any():
            biggest = max(biggest, float(np.nanmax(norm)))
    return FORCE_FRACTION * size / biggest if biggest > 0 else 0.0


def force_legend(result, scale: float) -> str:
    """``"forces: 1 m = 250 N"``: what one length unit of the force arrows stands for."""
    units = result.units()
    return f"forces: 1 {units['length']} = {1 / scale:.3g} {units['force']}"
