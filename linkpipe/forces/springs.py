"""Springs as arrays: two-point springs of every kind (their tension and potential energy) and
torsion springs between links (their angle, torque, energy and couples).

Each law comes with its potential energy ``V`` such that the tension is ``dV/dlength`` (a torsion
spring's torque ``dV/dangle``), so the input force by virtual work is the derivative of the
total potential energy along a quasi-static sweep (``tests/test_springs.py`` checks both)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from ..scene.tables import GROUND
from .applied import Applied, couple_as_body, link_index, merge_bodies, scatter_pairs


@dataclass(frozen=True)
class SpringGeometry:
    """Every spring's end points, length (S, n_springs), unit vector a->b (S, n_springs, 2),
    free length, preload and stiffness (n_springs,) or (S, n_springs), and a gas spring's
    ``gas`` = (force_extended, extended_length, dead_length, gamma), each the same shape."""

    ia: np.ndarray
    ib: np.ndarray
    length: np.ndarray
    unit: np.ndarray
    free_length: np.ndarray
    preload: np.ndarray
    k: np.ndarray
    gas: tuple = ()

    @classmethod
    def of(cls, ctx) -> "SpringGeometry":
        """From the context's positions and force constants (``ctx.constants``: per spring,
        or per step and spring)."""
        model, springs, c = ctx.model, ctx.model.scene.springs, ctx.constants
        names = model.point_names
        ia = np.array([names.index(sp.between[0]) for sp in springs], dtype=np.intp)
        ib = np.array([names.index(sp.between[1]) for sp in springs], dtype=np.intp)
        d = ctx.position[:, ib] - ctx.position[:, ia]
        length = np.hypot(d[..., 0], d[..., 1])
        d0 = c.start_assembled[..., ib, :] - c.start_assembled[..., ia, :]
        start_len = np.hypot(d0[..., 0], d0[..., 1])
        given = np.array([sp.free_length is not None for sp in springs], dtype=bool)
        free = np.where(given, c.spring_free_length, start_len)
        preload = np.where(given | np.isnan(c.spring_preload), 0.0, c.spring_preload)
        unit = d / np.where(length > 0, length, np.nan)[..., None]
        gas = (c.gas_force_extended, c.gas_extended_length, c.gas_dead_length, c.gas_gamma)
        return cls(ia, ib, length, unit, free, preload, c.spring_k, gas)

    def damping_force(self, ctx) -> np.ndarray:
        """(S, n_springs) the damper's force, c times the rate of lengthening; 0 where a spring
        has no damper (c 0 or none), even where the rates are unknown (a singular step)."""
        c = np.nan_to_num(ctx.constants.spring_damping)  # no damping given: none
        rate = np.einsum("skj,skj->sk", ctx.velocity[:, self.ib] - ctx.velocity[:, self.ia], self.unit)
        return np.where(c != 0, c * rate, 0.0)

    def as_point_forces(self, ctx, force: np.ndarray) -> Applied:
        point_forces = ctx.zeros_points()
        scatter_pairs(point_forces, self.ia, self.ib, force[..., None] * self.unit)
        return Applied(point_forces, ctx.zeros_links())


def spring_law(geo: SpringGeometry, springs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (tension, energy, extension), each (S, n_springs), by each spring's kind.

    linear: ``T = p + k s`` with ``s = length - free_length``, ``V = p s + k s^2 / 2`` (zero at
    the free length, or at the start with a preload p); tension_only / compression_only: ``T``
    where it pulls / pushes, else 0, ``V = k e^2 / 2`` there (``e`` the extension, so
    ``V = T^2 / (2 k)``), 0 where slack (k = 0: ``V = T s``);
    gas: ``T = -F1 r^gamma`` with ``r = (L1 - d) / (length - d)``, ``V = F1 (L1 - d) (r^(gamma-1)
    - 1) / (gamma - 1)`` (``F1 (L1 - d) ln r`` at gamma = 1), zero at the extended length;
    infinite at and below the dead length. Extension: length minus the length at zero tension
    (a gas spring, which has none: length minus its extended length)."""
    stretch = geo.length - geo.free_length
    tension = geo.preload + geo.k * stretch
    energy = geo.preload * stretch + 0.5 * geo.k * stretch ** 2
    k_pos = np.where(geo.k > 0, geo.k, 1.0)
    extension = geo.length - np.where(geo.k > 0, geo.free_length - geo.preload / k_pos, geo.free_length)
    for j, sp in enumerate(springs):
        if sp.kind in ("tension_only", "compression_only"):
            t, kj = tension[:, j], geo.k[..., j]
            # a NaN tension (a failed step's NaN length) stays NaN, not "slack"
            active = (t > 0 if sp.kind == "tension_only" else t < 0) | np.isnan(t)
            one_sided = np.where(kj > 0, 0.5 * kj * extension[:, j] ** 2, t * stretch[:, j])
            tension[:, j] = np.where(active, t, 0.0)
            energy[:, j] = np.where(active, one_sided, 0.0)
        elif sp.kind == "gas":
            f1, l1, d, gamma = (a[..., j] for a in geo.gas)
            tension[:, j], energy[:, j] = gas_law(geo.length[:, j], f1, l1, d, gamma)
            extension[:, j] = geo.length[:, j] - l1
    return tension, energy, extension


def gas_law(length: np.ndarray, f1, l1, d, gamma) -> tuple[np.ndarray, np.ndarray]:
    """(tension, energy) (S,) of a gas spring at ``length`` (S,): force at the extended length
    ``f1``, extended length ``l1``, dead length ``d``, exponent ``gamma``, each a number or (S,)
    (a study's variants); -inf and +inf at or below the dead length (the gas volume is gone:
    that step's stored force is not finite, status non_finite)."""
    volume = length - d
    alive = volume > 0
    isothermal = gamma == 1.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        x = np.log((l1 - d) / np.where(alive, volume, 1.0))  # ln r
        tension = -f1 * np.exp(gamma * x)
        less = np.where(isothermal, 1.0, gamma - 1.0)
        shape = np.where(isothermal, x, np.expm1(less * x) / less)
        energy = f1 * (l1 - d) * shape
    # a NaN length (a failed step) stays NaN; a reached dead length is an infinite push
    unknown = np.isnan(length)
    dead = ~alive & ~unknown
    tension = np.where(unknown, np.nan, np.where(dead, -np.inf, tension))
    return tension, np.where(unknown, np.nan, np.where(dead, np.inf, energy))


@dataclass(frozen=True)
class TorsionSprings:
    """Every torsion spring's links (``second`` -1 for ground), angle (S, n) unwrapped along
    the sweep, torque and energy."""

    first: np.ndarray
    second: np.ndarray
    angle: np.ndarray
    torque: np.ndarray
    energy: np.ndarray

    @classmethod
    def of(cls, model: Model, link_angle: np.ndarray, k: np.ndarray | None = None,
           free_angle: np.ndarray | None = None) -> "TorsionSprings":
        """The angle is the first link's angle minus the second's (ground: 0), as the
        contract defines it: the links' ``link_angle`` (S, n_links), unwrapped along the whole
        sweep by stage 1 (a full turn winds the spring; a link an angle driver turns carries
        the driver's whole turns), no turns taken off, so ``free_angle`` is read as written
        (-720 is a spring wound two turns); ``k`` the rates and ``free_angle`` the free angles
        (degrees), (n_torsion_springs,) or per step (S, n_torsion_springs) (default: the
        scene's)."""
        tsprings = model.scene.torsion_springs
        first, second = torsion_links(model)
        angle = torsion_raw_angle(model, link_angle)
        free = np.deg2rad([t.free_angle for t in tsprings] if free_angle is None else free_angle)
        if k is None:
            k = np.array([t.k for t in tsprings], dtype=float)
        torque = k * (angle - free)
        return cls(first, second, angle, torque, 0.5 * k * (angle - free) ** 2)

    def couples(self, n_links: int) -> np.ndarray:
        """(S, n_links) the couples on the links, CCW positive: -torque on the first link,
        +torque on the second (none on ground)."""
        out = np.zeros((self.torque.shape[0], n_links))
        for j, (a, b) in enumerate(zip(self.first, self.second)):
            out[:, a] -= self.torque[:, j]
            if b >= 0:
                out[:, b] += self.torque[:, j]
        return out


def torsion_links(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Each torsion spring's first and second link (indices; -1 for ground)."""
    tsprings = model.scene.torsion_springs
    first = np.array([link_index(model, t.links[0]) for t in tsprings], dtype=np.intp)
    second = np.array([-1 if t.links[1] == GROUND else link_index(model, t.links[1])
                       for t in tsprings], dtype=np.intp)
    return first, second


def torsion_raw_angle(model: Model, link_angle: np.ndarray) -> np.ndarray:
    """First link's angle minus second's (..., S, n_torsion_springs), from unwrapped link angles
    (..., S, n_links)."""
    first, second = torsion_links(model)
    ground = np.zeros(link_angle.shape[:-1] + (1,))
    return link_angle[..., first] - np.concatenate([link_angle, ground], axis=-1)[..., second]


def couples_on_bodies(model: Model, couples, X) -> dict:
    """{link: {point: (S, 2)}} each link's couple as a force pair, negated: its part of that
    body's own ``M_k Xdd - Q_k`` (a couple acts on the body, not at a pin)."""
    return {int(li): merge_bodies({}, couple_as_body(model, couples[:, li], li, X), -1.0)
            for li in np.flatnonzero(np.any(couples != 0, axis=0))}
