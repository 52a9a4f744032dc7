"""Turn a scene into index arrays and evaluate the constraints, vectorised over steps.

Natural coordinates: the unknowns ``q`` are the x, y of every moving point, in scene point
order (``q = X[:, moving].reshape(S, -1)``). Every function here works on whole sweeps:
point positions ``X`` of shape ``(S, n_points, 2)`` (fixed points included), driver values
``(S, n_drivers)`` in internal units (radians for angle drivers, lengths for coordinate
drivers). Constraint rows, in this order:

1. ``dist``   one per link: ``(|b - a|^2 - L^2) / (2 L)`` (a length; gradient of unit size)
2. ``local``  two per further point p of a link: ``p - a - (u d + v d_perp) / L`` with d = b - a
3. ``sfix``   one per fixed-guide slider: ``n . (p - c)`` with n the guide's unit normal
4. ``smov``   one per moving-guide slider: ``cross(e - d, p - d) / L_de`` for guide points d, e
5. ``driver`` one per driver: angle ``cross(u(theta), b - a)``; coordinate ``p[axis] - s``

All rows are lengths with O(1) gradients, so tolerances scale with the mechanism's size and
the Jacobian's conditioning does not depend on the unit system.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SceneError
from .scene import Scene

_R90 = np.array([[0.0, -1.0], [1.0, 0.0]])  # d_perp = _R90 @ d


@dataclass(frozen=True)
class Model:
    """Index arrays of one scene (names resolved to indices once, here)."""

    scene: Scene
    point_names: tuple[str, ...]
    start_position: np.ndarray  # (n_points, 2) as written in the scene
    fixed: np.ndarray  # (n_points,) bool
    moving: np.ndarray  # (n_moving,) point indices of moving points
    size: float  # length scale of the mechanism (bounding-box diagonal of the start)
    # dist rows
    dist_a: np.ndarray
    dist_b: np.ndarray
    dist_len: np.ndarray
    # local rows (two each)
    loc_a: np.ndarray
    loc_b: np.ndarray
    loc_p: np.ndarray
    loc_u: np.ndarray
    loc_v: np.ndarray
    loc_len: np.ndarray
    # fixed sliders
    sfix_p: np.ndarray
    sfix_c: np.ndarray  # (k, 2)
    sfix_n: np.ndarray  # (k, 2) unit normal
    # moving sliders
    smov_p: np.ndarray
    smov_d: np.ndarray
    smov_e: np.ndarray
    smov_len: np.ndarray
    # drivers
    drv_angle: np.ndarray  # (n_drivers,) bool
    drv_a: np.ndarray  # angle: tail point; coordinate: the point
    drv_b: np.ndarray  # angle: head point; coordinate: -1
    drv_axis: np.ndarray  # coordinate: 0/1; angle: -1
    # link frames (every link, ground links included) for link angles
    link_a: np.ndarray
    link_b: np.ndarray
    # which link each body row belongs to: dist rows, and local pairs (two rows each)
    dist_link: np.ndarray
    loc_link: np.ndarray

    @property
    def n_points(self) -> int:
        return len(self.point_names)

    @property
    def n_q(self) -> int:
        return 2 * len(self.moving)

    @property
    def n_drivers(self) -> int:
        return len(self.drv_angle)

    @property
    def n_constraints(self) -> int:
        """Rows without the drivers."""
        return (len(self.dist_a) + 2 * len(self.loc_a) + len(self.sfix_p) + len(self.smov_p))

    @property
    def n_rows(self) -> int:
        return self.n_constraints + self.n_drivers

    @property
    def driver_rows(self) -> slice:
        return slice(self.n_constraints, self.n_rows)

    @property
    def q_columns(self) -> np.ndarray:
        """Columns of the moving coordinates among all ``2 * n_points`` point coordinates."""
        return np.stack([2 * self.moving, 2 * self.moving + 1], axis=1).reshape(-1)

    # ------------------------------------------------------------------ conversions
    def positions(self, q: np.ndarray) -> np.ndarray:
        """Return all point positions ``(S, n_points, 2)`` from ``q`` ``(S, n_q)``."""
        q = np.asarray(q, dtype=float)
        S, mv = q.shape[0], self.moving
        X = np.empty((S, self.n_points, 2))
        for p in np.flatnonzero(self.fixed):  # a plain slice per point: no fancy-index write
            X[:, p] = self.start_position[p]
        q3 = q.reshape(S, -1, 2)
        if len(mv) > 8:
            X[:, mv] = q3
            return X
        # runs of consecutive moving points as slices: cheaper than a fancy-index write
        cut = [0] + [k for k in range(1, len(mv)) if mv[k] != mv[k - 1] + 1] + [len(mv)]
        for k0, k1 in zip(cut[:-1], cut[1:]):
            X[:, mv[k0]:mv[k0] + (k1 - k0)] = q3[:, k0:k1]
        return X

    def q_of(self, X: np.ndarray) -> np.ndarray:
        """Return ``q`` ``(S, n_q)`` from positions ``(S, n_points, 2)``."""
        return X[:, self.moving].reshape(X.shape[0], -1)

    def velocities(self, qdot: np.ndarray) -> np.ndarray:
        """Return point velocities ``(S, n_points, 2)`` (zero at fixed points)."""
        V = np.zeros((qdot.shape[0], self.n_points, 2))
        V[:, self.moving] = qdot.reshape(qdot.shape[0], -1, 2)
        return V

    # ------------------------------------------------------------------ constraints
    def phi(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return the constraint residuals ``(S, n_rows)`` at positions X and driver values s."""
        rows = []
        d = X[:, self.dist_b] - X[:, self.dist_a]
        rows.append((np.einsum("skj,skj->sk", d, d) - self.dist_len**2) / (2 * self.dist_len))
        d = X[:, self.loc_b] - X[:, self.loc_a]
        dp = d @ _R90.T
        r = X[:, self.loc_p] - X[:, self.loc_a] - (self.loc_u[:, None] * d + self.loc_v[:, None] * dp) / self.loc_len[:, None]
        rows.append(r.reshape(X.shape[0], -1))
        rows.append(np.einsum("skj,kj->sk", X[:, self.sfix_p] - self.sfix_c, self.sfix_n))
        e = X[:, self.smov_e] - X[:, self.smov_d]
        f = X[:, self.smov_p] - X[:, self.smov_d]
        rows.append(_cross(e, f) / self.smov_len)
        rows.append(self._driver_phi(X, s))
        return np.concatenate(rows, axis=1)

    def _driver_phi(self, X, s):
        out = np.empty((X.shape[0], self.n_drivers))
        ang = self.drv_angle
        if ang.any():
            u = np.stack([np.cos(s[:, ang]), np.sin(s[:, ang])], axis=-1)
            d = X[:, self.drv_b[ang]] - X[:, self.drv_a[ang]]
            out[:, ang] = _cross(u, d)
        crd = ~ang
        if crd.any():
            out[:, crd] = X[:, self.drv_a[crd], self.drv_axis[crd]] - s[:, crd]
        return out

    def jacobian_points(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return dPhi/dX ``(S, n_rows, n_points, 2)`` over all point coordinates."""
        S = X.shape[0]
        J = np.zeros((S, self.n_rows, self.n_points, 2))
        row = 0
        k = len(self.dist_a)
        if k:
            d = (X[:, self.dist_b] - X[:, self.dist_a]) / self.dist_len[:, None]
            rk = np.arange(row, row + k)
            J[slice(None), rk, self.dist_b] += d
            J[slice(None), rk, self.dist_a] += -d
            row += k
        k = len(self.loc_a)
        if k:
            # rows 2i (x) and 2i+1 (y): p - a - (u I + v R) (b - a) / L
            M = (self.loc_u[:, None, None] * np.eye(2) + self.loc_v[:, None, None] * _R90) / self.loc_len[:, None, None]
            rx = row + 2 * np.arange(k)
            for c in range(2):
                rc = rx + c
                e_c = np.zeros(2)
                e_c[c] = 1.0
                # d(row c)/dp = e_c ; d/da = -e_c + M[c] ; d/db = -M[c]
                J[slice(None), rc, self.loc_p] += e_c
                J[slice(None), rc, self.loc_a] += -e_c + M[:, c, :]
                J[slice(None), rc, self.loc_b] += -M[:, c, :]
            row += 2 * k
        k = len(self.sfix_p)
        if k:
            rk = np.arange(row, row + k)
            J[slice(None), rk, self.sfix_p] += self.sfix_n
            row += k
        k = len(self.smov_p)
        if k:
            e = X[:, self.smov_e] - X[:, self.smov_d]
            f = X[:, self.smov_p] - X[:, self.smov_d]
            L = self.smov_len[:, None]
            de = np.stack([f[..., 1], -f[..., 0]], axis=-1) / L  # d cross / d e
            df = np.stack([-e[..., 1], e[..., 0]], axis=-1) / L  # d cross / d f
            rk = np.arange(row, row + k)
            J[slice(None), rk, self.smov_e] += de
            J[slice(None), rk, self.smov_p] += df
            J[slice(None), rk, self.smov_d] += -de - df
            row += k
        for j in range(self.n_drivers):
            r = row + j
            if self.drv_angle[j]:
                c, sn = np.cos(s[:, j]), np.sin(s[:, j])
                g = np.stack([-sn, c], axis=-1)  # d cross(u, b - a) / d b
                J[:, r, self.drv_b[j]] += g
                J[:, r, self.drv_a[j]] -= g
            else:
                J[:, r, self.drv_a[j], self.drv_axis[j]] += 1.0
        return J

    def jacobian(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi_q ``(S, n_rows, n_q)``: the Jacobian with respect to the unknowns."""
        J = self.jacobian_points(X, s).reshape(X.shape[0], self.n_rows, -1)
        return J[:, :, self.q_columns]

    def phi_t(self, X: np.ndarray, s: np.ndarray, s_dot: np.ndarray) -> np.ndarray:
        """Return dPhi/dt ``(S, n_rows)`` (non-zero only in driver rows)."""
        out = np.zeros((X.shape[0], self.n_rows))
        out[:, self.driver_rows] = self.phi_s(X, s) * s_dot
        return out

    def phi_s(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return dPhi_driver/ds ``(S, n_drivers)`` (each driver row depends on its own value)."""
        out = -np.ones((X.shape[0], self.n_drivers))
        ang = self.drv_angle
        if ang.any():
            u = np.stack([np.cos(s[:, ang]), np.sin(s[:, ang])], axis=-1)
            d = X[:, self.drv_b[ang]] - X[:, self.drv_a[ang]]
            out[:, ang] = -np.einsum("skj,skj->sk", u, d)
        return out

    def gamma(self, X, V, s, s_dot, s_ddot) -> np.ndarray:
        """Return the acceleration right-hand side ``(S, n_rows)``: Phi_q qdd = gamma."""
        S = X.shape[0]
        parts = []
        dv = V[:, self.dist_b] - V[:, self.dist_a]
        parts.append(-np.einsum("skj,skj->sk", dv, dv) / self.dist_len)
        parts.append(np.zeros((S, 2 * len(self.loc_a))))
        parts.append(np.zeros((S, len(self.sfix_p))))
        ev = V[:, self.smov_e] - V[:, self.smov_d]
        fv = V[:, self.smov_p] - V[:, self.smov_d]
        parts.append(-2.0 * _cross(ev, fv) / self.smov_len)
        g = np.empty((S, self.n_drivers))
        ang = self.drv_angle
        if ang.any():
            th, w, al = s[:, ang], s_dot[:, ang], s_ddot[:, ang]
            u = np.stack([np.cos(th), np.sin(th)], axis=-1)
            d = X[:, self.drv_b[ang]] - X[:, self.drv_a[ang]]
            dd = V[:, self.drv_b[ang]] - V[:, self.drv_a[ang]]
            g[:, ang] = (al * np.einsum("skj,skj->sk", u, d) + w**2 * _cross(u, d)
                         + 2 * w * np.einsum("skj,skj->sk", u, dd))
        crd = ~ang
        if crd.any():
            g[:, crd] = s_ddot[:, crd]
        parts.append(g)
        return np.concatenate(parts, axis=1)

    def driver_values_at(self, X: np.ndarray) -> np.ndarray:
        """Return the driver values ``(S, n_drivers)`` that positions ``X`` (S, n_points, 2) show,
        in internal units: an angle driver's direction in radians (in (-pi, pi]), a coordinate
        driver's coordinate."""
        out = np.empty((X.shape[0], self.n_drivers))
        for j in range(self.n_drivers):
            a = X[:, self.drv_a[j]]
            if self.drv_angle[j]:
                d = X[:, self.drv_b[j]] - a
                out[:, j] = np.arctan2(d[:, 1], d[:, 0])
            else:
                out[:, j] = a[:, self.drv_axis[j]]
        return out

    def link_angles(self, X: np.ndarray) -> np.ndarray:
        """Return each link's direction (first to second point) in radians ``(S, n_links)``."""
        d = X[:, self.link_b] - X[:, self.link_a]
        return np.arctan2(d[..., 1], d[..., 0])


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def build_model(scene: Scene) -> Model:
    """Resolve names to indices, lengths and local coordinates (from the start where not given)."""
    names = scene.point_names
    index = {n: i for i, n in enumerate(names)}
    X0 = np.array([[p.x, p.y] for p in scene.points], dtype=float)
    fixed = np.array([p.fixed for p in scene.points], dtype=bool)
    span = X0.max(axis=0) - X0.min(axis=0) if len(X0) else np.zeros(2)
    size = float(np.hypot(*span))
    lens = [float(np.hypot(*(X0[index[l.points[1]]] - X0[index[l.points[0]]]))) for l in scene.links]
    size = max([size] + lens) or 1.0

    dist_a, dist_b, dist_len, dist_link = [], [], [], []
    loc = {k: [] for k in ("a", "b", "p", "u", "v", "len", "link")}
    for li, link in enumerate(scene.links):
        ia, ib = index[link.points[0]], index[link.points[1]]
        idx = [index[p] for p in link.points]
        if all(fixed[i] for i in idx):
            continue  # a drawn piece of ground: no unknowns, no rows
        d0 = X0[ib] - X0[ia]
        L0 = float(np.hypot(*d0))
        L = float(link.length) if link.length is not None else L0
        if not fixed[ia] or not fixed[ib]:
            dist_a.append(ia)
            dist_b.append(ib)
            dist_len.append(L)
            dist_link.append(li)
        e = d0 / L0
        ep = _R90 @ e
        for pname in link.points[2:]:
            ip = index[pname]
            if fixed[ip] and fixed[ia] and fixed[ib]:
                continue
            if pname in link.local:
                u, v = link.local[pname]
            else:
                r = X0[ip] - X0[ia]
                u, v = float(r @ e), float(r @ ep)
            reach = float(np.hypot(u, v)) / L
            if reach**2 * scene.solver.singular_rcond >= 1.0:
                # the Jacobian's condition grows as reach^2: every step would count as singular
                raise SceneError(
                    scene.path, f'links "{link.name}"', "local" if pname in link.local else "points",
                    f'point "{pname}" is {reach:.3g} times farther from "{link.points[0]}" than '
                    f'the link\'s second point "{link.points[1]}": a frame that short cannot hold '
                    f"it (the constraint Jacobian's condition grows as the square of that ratio, "
                    f"about {reach**2:.1g} here, and every step would count as singular)",
                    f'list a far point second so that the frame is long, e.g. points = '
                    f'["{link.points[0]}", "{pname}", ...] (lengths and local refer to the first '
                    f"two points)")
            for key, val in zip(("a", "b", "p", "u", "v", "len", "link"), (ia, ib, ip, u, v, L, li)):
                loc[key].append(val)

    sfix_p, sfix_c, sfix_n = [], [], []
    smov = {k: [] for k in ("p", "d", "e", "len")}
    for sl in scene.sliders:
        ip = index[sl.point]
        if sl.moving:
            idd, ie = index[sl.line_points[0]], index[sl.line_points[1]]
            smov["p"].append(ip)
            smov["d"].append(idd)
            smov["e"].append(ie)
            smov["len"].append(float(np.hypot(*(X0[ie] - X0[idd]))))
        else:
            dvec = np.asarray(sl.direction, dtype=float)
            dvec = dvec / np.hypot(*dvec)
            sfix_p.append(ip)
            sfix_c.append(sl.through)
            sfix_n.append(_R90 @ dvec)

    drv_angle, drv_a, drv_b, drv_axis = [], [], [], []
    for dr in scene.drivers:
        if dr.kind == "angle":
            drv_angle.append(True)
            drv_a.append(index[dr.points[0]])
            drv_b.append(index[dr.points[1]])
            drv_axis.append(-1)
        else:
            drv_angle.append(False)
            drv_a.append(index[dr.points[0]])
            drv_b.append(-1)
            drv_axis.append(int(dr.axis))

    ia = np.array([index[l.points[0]] for l in scene.links], dtype=np.intp)
    ib = np.array([index[l.points[1]] for l in scene.links], dtype=np.intp)

    def ints(x):
        return np.asarray(x, dtype=np.intp).reshape(-1)

    def flts(x, shape=(-1,)):
        return np.asarray(x, dtype=float).reshape(shape)

    return Model(
        scene=scene, point_names=names, start_position=X0, fixed=fixed,
        moving=np.flatnonzero(~fixed), size=size,
        dist_a=ints(dist_a), dist_b=ints(dist_b), dist_len=flts(dist_len),
        loc_a=ints(loc["a"]), loc_b=ints(loc["b"]), loc_p=ints(loc["p"]),
        loc_u=flts(loc["u"]), loc_v=flts(loc["v"]), loc_len=flts(loc["len"]),
        sfix_p=ints(sfix_p), sfix_c=flts(sfix_c, (-1, 2)), sfix_n=flts(sfix_n, (-1, 2)),
        smov_p=ints(smov["p"]), smov_d=ints(smov["d"]), smov_e=ints(smov["e"]),
        smov_len=flts(smov["len"]),
        drv_angle=np.array(drv_angle, dtype=bool), drv_a=ints(drv_a), drv_b=ints(drv_b),
        drv_axis=ints(drv_axis), link_a=ia, link_b=ib,
        dist_link=ints(dist_link), loc_link=ints(loc["link"]),
    )


def driver_values(scene: Scene) -> np.ndarray:
    """Return every step's driver values ``(n_steps, n_drivers)`` in scene units (degrees)."""
    cols = []
    for dr in scene.drivers:
        i = np.arange(dr.steps, dtype=float)
        if dr.step is not None:
            cols.append(dr.from_value + i * dr.step)
        elif dr.steps == 1:
            cols.append(np.full(1, float(dr.from_value)))
        else:
            cols.append(dr.from_value + i * (dr.to_value - dr.from_value) / (dr.steps - 1))
    return np.stack(cols, axis=1)


def driver_scale(scene: Scene) -> np.ndarray:
    """Return the factor ``(n_drivers,)`` from scene driver units to internal (deg -> rad)."""
    return np.array([np.pi / 180.0 if d.kind == "angle" else 1.0 for d in scene.drivers])


@dataclass(frozen=True)
class Mobility:
    """Degrees of freedom and redundancy from the rank of the constraint Jacobian."""

    n_q: int
    n_constraints: int
    rank: int
    dof: int
    redundant: int


def mobility(model: Model, X: np.ndarray | None = None, rtol: float = 1e-9) -> Mobility:
    """Return the mobility at positions X ``(n_points, 2)`` (default: the start as written)."""
    X = model.start_position if X is None else X
    s0 = np.zeros((1, model.n_drivers))
    J = model.jacobian(X[None], s0)[0, : model.n_constraints]
    if J.size:
        sv = np.linalg.svd(J, compute_uv=False)
        rank = int((sv > rtol * max(sv.max(), 1.0)).sum())
    else:
        rank = 0
    return Mobility(model.n_q, model.n_constraints, rank, model.n_q - rank, model.n_constraints - rank)


def _project(model: Model, X: np.ndarray, max_iter: int = 30) -> np.ndarray | None:
    """Return positions near X ``(n_points, 2)`` satisfying the constraints (drivers left out).

    Gauss-Newton with minimum-norm steps, so redundant (consistent) constraints are no obstacle.
    None when the constraints cannot be met from there.
    """
    rows = slice(0, model.n_constraints)
    s0 = np.zeros((1, model.n_drivers))
    q = model.q_of(X[None])
    for _ in range(max_iter):
        Xq = model.positions(q)
        F = model.phi(Xq, s0)[0, rows]
        if not F.size or np.abs(F).max() <= 1e-13 * model.size:
            return Xq[0]
        J = model.jacobian(Xq, s0)[0, rows]
        q = q - np.linalg.lstsq(J, F, rcond=None)[0][None]
        if not np.all(np.isfinite(q)):
            return None
    return None


def generic_mobility(model: Model) -> Mobility:
    """Return the mobility of the mechanism: the rank at assembled shapes, not at one guess.

    Redundancy holds only on the constraint manifold (a double parallelogram written with
    rounded coordinates looks rigid), and the rank drops at a start guess with links collinear,
    at a change point or on a dead centre. So the rank is taken at the start projected onto the
    constraints and, when that does not match the drivers, the largest rank found at assembled
    shapes projected from small steps (1e-3 of the size) along the near-null directions.
    Falls back to the start as written when nothing can be assembled.
    """
    X0 = model.start_position
    nd = model.n_drivers
    Xa = _project(model, X0)
    mob = mobility(model, X0 if Xa is None else Xa)
    if (mob.dof == nd and Xa is not None) or not model.n_q or not model.n_constraints:
        return mob
    found = Xa is not None
    s0 = np.zeros((1, nd))
    base = X0 if Xa is None else Xa
    J = model.jacobian(base[None], s0)[0, : model.n_constraints]
    for v in np.linalg.svd(J)[2][::-1]:  # near-null directions first
        for sign in (1.0, -1.0):
            q = model.q_of(base[None])[0] + sign * 1e-3 * model.size * v
            Xn = _project(model, model.positions(q[None])[0])
            if Xn is None:
                continue
            other = mobility(model, Xn)
            if not found or other.rank > mob.rank:
                mob, found = other, True
            if mob.dof == nd:
                return mob
    return mob


def check_mobility(model: Model) -> Mobility:
    """Raise SceneError unless the degrees of freedom equal the number of drivers."""
    mob = generic_mobility(model)
    nd = model.n_drivers
    if mob.dof != nd:
        sc = model.scene
        hint = ("add a driver or a constraint (link, slider)" if mob.dof > nd
                else "remove a driver, or free the mechanism (too many links or sliders)")
        on_links = {p for link in sc.links for p in link.points}
        loose = [p.name for p in sc.points if not p.fixed and p.name not in on_links]
        if loose and mob.dof > nd:
            hint = (f"point(s) {', '.join(loose)} belong to no link (2 degrees of freedom each): "
                    "put them on a link, or remove them")
        raise SceneError(sc.path, "drivers", None,
                         f"the mechanism has {mob.dof} degree(s) of freedom "
                         f"({mob.n_q} unknowns, constraint rank {mob.rank}"
                         + (f", {mob.redundant} redundant constraint(s)" if mob.redundant else "")
                         + f") but {nd} driver(s)", hint)
    return mob


def constraint_source(model: Model, row: int) -> tuple[str, str]:
    """Return the scene table and key (as in SceneError) that constraint row ``row`` comes from."""
    sc = model.scene
    k = len(model.dist_a)
    if row < k:
        a, b = model.dist_a[row], model.dist_b[row]
        for li, link in enumerate(sc.links):
            if model.link_a[li] == a and model.link_b[li] == b:
                return f'links "{link.name}"', "lengths" if link.length is not None else "points"
    row -= k
    k = 2 * len(model.loc_a)
    if row < k:
        a, b, p = (int(x[row // 2]) for x in (model.loc_a, model.loc_b, model.loc_p))
        for li, link in enumerate(sc.links):
            if model.link_a[li] == a and model.link_b[li] == b and model.point_names[p] in link.points:
                return f'links "{link.name}"', "local" if model.point_names[p] in link.local else "points"
    row -= k
    fixed = [s for s in sc.sliders if not s.moving]
    moving = [s for s in sc.sliders if s.moving]
    if row < len(fixed):
        return f'sliders "{fixed[row].name}"', "along"
    row -= len(fixed)
    if row < len(moving):
        return f'sliders "{moving[row].name}"', "along"
    row -= len(moving)
    if 0 <= row < len(sc.drivers):
        return f'drivers "{sc.drivers[row].name}"', "from"
    return "points", None
