"""Stage 1 of a scene: positions, velocities, accelerations, condition and influence
coefficients, over the whole sweep or segment by segment (:class:`Stage1`), and
:class:`Kinematics`, what it hands to the force stage and keeps with the Result."""
from __future__ import annotations

import dataclasses
import functools
import time as _time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from . import kinematics as kin
from .cache import derived
from .model import check_mobility, content_key
from .model import driver_scale as model_driver_scale
from .model.drive import driver_motion as drive_motion
from .result import Motion
from .scene import Scene
from .status import OK, finite_rows


def mobility_of(model):
    """:func:`check_mobility`; on a large mechanism (from ``kinematics.SPARSE_FROM`` unknowns)
    with one BLAS thread whatever ``threads`` says: its dense SVD and least squares of a few
    hundred unknowns gain nothing from threads and, multi-threaded on a busy machine, were
    measured to stall for up to a second (docs/performance.md)."""
    return derived(model, "mobility", _mobility, content_key(model))  # a model's numbers alone


def _mobility(model):
    if model.n_q < kin.SPARSE_FROM:
        return check_mobility(model)
    with threadpool_limits(limits=1, user_api="blas"):
        return check_mobility(model)


@dataclass(frozen=True)
class Kinematics:
    """Stage 1 of a solved scene, kept with its Result so that a scene differing only in force
    parameters (springs, masses, loads, gravity) can re-run stage 2 alone (``linkpipe fit``)."""

    mobility: object
    drive: object
    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray
    sweep: object
    link_angle: np.ndarray
    der: dict
    velocity: np.ndarray | None
    acceleration: np.ndarray | None
    link_rates: tuple
    #: what the force stage may keep between calls on this stage 1 without the Lagrange side
    #: (influence coefficients, effects whose scene inputs are unchanged: forces.compute_forces)
    force_cache: dict = field(default_factory=dict, compare=False, repr=False)
    #: why the sweep's first steps are no_assembly: its first driver value out of the
    #: drawing's reach (:func:`linkpipe.kinematics.start.steps_out_of_reach`), or ""
    reach_note: str = ""

    def motion(self) -> Motion:
        """The sweep as the force stage takes it."""
        return Motion(s=self.s, s_dot=self.s_dot, s_ddot=self.s_ddot,
                      position=self.sweep.position, velocity=self.velocity,
                      acceleration=self.acceleration, status=self.der["status"],
                      influence=self.der["influence"],
                      link_angular_acceleration=self.link_rates[1], link_angle=self.link_angle)

    def stored(self) -> list[np.ndarray]:
        """The kinematic arrays a Result stores that must be finite at an ok step (the one
        list: :attr:`finite`), step axis first."""
        arrays = [self.sweep.position, self.link_angle, self.velocity, self.acceleration,
                  *self.link_rates]
        return [a for a in arrays if a is not None]

    @functools.cached_property
    def finite(self) -> np.ndarray:
        """(S,) True where every :meth:`stored` array is finite (computed once: a fit's trials
        reuse it)."""
        return finite_rows(self.stored(), len(self.s))

    def tiled(self, V: int, position: np.ndarray | None = None) -> "Kinematics":
        """This stage 1 repeated for V variants on one (variant, step) row axis (V x S rows,
        variant first): a study's variants that share it; ``position`` (V x S, n_points, 2):
        the rows' own positions (anchors moved) instead of the tiled ones."""
        def rows(a):
            return None if a is None else np.tile(a, (V,) + (1,) * (a.ndim - 1))

        drive = dataclasses.replace(self.drive, **{
            f.name: rows(getattr(self.drive, f.name)) for f in dataclasses.fields(self.drive)
            if isinstance(getattr(self.drive, f.name), np.ndarray)})
        sweep = dataclasses.replace(  # its rates are the Kinematics' own (tiled once, below)
            self.sweep, position=rows(self.sweep.position) if position is None else position,
            velocity=None, acceleration=None,
            **{f: rows(getattr(self.sweep, f)) for f in ("residual", "iterations", "status")})
        velocity, acceleration = rows(self.velocity), rows(self.acceleration)
        der = {key: rows(a) if isinstance(a, np.ndarray) else a for key, a in self.der.items()
               if key not in ("velocity", "acceleration")}
        der.update(velocity=velocity, acceleration=acceleration)
        return Kinematics(self.mobility, drive, rows(self.s), rows(self.s_dot), rows(self.s_ddot),
                          sweep, rows(self.link_angle), der, velocity, acceleration,
                          tuple(rows(a) for a in self.link_rates), reach_note=self.reach_note)


#: what :meth:`Stage1.parts` yields where the sweep's plan left the closed-form dyads for
#: Newton after some segments: the segments come again from the first step
RESTART = object()


class Stage1:
    """Stage 1 of one scene, solved over the whole sweep or segment by segment (:meth:`parts`;
    a long sweep streamed to its files: :mod:`linkpipe.segments`); segments give the whole
    sweep's rows to the last bit (``tests/test_segments.py``).

    Made once per sweep: the drivers' motion (S, nd) in internal units, the time axis and how
    the positions are found (:class:`linkpipe.kinematics.Plan`: the method, the start, the
    dyads' branches, carried across segments; it switches itself to Newton where auto must
    leave the dyads, and :meth:`parts` then starts again from the first segment). Link angles
    are unwrapped across segments (:class:`~linkpipe.kinematics.angles.AngleCarry`), torsion
    springs' turns set at the sweep's first solved step.
    """

    def __init__(self, scene: Scene, model, stages, tell=lambda stage: None,
                 seconds: dict | None = None):
        self.scene, self.model, self.stages, self.tell = scene, model, stages, tell
        self.seconds = seconds if seconds is not None else {}
        self.mobility = mobility_of(model)
        self.drive = drive_motion(scene)  # in scene units; internal units below (deg -> rad)
        scale = model_driver_scale(scene)
        self.s, self.s_dot, self.s_ddot = (self.drive.value * scale, self.drive.rate * scale,
                                           self.drive.acceleration * scale)
        self.time_axis = time_axis(scene, self.drive.value)
        self.order = stages.order
        t0 = _time.perf_counter()
        self.plan = kin.Plan(model, self.s)  # the general path solves the whole sweep here
        self._add("positions", t0)
        self.reach_note = self.plan.reach_note
        self.restart()

    @property
    def n_steps(self) -> int:
        return self.s.shape[0]

    def restart(self) -> None:
        """Segments from the first step again (what is carried from one segment to the next)."""
        self.plan.restart()
        self.angle_carry = kin.AngleCarry.start(len(self.model.link_a))

    def _add(self, stage: str, t0: float) -> None:
        self.seconds[stage] = self.seconds.get(stage, 0.0) + _time.perf_counter() - t0

    def whole(self) -> Kinematics:
        """The whole sweep as one segment."""
        _, _, k = next(self.parts(self.n_steps))
        return k

    def parts(self, segment: int):
        """Yield ``(lo, hi, Kinematics)`` of each segment of ``segment`` steps, in step order,
        or :data:`RESTART` where the plan left the dyads for Newton after earlier segments (the
        segments then come again from the first step; a sweep of one segment never restarts)."""
        S, lo = self.n_steps, 0
        while True:
            hi = min(S, lo + segment)
            k = self._segment(lo, hi)
            if k is None:
                lo = 0
                yield RESTART
                continue
            yield lo, hi, k
            if hi >= S:
                return
            lo = hi

    def _link_rates(self, sweep, der, X, velocity, acceleration) -> tuple:
        """The links' angular velocities and accelerations (S, n_links) (None, None without
        rates): the dyads' own, from their pass, where they gave them (the steps that are not
        ok recomputed from the final rates: NaN, or a link's fixed points' zeros), else from
        the positions and rates (:func:`linkpipe.kinematics.link_rates`)."""
        if not self.stages.velocity:
            return None, None
        given = sweep.link_rates
        if given is None or self.scene.solver.derivatives == "finite_difference":
            return kin.link_rates(self.model, X, velocity, acceleration)
        w, al = given[0], given[1] if acceleration is not None else None
        redo = np.flatnonzero(der["status"] != OK)
        if len(redo):
            w[redo], al_redo = kin.link_rates(self.model, X[redo], velocity[redo],
                                              None if al is None else acceleration[redo])
            if al is not None:
                al[redo] = al_redo
        return w, al

    def _segment(self, lo: int, hi: int) -> Kinematics | None:
        """Stage 1 of steps ``lo .. hi - 1``, or None where the plan left the dyads for Newton
        here after earlier segments (the carries restarted)."""
        model, stages, rows = self.model, self.stages, slice(lo, hi)
        self.tell("positions")
        t0 = _time.perf_counter()
        s, s_dot, s_ddot = self.s[rows], self.s_dot[rows], self.s_ddot[rows]
        path = self.plan.used
        sweep = self.plan.positions(rows, s_dot, s_ddot, self.order, links=True)
        if self.plan.used != path and lo > 0:
            self._add("positions", t0)
            self.restart()
            return None
        X = sweep.position
        raw = sweep.link_angle  # the dyads' own pass: exact where every point is finite
        if raw is not None:
            redo = np.flatnonzero(sweep.status != OK)
            raw[redo] = model.link_angles(X[redo])
        link_angle, self.angle_carry = kin.link_angles_unwrapped(
            model, X, carry=self.angle_carry, s=s, raw=raw, compiled=self.plan.compiled)
        self._add("positions", t0)
        self.tell("jacobian")
        t0 = _time.perf_counter()
        Xz = X if np.isfinite(X).all() else np.where(np.isfinite(X), X, 0.0)
        der = kin.derivatives(model, Xz, s, s_dot, s_ddot, sweep.status, stages.acceleration,
                              velocity=sweep.velocity, acceleration=sweep.acceleration,
                              need_influence=stages.forces, need_velocity=stages.velocity,
                              residuals=self.scene.solver.rate_residuals,
                              compiled=self.plan.compiled, trig=sweep.trig)
        self._add("jacobian", t0)
        if self.scene.solver.derivatives == "finite_difference" and stages.velocity:
            if (lo, hi) != (0, self.n_steps):
                raise ValueError("finite-difference derivatives need the whole sweep")
            t0 = _time.perf_counter()
            der.update(_fd_derivatives(model, X, Xz, s, s_dot, s_ddot, der["status"],
                                       stages.acceleration, self.drive.time))
            self._add("fd_derivatives", t0)
        velocity = der["velocity"] if stages.velocity else None
        acceleration = der["acceleration"] if stages.acceleration else None
        t0 = _time.perf_counter()
        link_rates = self._link_rates(sweep, der, X, velocity, acceleration)
        self._add("jacobian", t0)  # the links' rates: derivatives too
        drive = dataclasses.replace(self.drive, **{
            f.name: getattr(self.drive, f.name)[rows] for f in dataclasses.fields(self.drive)
            if isinstance(getattr(self.drive, f.name), np.ndarray)})
        return Kinematics(self.mobility, drive, s, s_dot, s_ddot, sweep, link_angle, der,
                          velocity, acceleration, link_rates, reach_note=self.reach_note)


def _fd_derivatives(model, X, Xz, s, s_dot, s_ddot, status, need_acceleration, time) -> dict:
    """Velocities (and accelerations) by finite differences of the positions along the sweep,
    NaN where a step is not ok, with the residuals of the stored (finite-difference) values."""
    fdV, fdA = kin.fd_derivatives(X, s, s_dot, s_ddot, status, need_acceleration, time)
    ok = (status == OK)[:, None, None]
    out = {"velocity": np.where(ok, fdV, np.nan)}
    if need_acceleration:
        out["acceleration"] = np.where(ok, fdA, np.nan)
    out.update(_residuals(model, Xz, s, s_dot, s_ddot, out["velocity"], out.get("acceleration")))
    return out


def _residuals(model, X, s, s_dot, s_ddot, V, A) -> dict:
    """Return the residuals of ``Phi_q qd = -Phi_t`` and ``Phi_q qdd = gamma`` for given V, A."""
    S = X.shape[0]
    out = {"velocity_residual": np.full(S, np.nan)}
    good = np.isfinite(V).all(axis=(1, 2))
    if A is not None:
        out["acceleration_residual"] = np.full(S, np.nan)
        good &= np.isfinite(A).all(axis=(1, 2))
    idx = np.flatnonzero(good)
    chunk = kin.dense_chunk(model)  # dense (chunk, m, n) Jacobians: bounded, large mechanisms too
    for lo in range(0, len(idx), chunk):
        i = idx[lo:lo + chunk]
        J = model.jacobian(X[i], s[i])
        qd = model.q_of(V[i])
        out["velocity_residual"][i] = np.abs(np.einsum("sij,sj->si", J, qd) + model.phi_t(
            X[i], s[i], s_dot[i])).max(axis=1)
        if A is not None:
            g = model.gamma(X[i], V[i], s[i], s_dot[i], s_ddot[i])
            out["acceleration_residual"][i] = np.abs(
                np.einsum("sij,sj->si", J, model.q_of(A[i])) - g).max(axis=1)
    return out


def time_axis(scene: Scene, value: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Return (seconds per step, note): the time when every driver that moves has a rate and
    no acceleration, ``|value - from| / |rate|``, and all of them agree on it (to 1e-9 of the
    sweep's duration); else None, with a note saying why when the rates alone would give one.
    A driver held (from = to while another moves) gives no time: it is left out; every driver
    held, each with a rate and no acceleration, is the formula's 0 s at every step."""
    if scene.time is not None:
        return np.asarray(scene.time.instants, dtype=float), ""
    moving = [(j, d) for j, d in enumerate(scene.drivers) if d.from_value != d.to_value]
    if not moving and all(d.rate != 0 and d.acceleration == 0 for d in scene.drivers):
        return np.zeros(value.shape[0]), ""
    rates = np.array([d.rate for _, d in moving], dtype=float)
    accs = np.array([d.acceleration for _, d in moving], dtype=float)
    if not len(rates) or np.any(rates == 0) or np.any(accs != 0):
        return None, ""
    times = [np.abs(value[:, j] - d.from_value) / abs(d.rate) for j, d in moving]
    t = times[0]
    if not all(np.isfinite(tj).all() for tj in times):
        return None, ("no time axis: a rate this small gives times beyond the floating-point "
                      "range")
    span = float(max(tj.max() for tj in times)) if value.shape[0] else 0.0
    for tj in times[1:]:
        if not np.allclose(tj, t, rtol=0, atol=1e-9 * max(span, 1e-300)):
            ends = ", ".join(f"{d.name} {tj[-1]:.6g} s" for (_, d), tj in zip(moving, times))
            return None, (f"no time axis: the drivers' rates give different times for the same "
                          f"steps (at the last step: {ends}); make each driver's "
                          f"(to - from) / rate the same")
    return t, ""
