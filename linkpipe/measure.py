"""Measured against computed: each ``[[measurements]]`` signal beside the stored variable it
measures, and their difference. Pure numpy on a solved :class:`~linkpipe.result.Result`."""
from __future__ import annotations

import numpy as np

from .output_units import measured_units


def computed_series(result, of: tuple) -> np.ndarray:
    """The computed counterpart (S,) of a measurement's ``of`` = (variable, name, axis), or a
    KeyError naming what the run did not compute."""
    variable, name, axis = of
    found = {v.name: v for v in result.variables()}
    if variable not in found:
        raise KeyError(variable)
    var = found[variable]
    labels = {c.name: list(c.data) for c in result.coordinates()}[var.dims[1]]
    data = var.data[:, labels.index(name)]
    return data if axis is None else data[:, axis]


def compare(result) -> dict | None:
    """Return {names, measured (S, M), residual (S, M) computed - measured, rms (M,), max_abs
    (M,)} over the steps where both are finite (NaN where none), or None without measurements.
    Units: the measured entry's, per measurement (:func:`~linkpipe.output_units.measured_units`)."""
    ms = result.scene.measurements
    if not ms:
        return None
    measured = np.stack([m.values for m in ms], axis=1)
    computed = np.stack([computed_series(result, m.of) for m in ms], axis=1)
    residual = computed - measured
    both = np.isfinite(residual)
    with np.errstate(invalid="ignore"):
        n = both.sum(axis=0)
        rms = np.where(n > 0, np.sqrt((np.where(both, residual, 0.0) ** 2).sum(axis=0)
                                      / np.maximum(n, 1)), np.nan)
        max_abs = np.where(n > 0, np.where(both, np.abs(residual), 0.0).max(axis=0), np.nan)
    return dict(names=[m.name for m in ms], measured=measured, residual=residual, rms=rms,
                max_abs=max_abs, units=measured_units(result.scene))
