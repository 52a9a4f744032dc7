"""What the recording draws, as numbers: bounds, sizes, arrow scales, the outline of a plate."""
from __future__ import annotations

import numpy as np

from ...cache import derived

#: longest velocity / acceleration arrow, as a fraction of the mechanism's size
ARROW_FRACTION = 0.25


def bounds(result, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the (lower, upper) corners of the finite rows of ``points`` (N, 2)."""
    # NaN rows (failed steps) drop out of nanmin/nanmax; no masked copy of (S * P, 2) points
    with np.errstate(invalid="ignore"):
        finite = finite_rows(points)
    if not finite.any():
        points = np.array([[p.x, p.y] for p in result.scene.points], dtype=float)
        return points.min(axis=0), points.max(axis=0)
    if finite.all():  # per coordinate: numpy's reductions over a length-2 axis are slow
        x, y = points[:, 0], points[:, 1]
        return np.array([x.min(), y.min()]), np.array([x.max(), y.max()])
    return np.nanmin(points, axis=0), np.nanmax(points, axis=0)


def finite_rows(a: np.ndarray) -> np.ndarray:
    """Return ``np.isfinite(a).all(axis=-1)``: a NaN or inf survives the row's sum."""
    with np.errstate(invalid="ignore", over="ignore"):
        return np.isfinite(a.sum(axis=-1)) if a.shape[-1] > 2 else np.isfinite(a[..., 0] + a[..., -1])


def mechanism_size(result) -> float:
    """Return the diagonal of the bounding box of every position of the sweep (1 if none)."""
    return derived(result, "rrd_mechanism_size", _mechanism_size)  # asked for several times


def _mechanism_size(result) -> float:
    lo, hi = bounds(result, result.position.reshape(-1, 2))
    return float(np.hypot(*(hi - lo))) or 1.0


def arrow_scales(result) -> dict[str, float]:
    """Return the length per unit of each vector quantity: its longest arrow is 25 % of the size."""
    return dict(derived(result, "rrd_arrow_scales", _arrow_scales))  # blueprint and log ask


def _arrow_scales(result) -> dict[str, float]:
    k = point_index(result, result.scene.outputs.vectors)
    scales = {}
    for name in ("velocity", "acceleration"):
        data = getattr(result, name)
        if data is None or not k:
            continue
        norm = np.linalg.norm(data[:, k], axis=-1)
        vmax = np.nanmax(norm) if np.isfinite(norm).any() else 0.0
        scales[name] = ARROW_FRACTION * mechanism_size(result) / vmax if vmax > 0 else 1.0
    return scales


def arrow_legend(result, quantity: str) -> str:
    """Return ``"1 m = 7.51 m/s"``: what one length unit of ``quantity``'s arrows stands for."""
    unit = {v.name: v.units for v in result.variables()}[quantity]
    return f"1 {result.units()['length']} = {1 / arrow_scales(result)[quantity]:.3g} {unit}"


def point_index(result, names) -> list[int]:
    index = {n: i for i, n in enumerate(result.point_names)}
    return [index[n] for n in names]


def runs(path: np.ndarray) -> list[np.ndarray]:
    """Split an (S, 2) path at its non-finite rows into runs of 2 or more points."""
    ok = np.isfinite(path).all(axis=1)
    edges = np.flatnonzero(np.diff(ok.astype(np.int8))) + 1
    return [run for run, good in zip(np.split(path, edges), np.split(ok, edges))
            if good[0] and len(run) >= 2]


# ------------------------------------------------------------------------------ plates
def outline(result, k: list[int]) -> list[int]:
    """Point indices (into ``result.point_names``) of a link's drawn outline.

    A bar: its two points. A plate (3 or more points): the convex hull of its points, counter-
    clockwise and closed (its last index is its first), so that it never crosses itself
    whatever order the scene lists the points in; points inside the hull (or on its edges)
    stay points. A plate whose points lie on one line: the segment between its two extreme
    points. The shape is taken at the first step where every point of the link is finite (a
    rigid body's outline does not change along the sweep), else as drawn in the scene.
    """
    if len(k) < 3:
        return list(k)
    xy = _shape(result, k)
    span = float(np.max(np.ptp(xy, axis=0))) or 1.0
    hull = _convex_hull(xy)
    if len(hull) < 3 or abs(_area(xy[hull])) <= 1e-9 * span ** 2:   # on one line
        axis = xy[np.argmax(np.hypot(*(xy - xy[0]).T))] - xy[0]
        along = (xy - xy[0]) @ axis
        return [k[int(np.argmin(along))], k[int(np.argmax(along))]]
    return [k[i] for i in hull] + [k[hull[0]]]


def _shape(result, k: list[int]) -> np.ndarray:
    X = result.position[:, k]
    ok = finite_rows(X.reshape(len(X), -1))
    if ok.any():
        return np.asarray(X[int(np.argmax(ok))], dtype=float)
    return np.array([[result.scene.points[i].x, result.scene.points[i].y] for i in k], dtype=float)


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _convex_hull(xy: np.ndarray) -> list[int]:
    """Indices of the convex hull of ``xy`` (n, 2), counter-clockwise (Andrew's monotone chain)."""
    order = sorted(range(len(xy)), key=lambda i: (xy[i][0], xy[i][1]))

    def half(indices):
        chain: list[int] = []
        for i in indices:
            while len(chain) >= 2 and _cross(xy[chain[-2]], xy[chain[-1]], xy[i]) <= 0:
                chain.pop()
            chain.append(i)
        return chain[:-1]

    return half(order) + half(order[::-1])


def _area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(x @ np.roll(y, -1) - y @ np.roll(x, -1))
