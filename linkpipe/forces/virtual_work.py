"""The input force by virtual work: influence coefficients ``dq/ds`` of the solved sweep, the
generalized force of every effect, its power, and the input along the actuator's direction."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from ..output_units import common_unit, input_force_units
from ..status import NO_LEVERAGE, OK

LEVERAGE_RTOL = 1e-9  # |n . dr_H/ds| below this times the mechanism size: no leverage


@dataclass(frozen=True)
class Influence:
    """How the mechanism moves per unit driver value, at every step: ``points`` (S, n_points,
    2, n_drivers) = dX/ds (zero at fixed points), ``link_angles`` (S, n_links, n_drivers) =
    dtheta/ds, ``phi_s`` (S, n_drivers) = dPhi_driver/ds."""

    points: np.ndarray
    link_angles: np.ndarray
    phi_s: np.ndarray

    @classmethod
    def of(cls, model: Model, X, Xz, s, dq_ds, rows=None) -> "Influence":
        """From ``dq_ds`` (S, n_q, nd) = ``-J^-1 Phi_s`` over the driver rows (defined at rate 0;
        :func:`linkpipe.kinematics.derivatives` solves it); ``rows``: the model's rows with
        per-step constants (:meth:`Model.phi_s`)."""
        n_steps, n_drivers = X.shape[0], model.n_drivers
        phi_s = model.phi_s(Xz, s, rows)
        points = np.zeros((n_steps, model.n_points, 2, n_drivers))
        points[:, model.moving] = dq_ds.reshape(n_steps, -1, 2, n_drivers)
        d = X[:, model.link_b] - X[:, model.link_a]  # dtheta/ds = cross(d, dd/ds) / L^2
        dd = points[:, model.link_b] - points[:, model.link_a]
        link_angles = ((d[..., 0, None] * dd[..., 1, :] - d[..., 1, None] * dd[..., 0, :])
                       / np.einsum("slj,slj->sl", d, d)[..., None])
        return cls(points, link_angles, phi_s)

    def generalized(self, applied) -> np.ndarray:
        """(S, n_drivers) the work of ``applied`` loads per unit driver value: Q . dq/ds."""
        return (np.einsum("spj,spjd->sd", applied.point_forces, self.points)
                + self.couples_work(applied.couples))

    def couples_work(self, couples) -> np.ndarray:
        """(S, n_drivers) the work of link couples ``couples`` (S, n_links) alone."""
        return np.einsum("sl,sld->sd", couples, self.link_angles)


def along_input_directions(model: Model, influence: Influence, forces: list, status, units: dict,
                           X: np.ndarray, size=None):
    """Turn the drivers' generalized forces (``forces``: arrays (S, n_drivers), changed in
    place) into what each actuator gives: a push along ``input.direction`` at ``input.point``
    where the scene gives ``input`` (``n`` global, or turning with ``input.link``: positions X
    (S, P, 2)), a torque or axial force along the driver's own value elsewhere.

    A push ``P_k`` at its point ``H_k`` does work along every driver's value:
    ``L_jk = n_k . dr_Hk/ds_j``. The generalized forces ``G`` are what the actuators together
    supply, ``G_j = sum_k L_jk P_k + tau_j`` (``tau_j`` zero for a pushed driver), so the
    pushes solve ``L_II P = G_I`` over the pushed drivers I and every other driver keeps
    ``tau_j = G_j - L_jI P`` (one pushed driver: ``P = G / L``, its leverage). A step where
    ``L_II`` is singular (a push that cannot move its own driver: ``|L_jj|`` or the system's
    condition) gets NO_LEVERAGE and NaN in every push and in each other driver its pushes do
    work on (a driver no push moves keeps its force); a step whose kinematics failed gets
    NaN in every driver's. ``size``: the mechanism's length scale, float or (S,) (default
    ``model.size``). Returns (status, unit of the input force)."""
    failed = status != OK  # the kinematics' own failures: every driver NaN there
    status = status.copy()
    drivers = model.scene.drivers
    pushed = [j for j, d in enumerate(drivers) if d.input is not None]
    if pushed:
        size = model.size if size is None else size
        scale = np.stack([np.broadcast_to(np.asarray(size, float), (X.shape[0],))
                          if d.kind == "angle" else np.ones(X.shape[0]) for d in drivers],
                         axis=1)  # (S, nd): length per rad, or length per length
        L = np.empty((X.shape[0], len(drivers), len(pushed)))  # (S, j, k)
        for c, (_, ip, n) in enumerate(pushes(model, X)):
            L[:, :, c] = np.einsum("sx,sxj->sj", n, influence.points[:, ip])
        own = L[:, pushed, :]  # (S, I, I)
        diag = np.abs(np.diagonal(own, axis1=1, axis2=2))  # (S, I)
        flat = (diag < LEVERAGE_RTOL * scale[:, pushed]).any(axis=1)
        if len(pushed) > 1:  # rows in their drivers' scales: a condition free of units
            scaled = own / scale[:, pushed, None]
            with np.errstate(all="ignore"):
                cond = np.linalg.cond(np.where(np.isfinite(scaled), scaled, 0.0))
            flat |= ~(cond < 1.0 / LEVERAGE_RTOL)
        status[flat & (status == OK)] = NO_LEVERAGE
        solvable = ~flat & np.isfinite(own).all(axis=(1, 2))
        others = [j for j in range(len(drivers)) if j not in pushed]
        moved = np.abs(L[:, others, :]) >= LEVERAGE_RTOL * scale[:, others, None]  # (S, o, I)
        for force in forces:
            G = force.copy()
            P = np.full((X.shape[0], len(pushed)), np.nan)
            if solvable.any():
                P[solvable] = np.linalg.solve(own[solvable], G[solvable][:, pushed, None])[..., 0]
            force[:, pushed] = P
            if others:
                tau = G[:, others] - np.einsum("sok,sk->so", L[:, others, :],
                                               np.where(np.isnan(P), 0.0, P))
                undefined = flat[:, None] & moved.any(axis=2)
                force[:, others] = np.where(undefined, np.nan, tau)
    for force in forces:
        force[failed] = np.nan
    return status, common_unit(input_force_units(model.scene.drivers, units))


def input_direction(model: Model, driver_input, X: np.ndarray) -> np.ndarray:
    """Return the unit direction (S, 2) an actuator pushes along at every step: the scene's
    global direction, or with ``link`` its (u, v) in that link's frame (u from the link's first
    point to its second, v a quarter turn counter-clockwise), turning with the link."""
    n = np.asarray(driver_input.direction, dtype=float)
    n = n / np.hypot(*n)
    if driver_input.link is None:
        return np.broadcast_to(n, (X.shape[0], 2))
    li = [ln.name for ln in model.scene.links].index(driver_input.link)
    d = X[:, model.link_b[li]] - X[:, model.link_a[li]]
    e = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    return np.stack([n[0] * e[:, 0] - n[1] * e[:, 1], n[0] * e[:, 1] + n[1] * e[:, 0]], axis=1)


def pushes(model: Model, X: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """``(driver, point, direction (S, 2))`` of each driver with ``input``, in driver order."""
    return [(j, model.point_names.index(d.input.point), input_direction(model, d.input, X))
            for j, d in enumerate(model.scene.drivers) if d.input is not None]


def actuator_forces(model: Model, input_force: np.ndarray, X: np.ndarray):
    """The actuators the scene's ``input`` tables describe, as forces: ``(point_forces (S, P, 2),
    {link: {point: force (S, 2)}})``, each driver's input force (S, n_drivers, along its
    direction: :func:`along_input_directions`) times its direction at its input point, and the
    body it pushes on; None where no driver has ``input``.

    The body: ``input.link`` where the point is on it, else the one link the point is on, else
    (a pin) the link sharing most points with the driver's own, the first in scene order on a
    tie. The reactions and internal forces take these forces as applied loads (the driver's
    own multiplier then vanishes): they are those of the actuator the input force describes,
    not of a torque at the driver's pivot."""
    each = pushes(model, X)
    if not each:
        return None
    points = np.zeros(X.shape[:2] + (2,))
    bodies: dict = {}
    for j, p, n in each:
        force = input_force[:, j, None] * n  # (S, 2)
        points[:, p] += force
        li = _pushed_link(model.scene, model.scene.drivers[j])
        if li is not None:
            body = bodies.setdefault(li, {})
            body[p] = body[p] + force if p in body else force
    return points, bodies


def _pushed_link(scene, driver) -> int | None:
    """The link (index) an actuator at ``driver.input.point`` pushes on (see
    :func:`actuator_forces`); None where no link carries the point."""
    point = driver.input.point
    on = [li for li, ln in enumerate(scene.links) if point in ln.points]
    names = [scene.links[li].name for li in on]
    if driver.input.link in names:
        return on[names.index(driver.input.link)]
    if len(on) <= 1:
        return on[0] if on else None
    return max(on, key=lambda li: (len(set(scene.links[li].points) & set(driver.points)), -li))
