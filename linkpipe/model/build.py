"""Turn a scene into index arrays (names resolved once): the :class:`Model`.

Natural coordinates: the unknowns ``q`` are the x, y of every moving point, in scene point
order (``q = X[:, moving].reshape(S, -1)``). Positions ``X`` are ``(S, n_points, 2)`` (fixed
points included), driver values ``(S, n_drivers)`` in internal units (radians for angle
drivers, lengths for coordinate drivers). The constraint rows themselves are written once, in
:mod:`linkpipe.model.equations`; ``Model.phi``, ``Model.jacobian``, ``Model.phi_s`` and
``Model.gamma`` assemble them on whole sweeps.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..scene import Scene
from . import equations as eq
from .rows import driver_rows, link_rows, slider_rows


#: the residual a drawing's coordinates can meet, in units of eps x its largest |coordinate|
#: (a constraint row sums a few coordinates' rounding), for a drawing farther than
#: FAR_FROM_ORIGIN x its size from the origin (nearer, a tol that rounding cannot meet is the
#: scene's error at [solver] tol)
ROUNDING_FLOOR = 4.0
FAR_FROM_ORIGIN = 100.0


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
    drv_kind: np.ndarray  # (n_drivers,) equations.COORDINATE / ANGLE / DISTANCE / RELATIVE
    drv_angle: np.ndarray  # (n_drivers,) bool: the value is an angle (absolute or relative)
    drv_a: np.ndarray  # angle, distance: tail point; coordinate: the point
    drv_b: np.ndarray  # angle, distance: head point; coordinate: -1
    drv_axis: np.ndarray  # coordinate: 0/1; else -1
    drv_c: np.ndarray  # relative angle: the reference vector's tail; else -1
    drv_d: np.ndarray  # relative angle: the reference vector's head; else -1
    drv_len: np.ndarray  # distance: its largest length; relative: |d - c| at the start; else 0
    # link frames (every link, ground links included) for link angles
    link_a: np.ndarray
    link_b: np.ndarray
    # which link each body row belongs to: dist rows, and local pairs (two rows each)
    dist_link: np.ndarray
    loc_link: np.ndarray
    # the same rows as plain numbers, for model/equations.py (built from the arrays above)
    rows: eq.Rows
    #: the largest |coordinate| of the drawing (its distance from the origin sets the rounding
    #: of every position: eps x extent)
    extent: float = 0.0

    def tolerance(self, tol: float | None = None, size=None):
        """The absolute residual tolerance (length units): ``tol`` (default ``[solver] tol``)
        times the mechanism's size (``size``: a study's per-variant sizes), but never below
        what float64 can resolve at the drawing's distance from the origin where that is more
        than :data:`FAR_FROM_ORIGIN` sizes: :data:`ROUNDING_FLOOR` x eps x extent (a four-bar
        of size 5 drawn at (1e5, 1e5) has coordinates fixed only to ~1.5e-11; 1e-12 x 5 would
        refuse every step of it). Nearer the origin a tol below rounding stays the scene's
        error at [solver] tol."""
        tol = self.scene.solver.tol if tol is None else tol
        size = self.size if size is None else size
        far = self.extent > FAR_FROM_ORIGIN * np.max(size)
        floor = ROUNDING_FLOOR * np.finfo(float).eps * self.extent if far else 0.0
        return np.maximum(tol * size, floor)

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

    def qT_of(self, X: np.ndarray) -> np.ndarray:
        """Return ``q_of(X).T`` ``(n_q, S)``, contiguous, in one gather (coordinates first,
        steps last: the sparse engine's layout)."""
        return X.transpose(1, 2, 0)[self.moving].reshape(self.n_q, -1)

    def velocities(self, qdot: np.ndarray) -> np.ndarray:
        """Return point velocities ``(S, n_points, 2)`` (zero at fixed points)."""
        V = np.zeros((qdot.shape[0], self.n_points, 2))
        V[:, self.moving] = qdot.reshape(qdot.shape[0], -1, 2)
        return V

    # ------------------------------------------------------------------ constraints
    # Each method assembles the rows that model/equations.py writes, on stacked arrays.
    # ``rows``: the rows' constants when they differ row by row (a study's variants on one
    # (variant, step) row axis: :meth:`equations.Rows.take` of them at X's rows); default the
    # model's own.
    def phi(self, X: np.ndarray, s: np.ndarray, rows: eq.Rows | None = None) -> np.ndarray:
        """Return the constraint residuals ``(S, n_rows)`` at positions X and driver values s."""
        xy, cos_s, sin_s = _stacked(X, s)
        out = np.empty((X.shape[0], self.n_rows))
        for r, row in enumerate(eq.phi_rows(rows or self.rows, xy, s.T, cos_s, sin_s)):
            out[:, r] = row
        return out

    def jacobian_points(self, X: np.ndarray, s: np.ndarray,
                        rows: eq.Rows | None = None) -> np.ndarray:
        """Return dPhi/dX ``(S, n_rows, n_points, 2)`` over all point coordinates."""
        xy, cos_s, sin_s = _stacked(X, s)
        J = np.zeros((X.shape[0], self.n_rows, self.n_points, 2))
        for r, p, gx, gy in eq.jacobian_terms(rows or self.rows, xy, cos_s, sin_s):
            J[:, r, p, 0] += gx
            J[:, r, p, 1] += gy
        return J

    def jacobian_terms(self, X: np.ndarray, s: np.ndarray, rows: eq.Rows | None = None):
        """Yield Phi_X's non-zero terms ``(row, point, dphi/dx (S,), dphi/dy (S,))`` (floats where
        constant; a point may recur in a row: add them) at positions X (S, P, 2): the sparse
        form of :meth:`jacobian_points`, for work that must not form it densely."""
        xy, cos_s, sin_s = _stacked(X, s)
        return eq.jacobian_terms(rows or self.rows, xy, cos_s, sin_s)

    def jacobian(self, X: np.ndarray, s: np.ndarray, rows: eq.Rows | None = None) -> np.ndarray:
        """Return Phi_q ``(S, n_rows, n_q)``: the Jacobian with respect to the unknowns."""
        J = self.jacobian_points(X, s, rows).reshape(X.shape[0], self.n_rows, -1)
        return J[:, :, self.q_columns]

    def phi_t(self, X: np.ndarray, s: np.ndarray, s_dot: np.ndarray,
              rows: eq.Rows | None = None) -> np.ndarray:
        """Return dPhi/dt ``(S, n_rows)`` (non-zero only in driver rows)."""
        out = np.zeros((X.shape[0], self.n_rows))
        out[:, self.driver_rows] = self.phi_s(X, s, rows) * s_dot
        return out

    def phi_s(self, X: np.ndarray, s: np.ndarray, rows: eq.Rows | None = None) -> np.ndarray:
        """Return dPhi_driver/ds ``(S, n_drivers)`` (each driver row depends on its own value)."""
        xy, cos_s, sin_s = _stacked(X, s)
        out = np.empty((X.shape[0], self.n_drivers))
        for j, row in enumerate(eq.phi_s_rows(rows or self.rows, xy, s.T, cos_s, sin_s)):
            out[:, j] = row
        return out

    def gamma(self, X, V, s, s_dot, s_ddot, rows: eq.Rows | None = None) -> np.ndarray:
        """Return the acceleration right-hand side ``(S, n_rows)``: Phi_q qdd = gamma."""
        xy, cos_s, sin_s = _stacked(X, s)
        vxy, _, _ = _stacked(V, s[:, :0])
        out = np.empty((X.shape[0], self.n_rows))
        values = eq.gamma_rows(rows or self.rows, xy, vxy, s.T, s_dot.T, s_ddot.T, cos_s, sin_s)
        for r, row in enumerate(values):
            out[:, r] = row
        return out

    def driver_values_at(self, X: np.ndarray) -> np.ndarray:
        """Return the driver values ``(S, n_drivers)`` that positions ``X`` (S, n_points, 2) show,
        in internal units: an angle driver's direction in radians (in (-pi, pi]; a relative one's
        from its reference vector), a coordinate driver's coordinate, a distance driver's
        distance."""
        out = np.empty((X.shape[0], self.n_drivers))
        for j in range(self.n_drivers):
            a = X[:, self.drv_a[j]]
            kind = self.drv_kind[j]
            if kind == eq.COORDINATE:
                out[:, j] = a[:, self.drv_axis[j]]
                continue
            d = X[:, self.drv_b[j]] - a
            if kind == eq.ANGLE:
                out[:, j] = np.arctan2(d[:, 1], d[:, 0])
            elif kind == eq.DISTANCE:
                out[:, j] = np.hypot(d[:, 0], d[:, 1])
            else:
                r = X[:, self.drv_d[j]] - X[:, self.drv_c[j]]
                out[:, j] = np.arctan2(r[:, 0] * d[:, 1] - r[:, 1] * d[:, 0],
                                       r[:, 0] * d[:, 0] + r[:, 1] * d[:, 1])
        return out

    def aligned(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return (S,) True where every angle driver's vector points along (not against) the
        direction its value asks for (:func:`equations.alignment_rows`)."""
        xy, cos_s, sin_s = _stacked(X, s)
        ok = np.ones(X.shape[0], dtype=bool)
        for _, value in eq.alignment_rows(self.rows, xy, cos_s, sin_s):
            ok &= value > 0
        return ok

    def link_angles(self, X: np.ndarray) -> np.ndarray:
        """Return each link's direction (first to second point) in radians ``(S, n_links)``
        (link by link on contiguous columns: no (S, n_links, 2) temporary)."""
        out = np.empty((X.shape[0], len(self.link_a)))
        for j, (a, b) in enumerate(zip(self.link_a, self.link_b)):
            out[:, j] = np.arctan2(X[:, b, 1] - X[:, a, 1], X[:, b, 0] - X[:, a, 0])
        return out


def _stacked(X: np.ndarray, s: np.ndarray):
    """Return the accessor ``xy(p) -> (x (S,), y (S,))`` of stacked positions X (S, P, 2) and
    the drivers' ``cos``, ``sin`` (n_drivers, S) of values s (S, n_drivers)."""
    def xy(p):
        return X[:, p, 0], X[:, p, 1]

    sT = s.T
    return xy, np.cos(sT), np.sin(sT)


def build_model(scene: Scene) -> Model:
    """Resolve names to indices, lengths and local coordinates (from the start where not given)."""
    names = scene.point_names
    index = {n: i for i, n in enumerate(names)}
    X0 = np.array([[p.x, p.y] for p in scene.points], dtype=float)
    fixed = np.array([p.fixed for p in scene.points], dtype=bool)
    size = mechanism_size(scene, X0)

    def ints(x):
        return np.asarray(x, dtype=np.intp).reshape(-1)

    def flts(x, shape=(-1,)):
        return np.asarray(x, dtype=float).reshape(shape)

    dist, loc = link_rows(scene, index, X0, fixed)
    sfix_p, sfix_c, sfix_n, smov = slider_rows(scene, index, X0)
    drivers = driver_rows(scene, index, X0)
    arrays = dict(
        dist_a=ints(dist["a"]), dist_b=ints(dist["b"]), dist_len=flts(dist["len"]),
        loc_a=ints(loc["a"]), loc_b=ints(loc["b"]), loc_p=ints(loc["p"]),
        loc_u=flts(loc["u"]), loc_v=flts(loc["v"]), loc_len=flts(loc["len"]),
        sfix_p=ints(sfix_p), sfix_c=flts(sfix_c, (-1, 2)), sfix_n=flts(sfix_n, (-1, 2)),
        smov_p=ints(smov["p"]), smov_d=ints(smov["d"]), smov_e=ints(smov["e"]),
        smov_len=flts(smov["len"]),
        drv_kind=ints(drivers["kind"]), drv_a=ints(drivers["a"]), drv_b=ints(drivers["b"]),
        drv_axis=ints(drivers["axis"]), drv_c=ints(drivers["c"]), drv_d=ints(drivers["d"]),
        drv_len=flts(drivers["len"]))
    arrays["drv_angle"] = np.isin(arrays["drv_kind"], (eq.ANGLE, eq.RELATIVE))
    ia = np.array([index[l.points[0]] for l in scene.links], dtype=np.intp)
    ib = np.array([index[l.points[1]] for l in scene.links], dtype=np.intp)
    return Model(
        scene=scene, point_names=names, start_position=X0, fixed=fixed,
        moving=np.flatnonzero(~fixed), size=size, **arrays, link_a=ia, link_b=ib,
        dist_link=ints(dist["link"]), loc_link=ints(loc["link"]), rows=eq.rows_of(**arrays),
        extent=float(np.abs(X0).max()) if X0.size else 0.0,
    )


def content_key(model: Model) -> tuple:
    """A key of everything that what is derived from a model alone reads (the sparse engine,
    the one-step kernels, the assembled drawing, the mobility): every array and number of the
    model and the scene's ``[solver]`` table, not the rest of the scene (its drivers' values,
    logs, measurements). Two models equal in it give the same derived objects to the last bit
    (:func:`linkpipe.cache.derived`'s ``same``); computed once per model."""
    from ..cache import derived

    def build(md: Model) -> tuple:
        parts = [repr(md.scene.solver), md.point_names, float(md.size), float(md.extent)]
        for f in fields(md):
            value = getattr(md, f.name)
            if isinstance(value, np.ndarray):
                parts.append((f.name, value.dtype.str, value.shape, value.tobytes()))
        return tuple(parts)

    return derived(model, "content_key", build)


def mechanism_size(scene: Scene, X0: np.ndarray):
    """The mechanism's length scale: the diagonal of its drawn points' bounding box, or its
    longest link (first two points) where longer; 1 when both are 0. ``X0`` (P, 2) -> float,
    or (R, P, 2) -> (R,) (a study's variants, each with its own drawing)."""
    index = {n: i for i, n in enumerate(scene.point_names)}
    span = (X0.max(axis=-2) - X0.min(axis=-2)) if X0.shape[-2] else np.zeros(X0.shape[:-2] + (2,))
    size = np.hypot(span[..., 0], span[..., 1])
    for link in scene.links:
        d = X0[..., index[link.points[1]], :] - X0[..., index[link.points[0]], :]
        size = np.maximum(size, np.hypot(d[..., 0], d[..., 1]))
    size = np.where(size > 0, size, 1.0)
    return float(size) if size.ndim == 0 else size


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
