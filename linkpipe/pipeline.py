"""Decide which stages a scene needs, run them, time them; return a :class:`Result`."""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import time as _time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from . import kinematics as kin
from .model import build_model, check_mobility
from .model import driver_scale as model_driver_scale
from .model.drive import driver_motion as drive_motion
from .result import Motion, Result, units_of
from .status import NO_INPUT, OK, assign, code_counts, finite_rows
from .status import message as status_message
from .errors import MemoryRefused, SceneError
from .scene import Scene, load_scene


@dataclass(frozen=True)
class Stages:
    """What a scene calls for: kinematic orders and whether the force stage runs."""

    velocity: bool
    acceleration: bool
    forces: bool

    @classmethod
    def of(cls, scene: Scene) -> "Stages":
        eff = set(scene.effects)
        out = scene.outputs
        vectors = bool(out.vectors)
        acc = "inertia" in eff or "acceleration" in out.kinematics or vectors
        vel = acc or "damping" in eff or "velocity" in out.kinematics or vectors
        return cls(velocity=vel, acceleration=acc, forces=bool(eff))

    @property
    def stages(self) -> tuple[str, ...]:
        return ("positions",) + (("velocities",) if self.velocity else ()) + (
            ("accelerations",) if self.acceleration else ()) + (("forces",) if self.forces else ())


#: what a run needs beside its stored arrays: the interpreter and libraries (~0.25 GB measured
#: with numpy, scipy, pandas, h5py and rerun loaded), a recording of at most --rrd-max-steps
#: rows, and one chunk's working set
FIXED_BYTES = 600 * 2**20
#: the stored arrays times this: the transients of the stages around them (each stage's own
#: work goes in chunks of steps; measured peaks: benchmarks/bench_logs.py prints both)
TRANSIENT_FACTOR = 1.3


def bytes_per_step(scene: Scene) -> int:
    """The bytes a run keeps per step, from the scene's counts alone (before any work): every
    array the Result stores (docs/output-format.md) and what stage 1 hands to the force stage
    (driver values in internal units, influence coefficients), 8 bytes a number."""
    stages = Stages.of(scene)
    P, L, nd = len(scene.points), len(scene.links), max(1, len(scene.drivers))
    n_q = 2 * sum(not p.fixed for p in scene.points)
    rates = (2 * P + L + 1) * (int(stages.velocity) + int(stages.acceleration))
    numbers = 2 * P + L + 6 + 6 * nd + rates  # positions, angles, residuals, driver values
    if stages.forces:
        joints = sum(len(link.points) for link in scene.links)
        fixed = sum(p.fixed for p in scene.points)
        numbers += (n_q * nd + 2 * nd + len(scene.effects) + L + 2 * joints + 2 * fixed
                    + 5 * len(scene.springs) + 3 * len(scene.torsion_springs)
                    + len(scene.sliders) + 1)
    return 8 * (numbers + 2 * len(scene.measurements))


def whole_sweep_bytes_per_step(scene: Scene) -> int:
    """The bytes per step a run in segments (:mod:`linkpipe.segments`) keeps for the whole
    sweep: the drivers' motion in scene and internal units, the time axis, and the general
    path's positions with their residuals, iterations and statuses (the dyads need none, but
    the path is known only once solved: an upper bound)."""
    nd, P = max(1, len(scene.drivers)), len(scene.points)
    n_q = 2 * sum(not p.fixed for p in scene.points)
    return 8 * (6 * nd + 2) + 1 + 8 * (2 * P + n_q + 1) + 5


def memory_needed(scene: Scene, segment: int | None = None, recorded_steps: int = 0) -> int:
    """An upper bound of a run's peak memory in bytes (checked against measured peaks in
    benchmarks/bench_memory.py): the whole sweep's arrays, or with ``segment`` (steps) a run in
    segments: one segment's arrays, what stays whole, and the ``recorded_steps`` rows it keeps
    for its recording (the fixed part holds a recording of up to the default 100,000 rows of a
    small scene; more rows, or larger ones, count here)."""
    if segment is None or segment >= scene.n_steps:
        return int(scene.n_steps * bytes_per_step(scene) * TRANSIENT_FACTOR) + FIXED_BYTES
    return int(segment * bytes_per_step(scene) * TRANSIENT_FACTOR
               + scene.n_steps * whole_sweep_bytes_per_step(scene)
               + recorded_steps * bytes_per_step(scene)) + FIXED_BYTES


def available_memory() -> int | None:
    """Return the memory the kernel says is available (bytes), or None where it does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def check_memory(scene: Scene, segment: int | None = None, recorded_steps: int = 0) -> None:
    """MemoryRefused (a SceneError) when the sweep would need more memory than is available
    (before any work: a run that the kernel kills half-way writes nothing). What the steps
    need is compared with the memory still free: the fixed part of the estimate (libraries,
    the recording) is held already or bounded, and no number of steps could remove it."""
    need = memory_needed(scene, segment, recorded_steps)
    avail = available_memory()
    if avail is not None and need - FIXED_BYTES > avail:
        first = scene.drivers[0] if scene.drivers else None
        driver = first.name if first else ""
        key = "step" if first is not None and first.step is not None else "steps"
        raise MemoryRefused(scene.path, f'drivers "{driver}"', key,
                         f"{scene.n_steps:,} steps of {len(scene.points)} points need about "
                         f"{need / 2**30:.1f} GiB of memory; {avail / 2**30:.1f} GiB is available",
                         ("use a larger step" if key == "step" else "use fewer steps")
                         + ", or split the sweep into several scenes")


def preflight(scene: Scene, segment: int | None = None, recorded_steps: int = 0):
    """Check what can be checked before solving; return (model, mobility).

    The scene's memory need (of a run in segments of ``segment`` steps keeping
    ``recorded_steps`` rows for its recording: :func:`memory_needed`), its degrees of freedom
    against its drivers, and that the start assembles at the first driver value (SceneError
    otherwise): what ``check`` reports."""
    check_memory(scene, segment, recorded_steps)
    model = build_model(scene)
    mob = _mobility(model)
    _, s, _, _ = kin.driver_motion(model)  # a scene has at least one step
    present = np.flatnonzero(np.isfinite(s).all(axis=1))  # not every logged value is missing
    if len(present):
        kin.start_state(model, s[present[0]], scene.solver.tol * model.size,
                        scene.solver.max_iter)
    return model, mob


def _mobility(model):
    """:func:`check_mobility`; on a large mechanism (from ``kinematics.SPARSE_FROM`` unknowns)
    with one BLAS thread whatever ``threads`` says: its dense SVD and least squares of a few
    hundred unknowns gain nothing from threads and, multi-threaded on a busy machine, were
    measured to stall for up to a second (docs/performance.md)."""
    if model.n_q < kin.SPARSE_FROM:
        return check_mobility(model)
    with threadpool_limits(limits=1, user_api="blas"):
        return check_mobility(model)


#: BLAS threads while a scene is solved: its solves are many small systems (stacks of 2x2 to
#: few-hundred-square blocks), where a multi-threaded BLAS only adds overhead (measured:
#: benchmarks/bench_threads.py; docs/performance.md)
DEFAULT_THREADS = 1


def solve(scene: Scene | str, progress=None, threads: int | None = DEFAULT_THREADS,
          kinematics: Kinematics | None = None, wanted: frozenset | None = None) -> Result:
    """Run every stage the scene calls for and return the result (failed steps are data).

    ``progress``: an optional callable ``progress(stage_name)`` told as each stage starts
    (the CLI drives a tqdm bar with it on long sweeps). ``threads``: the BLAS thread pool's
    size while solving (threadpoolctl; None leaves the library's own). ``kinematics``: the
    ``Result.kinematics`` of a scene with the same geometry and drivers (only force parameters
    differ): stage 1 is reused, not solved again. ``wanted``: the names of the variables the
    caller will read (None: every one the scene calls for); the Lagrange multipliers and the
    forces only they give are solved only when one of them is wanted (a fit's trials read its
    measurements alone). The Result is built once, here.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    # overflow and 0/0 are data here, not warnings: such steps are marked (status.assign)
    # threads None: the pools as they are (no threadpoolctl call: finding the libraries costs
    # milliseconds, a study's variant-by-variant path sets the pool once for a whole batch)
    pools = (contextlib.nullcontext() if threads is None
             else threadpool_limits(limits=threads, user_api="blas"))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"), pools:
        return _solve(scene, progress, kinematics, wanted)


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
    #: (S, n_torsion_springs) the multiple of 2 pi (rad) each torsion spring's angle drops (a
    #: broadcast view), or None without torsion springs
    #: (:func:`linkpipe.forces.springs.torsion_offset`)
    torsion_offset: np.ndarray | None = None
    #: what the force stage may keep between calls on this stage 1 without the Lagrange side
    #: (influence coefficients, effects whose scene inputs are unchanged: forces.compute_forces)
    force_cache: dict = field(default_factory=dict, compare=False, repr=False)

    def motion(self) -> Motion:
        """The sweep as the force stage takes it."""
        return Motion(s=self.s, s_dot=self.s_dot, s_ddot=self.s_ddot,
                      position=self.sweep.position, velocity=self.velocity,
                      acceleration=self.acceleration, status=self.der["status"],
                      influence=self.der["influence"],
                      link_angular_acceleration=self.link_rates[1], link_angle=self.link_angle,
                      torsion_offset=self.torsion_offset)

    @functools.cached_property
    def finite(self) -> np.ndarray:
        """(S,) True where every stored kinematic array is finite (computed once: a fit's
        trials reuse it)."""
        stored = [self.sweep.position, self.link_angle, self.velocity, self.acceleration,
                  *self.link_rates]
        return finite_rows([a for a in stored if a is not None], len(self.s))


def _solve(scene: Scene, progress, kinematics: Kinematics | None = None,
           wanted: frozenset | None = None) -> Result:
    stages = Stages.of(scene)
    tell = progress if callable(progress) else (lambda stage: None)
    seconds: dict[str, float] = {}
    t0 = _time.perf_counter()
    if kinematics is None:  # a reused stage 1 was checked when it was solved
        check_memory(scene)
    model = build_model(scene)
    seconds["model"] = _time.perf_counter() - t0
    k = _stage1(scene, model, stages, tell, seconds) if kinematics is None else kinematics
    kinematic_status = k.der["status"]
    forces = None
    if stages.forces:
        from .forces import LAGRANGE_VARIABLES, compute_forces

        tell("forces")
        t0 = _time.perf_counter()
        motion = k.motion()
        lagrange = wanted is None or bool(wanted & LAGRANGE_VARIABLES)
        forces = compute_forces(model, motion, units_of(scene), lagrange=lagrange,
                                cache=k.force_cache if kinematics is not None and not lagrange
                                else None)
        seconds["forces"] = _time.perf_counter() - t0
    status = status_of(model, kinematic_status, k.sweep.residual, [], forces, finite=k.finite)
    result = result_of(scene, model, k, forces, status, seconds)
    return _with_measurements(result) if scene.measurements else result


def result_of(scene: Scene, model, k: Kinematics, forces, status, seconds: dict,
              time_axis: tuple | None = None, step_numbers: np.ndarray | None = None) -> Result:
    """The Result of a solved stage 1 ``k``, its ``forces`` (or None) and final ``status``
    (S,): step-first arrays of any number of rows (a study's (variant, step) rows too).
    ``time_axis``: (time, note) of the whole sweep where ``k`` holds a segment of it, with the
    segment's ``step_numbers``."""
    stages = Stages.of(scene)
    X, der = k.sweep.position, k.der
    value, drive = k.drive.value, k.drive
    time, time_note = _time_axis(scene, value) if time_axis is None else time_axis
    return Result(
        scene=scene, model=model, mobility=k.mobility, driver_value=value, time=time,
        driver_velocity=drive.rate if scene.time is not None else None,
        driver_acceleration=drive.acceleration if scene.time is not None else None,
        time_note=time_note, position=X, link_angle=k.link_angle, status=status,
        residual=k.sweep.residual, iterations=k.sweep.iterations, condition=der["condition"],
        velocity=k.velocity, acceleration=k.acceleration,
        link_angular_velocity=k.link_rates[0], link_angular_acceleration=k.link_rates[1],
        velocity_residual=der["velocity_residual"] if stages.velocity else None,
        acceleration_residual=der["acceleration_residual"] if stages.acceleration else None,
        forces=forces.variables if forces else None,
        force_coords=forces.coords if forces else {},
        seconds=seconds, message=message(status),
        solver_method_used=k.sweep.method, solver_note=k.sweep.note,
        linear_algebra_used=kin.linear_algebra_used(model) if k.sweep.method == "newton" else "",
        kinematics=k, step_numbers=step_numbers)


def status_of(model, kinematic_status, residual, stored: list, forces, size=None,
              finite: np.ndarray | None = None) -> np.ndarray:
    """Every step's final status (S,): the stages' verdicts, the residual against the
    tolerance, and whether everything ``stored`` (kinematic arrays, step axis first, None
    where not computed) and the forces' arrays are finite (:func:`linkpipe.status.assign`).
    ``size``: the length scale of the tolerance, float or (S,) (default ``model.size``);
    ``finite`` (S,): rows of arrays checked before (:attr:`Kinematics.finite`)."""
    if forces:
        stored = stored + forces.defined_arrays()
    return assign([kinematic_status] + ([forces.status] if forces else []), residual,
                  model.scene.solver.tol * (model.size if size is None else size),
                  [a for a in stored if a is not None], finite=finite)


def _stage1(scene: Scene, model, stages: Stages, tell, seconds: dict) -> Kinematics:
    """Positions, velocities, accelerations, condition and influence coefficients of the whole
    sweep: :class:`Stage1` with the sweep as one segment."""
    return Stage1(scene, model, stages, tell, seconds).whole()


class Stage1:
    """Stage 1 of one scene, solved over the whole sweep or segment by segment (a long sweep
    streamed to its files: :mod:`linkpipe.segments`); segments give the whole sweep's rows to
    the last bit (``tests/test_segments.py``).

    Made once per sweep: the drivers' motion (S, nd) in internal units, the time axis, the
    start and the dyads' branches. The closed-form dyads solve segment by segment (their
    branch margins carried across); where auto must leave them for Newton at some segment
    (:meth:`segment` returns None), :meth:`use_newton` solves the positions of the whole sweep
    by the general path, and the segments start again from the first. Link angles are unwrapped
    across segments (:class:`~linkpipe.kinematics.rates.AngleCarry`), torsion springs' turns
    set at the sweep's first solved step.
    """

    def __init__(self, scene: Scene, model, stages: Stages, tell=lambda stage: None,
                 seconds: dict | None = None):
        self.scene, self.model, self.stages, self.tell = scene, model, stages, tell
        self.seconds = seconds if seconds is not None else {}
        self.mobility = _mobility(model)
        self.drive = drive_motion(scene)  # in scene units; internal units below (deg -> rad)
        scale = model_driver_scale(scene)
        self.s, self.s_dot, self.s_ddot = (self.drive.value * scale, self.drive.rate * scale,
                                           self.drive.acceleration * scale)
        self.time_axis = _time_axis(scene, self.drive.value)
        self.order = 2 if stages.acceleration else 1 if stages.velocity else 0
        self.present = np.isfinite(self.s).all(axis=1)  # False where a logged value is missing
        self.newton: kin.Sweep | None = None
        self.chain, self.note, self.start = None, "", None
        method = scene.solver.method
        first = np.flatnonzero(self.present)[:2]
        if not len(first):
            self.newton = _sweep_where_present(model, self.s, self.present)
        elif method in ("auto", "dyads"):
            self.chain, self.note, self.start = kin.dyad_plan(model, self.s[first],
                                                              method == "dyads")
        if self.chain is None and self.newton is None:
            self.use_newton()
        self.restart()

    @property
    def n_steps(self) -> int:
        return self.s.shape[0]

    def restart(self) -> None:
        """Segments from the first step again (what is carried from one segment to the next)."""
        self.chain_carry: dict = {}
        self.angle_carry = kin.AngleCarry.start(len(self.model.link_a))
        self.turns = (np.full(len(self.scene.torsion_springs), np.nan)
                      if self.scene.torsion_springs else None)

    def use_newton(self) -> None:
        """The general path's positions of the whole sweep (auto left the dyads, or the scene
        asks for Newton); segments then slice them."""
        t0 = _time.perf_counter()
        note = self.note or (kin.DYADS_LEFT if self.chain is not None else "")
        self.chain = None
        if self.present.all():
            self.newton = kin.solve_with_newton(self.model, self.s, note, self.start)
        else:
            self.newton = _sweep_where_present(self.model, self.s, self.present, note,
                                               self.start)
        self._add("positions", t0)
        self.restart()

    def _add(self, stage: str, t0: float) -> None:
        self.seconds[stage] = self.seconds.get(stage, 0.0) + _time.perf_counter() - t0

    def whole(self) -> Kinematics:
        """The whole sweep as one segment."""
        k = self.segment(0, self.n_steps)
        if k is None:
            self.use_newton()
            k = self.segment(0, self.n_steps)
        return k

    def _positions(self, rows: slice) -> kin.Sweep | None:
        """The Sweep of steps ``rows``: the dyads' (None where auto must leave them) or a slice
        of the general path's."""
        if self.newton is not None:
            return kin.Sweep(*(getattr(self.newton, f)[rows] for f in
                               ("position", "residual", "iterations", "status")),
                             self.newton.method, self.newton.note)
        forced = self.scene.solver.method == "dyads"
        present = self.present[rows]
        s, sd, sdd = self.s[rows], self.s_dot[rows], self.s_ddot[rows]
        if present.all():
            return kin.dyad_sweep(self.model, self.chain, s, sd, sdd, self.order, forced,
                                  self.chain_carry)
        idx = np.flatnonzero(present)
        sub = kin.dyad_sweep(self.model, self.chain, s[idx], sd[idx], sdd[idx], self.order,
                             forced, self.chain_carry)
        return None if sub is None else _scattered(self.model, sub, idx, len(present))

    def segment(self, lo: int, hi: int) -> Kinematics | None:
        """Stage 1 of steps ``lo .. hi - 1``, or None where auto must leave the dyads for
        Newton (call :meth:`use_newton`, then start again from the first segment)."""
        model, stages, rows = self.model, self.stages, slice(lo, hi)
        self.tell("positions")
        t0 = _time.perf_counter()
        sweep = self._positions(rows)
        if sweep is None:
            return None
        X = sweep.position
        link_angle, self.angle_carry = kin.link_angles_unwrapped(model, X, carry=self.angle_carry)
        self._add("positions", t0)
        self.tell("jacobian")
        t0 = _time.perf_counter()
        s, s_dot, s_ddot = self.s[rows], self.s_dot[rows], self.s_ddot[rows]
        Xz = X if np.isfinite(X).all() else np.where(np.isfinite(X), X, 0.0)
        der = kin.derivatives(model, Xz, s, s_dot, s_ddot, sweep.status, stages.acceleration,
                              velocity=sweep.velocity, acceleration=sweep.acceleration,
                              need_influence=stages.forces)
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
        link_rates = (kin.link_rates(model, X, velocity, acceleration) if stages.velocity
                      else (None, None))
        self._add("jacobian", t0)  # the links' rates: derivatives too
        offset = None
        if self.turns is not None:
            from .forces.springs import torsion_offset

            unset = np.isnan(self.turns)
            if unset.any():
                self.turns = np.where(unset, torsion_offset(model, link_angle), self.turns)
            offset = np.broadcast_to(self.turns, (hi - lo, len(self.turns)))
        drive = dataclasses.replace(self.drive, **{
            f.name: getattr(self.drive, f.name)[rows] for f in dataclasses.fields(self.drive)
            if isinstance(getattr(self.drive, f.name), np.ndarray)})
        return Kinematics(self.mobility, drive, s, s_dot, s_ddot, sweep, link_angle, der,
                          velocity, acceleration, link_rates, offset)


def _scattered(model, sub: kin.Sweep, idx: np.ndarray, S: int) -> kin.Sweep:
    """A Sweep of S steps with ``sub``'s rows at ``idx`` (steps that have every driver value);
    the others no_input, every moving quantity NaN."""
    X = np.full((S, model.n_points, 2), np.nan)
    X[:, model.fixed] = model.start_position[model.fixed]
    full = dict(position=X, residual=np.full(S, np.nan), iterations=np.zeros(S, np.int32),
                status=np.full(S, NO_INPUT, np.int8))
    for key in ("position", "residual", "iterations", "status"):
        full[key][idx] = getattr(sub, key)
    for key in ("velocity", "acceleration"):
        if getattr(sub, key) is not None:
            full[key] = np.full((S, model.n_points, 2), np.nan)
            full[key][idx] = getattr(sub, key)
    return kin.Sweep(**full, method=sub.method, note=sub.note)


def _with_measurements(result: Result) -> Result:
    """The result with its measurements beside their computed counterparts (linkpipe.measure);
    a measurement of a quantity the run did not compute is the scene's mistake."""
    from dataclasses import replace

    from .measure import compare

    try:
        return replace(result, measurements=compare(result))
    except KeyError as missing:
        m = next(m for m in result.scene.measurements if m.of[0] == missing.args[0])
        raise SceneError(result.scene.path, f'measurements "{m.name}"', "of",
                         f'"{m.of[0]}" is not computed by this scene',
                         "turn on what computes it: [analysis] effects for forces, "
                         '[outputs] kinematics = ["velocity", "acceleration"] for rates') from None


def _sweep_where_present(model, s, present, note: str = "", start=None) -> kin.Sweep:
    """The general path on the steps that have every driver value (the others: status
    no_input, every moving quantity NaN). The continuation runs from one present step to the
    next, so a missing sample leaves its neighbours' solutions as they would be without it."""
    S, idx = s.shape[0], np.flatnonzero(present)
    if not len(idx):
        X = np.full((S, model.n_points, 2), np.nan)
        X[:, model.fixed] = model.start_position[model.fixed]
        return kin.Sweep(X, np.full(S, np.nan), np.zeros(S, np.int32),
                         np.full(S, NO_INPUT, np.int8), method="none",
                         note="no step has every driver value")
    return _scattered(model, kin.solve_with_newton(model, s[idx], note, start), idx, S)


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


def _time_axis(scene: Scene, value: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Return (seconds per step, note): the time when every driver has a rate and no
    acceleration, ``|value - from| / |rate|``, and all drivers agree on it (to 1e-9 of the
    sweep's duration); else None, with a note saying why when the rates alone would give one."""
    if scene.time is not None:
        return np.asarray(scene.time.instants, dtype=float), ""
    rates = np.array([d.rate for d in scene.drivers], dtype=float)
    accs = np.array([d.acceleration for d in scene.drivers], dtype=float)
    if not len(rates) or np.any(rates == 0) or np.any(accs != 0):
        return None, ""
    times = [np.abs(value[:, j] - d.from_value) / abs(d.rate) for j, d in enumerate(scene.drivers)]
    t = times[0]
    if not all(np.isfinite(tj).all() for tj in times):
        return None, ("no time axis: a rate this small gives times beyond the floating-point "
                      "range")
    span = float(max(tj.max() for tj in times)) if value.shape[0] else 0.0
    for tj in times[1:]:
        if not np.allclose(tj, t, rtol=0, atol=1e-9 * max(span, 1e-300)):
            ends = ", ".join(f"{d.name} {tj[-1]:.6g} s" for d, tj in zip(scene.drivers, times))
            return None, (f"no time axis: the drivers' rates give different times for the same "
                          f"steps (at the last step: {ends}); make each driver's "
                          f"(to - from) / rate the same")
    return t, ""


def message(status: np.ndarray) -> str:
    """One line: how many steps are ok, and what the others are."""
    return status_message(code_counts(status))
