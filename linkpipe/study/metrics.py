"""The metrics of a batch of variants, from their arrays with a leading variant axis.

Every reduction runs over the steps whose status is ok (the others are NaN first), for all
variants of a batch at once. What a batch hands over (:class:`BatchArrays`): ``status``
(V, S) int8, ``input_force`` (V, S, n_drivers) or None when the scene computes no forces,
``position`` (V, S, n_points, 2) and ``series`` {(variable, index): (V, S)} of what the named
metrics read.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..status import OK
from . import reductions


@dataclass
class BatchArrays:
    status: np.ndarray
    input_force: np.ndarray | None
    position: np.ndarray
    series: dict


def transmission_pins(scene) -> list[tuple[int, int, int]]:
    """``(pin, other1, other2)`` point indices: each point where two moving links meet that
    no angle driver turns, with each link's other frame point. The transmission angle there
    is the angle between ``other1 - pin`` and ``other2 - pin`` (a four-bar's coupler and
    rocker at their joint)."""
    index = {n: i for i, n in enumerate(scene.point_names)}
    fixed = {p.name for p in scene.points if p.fixed}
    driven = {frozenset(d.points) for d in scene.drivers if d.kind == "angle" and len(d.points) == 2}
    links = [l for l in scene.links
             if not set(l.points) <= fixed and not any(dp <= set(l.points) for dp in driven)]
    out = []
    for name in scene.point_names:
        if name in fixed:
            continue
        at = [l for l in links if name in l.points]
        for a in range(len(at)):
            for b in range(a + 1, len(at)):
                others = [next(p for p in l.points if p != name) for l in (at[a], at[b])]
                out.append((index[name], index[others[0]], index[others[1]]))
    return out


def min_transmission_angle(position: np.ndarray, ok: np.ndarray, pins) -> np.ndarray:
    """(V,) degrees: the smallest over the pins and the ok steps of ``min(mu, 180 - mu)``, mu
    the angle at the pin between its two links (90 is ideal; NaN with no pin or no ok step)."""
    V = position.shape[0]
    if not pins:
        return np.full(V, np.nan)
    p, a, b = (np.array(c) for c in zip(*pins))
    u = position[:, :, a] - position[:, :, p]  # (V, S, n_pins, 2)
    w = position[:, :, b] - position[:, :, p]
    mu = np.degrees(np.arctan2(np.abs(u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]),
                               u[..., 0] * w[..., 0] + u[..., 1] * w[..., 1]))
    dev = np.minimum(mu, 180.0 - mu).min(axis=2)
    dev = np.where(ok, dev, np.inf).min(axis=1)
    return np.where(np.isfinite(dev), dev, np.nan)


def batch_metrics(study, arrays: BatchArrays, pins) -> dict[str, np.ndarray]:
    """The study file's rows for one batch: {variable: (V, ...)} (see the output contract)."""
    status = arrays.status
    V, S = status.shape
    ok = status == OK
    D = len(study.driver_names)
    out = {}
    if arrays.input_force is not None:
        f = np.where(ok[:, :, None], arrays.input_force, np.nan)
        per_driver = f.transpose(0, 2, 1).reshape(V * D, S)  # one row per (variant, driver)
        for name, how in (("peak_input_force", "max"), ("rms_input_force", "rms")):
            x = np.abs(per_driver) if how == "max" else per_driver
            out[name] = reductions.reduce_steps(how, x, None).reshape(V, D)
        out["input_force_range"] = (reductions.reduce_steps("max", per_driver, None)
                                    - reductions.reduce_steps("min", per_driver, None)).reshape(V, D)
    else:
        for name in ("peak_input_force", "rms_input_force", "input_force_range"):
            out[name] = np.full((V, D), np.nan)
    out["min_transmission_angle"] = min_transmission_angle(arrays.position, ok, pins)
    out["worst_status"] = status.max(axis=1).astype(np.int8)
    failed = ~ok
    out["first_failed_step"] = np.where(failed.any(axis=1), failed.argmax(axis=1), -1).astype(np.int32)

    def series(var, index):
        return np.where(ok, arrays.series[(var, index)], np.nan)

    for m in study.metrics:
        out[m.name] = np.broadcast_to(reductions.evaluate(m.tree, series, failed),
                                      (V,)).astype(float)
    return out
