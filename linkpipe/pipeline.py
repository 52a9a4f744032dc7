"""Decide which stages a scene needs, run them, time them; return a :class:`Result`."""
from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from . import batch
from . import kinematics as kin
from .model import build_model, check_mobility
from .result import Result
from .errors import SceneError
from .scene import Scene, load_scene


@dataclass(frozen=True)
class Plan:
    """What a scene calls for: kinematic orders and whether the force stage runs."""

    velocity: bool
    acceleration: bool
    forces: bool

    @classmethod
    def of(cls, scene: Scene) -> "Plan":
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


#: memory a sweep may need per step and point: 2 coordinates x 8 bytes x 40 arrays, an upper
#: bound of the measured peaks (about 31 such arrays for the 100k-step crank-rocker with every
#: effect, 9 for the Jansen linkage's kinematics); the force stage adds the constraint
#: Jacobian's inverse, (2 P)^2 numbers per step, counted twice for its temporaries
BYTES_PER_POINT_STEP = 2 * 8 * 40


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


def check_memory(scene: Scene) -> None:
    """SceneError when the sweep would need more memory than is available (before any work:
    a run that the kernel kills half-way writes nothing)."""
    P = max(1, len(scene.points))
    per_step = P * BYTES_PER_POINT_STEP + (2 * 8 * (2 * P) ** 2 if scene.effects else 0)
    need = scene.n_steps * per_step
    avail = available_memory()
    if avail is not None and need > avail:
        first = scene.drivers[0] if scene.drivers else None
        driver = first.name if first else ""
        key = "step" if first is not None and first.step is not None else "steps"
        raise SceneError(scene.path, f'drivers "{driver}"', key,
                         f"{scene.n_steps:,} steps of {len(scene.points)} points need about "
                         f"{need / 2**30:.1f} GiB of memory; {avail / 2**30:.1f} GiB is available",
                         ("use a larger step" if key == "step" else "use fewer steps")
                         + ", or split the sweep into several scenes")


def preflight(scene: Scene):
    """Check what can be checked before solving; return (model, mobility).

    The scene's memory need, its degrees of freedom against its drivers, and that the start
    assembles at the first driver value (SceneError otherwise): what ``check`` reports."""
    check_memory(scene)
    model = build_model(scene)
    mob = check_mobility(model)
    _, s, _, _ = kin.driver_motion(model)  # a scene has at least one step
    kin.start_state(model, s[0], scene.solver.tol * model.size, scene.solver.max_iter)
    return model, mob


def solve(scene: Scene | str, progress=None) -> Result:
    """Run every stage the scene calls for and return the result (failed steps are data).

    ``progress``: an optional callable ``progress(stage_name)`` told as each stage starts
    (the CLI drives a tqdm bar with it on long sweeps).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    plan = Plan.of(scene)
    tell = progress if callable(progress) else (lambda stage: None)
    seconds: dict[str, float] = {}
    t0 = _time.perf_counter()
    check_memory(scene)
    model = build_model(scene)
    mob = check_mobility(model)
    seconds["model"] = _time.perf_counter() - t0

    tell("positions")
    t0 = _time.perf_counter()
    value, s, s_dot, s_ddot = kin.driver_motion(model)
    # closed-form dyads or the general Newton path, as [solver] method says (see batch.stage1);
    # the dyad path also gives velocities and accelerations here
    order = 2 if plan.acceleration else 1 if plan.velocity else 0
    k1 = batch.stage1(model, s, s_dot, s_ddot, order)
    X, residual, iterations, status = k1["position"], k1["residual"], k1["iterations"], k1["status"]
    link_angle = kin.link_angles_unwrapped(model, X)
    seconds["positions"] = _time.perf_counter() - t0

    tell("jacobian")
    t0 = _time.perf_counter()
    Xz = np.where(np.isfinite(X), X, 0.0)
    der = batch.derivatives(model, Xz, s, s_dot, s_ddot, status, plan.acceleration,
                            velocity=k1["velocity"], acceleration=k1["acceleration"],
                            need_inverse=plan.forces)
    status = der["status"]
    seconds["jacobian"] = _time.perf_counter() - t0

    time, time_note = _time_axis(scene, value)
    res = Result(scene=scene, model=model, mobility=mob, driver_value=value,
                 time=time, time_note=time_note, position=X, link_angle=link_angle,
                 status=status, residual=residual, iterations=iterations,
                 condition=der["condition"], solver_method_used=k1["method"],
                 solver_note=k1["note"])
    if scene.solver.derivatives == "finite_difference" and plan.velocity:
        t0 = _time.perf_counter()
        fdV, fdA = kin.fd_derivatives(X, s, s_dot, s_ddot, status, plan.acceleration)
        der["velocity"] = np.where(status[:, None, None] == kin.OK, fdV, np.nan)
        if plan.acceleration:
            der["acceleration"] = np.where(status[:, None, None] == kin.OK, fdA, np.nan)
        # the stored residuals describe the stored (finite-difference) derivatives
        der.update(_residuals(model, Xz, s, s_dot, s_ddot, der["velocity"], der["acceleration"]
                              if plan.acceleration else None))
        seconds["fd_derivatives"] = _time.perf_counter() - t0
    if plan.velocity:
        res.velocity = der["velocity"]
        res.velocity_residual = der["velocity_residual"]
    if plan.acceleration:
        res.acceleration = der["acceleration"]
        res.acceleration_residual = der["acceleration_residual"]
    if plan.velocity:
        res.link_angular_velocity, res.link_angular_acceleration = kin.link_rates(
            model, X, res.velocity, res.acceleration)
    if plan.forces:
        from .forces import force_stage

        tell("forces")
        t0 = _time.perf_counter()
        res.forces = force_stage(res, der["jacobian_inverse"], s, s_dot, s_ddot)
        if "__status__" in res.forces:
            res.status = res.forces.pop("__status__")[1]
        seconds["forces"] = _time.perf_counter() - t0
    res.seconds = seconds
    res.message = _message(res)
    return res


def _residuals(model, X, s, s_dot, s_ddot, V, A) -> dict:
    """Return the residuals of ``Phi_q qd = -Phi_t`` and ``Phi_q qdd = gamma`` for given V, A."""
    S = X.shape[0]
    out = {"velocity_residual": np.full(S, np.nan)}
    good = np.isfinite(V).all(axis=(1, 2))
    if A is not None:
        out["acceleration_residual"] = np.full(S, np.nan)
        good &= np.isfinite(A).all(axis=(1, 2))
    if good.any():
        J = model.jacobian(X[good], s[good])
        qd = model.q_of(V[good])
        out["velocity_residual"][good] = np.abs(np.einsum("sij,sj->si", J, qd) + model.phi_t(
            X[good], s[good], s_dot[good])).max(axis=1)
        if A is not None:
            g = model.gamma(X[good], V[good], s[good], s_dot[good], s_ddot[good])
            out["acceleration_residual"][good] = np.abs(
                np.einsum("sij,sj->si", J, model.q_of(A[good])) - g).max(axis=1)
    return out


def _time_axis(scene: Scene, value: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Return (seconds per step, note): the time when every driver has a rate and no
    acceleration, ``|value - from| / |rate|``, and all drivers agree on it (to 1e-9 of the
    sweep's duration); else None, with a note saying why when the rates alone would give one."""
    rates = np.array([d.rate for d in scene.drivers], dtype=float)
    accs = np.array([d.acceleration for d in scene.drivers], dtype=float)
    if not len(rates) or np.any(rates == 0) or np.any(accs != 0):
        return None, ""
    times = [np.abs(value[:, j] - d.from_value) / abs(d.rate) for j, d in enumerate(scene.drivers)]
    t = times[0]
    span = float(max(tj.max() for tj in times)) if value.shape[0] else 0.0
    for tj in times[1:]:
        if not np.allclose(tj, t, rtol=0, atol=1e-9 * max(span, 1e-300)):
            ends = ", ".join(f"{d.name} {tj[-1]:.6g} s" for d, tj in zip(scene.drivers, times))
            return None, (f"no time axis: the drivers' rates give different times for the same "
                          f"steps (at the last step: {ends}); make each driver's "
                          f"(to - from) / rate the same")
    return t, ""


def _message(res: Result) -> str:
    counts = res.status_counts()
    failed = res.n_steps - res.n_ok
    if not failed:
        return f"all {res.n_steps} steps ok"
    return f"{res.n_ok}/{res.n_steps} steps ok; " + ", ".join(
        f"{n} {k}" for k, n in counts.items() if k != "ok")
