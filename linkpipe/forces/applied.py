"""Applied forces as arrays: where a body point's force lands on the body's basic points, link
couples as force pairs, and the frame of a mass centre. Everything is vectorised over steps:
point forces ``(S, n_points, 2)``, link couples ``(S, n_links)``."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from ..scene.sides import drawn_local


@dataclass(frozen=True)
class Applied:
    """One effect's applied loads: ``point_forces`` (S, n_points, 2) and ``couples``
    (S, n_links), CCW positive."""

    point_forces: np.ndarray
    couples: np.ndarray


def link_index(model: Model, name: str) -> int:
    return [link.name for link in model.scene.links].index(name)


def center_frame(model: Model, link_name: str, center, rows=None) -> tuple[int, int, float, float, float]:
    """Return (ia, ib, u, v, L) of a mass centre given as a point name or local (u, v).
    ``rows``: the model's rows with per-row constants (:class:`linkpipe.model.equations.Rows`:
    a study's variants of other link lengths): u, v, L then as they give them, (S,) arrays."""
    li = link_index(model, link_name)
    link = model.scene.links[li]
    names = model.point_names
    ia, ib = names.index(link.points[0]), names.index(link.points[1])
    X0 = model.start_position
    L0 = float(np.hypot(*(X0[ib] - X0[ia])))
    L = float(link.length) if link.length is not None else L0
    if rows is not None:  # the link's length as its own rows hold it
        given = [row[2] for row, k in zip(rows.dist, model.dist_link) if k == li]
        given += [row[5] for row, k in zip(rows.local, model.loc_link) if k == li]
        L = given[0] if given else L
    if isinstance(center, str):
        ip = names.index(center)
        if ip == ia:
            return ia, ib, 0.0, 0.0, L
        if ip == ib:
            return ia, ib, L, 0.0, L
        hit = np.flatnonzero((model.loc_a == ia) & (model.loc_b == ib) & (model.loc_p == ip))
        if len(hit) and rows is not None:
            return ia, ib, rows.local[hit[0]][3], rows.local[hit[0]][4], L
        if len(hit):
            return ia, ib, float(model.loc_u[hit[0]]), float(model.loc_v[hit[0]]), L
        return (ia, ib) + drawn_local(*X0[ia], *X0[ib], *X0[ip]) + (L,)
    u, v = center
    return ia, ib, float(u), float(v), L


def body_point(X, ia, ib, u, v, L):
    """Return a body point ``a + (u I + v R)(b - a)/L`` for stacks (S, P, 2) -> (S, 2) (u, v,
    L floats or (S,) per step)."""
    d = X[:, ib] - X[:, ia]
    u, v, L = (x[:, None] if np.ndim(x) else x for x in (u, v, L))
    return X[:, ia] + (u * d + v * perp(d)) / L


def perp(d):
    """Return d turned +90 degrees, for stacks (..., 2) (d @ _R90.T without a matmul)."""
    return np.stack([-d[..., 1], d[..., 0]], axis=-1)


def scatter_pairs(point_forces, ia, ib, f):
    """point_forces[:, ia[k]] += f[:, k] and [:, ib[k]] -= f[:, k] for each k, in place."""
    for k in range(f.shape[1]):
        point_forces[:, ia[k]] += f[:, k]
        point_forces[:, ib[k]] -= f[:, k]


def body_point_loads(force, ia, ib, u, v, L, n_steps: int) -> dict:
    """Return a force (S, 2) at body point (u, v) distributed onto the basic points, N_G^T f,
    as {point: (S, 2)} (the two points a and b only; u, v, L floats or (S,) per step)."""
    force = np.broadcast_to(force, (n_steps, 2))
    # r_G = (I - C) r_a + C r_b, C = (u I + v R90) / L entry by entry
    c00, c01, c10, c11 = u / L, -v / L, v / L, u / L
    # force @ M written out: BLAS' threaded matmul of (S, 2) x (2, 2) is slow on a busy machine
    out = {}
    for idx, M in ((ia, (1.0 - c00, 0.0 - c01, 0.0 - c10, 1.0 - c11)), (ib, (c00, c01, c10, c11))):
        f = np.empty((n_steps, 2))
        f[:, 0] = force[:, 0] * M[0] + force[:, 1] * M[2]
        f[:, 1] = force[:, 0] * M[1] + force[:, 1] * M[3]
        out[idx] = f
    return out


def add_at_body_point(point_forces, force, ia, ib, u, v, L):
    """Distribute a force at body point (u, v) onto the basic points: N_G^T f, in place."""
    add_body(point_forces, body_point_loads(force, ia, ib, u, v, L, point_forces.shape[0]))


# A body's own loads (its part of ``M_k Xdd - Q_k``) at the few points they act on: a dict
# {point index: (S, 2)}, never a (S, n_points, 2) array per body (that grows as bodies x points).

def add_body(point_forces, body: dict, sign: float = 1.0):
    """point_forces (S, P, 2) += sign * body ({point: (S, 2)}), in place; returns point_forces."""
    for p, f in body.items():
        if sign == 1.0:
            point_forces[:, p] += f
        else:
            point_forces[:, p] -= f
    return point_forces


def merge_bodies(into: dict, body: dict, sign: float = 1.0) -> dict:
    """into[p] (+)= sign * body[p] for each point of ``body`` ({point: (S, 2)}); returns into
    (new arrays: the inputs are not changed)."""
    for p, f in body.items():
        if p in into:
            into[p] = into[p] + f if sign == 1.0 else into[p] - f
        else:
            into[p] = f.copy() if sign == 1.0 else -f
    return into


def couple_as_body(model: Model, couple, li: int, X) -> dict:
    """A couple (S,) on link ``li`` as its force pair {b: tau R d / L^2, a: -tau R d / L^2}
    (as :func:`with_couples_as_pairs` places it)."""
    a, b = int(model.link_a[li]), int(model.link_b[li])
    d = X[:, b] - X[:, a]
    n2 = np.einsum("sj,sj->s", d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = (couple / n2)[:, None] * perp(d)
    return merge_bodies({b: f}, {a: f}, -1.0)


def with_couples_as_pairs(model: Model, point_forces, couples, X):
    """Return forces at every point (S, P, 2): point forces plus link couples as force pairs."""
    out = point_forces.copy()
    d = X[:, model.link_b] - X[:, model.link_a]
    n2 = np.einsum("slj,slj->sl", d, d)
    # a couple tau on a link = forces tau R d / L^2 on b and -tau R d / L^2 on a (failed
    # steps arrive zero-filled: 0 / 0 there, NaN, masked later like every failed step)
    with np.errstate(invalid="ignore", divide="ignore"):
        f = (couples / n2)[..., None] * perp(d)
    scatter_pairs(out, model.link_b, model.link_a, f)
    return out
