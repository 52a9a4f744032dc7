"""Stage 2: the effects a scene names, the input force by virtual work, Lagrange multipliers.

Everything is vectorised over steps. Notation (per step): ``q`` the moving coordinates,
``J = Phi_q`` (n_rows, n_q), ``K = dq/ds`` (n_q, n_drivers) the influence coefficients
(``K = -J^-1 Phi_s`` over the driver rows). Applied forces are point forces
``(S, n_points, 2)`` plus couples on links ``(S, n_links)`` (:mod:`.applied`).

1. :mod:`.effects`: each named effect (:data:`EFFECTS`) gives its applied loads.
2. :mod:`.virtual_work`: the actuator's generalized force per driver is ``F = -K^T Q`` where
   ``Q`` holds the applied loads including d'Alembert inertia ``-m a_G`` and ``-I alpha`` — so
   it is defined at ``rate = 0``; with ``input`` it is divided by the input point's leverage.
3. :mod:`.lagrange`: ``J^T lambda = Q - M qdd`` with each body's constant natural-coordinate
   mass matrix ``M = m N_G^T N_G + (I_G / L^2) D^T D`` — a different formulation and a different
   linear solve; the driver rows give ``F = lambda_d dPhi_d/ds`` again, the others the internal
   forces (tension positive), the ground reactions and the pin forces on every body.
"""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..result import Forces, Motion
from ..status import OK
from .applied import with_couples_as_pairs
from .constants import ForceConstants
from .effects import EFFECTS, Context, applies
from .lagrange import body_rows, internal_forces, joints, multipliers, reactions
from .virtual_work import Influence, along_input_directions

__all__ = ["compute_forces", "EFFECTS"]


def compute_forces(model: Model, motion: Motion, units: dict,
                   constants: ForceConstants | None = None) -> Forces:
    """Compute every named effect and the input force of a solved sweep.

    ``motion``: the sweep (positions, derivatives, kinematic status, Jacobian inverse);
    ``units``: the scene's unit strings; ``constants``: the force tables' numbers when they
    differ from the scene's (per step: a study's variants on one step axis). Returns :class:`Forces` (variables in the contract's
    names, the labels of the dimensions they add, and the status with no_leverage added).
    """
    ctx = Context.of(model, motion, units, constants)
    n_steps = ctx.n_steps
    Xz = np.where(np.isfinite(motion.position), motion.position, 0.0)
    influence = Influence.of(model, motion.position, Xz, motion.s, motion.influence)
    variables: dict = {}
    coords: dict = {}

    # 1. the effects; the Lagrange side's Q - M qdd and each body's M_k Xdd - Q_k beside them
    applied, bodies = {}, {}
    lagrange_points, lagrange_couples = ctx.zeros_points(), ctx.zeros_links()
    for name, effect_of in EFFECTS.items():
        if name not in ctx.effects or not applies(name, ctx):
            continue
        effect = effect_of(ctx)
        applied[name] = effect.applied
        variables.update(effect.variables)
        coords.update(effect.coords)
        if effect.lagrange is None:
            lagrange_points += effect.applied.point_forces
            lagrange_couples += effect.applied.couples
        else:
            lagrange_points = lagrange_points + effect.lagrange
        for li, body in effect.bodies.items():
            bodies[li] = bodies[li] + body if li in bodies else body

    # 2. virtual work: F_j = -sum(Q . dq/ds_j), and each effect's power
    generalized = {name: influence.generalized(a) for name, a in applied.items()}
    input_force = (-sum(generalized.values()) if generalized
                   else np.zeros((n_steps, model.n_drivers)))
    variables["power"] = (("step", "effect"), np.stack(
        [(generalized[e] * motion.s_dot).sum(axis=1) for e in applied], axis=1)
        if applied else np.zeros((n_steps, 0)), f"{units['force']}*{units['length']}/{units['time']}")
    coords["effect"] = list(applied)

    # 3. Lagrange multipliers: J^T lambda = Q - M qdd (an independent solve)
    ok = motion.status == OK
    q_minus_m_qdd = with_couples_as_pairs(model, lagrange_points, lagrange_couples, Xz)
    generalized_q = q_minus_m_qdd[:, model.moving].reshape(n_steps, -1)
    lam, undetermined = multipliers(model, Xz, motion.s, generalized_q, ok)
    input_force_lagrange = lam[:, model.driver_rows] * influence.phi_s
    status, unit = along_input_directions(model, influence, [input_force, input_force_lagrange],
                                          motion.status, units, Xz, ctx.constants.size)
    variables["input_force"] = (("step", "driver"), input_force, unit)
    variables["input_force_lagrange"] = (("step", "driver"), input_force_lagrange, unit)
    internal, internal_coords, undefined = internal_forces(model, lam, undetermined, units)
    variables.update(internal)
    coords.update(internal_coords)
    pins, pin_coords = _reactions(model, ctx, lam, q_minus_m_qdd, bodies, Xz, ok, undetermined,
                                  applied.get("loads"))
    variables.update(pins)
    coords.update(pin_coords)
    return Forces(variables=variables, coords=coords, status=status, undefined=undefined)


def _reactions(model: Model, ctx: Context, lam, q_minus_m_qdd, bodies, Xz, ok, undetermined,
               loads) -> tuple[dict, dict]:
    """``joint_force`` (and ``ground_reaction`` where there are fixed points), with the
    uniqueness flags a redundant scene needs."""
    scene, force_unit, n_steps = model.scene, ctx.units["force"], ctx.n_steps
    if loads is not None:  # a couple on a link acts on that body: part of its own -Q_k
        for li in np.flatnonzero(np.any(loads.couples != 0, axis=0)):
            couple = np.zeros_like(loads.couples)
            couple[:, li] = loads.couples[:, li]
            as_pairs = with_couples_as_pairs(model, np.zeros((n_steps, model.n_points, 2)), couple, Xz)
            bodies[li] = bodies[li] - as_pairs if li in bodies else -as_pairs
    ground, pin_forces = reactions(model, lam, q_minus_m_qdd, bodies, Xz, ctx.motion.s, ok)
    pairs = joints(model)
    out = {"joint_force": (("step", "joint", "xy"), pin_forces, force_unit)}
    coords = {"joint": [f"{model.point_names[p]}@{scene.links[li].name}" for li, p in pairs]}
    # under redundancy a self-stress changes the multipliers of the undetermined rows: a
    # reaction is not unique where such a row acts (minimum-norm choice reported, flagged)
    touched = None
    if undetermined.any() and ok.any():
        i0 = np.flatnonzero(ok)[0]
        touched = np.abs(model.jacobian_points(Xz[i0:i0 + 1], ctx.motion.s[i0:i0 + 1])[0]).max(axis=2)
        row_link = body_rows(model)
        unique = [0 if (touched[undetermined & (row_link == li), p] > 0).any() else 1 for li, p in pairs]
        out["joint_force_unique"] = (("joint",), np.array(unique, dtype=np.int8), "1")
    fixed = np.flatnonzero(model.fixed)
    if len(fixed):
        out["ground_reaction"] = (("step", "fixed_point", "xy"), ground, force_unit)
        coords["fixed_point"] = [model.point_names[i] for i in fixed]
        if touched is not None:
            hit = touched[undetermined][:, fixed].max(axis=0) > 0
            out["ground_reaction_unique"] = (("fixed_point",), (~hit).astype(np.int8), "1")
    return out, coords
