"""The effects a scene may name, one small function each, and their registry :data:`EFFECTS`.

Each effect takes the :class:`Context` of a solved sweep and returns an :class:`Effect`: the
loads it applies (for virtual work), what it adds to the Lagrange side ``Q - M qdd`` where that
differs (inertia enters there through the mass matrix), what it adds to each body's own
``M_k Xdd - Q_k`` (for the pin forces; at that body's points only: {point: (S, 2)}) and the output variables it stores. Adding an effect or a
spring kind is one function here (or a law in :mod:`.springs`) and one entry in :data:`EFFECTS`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import Model
from ..result import Motion
from .applied import (Applied, add_at_body_point, add_body, body_point, body_point_loads, center_frame,
                      link_index, merge_bodies)
from .constants import ForceConstants
from .springs import SpringGeometry, TorsionSprings, couples_on_bodies, spring_law


@dataclass(frozen=True)
class Context:
    """A solved sweep as the effects see it: positions, velocities and accelerations
    (S, n_points, 2; zeros where the scene needs none), the scene's units and effects,
    each mass with the frame of its centre ``(ia, ib, u, v, L)`` and the force tables'
    numbers (:class:`.constants.ForceConstants`, per step where a study varies them)."""

    model: Model
    motion: Motion
    units: dict
    effects: frozenset
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    masses: tuple
    constants: ForceConstants
    #: whether the Lagrange side (``lagrange``, ``bodies`` of each Effect) is wanted
    lagrange: bool = True

    @classmethod
    def of(cls, model: Model, motion: Motion, units: dict,
           constants: ForceConstants | None = None, lagrange: bool = True) -> "Context":
        X = motion.position
        V, A = motion.velocity, motion.acceleration
        zeros = np.zeros_like(X) if V is None or A is None else None
        constants = constants if constants is not None else ForceConstants.of(model)
        masses = tuple((m, center_frame(model, m.link, m.center, constants.model_rows))
                       for m in model.scene.masses)
        return cls(model, motion, units, frozenset(model.scene.effects), X,
                   V if V is not None else zeros, A if A is not None else zeros, masses,
                   constants, lagrange)

    @property
    def n_steps(self) -> int:
        return self.position.shape[0]

    def zeros_points(self) -> np.ndarray:
        return np.zeros((self.n_steps, self.model.n_points, 2))

    def zeros_links(self) -> np.ndarray:
        return np.zeros((self.n_steps, len(self.model.scene.links)))


@dataclass
class Effect:
    """What one effect contributes. ``lagrange``: its point forces on the Lagrange side when
    they differ from ``applied`` (None: the applied loads themselves); ``bodies``: {link index:
    {point: (S, 2)}} added to that body's ``M_k Xdd - Q_k``; ``variables``: output variables;
    ``coords``: {dimension: labels} of the dimensions those add."""

    applied: Applied
    lagrange: np.ndarray | None = None
    bodies: dict = field(default_factory=dict)
    variables: dict = field(default_factory=dict)
    coords: dict = field(default_factory=dict)


def springs(ctx: Context) -> Effect:
    """Two-point springs of every kind (:func:`.springs.spring_law`) and torsion springs
    (couples on their links, each also part of its body's own equations)."""
    F, L = ctx.units["force"], ctx.units["length"]
    applied, variables = Applied(ctx.zeros_points(), ctx.zeros_links()), {}
    if ctx.model.scene.springs:
        geo = SpringGeometry.of(ctx)
        tension, energy, extension = spring_law(geo, ctx.model.scene.springs)
        total = tension + (geo.damping_force(ctx) if "damping" in ctx.effects else 0.0)
        applied = geo.as_point_forces(ctx, tension)
        variables = {
            "spring_length": (("step", "spring"), geo.length, L),
            "spring_extension": (("step", "spring"), extension, L),
            "spring_energy": (("step", "spring"), energy, f"{F}*{L}"),
            "spring_force": (("step", "spring"), total, F)}
    if not ctx.model.scene.torsion_springs:
        return Effect(applied, variables=variables)
    tors = TorsionSprings.of(ctx.model, ctx.motion.link_angle, ctx.constants.torsion_k,
                             ctx.constants.torsion_free_angle)
    couples = tors.couples(len(ctx.model.scene.links))
    dims = ("step", "torsion_spring")
    variables.update({"torsion_spring_angle": (dims, tors.angle, "rad"),
                      "torsion_spring_torque": (dims, tors.torque, f"{F}*{L}"),
                      "torsion_spring_energy": (dims, tors.energy, f"{F}*{L}")})
    return Effect(Applied(applied.point_forces, applied.couples + couples),
                  bodies=couples_on_bodies(ctx.model, couples, ctx.position),
                  variables=variables,
                  coords={"torsion_spring": [t.name for t in ctx.model.scene.torsion_springs]})


def damping(ctx: Context) -> Effect:
    """Dampers beside the springs: force ``damping * d(length)/dt`` along the spring."""
    geo = SpringGeometry.of(ctx)
    force = geo.damping_force(ctx)
    return Effect(geo.as_point_forces(ctx, force), variables={
        "spring_damping_force": (("step", "spring"), force, ctx.units["force"])})


def gravity(ctx: Context) -> Effect:
    """Each mass's weight ``m g`` at its centre; its potential energy."""
    model, g, mass = ctx.model, ctx.constants.gravity, ctx.constants.mass
    bodies = {}
    for i, (m, frame) in enumerate(ctx.masses):  # -Q_k: the weight on the body
        merge_bodies(bodies.setdefault(link_index(model, m.link), {}),
                     body_point_loads(-mass[..., i, None] * g, *frame, ctx.n_steps))
    potential = np.zeros(ctx.n_steps)
    for i, (m, frame) in enumerate(ctx.masses):
        G = body_point(ctx.position, *frame)
        potential -= mass[..., i] * (G[:, 0] * g[..., 0] + G[:, 1] * g[..., 1])
    weight = ctx.zeros_points()
    for body in bodies.values():
        add_body(weight, body, -1.0)
    return Effect(Applied(weight, ctx.zeros_links()), bodies=bodies, variables={
        "gravity_energy": (("step",), potential, f"{ctx.units['force']}*{ctx.units['length']}")})


def loads(ctx: Context) -> Effect:
    """Constant point forces (global frame) and couples on links (CCW positive)."""
    model, c = ctx.model, ctx.constants
    point_forces, couples = ctx.zeros_points(), ctx.zeros_links()
    for k, ld in enumerate(model.scene.loads):
        if ld.point is not None:
            point_forces[:, model.point_names.index(ld.point)] += c.load_force[..., k, :]
        else:
            couples[:, link_index(model, ld.link)] += c.load_torque[..., k]
    return Effect(Applied(point_forces, couples))


def inertia(ctx: Context) -> Effect:
    """d'Alembert forces ``-m a_G`` at each centre and ``-I alpha`` on its link (virtual work);
    on the Lagrange side ``-M qdd`` with each body's constant natural-coordinate mass matrix."""
    model, A = ctx.model, ctx.acceleration
    point_forces, couples, m_qdd = ctx.zeros_points(), ctx.zeros_links(), ctx.zeros_points()
    bodies = {}
    for i, (m, (ia, ib, u, v, L)) in enumerate(ctx.masses):
        mass, inertia_ = ctx.constants.mass[..., i, None], ctx.constants.inertia[..., i]
        a_center = body_point(A, ia, ib, u, v, L)
        add_at_body_point(point_forces, -mass * a_center, ia, ib, u, v, L)
        li = link_index(model, m.link)
        couples[:, li] += -inertia_ * ctx.motion.link_angular_acceleration[:, li]
        if not ctx.lagrange:
            continue
        body_m_qdd = body_point_loads(mass * a_center, ia, ib, u, v, L, ctx.n_steps)  # M_k Xdd
        dd = A[:, ib] - A[:, ia]
        body_m_qdd[ib] += (inertia_ / L**2)[..., None] * dd
        body_m_qdd[ia] -= (inertia_ / L**2)[..., None] * dd
        add_body(m_qdd, body_m_qdd)
        merge_bodies(bodies.setdefault(li, {}), body_m_qdd)
    return Effect(Applied(point_forces, couples), lagrange=-m_qdd if ctx.lagrange else None,
                  bodies=bodies)


def applies(name: str, ctx: Context) -> bool:
    """Whether the named effect has anything to act on in this scene."""
    scene = ctx.model.scene
    if name == "springs":
        return bool(scene.springs or scene.torsion_springs)
    if name == "damping":
        return bool(scene.springs)
    if name in ("gravity", "inertia"):
        return bool(scene.masses)
    if name == "friction":
        return bool(scene.friction)
    return bool(scene.loads)


#: the effects, in the order they are summed and reported (HDF5 ``effect`` dimension)
EFFECTS = {"springs": springs, "damping": damping, "gravity": gravity, "loads": loads,
           "inertia": inertia, "friction": None}
# "friction" (linkpipe.forces.friction) depends on the forces the other effects make (a pin's
# friction on its pin force): it is solved after them, with them (forces.compute_forces)
