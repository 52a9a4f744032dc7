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
from ..result import Forces, Motion, combine_flags
from dataclasses import dataclass

from ..status import NO_ASSEMBLY, NO_INPUT, NOT_CONVERGED, OK, SINGULAR, worst
from . import friction
from .applied import Applied, couple_as_body, merge_bodies, with_couples_as_pairs
from .constants import ForceConstants
from .effects import EFFECTS, Context, Effect, applies
from .lagrange import (body_rows, internal_forces, joints, multipliers, reactions,
                       stacked_multipliers, stacked_reactions)
from .virtual_work import Influence, actuator_forces, along_input_directions

__all__ = ["compute_forces", "EFFECTS"]


#: steps per chunk of the force stage: each chunk's temporaries (a few dozen (chunk, P, 2)
#: arrays) stay in cache and the stage's peak memory is its outputs plus one chunk's work, not
#: a multiple of the sweep (benchmarks/bench_logs.py measures both)
FORCE_CHUNK = 16384

#: the same with pin or slider friction, whose unit load cases hold K + 1 times a frictionless
#: chunk's multipliers and pin forces (K: the links a pin friction turns and the sliders with
#: friction): half the steps keep them in cache (benchmarks/bench_friction.py; docs/performance.md)
FRICTION_CHUNK = 8192


#: the variables only the Lagrange multipliers give (an independent solve: skipped when a caller
#: such as a fit's trial needs none of them)
LAGRANGE_VARIABLES = frozenset({"input_force_lagrange", "link_force", "slider_force",
                                "joint_force", "ground_reaction"})


def compute_forces(model: Model, motion: Motion, units: dict,
                   constants: ForceConstants | None = None, chunk: int | None = None,
                   lagrange: bool = True, cache: dict | None = None) -> Forces:
    """Compute every named effect and the input force of a solved sweep, in chunks of steps.

    ``motion``: the sweep (positions, derivatives, kinematic status, influence coefficients);
    ``units``: the scene's unit strings; ``constants``: the force tables' numbers when they
    differ from the scene's (per step: a study's variants on one step axis; cut into the same
    chunks). Returns :class:`Forces` (variables in the contract's
    names, the labels of the dimensions they add, and the status with no_leverage added).
    Every step's forces depend on that step alone, so each chunk is solved on its own and
    written into outputs allocated once; the per-joint ``*_unique`` flags (no self-stress
    reaches that force at any ok step) are the minimum over the chunks. ``lagrange=False``
    leaves out the multipliers and what they give (:data:`LAGRANGE_VARIABLES`); then a
    ``cache`` dict kept with one stage 1 across calls (a fit's trials) saves the influence
    coefficients and every effect whose scene inputs did not change (:func:`_effect_terms`).
    ``chunk``: steps per chunk (default :data:`FORCE_CHUNK`, :data:`FRICTION_CHUNK` where pin
    or slider friction is solved).
    """
    n_steps = motion.position.shape[0]
    if chunk is None:
        coupled = ("friction" in model.scene.effects and model.scene.friction
                   and friction.Layout.of(model).coupled)
        chunk = FRICTION_CHUNK if coupled else FORCE_CHUNK
    if cache is not None and constants is not None:
        raise ValueError("a cache keys effects by the scene's tables: not with constants")
    if n_steps <= chunk:
        return _forces_of(model, motion, units, constants, lagrange, cache, (0, n_steps))
    out = None
    for lo in range(0, n_steps, chunk):
        rows = slice(lo, lo + chunk)
        part = _forces_of(model, motion.rows(rows), units,
                          None if constants is None else constants.rows(rows), lagrange, cache,
                          (lo, chunk))
        out = _gathered(out, part, n_steps)
        for name, (dims, data, unit) in part.variables.items():
            if dims[:1] == ("step",):
                out.variables[name][1][lo:lo + len(part.status)] = data
        out.status[lo:lo + len(part.status)] = part.status
    return out


def _gathered(out: Forces | None, part: Forces, n_steps: int) -> Forces:
    """The whole sweep's Forces, allocated from the first chunk (step-first variables of
    ``n_steps`` rows, filled by the caller); later chunks add their flags (minimum)."""
    if out is None:
        variables = {name: (dims, np.empty((n_steps,) + data.shape[1:], data.dtype)
                            if dims[:1] == ("step",) else data.copy(), unit)
                     for name, (dims, data, unit) in part.variables.items()}
        return Forces(variables=variables, coords=dict(part.coords),
                      status=np.empty(n_steps, part.status.dtype), undefined=part.undefined)
    combine_flags(out.variables, part.variables)
    return out


#: the scene entries each effect reads: an effect is computed again only when these change
EFFECT_INPUTS = {"springs": ("springs", "torsion_springs", "effects"), "damping": ("springs",),
                 "gravity": ("masses", "gravity"), "loads": ("loads",), "inertia": ("masses",)}


#: the values of one effect kept per chunk in a fit's cache, most recent first: a
#: finite-difference Jacobian moves one parameter at a time from the current point, so the
#: current point's value and the moved one are all it asks for again (bounded memory)
CACHED_VALUES = 3


def _effect_terms(ctx: Context, influence: Influence, cache: dict | None, chunk_key) -> dict:
    """{effect: (generalized force (S, nd), variables, coords, Effect or None)} of every effect
    the scene names. With ``cache`` (virtual work only: a fit's trials on one stage 1), an
    effect whose scene inputs (:data:`EFFECT_INPUTS`) equal those of one of the last
    :data:`CACHED_VALUES` calls on the same chunk is taken from it, its Effect left out (None)."""
    scene, out = ctx.model.scene, {}
    for name, effect_of in EFFECTS.items():
        if name not in ctx.effects or not applies(name, ctx) or effect_of is None:
            continue
        inputs = repr([getattr(scene, a) for a in EFFECT_INPUTS[name]])
        kept = cache.setdefault((chunk_key, name), {}) if cache is not None else None
        if kept is not None and inputs in kept:
            out[name] = kept[inputs] = kept.pop(inputs)  # now the most recent
            continue
        effect = effect_of(ctx)
        out[name] = (influence.generalized(effect.applied), effect.variables, effect.coords, effect)
        if kept is not None:
            kept[inputs] = out[name][:3] + (None,)
            while len(kept) > CACHED_VALUES:
                kept.pop(next(iter(kept)))  # the least recently used
    return out


#: the force stage's variables that are not forces and that the positions alone determine
#: (lengths, angles, energies): a singular step (positions solved; derivatives and what the
#: constraint Jacobian gives undetermined) keeps them; every force, a spring's and a torsion
#: spring's included, is NaN there, as the contract has it ("singular steps keep their
#: positions, with NaN derivatives and forces").
POSITION_ONLY = frozenset({"spring_length", "spring_extension", "spring_energy",
                           "torsion_spring_angle", "torsion_spring_energy", "gravity_energy"})

#: kinematic statuses whose steps hold no solved positions: every force-stage variable is NaN
UNSOLVED = (NO_ASSEMBLY, NOT_CONVERGED, NO_INPUT)


def failed_steps_as_nan(variables: dict, kinematic_status: np.ndarray) -> None:
    """Set, in place, each step-first float variable of ``variables`` {name: (dims, (S, ...),
    units)} to NaN at the steps stage 1 did not solve (no_assembly, not_converged, no_input)
    and, but for :data:`POSITION_ONLY`, at singular steps (docs/scene-format.md, "Results at
    steps that fail"). A law that maps a NaN length to a number (a gas spring's clamp, a
    one-sided spring's slack branch) cannot then leave a finite force at a failed step."""
    unsolved = np.isin(kinematic_status, UNSOLVED)
    singular = kinematic_status == SINGULAR
    if not (unsolved.any() or singular.any()):
        return
    for name, (dims, data, _) in variables.items():
        if dims[:1] != ("step",) or data.dtype.kind != "f":
            continue
        data[unsolved if name in POSITION_ONLY else unsolved | singular] = np.nan


def _forces_of(model: Model, motion: Motion, units: dict, constants=None, lagrange: bool = True,
               cache: dict | None = None, chunk_key=0) -> Forces:
    """The force stage on one chunk of steps (see :func:`compute_forces`); at failed steps
    every variable is NaN (:func:`failed_steps_as_nan`)."""
    forces = _forces_computed(model, motion, units, constants, lagrange, cache, chunk_key)
    failed_steps_as_nan(forces.variables, motion.status)
    return forces


def _forces_computed(model: Model, motion: Motion, units: dict, constants=None,
                     lagrange: bool = True, cache: dict | None = None, chunk_key=0) -> Forces:
    """The force stage's computation on one chunk of steps, before failed steps are masked."""
    layout = (friction.Layout.of(model) if "friction" in model.scene.effects
              and model.scene.friction else None)
    wanted = lagrange  # whether the Lagrange side's own variables are stored
    lagrange = lagrange or (layout is not None and layout.coupled)  # pins', sliders' friction
    ctx = Context.of(model, motion, units, constants, lagrange)
    n_steps = ctx.n_steps
    Xz = np.where(np.isfinite(motion.position), motion.position, 0.0)
    if cache is not None and (chunk_key, "influence") in cache:
        influence = cache[(chunk_key, "influence")]
    else:
        influence = Influence.of(model, motion.position, Xz, motion.s, motion.influence,
                                 ctx.constants.model_rows)
        if cache is not None:
            cache[(chunk_key, "influence")] = influence
    terms = _effect_terms(ctx, influence, None if lagrange else cache, chunk_key)
    seal = None
    if layout is not None:  # the seals now, pins and sliders with the forces they change
        seal = friction.seal_loads(ctx, layout, influence.phi_s)
        terms["friction"] = (influence.generalized(seal[1]), {}, {},
                             Effect(seal[1], bodies=seal[2]))
    if lagrange:
        return _with_lagrange(model, ctx, motion, units, influence, terms, Xz, layout, seal,
                              None if cache is None else (cache, chunk_key), wanted)
    if layout is not None:
        _friction_term(ctx, influence, terms, layout, seal, None, None, Xz)
    variables, coords = _effect_variables(terms, motion, units)
    input_force = _virtual_work(model, terms, n_steps)
    status, unit = along_input_directions(model, influence, [input_force], motion.status,
                                          units, Xz, ctx.constants.size)
    variables["input_force"] = (("step", "driver"), input_force, unit)
    return Forces(variables=variables, coords=coords, status=status)


def _virtual_work(model: Model, terms: dict, n_steps: int) -> np.ndarray:
    """F_j = -sum(Q . dq/ds_j) over every effect: the drivers' generalized forces (S, nd)."""
    return (-sum(t[0] for t in terms.values()) if terms
            else np.zeros((n_steps, model.n_drivers)))


def _effect_variables(terms: dict, motion: Motion, units: dict) -> tuple[dict, dict]:
    """The effects' own variables and labels, and ``power``: each effect's power per step."""
    variables: dict = {}
    coords: dict = {}
    for _, names, labels, _ in terms.values():
        variables.update(names)
        coords.update(labels)
    n_steps = motion.s.shape[0]
    variables["power"] = (("step", "effect"), np.stack(
        [(t[0] * motion.s_dot).sum(axis=1) for t in terms.values()], axis=1)
        if terms else np.zeros((n_steps, 0)), f"{units['force']}*{units['length']}/{units['time']}")
    coords["effect"] = list(terms)
    return variables, coords


def _friction_term(ctx, influence, terms, layout, seal, solved, rates, Xz) -> None:
    """Put the whole friction effect in ``terms``: the seals' loads plus, where ``solved``
    (pair torques, slider forces, link couples), the pins' and sliders'."""
    seal_signed, applied, bodies = seal
    n_pairs, n_slides = len(layout.pairs), len(layout.slides)
    torque = np.zeros((ctx.n_steps, n_pairs)) if solved is None else solved[0]
    force = np.zeros((ctx.n_steps, n_slides)) if solved is None else solved[1]
    work = terms["friction"][0]  # the seals' virtual work, put there with their loads
    if solved is not None:  # plus the pins' couples' and the sliders' forces'
        more = friction.applied_of(ctx, layout, solved[2], force, Xz)
        if layout.slides:
            applied = Applied(applied.point_forces + more.point_forces,
                              applied.couples + more.couples)
            work = work + influence.generalized(more)
        else:  # couples alone: no point forces to add or to take the work of
            applied = Applied(applied.point_forces, applied.couples + more.couples)
            work = work + influence.couples_work(more.couples)
    if rates is None:
        rates = friction.Rates(np.zeros((ctx.n_steps, n_pairs)), np.zeros((ctx.n_steps, n_slides)))
    names, labels = friction.variables(ctx, layout, seal_signed, ctx.motion.s_dot, rates,
                                       torque, force)
    terms["friction"] = (work, names, labels, Effect(applied, bodies=bodies))


def _lagrange_sides(model, ctx, terms, Xz):
    """Each body's ``M_k Xdd - Q_k`` ({link: {point: (S, 2)}}, link couples of ``loads`` and
    the seals' body loads included) and ``Q - M qdd`` at every point (S, P, 2), couples as
    force pairs (inertia enters through the mass matrix)."""
    bodies = {}
    lagrange_points, lagrange_couples = ctx.zeros_points(), ctx.zeros_links()
    for name, (_, _, _, effect) in terms.items():
        if effect.lagrange is None:
            lagrange_points += effect.applied.point_forces
            lagrange_couples += effect.applied.couples
        else:
            lagrange_points = lagrange_points + effect.lagrange
        for li, body in effect.bodies.items():
            merge_bodies(bodies.setdefault(li, {}), body)
        if name == "loads":  # a couple on a link acts on that body: part of its own -Q_k
            for li in np.flatnonzero(np.any(effect.applied.couples != 0, axis=0)):
                as_pairs = couple_as_body(model, effect.applied.couples[:, li], int(li), Xz)
                merge_bodies(bodies.setdefault(int(li), {}), as_pairs, -1.0)
    return bodies, with_couples_as_pairs(model, lagrange_points, lagrange_couples, Xz)


@dataclass
class _Case:
    """One load case on the Lagrange side (linear in its loads: friction's unknowns are added
    case by case). ``input_force`` by virtual work and ``input_force_lagrange`` (S, nd) along
    the inputs' directions; ``lam`` the multipliers the reactions come from (with the pushes
    of ``input`` as loads), ``pins`` (S, n_joints, 2), ``ground`` (S, n_fixed, 2)."""

    input_force: np.ndarray
    input_force_lagrange: np.ndarray
    lam: np.ndarray
    undetermined: np.ndarray
    status: np.ndarray
    unit: str
    pins: np.ndarray
    ground: np.ndarray
    ok: np.ndarray
    q_minus_m_qdd: np.ndarray

    def plus(self, u: np.ndarray, cases: dict) -> "_Case":
        """This case plus ``u[:, k]`` (S,) times each of ``cases`` ({name: (K, S, ...)})."""
        out = {}
        uT = np.ascontiguousarray(u.T)  # (K, S)
        for name in ("input_force", "input_force_lagrange", "lam", "pins", "ground"):
            # the cases' sum in one pass over them, the step axis last (where the stacked
            # cases keep it contiguous), laid out (..., K, S)
            total = np.einsum("...ks,ks->...s", np.moveaxis(cases[name], (0, 1), (-2, -1)), uT)
            total += np.moveaxis(getattr(self, name), 0, -1)
            out[name] = np.moveaxis(total, -1, 0)
        return _Case(**out, undetermined=self.undetermined, status=self.status, unit=self.unit,
                     ok=self.ok, q_minus_m_qdd=self.q_minus_m_qdd)


def _case(model, ctx, motion, units, influence, q_minus_m_qdd, bodies, generalized, Xz,
          factors: dict | None = None, only=None) -> _Case:
    """Solve one load case: ``q_minus_m_qdd`` (S, P, 2), ``bodies`` {link: {point: (S, 2)}}
    (changed: the pushes' body loads are added), ``generalized`` (S, nd) its virtual work;
    ``factors``: the Jacobian's entries kept across cases (:func:`.lagrange.multipliers`)."""
    n_steps = ctx.n_steps
    ok = motion.status == OK
    input_force = -generalized
    lam, undetermined = multipliers(model, Xz, motion.s,
                                    q_minus_m_qdd[:, model.moving].reshape(n_steps, -1), ok,
                                    ctx.constants.pivots, ctx.constants.model_rows, factors)
    input_force_lagrange = lam[:, model.driver_rows] * influence.phi_s
    status, unit = along_input_directions(model, influence, [input_force, input_force_lagrange],
                                          motion.status, units, Xz, ctx.constants.size)
    actuators = actuator_forces(model, input_force, Xz)
    if actuators is not None:  # the reactions of the actuators `input` describes (a push at
        pushes, on_bodies = actuators  # its point), not of a torque at the driver's pivot
        q_minus_m_qdd = q_minus_m_qdd + pushes
        ok = status == OK  # where the push is known (not no_leverage)
        lam, undetermined = multipliers(model, Xz, motion.s,
                                        q_minus_m_qdd[:, model.moving].reshape(n_steps, -1), ok,
                                        ctx.constants.pivots, ctx.constants.model_rows, factors)
        for li, body in on_bodies.items():  # part of the body's own Q_k
            merge_bodies(bodies.setdefault(li, {}), body, -1.0)
    ground, pins = reactions(model, lam, q_minus_m_qdd, bodies, Xz, motion.s, ok,
                             ctx.constants.model_rows, only)
    return _Case(input_force, input_force_lagrange, lam, undetermined, status, unit, pins,
                 ground, ok, q_minus_m_qdd)


def _with_lagrange(model, ctx, motion, units, influence, terms, Xz, layout=None,
                   seal=None, kept=None, wanted: bool = True) -> Forces:
    """The Lagrange side: ``J^T lambda = Q - M qdd`` (an independent solve), the input force
    from it, internal forces and every pin's reaction; with pin or slider friction, the
    friction that makes them consistent (:func:`linkpipe.forces.friction.solve_magnitudes`)."""
    bodies, q_minus_m_qdd = _lagrange_sides(model, ctx, terms, Xz)
    factors = only = None  # with friction's load cases: one Jacobian's entries for all of them
    if layout is not None and layout.coupled:
        factors = {} if kept is None else kept[0].setdefault((kept[1], "factors"), {})
        if not wanted:  # the pin forces friction needs, no more
            only = {(b, p) for _, p, i, j in layout.pairs for b in (i, j) if b >= 0}
    base = _case(model, ctx, motion, units, influence, q_minus_m_qdd, bodies,
                 sum(t[0] for t in terms.values()) if terms
                 else np.zeros((ctx.n_steps, model.n_drivers)), Xz, factors, only)
    extra_status = None
    if layout is not None:
        case, extra_status = _with_friction(model, ctx, motion, units, influence, terms, Xz,
                                            layout, seal, base, kept, factors, wanted)
    else:
        case = base
    variables, coords = _effect_variables(terms, motion, units)
    input_force = _virtual_work(model, terms, ctx.n_steps)
    status, unit = along_input_directions(model, influence, [input_force], motion.status,
                                          units, Xz, ctx.constants.size)
    if extra_status is not None:
        status = worst(status, extra_status)
    variables["input_force"] = (("step", "driver"), input_force, unit)
    if not wanted:  # friction needed the multipliers; the caller wants none of what they give
        if extra_status is not None:
            failed_steps_as_nan(variables, extra_status)
        return Forces(variables=variables, coords=coords, status=status)
    variables["input_force_lagrange"] = (("step", "driver"), case.input_force_lagrange, unit)
    internal, internal_coords, undefined = internal_forces(model, case.lam, case.undetermined,
                                                           units)
    variables.update(internal)
    coords.update(internal_coords)
    pins, pin_coords = _reactions(model, ctx, case, Xz)
    variables.update(pins)
    coords.update(pin_coords)
    if extra_status is not None:  # friction that did not converge: no force there is known
        failed_steps_as_nan(variables, extra_status)
    return Forces(variables=variables, coords=coords, status=status, undefined=undefined)


def _with_friction(model, ctx, motion, units, influence, terms, Xz, layout, seal, base,
                   kept=None, factors=None, wanted: bool = True):
    """Solve the pins' and sliders' friction with the forces they change: one load case per
    unknown, the magnitudes iterated per step; returns (the total case, status (S,) with
    not_converged where the iteration did not converge). ``kept``: (a fit's cache, chunk key):
    the unit load cases depend on the kinematics alone and are solved once per stage 1;
    ``wanted`` False: the Lagrange side's variables are not stored (the base case returned)."""
    rates = friction.Rates.of(ctx, layout, Xz)
    if not layout.coupled:
        _friction_term(ctx, influence, terms, layout, seal, None, rates, Xz)
        return base, None
    pin_index = {pair: k for k, pair in enumerate(joints(model))}
    key = None if kept is None else (kept[1], "friction_cases", repr(layout))
    resp = kept[0].get(key) if kept is not None else None
    if resp is None:
        resp = _unit_cases(model, ctx, motion, units, influence, layout, Xz, factors)
        if kept is not None:
            kept[0][key] = resp
    # every force pin (row) first, the step axis last: the base case's (S, ...) arrays as
    # views, the unit cases' (K, S, ...) views as the (row, ..., K, S) memory they are
    torque, force, couples, converged = friction.solve_magnitudes(
        ctx, layout, rates, friction.pair_forces(layout, pin_index, np.moveaxis(base.pins, 0, -1)),
        friction.normal_forces(ctx, layout, base.lam.T, Xz),
        friction.pair_forces(layout, pin_index, np.moveaxis(resp["pins"], (0, 1), (2, 3))),
        friction.normal_forces(ctx, layout, np.moveaxis(resp["lam"], 2, 0), Xz), base.ok)
    _friction_term(ctx, influence, terms, layout, seal, (torque, force, couples), rates, Xz)
    u = np.concatenate([couples, -force], axis=1)
    status = np.where(base.ok & ~converged, NOT_CONVERGED, OK).astype(np.int8)
    return (base.plus(u, resp) if wanted else base), status


def _unit_cases(model, ctx, motion, units, influence, layout, Xz, factors) -> dict:
    """The unknowns' unit load cases (:func:`.friction.unit_loads`), K along a leading axis:
    {input_force, input_force_lagrange (K, S, nd), lam (K, S, n_rows), pins (K, S, n_joints,
    2), ground (K, S, n_fixed, 2)}. Solved together (one pass of the block solves and of
    Phi_X's terms) where no driver pushes (``input``) and the model has a sparse engine; else
    case by case (:func:`_case`)."""
    names = ("input_force", "input_force_lagrange", "lam", "pins", "ground")
    if any(d.input is not None for d in model.scene.drivers):
        cases = [_case(model, ctx, motion, units, influence, rhs, bodies, work, Xz, factors)
                 for rhs, work, bodies in friction.unit_loads(ctx, layout, influence, Xz)]
        return {name: np.stack([getattr(c, name) for c in cases]) for name in names}
    n_steps = ctx.n_steps
    # each case's loads straight into the solve's layout (moving coordinates, (K, S, n_q)) and
    # the reactions' (fixed points): no (K, S, n_points, 2) stack of them
    fixed = np.flatnonzero(model.fixed)
    n_cases = len(layout.links) + len(layout.slides)
    # and only at the few points each loads (zeros elsewhere, as the dense loads hold)
    # laid out (n_q, K, S), each coordinate's block contiguous: what the block solves read
    gq_rows = np.zeros((model.n_q, n_cases, n_steps))
    at_fixed = np.zeros((n_cases, n_steps, len(fixed), 2))
    column = {int(p): c for c, p in enumerate(model.moving)}
    fixed_slot = {int(p): c for c, p in enumerate(fixed)}
    generalized, bodies = [], []
    for k, (forces, w, b) in enumerate(friction.unit_load_terms(ctx, layout, influence, Xz)):
        for p, f in forces:
            if p in column:
                gq_rows[2 * column[p]:2 * column[p] + 2, k] += f.T
            else:
                at_fixed[k, :, fixed_slot[p]] += f
        generalized.append(w)
        bodies.append(b)
    gq = np.moveaxis(gq_rows, 0, 2)  # (K, S, n_q) view
    generalized = np.stack(generalized)
    ok = motion.status == OK
    lam = stacked_multipliers(model, Xz, motion.s, gq, ok,
                              ctx.constants.pivots, ctx.constants.model_rows, factors)
    if lam is None:  # no sparse engine: case by case
        lam = np.stack([multipliers(model, Xz, motion.s, g, ok,
                                    ctx.constants.pivots, ctx.constants.model_rows)[0]
                        for g in gq])
    input_force = -generalized
    input_force_lagrange = lam[:, :, model.driver_rows] * influence.phi_s
    input_force[:, ~ok] = np.nan
    input_force_lagrange[:, ~ok] = np.nan
    ground, pins = stacked_reactions(model, lam, at_fixed, bodies, Xz, motion.s, ok,
                                     ctx.constants.model_rows, at_fixed=True)
    return dict(input_force=input_force, input_force_lagrange=input_force_lagrange, lam=lam,
                pins=pins, ground=ground)


def _reactions(model: Model, ctx: Context, case: "_Case", Xz) -> tuple[dict, dict]:
    """``joint_force`` (and ``ground_reaction`` where there are fixed points), with the
    uniqueness flags a redundant scene needs."""
    scene, force_unit = model.scene, ctx.units["force"]
    ground, pin_forces, undetermined, ok = case.ground, case.pins, case.undetermined, case.ok
    pairs = joints(model)
    out = {"joint_force": (("step", "joint", "xy"), pin_forces, force_unit)}
    coords = {"joint": [f"{model.point_names[p]}@{scene.links[li].name}" for li, p in pairs]}
    # under redundancy a self-stress changes the multipliers of the undetermined rows: a
    # reaction is not unique where such a row acts (minimum-norm choice reported, flagged)
    touched = None
    if undetermined.any() and ok.any():
        i0 = np.flatnonzero(ok)[0]
        rows = None if ctx.constants.model_rows is None else ctx.constants.model_rows.take(slice(i0, i0 + 1))
        touched = np.abs(model.jacobian_points(Xz[i0:i0 + 1], ctx.motion.s[i0:i0 + 1],
                                               rows)[0]).max(axis=2)
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
