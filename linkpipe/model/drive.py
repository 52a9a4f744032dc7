"""The drivers' motion over the sweep: value, rate and acceleration at every step.

A version 1 sweep: evenly spaced values, a constant rate and acceleration. A ``[time]`` sweep:
each driver's value is a function of time, and its rate and acceleration are that function's
exact first and second derivatives at each instant:

- a motion law over [time], ``value = from + (to - from) f(tau)``, ``tau = (t - t0) / T``:
  :data:`LAWS` holds f, f' and f'' in closed form (the rates are ``(to - from) f'(tau) / T``
  and ``(to - from) f''(tau) / T^2``);
- ``rate`` (and ``acceleration``): ``from + rate (t - t0) + acceleration (t - t0)^2 / 2``;
- a log column (in the driver's units, times ``scale``, plus ``offset``) through a cubic
  spline, :func:`log_spline`, at the instants on the log's true time (``t_logged - lag``).

All of it is vectorised: arrays (S, n_drivers), S the number of instants.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Scene

_TWO_PI = 2.0 * np.pi

#: f, f', f'' of each law on tau in [0, 1]; f(0) = 0, f(1) = 1
LAWS = {
    "linear": (lambda u: u, lambda u: np.ones_like(u), lambda u: np.zeros_like(u)),
    "harmonic": (lambda u: 0.5 * (1.0 - np.cos(np.pi * u)),
                 lambda u: 0.5 * np.pi * np.sin(np.pi * u),
                 lambda u: 0.5 * np.pi ** 2 * np.cos(np.pi * u)),
    "cycloidal": (lambda u: u - np.sin(_TWO_PI * u) / _TWO_PI,
                  lambda u: 1.0 - np.cos(_TWO_PI * u),
                  lambda u: _TWO_PI * np.sin(_TWO_PI * u)),
    "polynomial345": (lambda u: u ** 3 * (10.0 - 15.0 * u + 6.0 * u * u),
                      lambda u: 30.0 * u * u * (1.0 - u) ** 2,
                      lambda u: 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)),
}


@dataclass(frozen=True)
class DriverMotion:
    """Every step's driver ``value``, ``rate``, ``acceleration`` (S, n_drivers) in scene units
    (degrees for angles), ``time`` (S,) the instants of a [time] sweep (else None), and
    ``present`` (S,) False where a logged value is missing (status no_input; NaN there)."""

    value: np.ndarray
    rate: np.ndarray
    acceleration: np.ndarray
    time: np.ndarray | None
    present: np.ndarray


def law_motion(law: str, start: float, stop: float, t: np.ndarray, t0: float, T: float):
    """Value, rate and acceleration (S,) of a law from ``start`` to ``stop`` over [t0, t0 + T]."""
    f, df, ddf = LAWS[law]
    tau = (t - t0) / T
    lift = stop - start
    return start + lift * f(tau), lift * df(tau) / T, lift * ddf(tau) / (T * T)


def rate_motion(start: float, rate: float, acc: float, t: np.ndarray, t0: float):
    """Value, rate and acceleration (S,) of ``from + rate t + acceleration t^2/2`` (t from t0)."""
    dt = t - t0
    return start + rate * dt + 0.5 * acc * dt * dt, rate + acc * dt, np.full_like(dt, acc)


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


def driver_motion(scene: Scene) -> DriverMotion:
    """Every step's driver values and rates in scene units: a v1 sweep or a [time] sweep."""
    if scene.time is None:
        from .build import driver_values

        value = driver_values(scene)
        S = value.shape[0]
        rate = np.array([d.rate for d in scene.drivers], dtype=float)
        acc = np.array([d.acceleration for d in scene.drivers], dtype=float)
        return DriverMotion(value, np.broadcast_to(rate, value.shape).copy(),
                            np.broadcast_to(acc, value.shape).copy(), None, np.ones(S, bool))
    t = np.asarray(scene.time.instants, dtype=float)
    t0, T = scene.time.from_value, scene.time.to_value - scene.time.from_value
    logs = {log.name: log for log in scene.logs}
    S, nd = len(t), len(scene.drivers)
    value, rate, acc = (np.empty((S, nd)) for _ in range(3))
    present = np.ones(S, dtype=bool)
    for j, dr in enumerate(scene.drivers):
        if dr.timed == "law":
            cols = law_motion(dr.law, dr.from_value, dr.to_value, t, t0, T)
        elif dr.timed == "rate":
            cols = rate_motion(dr.from_value, dr.rate, dr.acceleration, t, t0)
        else:
            log = logs[dr.log[0]]
            y = log.columns[dr.log[1]]
            gain = dr.scale * dr.unit_factor
            cols = tuple(gain * v + (dr.offset if nu == 0 else 0.0)
                         for nu, v in enumerate(spline_values(log.t, y, dr.smoothing, t)))
            present &= ~missing_at(log.t, y, t)
        value[:, j], rate[:, j], acc[:, j] = cols
    for arr in (value, rate, acc):
        arr[~present] = np.nan
    return DriverMotion(value, rate, acc, t, present)


def internal_motion(model):
    """Return driver values in scene units and (s, s_dot, s_ddot) in internal units, each
    (S, nd), of ``model``'s scene (:func:`driver_motion` scaled by
    :func:`linkpipe.model.build.driver_scale`; NaN at steps without a logged value)."""
    from .build import driver_scale

    motion = driver_motion(model.scene)
    scale = driver_scale(model.scene)
    return motion.value, motion.value * scale, motion.rate * scale, motion.acceleration * scale
