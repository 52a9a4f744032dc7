"""A log column as a function of time: the spline through its samples (:func:`log_spline`),
its values and derivatives at instants, kept for a fit's repeated trials
(:func:`spline_values`), and the instants a missing sample leaves without a value
(:func:`missing_at`). Pure maths (numpy, scipy), imported by the drivers' motion
(:mod:`linkpipe.model.drive`) and by a measurement read from a second logger
(:mod:`linkpipe.scene.timing`)."""
from __future__ import annotations

import numpy as np


def log_spline(t: np.ndarray, y: np.ndarray, smoothing: float):
    """The spline through a log column's finite samples (``t`` strictly increasing).

    ``smoothing`` 0: :class:`scipy.interpolate.CubicSpline` (not-a-knot ends), which
    interpolates: exact at every sample, twice continuously differentiable, and for a smooth
    signal sampled at spacing h its error is O(h^4) in value, O(h^3) in the first derivative
    and O(h^2) in the second. ``smoothing`` > 0:
    :func:`scipy.interpolate.make_smoothing_spline` with ``lam = smoothing``, the cubic
    spline minimising ``sum (y_i - g(t_i))^2 + lam * integral g''(t)^2 dt``. Chosen over
    :class:`~scipy.interpolate.UnivariateSpline` because its answer is the unique minimiser
    of that stated criterion (knots at every sample, any spacing, linear in the data, so
    ``scale`` commutes with it), while FITPACK's ``s`` is a bound on the residual that it
    meets by choosing knots heuristically, so a small change of ``s`` or of the data can
    change the knots and jump the derivatives. ``lam`` has units of time^3; as it goes to 0
    the spline tends to the interpolating (natural) spline.

    A missing sample is left out: the spline runs through its finite neighbours. It is a
    global fit, so a gap also moves the spline's derivatives near it (the span across the
    gap is one cubic piece instead of two); at samples away from a gap the change decays
    geometrically, by a factor of about 2 - sqrt(3) = 0.27 per sample (the interpolating
    spline's influence function), and positions at the finite samples stay exact.
    """
    from scipy.interpolate import CubicSpline, make_smoothing_spline

    keep = np.isfinite(y)
    tk, yk = t[keep], y[keep]
    if smoothing > 0:
        return make_smoothing_spline(tk, yk, lam=smoothing)
    # two samples: a line; three: the parabola (not-a-knot with 3 points); four and more: cubic
    return CubicSpline(tk, yk, bc_type="not-a-knot")


#: splines' values at instants, by the bytes of (samples, values, instants) and smoothing: a
#: fit's trials that move a log driver's offset or scale, or anything but the log, read the
#: same spline again (bounded to MAX_SPLINE_BYTES: the oldest go)
_SPLINE_VALUES: dict = {}
MAX_SPLINE_BYTES = 128 * 2 ** 20


def spline_values(t: np.ndarray, y: np.ndarray, smoothing: float, instants: np.ndarray):
    """The log spline's value, first and second derivative (each (S,)) at ``instants``
    (:func:`log_spline`), kept for the same samples and instants."""
    import hashlib

    digest = hashlib.blake2b(digest_size=16)
    for arr in (t, y, instants):
        digest.update(np.ascontiguousarray(arr, dtype=float).tobytes())
    key = (digest.digest(), float(smoothing), len(t), len(instants))
    if key in _SPLINE_VALUES:
        return _SPLINE_VALUES[key]
    spline = log_spline(t, y, smoothing)
    values = tuple(spline(instants, nu) for nu in range(3))
    if 3 * 8 * len(instants) <= MAX_SPLINE_BYTES // 8:  # (a long sweep is not kept)
        for v in values:
            v.setflags(write=False)
        _SPLINE_VALUES[key] = values
        while sum(3 * v[0].nbytes for v in _SPLINE_VALUES.values()) > MAX_SPLINE_BYTES:
            _SPLINE_VALUES.pop(next(iter(_SPLINE_VALUES)))
    return values


def forget_spline_values() -> None:
    """Drop the splines' values kept by :func:`spline_values` (``follow`` solves each window of
    its log once: kept, they only filled memory, up to :data:`MAX_SPLINE_BYTES`)."""
    _SPLINE_VALUES.clear()


def missing_at(t_log: np.ndarray, y: np.ndarray, instants: np.ndarray) -> np.ndarray:
    """(S,) True at the instants a missing sample leaves without a value: those strictly between
    the finite samples on either side of a missing row (with [time] log: exactly the missing
    rows; before the first or after the last finite sample up to the missing row's end)."""
    missing = ~np.isfinite(y)
    if not missing.any():
        return np.zeros(len(instants), dtype=bool)
    finite_t = t_log[~missing]
    # each instant's neighbouring finite samples: the gap between them holds a missing row?
    k = np.searchsorted(finite_t, instants, side="right")  # finite samples at or before
    at_sample = np.zeros(len(instants), dtype=bool)
    inside = (k > 0)
    at_sample[inside] = finite_t[k[inside] - 1] == instants[inside]
    # missing rows between consecutive finite samples (and before the first / after the last)
    rows_before = np.searchsorted(t_log, finite_t)  # row index of each finite sample
    edges = np.r_[-1, rows_before, len(t_log)]
    gap_has_missing = np.diff(edges) > 1  # (n_finite + 1,) gaps between finite samples
    return gap_has_missing[k] & ~at_sample
