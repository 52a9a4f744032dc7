"""Degrees of freedom and redundancy of a model, and which scene key a constraint row comes from."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .build import Model


@dataclass(frozen=True)
class Mobility:
    """Degrees of freedom and redundancy from the rank of the constraint Jacobian."""

    n_q: int
    n_constraints: int
    rank: int
    dof: int
    redundant: int


#: the generic-rank search looks along at most this many near-null directions, and only where
#: the rank found falls at most this short of the drivers (bounded work, at any size)
MAX_DIRECTIONS, MAX_RANK_DROP = 8, 4


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
        try:
            q = q - np.linalg.lstsq(J, F, rcond=None)[0][None]
        except np.linalg.LinAlgError:  # non-finite entries (a degenerate drawing): not assembled
            return None
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
    if mob.dof - nd > MAX_RANK_DROP:
        # a special shape drops the rank by one or two (a dead centre, a change point); this
        # many missing drivers is the scene's, and the search below would cost O(n^4)
        return mob
    s0 = np.zeros((1, nd))
    base = X0 if Xa is None else Xa
    J = model.jacobian(base[None], s0)[0, : model.n_constraints]
    for v in np.linalg.svd(J)[2][::-1][:MAX_DIRECTIONS]:  # near-null directions first
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
    if 0 <= row < len(sc.drivers):  # its first value: a log's first sample, or `from`
        driver = sc.drivers[row]
        return f'drivers "{driver.name}"', "log" if driver.timed == "log" else "from"
    return "points", None
