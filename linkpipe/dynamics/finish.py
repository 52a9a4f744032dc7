"""A trajectory made into a Result: the one place dynamics meets the pipeline's finish.

The output instants are a sweep like any other: the positions by stage 1's own solver at the
integrated driver values, the rates and influence coefficients by
:func:`linkpipe.kinematics.derivatives`, the drivers' accelerations from the equations of
motion, then the force stage, status and Result exactly as :func:`linkpipe.pipeline.solve`
builds them (the force stage here, then :func:`linkpipe.spine.finish`: status and Result).
Dynamics adds ``energy_error`` (step) to the forces and puts the applied force in
``input_force``.
"""
from __future__ import annotations

import numpy as np

from .. import kinematics as kin
from ..forces import compute_forces
from ..model.drive import DriverMotion
from ..output_units import units_of
from ..stage1 import Kinematics
from ..status import NO_ASSEMBLY, OK
from .equations import MotionEquations, State, potential_of
from .forcing import Forcing
from .integrate import Trajectory


def kinematics_of(eqs: MotionEquations, traj: Trajectory,
                  mobility) -> tuple[Kinematics, np.ndarray, State]:
    """(stage 1 of the S output instants: positions, rates, the accelerations the equations
    of motion give; the drivers' forces F (S, nd); the instants' State, NaN where unsolved)."""
    scene, model = eqs.scene, eqs.model
    S, nd = traj.s.shape
    solved = traj.solved
    s = np.where(solved[:, None], traj.s, np.nan)
    sd = np.where(solved[:, None], traj.sd, np.nan)
    X = np.full((S, model.n_points, 2), np.nan)
    X[:, model.fixed] = model.start_position[model.fixed]
    residual, iterations = np.full(S, np.nan), np.zeros(S, np.int32)
    status = np.full(S, NO_ASSEMBLY, np.int8)
    idx = np.flatnonzero(solved)
    if len(idx):
        sweep = kin.solve_sweep(model, s[idx], sd[idx], np.zeros_like(sd[idx]), 0)
        X[idx], residual[idx] = sweep.position, sweep.residual
        iterations[idx], status[idx] = sweep.iterations, sweep.status
        method, note = sweep.method, sweep.note
    else:
        method, note = "none", ""
    sz, sdz = np.nan_to_num(s), np.nan_to_num(sd)
    Xz = np.where(np.isfinite(X), X, 0.0)
    der = kin.derivatives(model, Xz, sz, sdz, np.zeros_like(sz), status, True, need_influence=True)
    link_angle = kin.link_angles_unwrapped(model, X, s=s)
    F = Forcing(scene).over(traj.t)
    state = eqs.state_of(X, sz, sdz, der["velocity"], der["acceleration"], der["influence"],
                         link_angle)
    sdd = eqs.accelerations(state, F)
    K = np.nan_to_num(der["influence"])
    A = der["acceleration"].copy()
    A[:, model.moving] += np.einsum("sid,sd->si", K, np.nan_to_num(sdd)).reshape(S, -1, 2)
    der["acceleration"] = A
    V = der["velocity"]
    link_rates = kin.link_rates(model, X, V, A)
    to_scene = np.array([180 / np.pi if d.kind == "angle" else 1.0 for d in scene.drivers])
    drive = DriverMotion(s * to_scene, sd * to_scene, sdd * to_scene, traj.t, solved.copy())
    sweep = kin.Sweep(X, residual, iterations, status, method, note)
    k = Kinematics(mobility, drive, s, sd, sdd, sweep, link_angle, der, V, A, link_rates)
    return k, F, state


def energy_error(eqs: MotionEquations, state: State, traj: Trajectory,
                 variables: dict) -> np.ndarray:
    """(S,) kinetic + stored energy (the force stage's ``variables``: springs, torsion springs,
    gravity) - their start values - the drivers' work - the work of the effects that store none
    (damping, loads) - friction's work (the seals'): zero for the exact motion."""
    E = eqs.kinetic_energy(state) + potential_of(variables, len(traj.t))
    return E - E[0] - traj.work_drivers - traj.work_other - traj.work_friction


def forces_of(eqs: MotionEquations, k: Kinematics, F: np.ndarray, state: State,
              traj: Trajectory):
    """The force stage of the motion (every effect, inertia too, the Lagrange side with the
    reactions), with ``input_force`` the applied force and ``energy_error`` added."""
    forces = compute_forces(eqs.model, k.motion(), units_of(eqs.scene))
    unit = forces.variables["input_force"][2]
    applied = np.where(k.der["status"][:, None] == OK, F, np.nan)
    forces.variables["input_force"] = (("step", "driver"), applied, unit)
    units = units_of(eqs.scene)
    err = np.where(k.der["status"] == OK, energy_error(eqs, state, traj, forces.variables),
                   np.nan)
    forces.variables["energy_error"] = (("step",), err, f"{units['force']}*{units['length']}")
    return forces


def describe(traj: Trajectory, err: np.ndarray) -> str:
    """The summary's line on the integration."""
    finite = err[np.isfinite(err)]
    worst = f"; max |energy_error| {np.abs(finite).max():.3g}" if len(finite) else ""
    line = (f"dynamics: {traj.method}, rtol {traj.rtol:g}, {traj.steps} steps, "
            f"{traj.evaluations} evaluations{worst}")
    if traj.event:
        line += f"; ended at t = {traj.end:.12g} s: {traj.event}; the steps after it are no_assembly"
    return line

