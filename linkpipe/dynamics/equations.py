"""The equations of motion of a scene, reduced to its drivers' coordinates.

Natural coordinates ``q`` (the moving points' x, y) with the scene's constraints
``Phi(q, s) = 0`` (:mod:`linkpipe.model.equations`, through :class:`~linkpipe.model.Model`):
with every driver row included, ``Phi_q`` is square where the drivers are the mechanism's
degrees of freedom, so the drivers' values ``s`` are independent coordinates and ``q(s)`` the
dependent ones (coordinate partitioning with the drivers as the partition: Wehage & Haug 1982;
García de Jalón & Bayo 1994, ch. 5). Differentiating the constraints,

    qd  = K sd,                K = dq/ds = -Phi_q^-1 Phi_s      (influence coefficients)
    qdd = K sdd + qdd_0,       qdd_0 = Phi_q^-1 gamma(sdd = 0)  (kinematics.derivatives)

and projecting the natural-coordinate equations ``M qdd + Phi_q^T lambda = Q`` on the
admissible motions ``dq = K ds`` (virtual power) gives the drivers' equations of motion

    K^T M K sdd = K^T Q - K^T M qdd_0 + F                        (nd x nd)

``M``: the constant natural-coordinate mass matrix, read once off the inertia effect
(:func:`linkpipe.forces.effects.inertia`'s Lagrange side); ``K^T Q``: every other effect's
generalized force by virtual work, as the force stage computes the input force
(:data:`linkpipe.forces.effects.EFFECTS` and :meth:`~linkpipe.forces.virtual_work.Influence.generalized`;
gravity's loads, constant in natural coordinates, read once off the gravity effect); ``F``:
the drivers' own forces (:mod:`.forcing`). Friction: a seal's is a function of its driver's
rate, in ``K^T Q``; a pin's or a slider's depends on the pin or normal force, so on ``sdd``:
solved with it by a fixed point on the force stage (:meth:`MotionEquations.accelerations`).
Nothing here writes a constraint row, a force law
or a mass matrix of its own: one state's ``Phi_q``, ``Phi_s`` and ``gamma`` are
:mod:`linkpipe.model.equations`' rows, on whole arrays (:meth:`MotionEquations.rates`) or on
Python floats through stage 1's one-step kernels (:meth:`MotionEquations.rates_one`).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .. import kinematics as kin
from ..forces import compute_forces, friction
from ..forces.effects import EFFECTS, Context, applies, inertia
from ..forces.virtual_work import Influence
from ..model import Model, build_model
from ..output_units import units_of
from ..result import Motion
from ..kinematics.linalg import condition_and_inverse, condition_and_inverse_one, is_singular
from ..kinematics.step import _step_kernels
from ..model import equations as eq
from ..status import NO_ASSEMBLY, OK


#: the most unknowns whose one-state rates use Phi_q's dense inverse
DENSE_UP_TO = 400


class NoAssembly(Exception):
    """The mechanism has no assembled, non-singular position at these driver values."""


def mass_matrix(model: Model) -> np.ndarray:
    """The natural-coordinate mass matrix ``M`` (n_q, n_q) of the moving coordinates: column i
    is the inertia effect's ``M qdd`` for ``qdd = e_i`` (constant: bodies of two basic points)."""
    n_q, P = model.n_q, model.n_points
    X = np.broadcast_to(model.start_position, (n_q, P, 2)).copy()
    A = np.zeros((n_q, P, 2))
    A[:, model.moving] = np.eye(n_q).reshape(n_q, -1, 2)
    zeros = np.zeros((n_q, model.n_drivers))
    motion = Motion(zeros, zeros, zeros, X, np.zeros_like(A), A, np.full(n_q, OK, np.int8),
                    np.zeros((n_q, n_q, model.n_drivers)), np.zeros((n_q, len(model.link_a))),
                    model.link_angles(X))
    effect = inertia(Context.of(model, motion, units_of(model.scene)))
    M = -effect.lagrange[:, model.moving].reshape(n_q, n_q)  # row i: M e_i
    return 0.5 * (M + M.T)


def gravity_loads(model: Model) -> np.ndarray | None:
    """Gravity's loads on the moving coordinates (n_q,), constant in natural coordinates (the
    gravity effect's point forces at the drawing), or None without gravity."""
    if "gravity" not in model.scene.effects or not model.scene.masses:
        return None
    nd = model.n_drivers
    X = model.start_position[None]
    zeros = np.zeros((1, nd))
    motion = Motion(zeros, zeros, zeros, X, np.zeros_like(X), np.zeros_like(X),
                    np.full(1, OK, np.int8), np.zeros((1, model.n_q, nd)), None,
                    model.link_angles(X))
    applied = EFFECTS["gravity"](Context.of(model, motion, units_of(model.scene))).applied
    return applied.point_forces[0, model.moving].reshape(-1)


def without_inputs(scene, keep_inertia: bool = False):
    """The scene with each driver's ``input`` left out and inertia off (unless
    ``keep_inertia``): the drivers' forces are generalized forces (torques, axial forces) and
    the mass matrix enters separately."""
    drivers = tuple(dataclasses.replace(d, input=None) for d in scene.drivers)
    effects = tuple(e for e in scene.effects if keep_inertia or e != "inertia")
    return dataclasses.replace(scene, drivers=drivers, effects=effects)


@dataclasses.dataclass
class State:
    """The mechanism at driver values ``s`` (B, nd) and rates ``sd`` (B, nd): positions X
    (B, P, 2), velocities V, the acceleration at ``sdd = 0`` A0, influence K (B, n_q, nd), link
    angles (B, n_links), every effect's generalized force but inertia's ``K^T Q`` (B, nd), the
    power of those that store no energy (damping, loads) ``power_other`` (B,) and friction's
    power ``power_friction`` (B,) (the seals'; with pin or slider friction every friction's,
    set by :meth:`MotionEquations.accelerations`)."""

    s: np.ndarray
    sd: np.ndarray
    X: np.ndarray
    V: np.ndarray
    A0: np.ndarray
    K: np.ndarray
    link_angle: np.ndarray
    generalized: np.ndarray
    power_other: np.ndarray
    power_friction: np.ndarray


class MotionEquations:
    """The drivers' equations of motion of one scene (see the module's docstring).

    ``positions`` keeps the last solved position as the next Newton guess (a first-order
    predictor along K), so successive evaluations along a trajectory take one or two
    iterations; positions meet the constraints to ``[solver] tol`` at every evaluation, so
    nothing drifts off them however long the run (there is nothing to project back)."""

    def __init__(self, scene, model: Model | None = None):
        self.scene = scene
        self.model = model if model is not None else build_model(scene)
        self.effects_model = build_model(without_inputs(scene))
        self.units = units_of(scene)
        self.M = mass_matrix(self.model)
        # gravity's loads on the natural coordinates are constant (each weight lands on its
        # body's basic points with constant shares): read once off the gravity effect
        self.Q_gravity = gravity_loads(self.effects_model)
        self.varying = tuple(e for e in self.effects_model.scene.effects
                             if e not in ("gravity", "friction"))
        #: the scene's friction: seals alone are a function of the drivers' rates (a
        #: generalized force on its driver, added in :meth:`generalized_forces`)
        self.friction = (friction.Layout.of(self.effects_model)
                         if "friction" in scene.effects and scene.friction else None)
        #: pin or slider friction: every friction (seals too) solved with the accelerations
        #: by the force stage itself (:meth:`accelerations`) on the scene with inertia
        self.coupled = self.friction is not None and self.friction.coupled
        self.forces_model = build_model(without_inputs(scene, keep_inertia=True)) \
            if self.coupled else None
        self._context = None
        self.tol = float(self.model.tolerance())
        self.rcond = scene.solver.singular_rcond
        self._last = None  # (s, q, K) of the last solved position
        #: one state's rates by the dense inverse (microseconds for a small mechanism, 0.2 ms
        #: at 82 unknowns), or beyond DENSE_UP_TO unknowns by the sparse engine (built for
        #: whole sweeps: one row through it costs ~1 ms per 20 unknowns)
        self.dense = self.model.n_q <= DENSE_UP_TO
        #: no redundant constraint: one state's rates on Python floats (:meth:`rates_one`)
        self.square = self.dense and self.model.n_rows == self.model.n_q
        self.kernels = _step_kernels(self.model)

    def start(self, s0: np.ndarray) -> np.ndarray:
        """Assemble the drawing at ``s0`` (nd,) (the scene's start, as stage 1 does); q (n_q,)."""
        q0, _ = kin.start_state(self.model, s0, self.tol, self.scene.solver.max_iter)
        self._last = (np.array(s0, float), np.array(q0, float), None)
        return q0

    def positions(self, s: np.ndarray) -> np.ndarray:
        """X (1, P, 2) at driver values ``s`` (nd,) by Newton from the last solution; raises
        NoAssembly where Newton finds none."""
        s_last, q_last, K_last = self._last
        guess = q_last if K_last is None else q_last + K_last @ (s - s_last)
        q, res, _, ok = kin.newton(self.model, guess[None], s[None], self.tol,
                                   self.scene.solver.max_iter)
        if not ok[0] or not np.isfinite(q).all():
            raise NoAssembly(float(res[0]))
        X = self.model.positions(q)
        if not self.model.aligned(X, s[None])[0]:  # an angle driver's mirror root (its
            raise NoAssembly(0.0)  # direction turned half a turn): not this motion's pose
        return X

    def state(self, s: np.ndarray, sd: np.ndarray) -> State:
        """The mechanism at one state ``s``, ``sd`` (nd,): positions, rates, influence and the
        effects' forces (raises NoAssembly at no position or a singular one)."""
        model = self.model
        s2, sd2 = s[None], sd[None]
        X = self.positions(s)
        status = np.full(1, OK, np.int8)
        if self.square:
            V, A0, K, singular = self.rates_one(model.q_of(X)[0], s, sd)
        elif self.dense:
            V, A0, K, singular = self.rates(X, s2, sd2)
        else:
            der = kin.derivatives(model, X, s2, sd2, np.zeros_like(s2), status, True,
                                  need_influence=True)
            V, A0, K, singular = (der["velocity"], der["acceleration"], der["influence"],
                                  der["status"] != OK)
        if singular[0]:
            raise NoAssembly(np.inf)
        self._last = (s.copy(), model.q_of(X)[0], K[0])
        # whole turns matter to torsion springs alone (their angle is the links' difference)
        link_angle = (kin.link_angles_unwrapped(model, X, s=s2) if self.scene.torsion_springs
                      else None)
        return self.state_of(X, s2, sd2, V, A0, K, link_angle)

    def state_of(self, X, s, sd, V, A0, K, link_angle) -> State:
        """A State from solved kinematics (B rows): the effects' generalized forces added."""
        generalized, power, rubbing = self.generalized_forces(X, s, sd, V, A0, K, link_angle)
        return State(s, sd, X, V, A0, K, link_angle, generalized, power, rubbing)

    def generalized_forces(self, X, s, sd, V, A0, K, link_angle):
        """(K^T Q (B, nd), the power of the effects that store no energy (B,), friction's
        power (B,)) of every effect but inertia: gravity's from its constant loads, the
        others' (springs, damping, loads) from :data:`linkpipe.forces.effects.EFFECTS` by
        virtual work (:meth:`Influence.generalized`, as the force stage computes the input
        force), the seals' friction from :func:`linkpipe.forces.friction.seal_loads` (the
        force stage's own loads: ``-f`` on its driver, ``f`` the seal's law at its rate)."""
        B = X.shape[0]
        generalized = np.einsum("bid,i->bd", K, self.Q_gravity) if self.Q_gravity is not None \
            else np.zeros((B, self.model.n_drivers))
        power, rubbing = np.zeros(B), np.zeros(B)
        if not self.varying and self.friction is None:
            return generalized, power, rubbing
        model = self.effects_model
        status = np.full(B, OK, np.int8)
        motion = Motion(s, sd, np.zeros_like(s), X, V, A0, status, K, None, link_angle)
        if self._context is None:  # the masses' frames and the force tables' numbers: once
            self._context = Context.of(model, motion, self.units, lagrange=False)
        ctx = dataclasses.replace(self._context, motion=motion, position=X, velocity=V,
                                  acceleration=A0)
        influence = Influence.of(model, X, X, s, K)
        for name in self.varying:
            if not applies(name, ctx):
                continue
            g = influence.generalized(EFFECTS[name](ctx).applied)
            generalized = generalized + g
            if name not in STORED:
                power += (g * sd).sum(axis=1)
        if self.friction is not None and self.friction.seals and not self.coupled:
            g = influence.generalized(friction.seal_loads(ctx, self.friction, influence.phi_s)[1])
            generalized = generalized + g
            rubbing = (g * sd).sum(axis=1)
        return generalized, power, rubbing

    def rates_one(self, q: np.ndarray, s: np.ndarray, sd: np.ndarray):
        """:meth:`rates` of one state (q (n_q,), s, sd (nd,)) with Phi_q, Phi_s and gamma
        evaluated on Python floats by the one-step kernels (kinematics.step: numpy's per-call
        overhead would dominate rows this small); the same rows of model/equations.py."""
        model, kern = self.model, self.kernels
        J = kern.jac(q, s)
        cond, inv = condition_and_inverse_one(J)
        if inv is None or is_singular(cond, self.rcond):
            return None, None, None, np.ones(1, bool)
        K = -inv[:, model.n_constraints:] * np.array(kern.phi_s(q, s))[None, :]
        qd = K @ sd
        X = kern.points(q)
        V = [0.0] * len(X)
        for k, v in zip(kern.qpos, qd.tolist()):
            V[k] = v
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        gamma = np.fromiter(eq.gamma_rows(model.rows, lambda p: (X[2 * p], X[2 * p + 1]),
                                          lambda p: (V[2 * p], V[2 * p + 1]), s.tolist(),
                                          sd.tolist(), [0.0] * len(s), cs, sn), float,
                            count=model.n_rows)
        qdd0 = inv @ gamma
        return (model.velocities(qd[None]), model.velocities(qdd0[None]), K[None],
                np.zeros(1, bool))

    def rates(self, X: np.ndarray, s: np.ndarray, sd: np.ndarray):
        """(V, A0 (B, P, 2), K (B, n_q, nd), singular (B,)) at positions X (B, P, 2), driver
        values and rates (B, nd): Phi_q's dense inverse (one LU per row; its 1-norm condition
        against ``[solver] singular_rcond``, the test every path uses), ``K = -Phi_q^-1
        Phi_s``, ``qd = K sd``, ``qdd_0 = Phi_q^-1 gamma(sdd = 0)`` (:func:`kinematics.derivatives`
        does the same with its sparse engine; this is its one-row form, 10x lighter)."""
        model = self.model
        J = model.jacobian(X, s)
        cond, inv = condition_and_inverse(J)
        singular = is_singular(cond, self.rcond)
        K = -inv[:, :, model.driver_rows] * model.phi_s(X, s)[:, None, :]
        V = model.velocities(np.einsum("bid,bd->bi", K, sd))
        qdd0 = np.einsum("bij,bj->bi", inv, model.gamma(X, V, s, sd, np.zeros_like(sd)))
        return V, model.velocities(qdd0), K, singular

    def reduced(self, st: State) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M_r (B, nd, nd), K^T M qdd_0 (B, nd), K^T Q (B, nd)) of a state."""
        model = self.model
        K = st.K
        qdd0 = model.q_of(st.A0)
        MK = np.einsum("ij,bjd->bid", self.M, K)
        Mr = np.einsum("bie,bid->bed", K, MK)
        bias = np.einsum("bid,bi->bd", MK, qdd0)
        return Mr, bias, st.generalized

    def accelerations(self, st: State, F: np.ndarray) -> np.ndarray:
        """sdd (B, nd) under the drivers' forces ``F`` (B, nd). With pin or slider friction
        (whose size depends on the pin and normal forces, so on sdd) by a fixed point on the
        force stage: sdd -> the force the drivers need for that motion, friction solved with
        the pin forces (:func:`linkpipe.forces.compute_forces`, every effect and friction on
        the Lagrange side) -> sdd += J^-1 (F - needed), until the gap is within
        :attr:`tol_force` of the largest term; J = d needed / d sdd starts at M_r (exact
        without friction: the first round shrinks the gap by friction's sensitivity to sdd,
        ~ mu r m arm / I) and takes Broyden's update after each round (superlinear).
        Friction's power is then ``st``'s; a row that does not converge in ``[solver]
        max_iter`` rounds or whose force stage fails is NaN."""
        Mr, bias, generalized = self.reduced(st)
        rhs = generalized - bias + F
        sdd = self._solve(Mr, rhs)
        if not self.coupled:
            return sdd
        size = np.abs(np.concatenate([generalized, bias, F], axis=1)).max(axis=1)
        live = np.isfinite(sdd).all(axis=1)
        J, last = np.nan_to_num(Mr), None  # d needed / d sdd, Broyden-updated from M_r
        for _ in range(self.scene.solver.max_iter + 1):
            forces = self.forces_at(st, sdd)
            gap = F - forces.variables["input_force"][1]
            live &= np.isfinite(gap).all(axis=1)
            done = ~live | (np.abs(gap).max(axis=1) <= self.tol_force * size)
            if done.all():
                break
            gap = np.nan_to_num(gap)
            if last is not None:  # Broyden: J ds = d needed along the last step
                ds, dn = sdd - last[0], last[1] - gap
                norm = np.einsum("bd,bd->b", ds, ds)
                use = live & (norm > 0)
                upd = (dn - np.einsum("bij,bj->bi", J, ds)) / np.where(use, norm, 1.0)[:, None]
                J = J + np.where(use[:, None, None], upd[:, :, None] * ds[:, None, :], 0.0)
            last = (sdd, gap)
            sdd = sdd + np.where(live[:, None], self._solve(J, gap), 0.0)
        # a force stage that fails, or friction with no consistent motion (a self-locking
        # pin: the round did not converge), leaves NaN: the integrator's step is refused
        sdd = np.where((live & done)[:, None], sdd, np.nan)
        st.power_friction = forces.variables["friction_power"][1].sum(axis=1)
        return sdd

    #: the relative tolerance of the friction fixed point on the drivers' forces
    tol_force = 1e-12

    @staticmethod
    def _solve(Mr, rhs):
        if Mr.shape[1] == 1:
            return rhs / Mr[:, :, 0]
        return np.linalg.solve(Mr, rhs[..., None])[..., 0]

    def forces_at(self, st: State, sdd: np.ndarray):
        """The force stage (all effects, inertia and friction, the Lagrange side) of state
        ``st`` moving with driver accelerations ``sdd`` (B, nd)."""
        model = self.forces_model
        A = st.A0.copy()
        A[:, model.moving] += np.einsum("bid,bd->bi", st.K, sdd).reshape(len(sdd), -1, 2)
        status = np.where(np.isfinite(A).all(axis=(1, 2)), OK, NO_ASSEMBLY).astype(np.int8)
        motion = Motion(st.s, st.sd, sdd, st.X, st.V, A, status, st.K,
                        kin.link_rates(model, st.X, st.V, A)[1], st.link_angle)
        return compute_forces(model, motion, self.units)

    def kinetic_energy(self, st: State) -> np.ndarray:
        """(B,) ½ qd^T M qd."""
        qd = self.model.q_of(st.V)
        return 0.5 * np.einsum("bi,ij,bj->b", qd, self.M, qd)

    def nonconservative_power(self, st: State) -> np.ndarray:
        """(B,) the power of the effects with no stored energy (damping, loads)."""
        return st.power_other

    def friction_power(self, st: State) -> np.ndarray:
        """(B,) friction's power (at most zero; after :meth:`accelerations` where friction
        depends on the forces)."""
        return st.power_friction


#: the effects whose work is stored as an energy (the others' power is integrated)
STORED = ("springs", "gravity")


def potential_of(variables: dict, n: int) -> np.ndarray:
    """(S,) the stored energy of the force stage's variables: springs, torsion springs, gravity."""
    total = np.zeros(n)
    for name in ("spring_energy", "torsion_spring_energy"):
        if name in variables:
            total += variables[name][1].sum(axis=1)
    if "gravity_energy" in variables:
        total += variables["gravity_energy"][1]
    return total
