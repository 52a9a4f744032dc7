"""Stroke limits (version 3): how far each actuator and gas spring is from the nearer end of
its stroke, and the steps where one is outside it (status ``out_of_stroke``).

An actuator's stroke is its driver's ``stroke = [shortest, longest]`` (driver units: degrees
for an angle); a gas spring's runs from ``compressed_length`` (where given) to
``extended_length`` (with the ``springs`` effect on). ``stroke_margin`` (S, n_strokes) is the
distance to the nearer end, negative outside. A step counts as outside only beyond the
position tolerance (a strut driven exactly to its extended length stays in).
"""
from __future__ import annotations

import numpy as np

from .status import OK, OUT_OF_STROKE


def names(scene) -> list[str]:
    """The ``stroke`` dimension's labels: drivers with a stroke, then gas springs."""
    return ([d.name for d in scene.drivers if d.stroke is not None]
            + [s.name for s in _gas_springs(scene)])


def _gas_springs(scene):
    return [s for s in scene.springs if s.kind == "gas"] if "springs" in scene.effects else []


def margins(scene, driver_value: np.ndarray, position: np.ndarray,
            extended_length: np.ndarray | None = None) -> np.ndarray | None:
    """(S, n_strokes) each stroke's margin, or None where the scene gives none.

    ``driver_value`` (S, nd) in scene units, ``position`` (S, P, 2); ``extended_length``
    (S, n_springs) per row where a study varies it (else each spring's own)."""
    labels = names(scene)
    if not labels:
        return None
    out = np.empty((position.shape[0], len(labels)))
    c = 0
    for j, d in enumerate(scene.drivers):
        if d.stroke is not None:
            value = driver_value[:, j]
            out[:, c] = np.minimum(value - d.stroke[0], d.stroke[1] - value)
            c += 1
    points = scene.point_names
    for sp in _gas_springs(scene):
        a, b = (points.index(p) for p in sp.between)
        length = np.hypot(*(position[:, b] - position[:, a]).T)
        longest = sp.extended_length
        if extended_length is not None:
            longest = np.broadcast_to(extended_length, (position.shape[0], len(scene.springs))
                                      )[:, scene.springs.index(sp)]
        margin = longest - length
        if sp.compressed_length is not None:
            margin = np.minimum(margin, length - sp.compressed_length)
        out[:, c] = margin
        c += 1
    return out


def units(scene, length_unit: str) -> list[str]:
    """Each stroke's unit: degrees for an angle driver, else the scene's length."""
    return ([("degree" if d.is_angle else length_unit) for d in scene.drivers
             if d.stroke is not None] + [length_unit] * len(_gas_springs(scene)))


def status(model, margin: np.ndarray | None, size=None) -> np.ndarray | None:
    """(S,) int8: ``out_of_stroke`` where some margin is below minus the position tolerance
    (an angle's in degrees: the tolerance over the mechanism's size), else ok; None without
    strokes. NaN margins (failed steps) are not judged here."""
    if margin is None:
        return None
    with np.errstate(invalid="ignore"):
        outside = (margin < -allowance(model, margin.shape, size)).any(axis=1)
    return np.where(outside, OUT_OF_STROKE, OK).astype(np.int8)


def allowance(model, shape: tuple[int, int], size=None) -> np.ndarray:
    """(S, n_strokes) how far beyond its end a stroke may be before the step is outside it:
    the position tolerance (an angle's in degrees: the tolerance over the mechanism's size);
    ``shape`` the margins' (S, n_strokes), ``size`` per row where a study varies it. The one
    place the decision is made: :func:`status` and forward dynamics' stroke events use it."""
    tol = np.asarray(model.tolerance(size=size), float)
    length_tol = np.broadcast_to(tol, (shape[0],))[:, None]
    size = np.broadcast_to(np.asarray(model.size if size is None else size, float),
                           (shape[0],))[:, None]
    scene = model.scene
    angle = np.array([d.is_angle for d in scene.drivers if d.stroke is not None]
                     + [False] * (shape[1] - sum(d.stroke is not None for d in scene.drivers)))
    return np.where(angle, np.degrees(length_tol / size), length_tol)
