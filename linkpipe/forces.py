"""Stage 2: the effects a scene names, the input force by virtual work, Lagrange multipliers.

Everything is vectorised over steps. Notation (per step): ``q`` the moving coordinates,
``J = Phi_q`` (n_rows, n_q), ``K = dq/ds`` (n_q, n_drivers) the influence coefficients
(``K = -J^+ Phi_s`` over the driver rows). Applied forces are collected as point forces
``(S, n_points, 2)`` plus couples on links ``(S, n_links)``.

* Virtual work: the actuator's generalized force per driver is ``F = -K^T Q`` where ``Q``
  holds the applied forces including d'Alembert inertia ``-m a_G`` and ``-I alpha`` — so it is
  defined at ``rate = 0``; with ``input`` it is divided by the input point's leverage
  ``n . dr_H/ds``.
* Lagrange: ``J^T lambda = Q - M qdd`` with the constant natural-coordinate mass matrix of each
  body, ``M = m N_G^T N_G + (I_G / L^2) D^T D`` (``N_G`` maps the basic points to the centre,
  ``D`` to their difference) — a different formulation and a different linear solve; the driver
  rows give ``F = lambda_d dPhi_d/ds``, the others the internal forces (tension positive).
"""
from __future__ import annotations

import numpy as np

from .kinematics.linalg import engine
from .result import Forces, Motion
from .status import NO_LEVERAGE, OK
from .model import Model, _R90

LEVERAGE_RTOL = 1e-9  # |n . dr_H/ds| below this times the mechanism size: no leverage


def _link_index(model: Model, name: str) -> int:
    return [l.name for l in model.scene.links].index(name)


def center_frame(model: Model, link_name: str, center) -> tuple[int, int, float, float, float]:
    """Return (ia, ib, u, v, L) of a mass centre given as a point name or local (u, v)."""
    li = _link_index(model, link_name)
    link = model.scene.links[li]
    names = model.point_names
    ia, ib = names.index(link.points[0]), names.index(link.points[1])
    X0 = model.start_position
    L0 = float(np.hypot(*(X0[ib] - X0[ia])))
    L = float(link.length) if link.length is not None else L0
    if isinstance(center, str):
        ip = names.index(center)
        if ip == ia:
            return ia, ib, 0.0, 0.0, L
        if ip == ib:
            return ia, ib, L, 0.0, L
        hit = np.flatnonzero((model.loc_a == ia) & (model.loc_b == ib) & (model.loc_p == ip))
        if len(hit):
            return ia, ib, float(model.loc_u[hit[0]]), float(model.loc_v[hit[0]]), L
        e = (X0[ib] - X0[ia]) / L0
        r = X0[ip] - X0[ia]
        return ia, ib, float(r @ e), float(r @ (_R90 @ e)), L
    u, v = center
    return ia, ib, float(u), float(v), L


def _center(X, ia, ib, u, v, L):
    """Return a body point ``a + (u I + v R)(b - a)/L`` for stacks (S, P, 2) -> (S, 2)."""
    d = X[:, ib] - X[:, ia]
    return X[:, ia] + (u * d + v * _perp(d)) / L


def compute_forces(model: Model, motion: Motion, units: dict) -> Forces:
    """Compute every named effect and the input force of a solved sweep.

    ``motion``: the sweep (positions, derivatives, kinematic status, Jacobian inverse);
    ``units``: the scene's unit strings. Returns :class:`Forces` (variables in the contract's
    names, the labels of the dimensions they add, and the status with no_leverage added).
    """
    s, s_dot, s_ddot, jacobian_inverse = motion.s, motion.s_dot, motion.s_ddot, motion.jacobian_inverse
    scene = model.scene
    eff = set(scene.effects)
    S, P = motion.position.shape[:2]
    nl = len(scene.links)
    u = units
    Lu, Fu, Tu = u["length"], u["force"], u["time"]
    X = motion.position
    V = motion.velocity if motion.velocity is not None else np.zeros_like(X)
    A = motion.acceleration if motion.acceleration is not None else np.zeros_like(X)
    out: dict = {}
    coords: dict = {}

    drv = model.driver_rows
    Jinv = jacobian_inverse
    Xz = np.where(np.isfinite(X), X, 0.0)
    phi_s = model.phi_s(Xz, s)  # (S, nd)
    K = -Jinv[:, :, drv] * phi_s[:, None, :]  # (S, n_q, nd) influence coefficients dq/ds
    Kp = np.zeros((S, P, 2, model.n_drivers))  # per point
    Kp[:, model.moving] = K.reshape(S, -1, 2, model.n_drivers)
    # link angle influence: dtheta/ds = cross(d, dd/ds) / L^2
    d = X[:, model.link_b] - X[:, model.link_a]
    Kd = Kp[:, model.link_b] - Kp[:, model.link_a]
    Ktheta = (d[..., 0, None] * Kd[..., 1, :] - d[..., 1, None] * Kd[..., 0, :]) / np.einsum("slj,slj->sl", d, d)[..., None]

    # applied forces per effect: point forces (S, P, 2) and link couples (S, n_links)
    effects: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    lagr_point = np.zeros((S, P, 2))  # the Lagrange side's Q (no inertia: that enters as M qdd)
    lagr_couple = np.zeros((S, nl))

    springs = scene.springs if ("springs" in eff or "damping" in eff) else ()
    if springs:
        names = model.point_names
        ia = np.array([names.index(sp.between[0]) for sp in springs])
        ib = np.array([names.index(sp.between[1]) for sp in springs])
        dd = X[:, ib] - X[:, ia]
        length = np.hypot(dd[..., 0], dd[..., 1])  # (S, n_springs)
        start_len = np.hypot(*(model.start_position[ib] - model.start_position[ia]).T)
        k = np.array([sp.k for sp in springs], dtype=float)
        ref = np.array([sp.free_length if sp.free_length is not None else start_len[i] for i, sp in enumerate(springs)])
        t0 = np.array([0.0 if sp.free_length is not None else sp.preload for sp in springs])
        e_ab = dd / np.where(length > 0, length, np.nan)[..., None]
        if "springs" in eff:
            tension = t0 + k * (length - ref)
            energy = t0 * (length - ref) + 0.5 * k * (length - ref) ** 2
            fp = np.zeros((S, P, 2))
            _scatter(fp, ia, ib, tension[..., None] * e_ab)
            effects["springs"] = (fp, np.zeros((S, nl)))
            out["spring_length"] = (("step", "spring"), length, Lu)
            out["spring_extension"] = (("step", "spring"), length - np.where(k > 0, ref - t0 / np.where(k > 0, k, 1), ref), Lu)
            out["spring_energy"] = (("step", "spring"), energy, f"{Fu}*{Lu}")
        if "damping" in eff:
            c = np.array([sp.damping for sp in springs], dtype=float)
            rate = np.einsum("skj,skj->sk", V[:, ib] - V[:, ia], e_ab)
            damp = c * rate
            fp = np.zeros((S, P, 2))
            _scatter(fp, ia, ib, damp[..., None] * e_ab)
            effects["damping"] = (fp, np.zeros((S, nl)))
            out["spring_damping_force"] = (("step", "spring"), damp, Fu)
        if "springs" in eff:
            total = tension + (damp if "damping" in eff else 0.0)
            out["spring_force"] = (("step", "spring"), total, Fu)

    masses = [(m, center_frame(model, m.link, m.center)) for m in scene.masses]
    # per body k: M_k Xdd - Q_k at its points (Q_k: the weight and couples on the body itself),
    # filled below where those effects are computed, for the pin forces
    bodies: dict[int, np.ndarray] = {}

    def body(li):
        if li not in bodies:
            bodies[li] = np.zeros((S, P, 2))
        return bodies[li]

    if "gravity" in eff and masses:
        g = np.asarray(scene.gravity, dtype=float)
        for m, (ia_, ib_, uu, vv, L) in masses:
            _add_at_center(body(_link_index(model, m.link)), -m.mass * g, ia_, ib_, uu, vv, L)
        effects["gravity"] = (-sum(bodies.values()), np.zeros((S, nl)))
        pot = np.zeros(S)
        for m, (ia_, ib_, uu, vv, L) in masses:
            G = _center(X, ia_, ib_, uu, vv, L)
            pot -= m.mass * (G[:, 0] * g[0] + G[:, 1] * g[1])
        out["gravity_energy"] = (("step",), pot, f"{Fu}*{Lu}")

    if "loads" in eff and scene.loads:
        fp = np.zeros((S, P, 2))
        cp = np.zeros((S, nl))
        for ld in scene.loads:
            if ld.point is not None:
                fp[:, model.point_names.index(ld.point)] += np.asarray(ld.force, dtype=float)
            else:
                cp[:, _link_index(model, ld.link)] += float(ld.torque)
        effects["loads"] = (fp, cp)

    for fp, cp in effects.values():
        lagr_point += fp
        lagr_couple += cp

    if "inertia" in eff and masses:
        # physical d'Alembert forces for virtual work: -m a_G at G, -I alpha on the link
        fp = np.zeros((S, P, 2))
        cp = np.zeros((S, nl))
        Mqdd = np.zeros((S, P, 2))
        for m, (ia_, ib_, uu, vv, L) in masses:
            aG = _center(A, ia_, ib_, uu, vv, L)
            _add_at_center(fp, -m.mass * aG, ia_, ib_, uu, vv, L)
            li = _link_index(model, m.link)
            cp[:, li] += -m.inertia * motion.link_angular_acceleration[:, li]
            # M qdd with the constant natural-coordinate mass matrix, per body
            Mk = np.zeros((S, P, 2))
            _add_at_center(Mk, m.mass * aG, ia_, ib_, uu, vv, L)
            ddd = A[:, ib_] - A[:, ia_]
            Mk[:, ib_] += m.inertia / L**2 * ddd
            Mk[:, ia_] -= m.inertia / L**2 * ddd
            Mqdd += Mk
            body(li)[:] += Mk
        effects["inertia"] = (fp, cp)
        lagr_point = lagr_point - Mqdd

    # ---- virtual work: F_j = -sum(Q . dq/ds_j)
    gen = {}
    for name, (fp, cp) in effects.items():
        gen[name] = np.einsum("spj,spjd->sd", fp, Kp) + np.einsum("sl,sld->sd", cp, Ktheta)
    F = -sum(gen.values()) if gen else np.zeros((S, model.n_drivers))
    out["power"] = (("step", "effect"), np.stack([(gen[e] * s_dot).sum(axis=1) for e in effects], axis=1)
                    if effects else np.zeros((S, 0)), f"{Fu}*{Lu}/{Tu}")
    coords["effect"] = list(effects)

    # ---- Lagrange multipliers: J^T lambda = Q - M qdd (an independent solve)
    Q_points = _point_forces(model, lagr_point, lagr_couple, Xz)  # Q - M Xdd at every point
    Qg = Q_points[:, model.moving].reshape(S, -1)  # (S, n_q) generalized
    lam = np.full((S, model.n_rows), np.nan)
    ok = motion.status == OK
    eng = engine(model)  # square and structurally regular: sparse block solves
    if ok.any() and eng is not None:
        idx = np.flatnonzero(ok)
        for lo in range(0, len(idx), 8192):
            ii = idx[lo:lo + 8192]
            E = eng.entries(model.q_of(Xz[ii]), s[ii])
            lam[ii] = np.stack(eng.solve_transpose(E, list(np.ascontiguousarray(Qg[ii].T))), axis=1)
        undetermined = np.zeros(model.n_rows, dtype=bool)
    elif ok.any():
        J = model.jacobian(Xz[ok], s[ok])
        JT = np.swapaxes(J, 1, 2)
        if J.shape[1] == J.shape[2]:
            lam[ok] = np.linalg.solve(JT, Qg[ok][..., None])[..., 0]
        else:
            lam[ok] = np.einsum("sij,sj->si", np.linalg.pinv(JT, rcond=1e-12), Qg[ok])
        undetermined = undetermined_rows(J)
    else:
        undetermined = np.zeros(model.n_rows, dtype=bool)
    FL = lam[:, drv] * phi_s

    # ---- report along the input direction where given
    status = motion.status.copy()
    units = []
    for j, dr in enumerate(scene.drivers):
        if dr.input is not None:
            n = np.asarray(dr.input.direction, dtype=float)
            n = n / np.hypot(*n)
            ip = model.point_names.index(dr.input.point)
            lev = Kp[:, ip, 0, j] * n[0] + Kp[:, ip, 1, j] * n[1]  # (S,) input displacement per unit driver value
            scale = model.size if dr.kind == "angle" else 1.0  # length/rad, or length/length
            flat = np.abs(lev) < LEVERAGE_RTOL * scale
            status[flat & (status == OK)] = NO_LEVERAGE
            safe = np.where(flat, np.nan, lev)
            F[:, j] = F[:, j] / safe
            FL[:, j] = FL[:, j] / safe
            units.append(Fu)
        else:
            units.append(f"{Fu}*{Lu}" if dr.kind == "angle" else Fu)
    bad = status != OK
    F[bad] = np.nan
    FL[bad] = np.nan
    unit = units[0] if len(set(units)) == 1 else "mixed"
    out["input_force"] = (("step", "driver"), F, unit)
    out["input_force_lagrange"] = (("step", "driver"), FL, unit)

    # ---- internal forces: links (tension positive) and sliders
    nd_rows = len(model.dist_a)
    link_force = np.full((S, nl), np.nan)
    row_of_link = {}
    r = 0
    for li, link in enumerate(scene.links):
        ia_, ib_ = model.link_a[li], model.link_b[li]
        if r < nd_rows and model.dist_a[r] == ia_ and model.dist_b[r] == ib_:
            row_of_link[li] = r
            r += 1
    for li, r in row_of_link.items():
        link_force[:, li] = lam[:, r]
    out["link_force"] = (("step", "link"), link_force, Fu)
    if undetermined.any():
        # redundant constraints: these are the minimum-norm choice, not the unique answer
        unique = np.ones(nl, dtype=np.int8)
        for li, r in row_of_link.items():
            unique[li] = 0 if undetermined[r] else 1
        out["link_force_unique"] = (("link",), unique, "1")
    if scene.sliders:
        first = nd_rows + 2 * len(model.loc_a)
        sl = np.full((S, len(scene.sliders)), np.nan)
        fixed_i = [i for i, x in enumerate(scene.sliders) if not x.moving]
        moving_i = [i for i, x in enumerate(scene.sliders) if x.moving]
        for k, i in enumerate(fixed_i):
            sl[:, i] = -lam[:, first + k]
        for k, i in enumerate(moving_i):
            sl[:, i] = -lam[:, first + len(fixed_i) + k]
        out["slider_force"] = (("step", "slider"), sl, Fu)
        if undetermined.any():
            rows = [first + k for k in range(len(fixed_i))] + [first + len(fixed_i) + k for k in range(len(moving_i))]
            unique = np.ones(len(scene.sliders), dtype=np.int8)
            for i, r in zip(fixed_i + moving_i, rows):
                unique[i] = 0 if undetermined[r] else 1
            out["slider_force_unique"] = (("slider",), unique, "1")
        coords["slider"] = [x.name for x in scene.sliders]
    fixed = np.flatnonzero(model.fixed)
    if "loads" in effects:
        couples = effects["loads"][1]
        for li in np.flatnonzero(np.any(couples != 0, axis=0)):
            cp = np.zeros_like(couples)
            cp[:, li] = couples[:, li]
            body(li)[:] -= _point_forces(model, np.zeros((S, P, 2)), cp, Xz)
    R, PF = reactions(model, lam, Q_points, bodies, Xz, s, ok)
    pairs = joints(model)
    out["joint_force"] = (("step", "joint", "xy"), PF, Fu)
    coords["joint"] = [f"{model.point_names[p]}@{scene.links[li].name}" for li, p in pairs]
    # under redundancy a self-stress changes the multipliers of the undetermined rows: a
    # reaction is not unique where such a row acts (minimum-norm choice reported, flagged)
    Jp0 = None
    if undetermined.any() and ok.any():
        i0 = np.flatnonzero(ok)[0]
        Jp0 = np.abs(model.jacobian_points(Xz[i0:i0 + 1], s[i0:i0 + 1])[0]).max(axis=2)  # (rows, P)
        row_link = body_rows(model)
        unique = [0 if (Jp0[undetermined & (row_link == li), p] > 0).any() else 1 for li, p in pairs]
        out["joint_force_unique"] = (("joint",), np.array(unique, dtype=np.int8), "1")
    if len(fixed):
        out["ground_reaction"] = (("step", "fixed_point", "xy"), R, Fu)
        coords["fixed_point"] = [model.point_names[i] for i in fixed]
        if Jp0 is not None:
            touched = Jp0[undetermined][:, fixed].max(axis=0) > 0
            out["ground_reaction_unique"] = (("fixed_point",), (~touched).astype(np.int8), "1")
    return Forces(variables=out, coords=coords, status=status)


def undetermined_rows(J: np.ndarray, tol: float = 1e-8) -> np.ndarray:
    """Return (n_rows,) True for multipliers that redundant constraints leave undetermined.

    ``J`` (S, n_rows, n_q) at solved (not singular) steps. With more rows than columns the
    left null space of J (the last ``n_rows - n_q`` left singular vectors) holds self-stresses:
    adding any of them to ``lambda`` still solves ``J^T lambda = Q``. A row with a component in
    it at any step is not unique there; the reported value is the minimum-norm choice.
    """
    S, m, n = J.shape
    if m <= n or S == 0:
        return np.zeros(m, dtype=bool)
    U = np.linalg.svd(J)[0]  # (S, m, m)
    return np.abs(U[:, :, n:]).max(axis=(0, 2)) > tol


def _perp(d):
    """Return d turned +90 degrees, for stacks (..., 2) (d @ _R90.T without a matmul)."""
    return np.stack([-d[..., 1], d[..., 0]], axis=-1)


def _scatter(fp, ia, ib, f):
    """fp[:, ia[k]] += f[:, k] and fp[:, ib[k]] -= f[:, k] for each k (np.add.at, but fast)."""
    for k in range(f.shape[1]):
        fp[:, ia[k]] += f[:, k]
        fp[:, ib[k]] -= f[:, k]


def _add_at_center(fp, force, ia, ib, u, v, L):
    """Distribute a force at body point (u, v) onto the basic points: N_G^T f, in place."""
    force = np.broadcast_to(force, (fp.shape[0], 2))
    C = (u * np.eye(2) + v * _R90) / L  # r_G = (I - C) r_a + C r_b
    # force @ M written out: BLAS' threaded matmul of (S, 2) x (2, 2) is slow on a busy machine
    for idx, M in ((ia, np.eye(2) - C), (ib, C)):
        fp[:, idx, 0] += force[:, 0] * M[0, 0] + force[:, 1] * M[1, 0]
        fp[:, idx, 1] += force[:, 0] * M[0, 1] + force[:, 1] * M[1, 1]


def _point_forces(model: Model, point_forces, couples, X):
    """Return forces at every point (S, P, 2): point forces plus link couples as force pairs."""
    fp = point_forces.copy()
    d = X[:, model.link_b] - X[:, model.link_a]
    n2 = np.einsum("slj,slj->sl", d, d)
    # a couple tau on a link = forces tau R d / L^2 on b and -tau R d / L^2 on a (failed
    # steps arrive zero-filled: 0 / 0 there, NaN, masked later like every failed step)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = (couples / n2)[..., None] * _perp(d)
    _scatter(fp, model.link_b, model.link_a, f)
    return fp


def reactions(model: Model, lam, point_forces, bodies, X, s, ok):
    """Return ground reactions (S, n_fixed, 2) and pin forces on bodies (S, n_joints, 2).

    Ground: a fixed point is a coordinate held by one more constraint; its multiplier mu follows
    from that coordinate's row of the equations of motion, ``-mu = Phi_X^T lambda - (Q - M Xdd)``
    (``point_forces`` (S, P, 2) holds ``Q - M Xdd`` at every point, fixed ones included).
    Pins: the force the pin at point P exerts on body k is ``(M_k Xdd - Q_k)_P + sum over the
    body's own rows of lambda_r dPhi_r/dX_P`` (``bodies``: {link: M_k Xdd - Q_k at the points}), for the
    pairs of :func:`joints`. NaN at steps that are not ok.
    """
    fixed = np.flatnonzero(model.fixed)
    pairs = joints(model)
    row_link = body_rows(model)
    S = X.shape[0]
    R = np.full((S, len(fixed), 2), np.nan)
    F = np.full((S, len(pairs), 2), np.nan)
    idx = np.flatnonzero(ok)
    rows_of = {li: np.flatnonzero(row_link == li) for li in sorted({li for li, _ in pairs})}
    for lo in range(0, len(idx), 8192):
        ii = idx[lo:lo + 8192]
        Jp = model.jacobian_points(X[ii], s[ii])  # (s, rows, P, 2)
        if len(fixed):
            R[ii] = np.einsum("sr,srfj->sfj", lam[ii], Jp[:, :, fixed]) - point_forces[ii][:, fixed]
        for li, rs in rows_of.items():
            own = np.einsum("sr,srpj->spj", lam[ii][:, rs], Jp[:, rs])
            if li in bodies:
                own = own + bodies[li][ii]
            for k, (lj, p) in enumerate(pairs):
                if lj == li:
                    F[ii, k] = own[:, p]
    return R, F


def body_rows(model: Model) -> np.ndarray:
    """Return (n_rows,) the link index of each body row, -1 elsewhere.

    Body rows: each link's distance and local rows, and an angle driver whose two points lie on
    one link (its multiplier is the actuator's couple on that body, reacted by the ground).
    Slider rows and coordinate drivers act on points (pins), not on a body.
    """
    out = np.full(model.n_rows, -1, dtype=np.intp)
    nd = len(model.dist_a)
    out[:nd] = model.dist_link
    out[nd:nd + 2 * len(model.loc_a)] = np.repeat(model.loc_link, 2)
    names = model.point_names
    with_rows = set(out[out >= 0].tolist())
    for j in np.flatnonzero(model.drv_angle):
        ends = {names[model.drv_a[j]], names[model.drv_b[j]]}
        for li, link in enumerate(model.scene.links):
            if li in with_rows and ends <= set(link.points):
                out[model.n_constraints + j] = li
                break
    return out


def joints(model: Model) -> list[tuple[int, int]]:
    """Return the (link index, point index) pairs of every point of every link with rows."""
    names = model.point_names
    has_rows = set(body_rows(model).tolist())
    return [(li, names.index(p)) for li, link in enumerate(model.scene.links) if li in has_rows
            for p in link.points]
