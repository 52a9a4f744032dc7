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

from ..log_splines import missing_at, spline_values
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
