"""The Lagrange multipliers of ``Φqᵀλ = Q − M·q̈`` (an independent solve beside virtual work)
and what they give: the input force again, link and slider forces, ground reactions and the
force of every pin on every body."""
from __future__ import annotations

import numpy as np

from ..kinematics.affine import entries_at
from ..kinematics.sparse import engine
from ..model import Model
from ..model import equations as eq
from ..kinematics.linalg import CHUNK



def multipliers(model: Model, Xz, s, generalized_q, ok, pivots: bool = False, rows=None,
                factors: dict | None = None):
    """Return (λ (S, n_rows) NaN where not ok, undetermined (n_rows,) bool).

    Square Jacobians go through the sparse engine's transposed block solve; redundant scenes
    (more rows than unknowns) take the minimum-norm solution, and the rows a self-stress can
    change are flagged ``undetermined``. ``pivots``: the fixed points of Xz differ row by row,
    ``rows``: the model's rows with per-row constants (:class:`.constants.ForceConstants`).
    ``factors``: a dict kept across solves with the same positions (friction's load cases, a
    fit's trials): each chunk's Jacobian entries and block inverses are made once there."""
    n_steps = Xz.shape[0]
    lam = np.full((n_steps, model.n_rows), np.nan)
    undetermined = np.zeros(model.n_rows, dtype=bool)
    if not ok.any():
        return lam, undetermined
    eng = engine(model)
    if eng is not None:
        idx = np.flatnonzero(ok)
        for lo in range(0, len(idx), CHUNK):
            ii = idx[lo:lo + CHUNK]
            key = (len(Xz), lo, len(ii), hash(ok.tobytes()))
            if factors is not None and key in factors:
                E, inverses = factors[key]
            else:
                E = (entries_at(eng, Xz[ii], s[ii], None if rows is None else rows.take(ii))
                     if pivots or rows is not None else eng.entries_of(Xz[ii], s[ii]))
                inverses = None
                if factors is not None:
                    inverses = factors[key] = E, eng.block_inverses_steps_last(E)
                    inverses = inverses[1]
            rhs = list(np.ascontiguousarray(generalized_q[ii].T))
            lam[ii] = np.stack(eng.solve_transpose(E, rhs, inverses), axis=1)
        return lam, undetermined
    J = model.jacobian(Xz[ok], s[ok], None if rows is None else rows.take(ok))
    JT = np.swapaxes(J, 1, 2)
    if J.shape[1] == J.shape[2]:
        lam[ok] = np.linalg.solve(JT, generalized_q[ok][..., None])[..., 0]
    else:
        lam[ok] = np.einsum("sij,sj->si", np.linalg.pinv(JT, rcond=1e-12), generalized_q[ok])
    return lam, undetermined_rows(J)


def stacked_multipliers(model: Model, Xz, s, generalized_q, ok, pivots: bool = False,
                        rows=None, factors: dict | None = None):
    """λ (K, S, n_rows) of K load cases at once, ``generalized_q`` (K, S, n_q), NaN where not
    ok, through the sparse engine's block solves (each right-hand side a (K, chunk) array;
    dense blocks by their inverses, kept in ``factors``); None where the model has no sparse
    engine (the caller solves case by case)."""
    eng = engine(model)
    if eng is None:
        return None
    K, n_steps = generalized_q.shape[:2]
    lam = _nan_where_not(ok, (model.n_rows, K, n_steps))  # as the block solve gives it; returned
    # as a (K, S, n_rows) view (each row's cases contiguous: what stacked_reactions reads)
    factors = {} if factors is None else factors
    idx = np.flatnonzero(ok)
    for lo in range(0, len(idx), CHUNK):
        ii = idx[lo:lo + CHUNK]
        key = (len(Xz), lo, len(ii), hash(ok.tobytes()))
        if key not in factors:
            E = (entries_at(eng, Xz[ii], s[ii], None if rows is None else rows.take(ii))
                 if pivots or rows is not None else eng.entries_of(Xz[ii], s[ii]))
            factors[key] = E, eng.block_inverses_steps_last(E)
        E, inverses = factors[key]
        at = ii
        if len(ii) and ii[-1] - ii[0] + 1 == len(ii):  # contiguous: a view, not a gather
            at = slice(int(ii[0]), int(ii[-1]) + 1)
        rhs = list(generalized_q[:, at].transpose(2, 0, 1))  # (K, n) rows: views where the
        # right-hand sides are laid out (n_q, K, S), as friction's unit cases are
        for r, y in enumerate(eng.solve_transpose(E, rhs, inverses)):
            lam[r][:, at] = y
    return np.moveaxis(lam, 0, 2)


def stacked_reactions(model: Model, lam, point_forces, bodies: list, X, s, ok, rows=None,
                      at_fixed: bool = False):
    """:func:`reactions` of K load cases at once: ``lam`` (K, S, n_rows), ``point_forces``
    (K, S, P, 2) (``at_fixed``: those at the fixed points alone, (K, S, n_fixed, 2)),
    ``bodies`` one dict per case; returns (K, S, n_fixed, 2), (K, S, n_joints, 2), Phi_X's
    terms computed once for all cases."""
    fixed = np.flatnonzero(model.fixed)
    fixed_slot = {int(p): k for k, p in enumerate(fixed)}
    pairs = joints(model)
    pair_slot = {(li, p): k for k, (li, p) in enumerate(pairs)}
    row_link = body_rows(model).tolist()
    K, S = lam.shape[:2]
    # filled in the chunks' own layout (slot, axis, case, step: each chunk's block contiguous)
    # and returned as (K, S, slot, 2) views of it
    R_ = _nan_where_not(ok, (len(fixed), 2, K, S))
    F_ = _nan_where_not(ok, (len(pairs), 2, K, S))
    relative = bool((model.drv_kind == eq.RELATIVE).any())
    idx = np.flatnonzero(ok)
    for lo in range(0, len(idx), CHUNK):
        ii = idx[lo:lo + CHUNK]
        n = len(ii)
        if n and ii[-1] - ii[0] + 1 == n:  # contiguous: views, not copies
            ii = slice(int(ii[0]), int(ii[-1]) + 1)
        lam_c = np.moveaxis(lam[:, ii], 2, 0)  # (n_rows, K, n): a view where lam is one of
        # stacked_multipliers' (each row's cases contiguous), else strided
        at = point_forces[:, ii] if at_fixed else point_forces[:, ii][:, :, fixed]
        in_place = isinstance(ii, slice)  # accumulate in the outputs' own memory (no copy)
        Rc = R_[..., ii] if in_place else np.empty((len(fixed), 2, K, n))
        Rc[...] = np.moveaxis(-at, (2, 3), (0, 1))
        Fc = F_[..., ii] if in_place else np.empty((len(pairs), 2, K, n))
        Fc[...] = 0.0  # slot, axis, case, step
        rows_c = None if rows is None else rows.take(ii)
        Xc, sc = X[ii], s[ii]
        for k, case_bodies in enumerate(bodies):
            extra = motor_terms(model, Xc, sc, lam[k, ii], rows_c) if relative else {}
            for (li, p), slot in pair_slot.items():
                for part in (extra.get(li, {}).get(p), case_bodies.get(li, {}).get(p)):
                    if part is not None:
                        Fc[slot, :, k] += (part if part.shape[0] == n else part[ii]).T
        tx, ty = np.empty((K, n)), np.empty((K, n))  # each term's products, made once
        for r, p, gx, gy in model.jacobian_terms(Xc, sc, rows_c):
            kf, kp = fixed_slot.get(p), pair_slot.get((row_link[r], p))
            if kf is None and kp is None:
                continue
            lr = lam_c[r]
            np.multiply(lr, gx, out=tx)
            np.multiply(lr, gy, out=ty)
            for out, k in ((Rc, kf), (Fc, kp)):
                if k is not None:
                    out[k, 0] += tx
                    out[k, 1] += ty
        if not in_place:
            R_[..., ii] = Rc
            F_[..., ii] = Fc
    return np.moveaxis(R_, (0, 1), (2, 3)), np.moveaxis(F_, (0, 1), (2, 3))


def _nan_where_not(ok, shape) -> np.ndarray:
    """An array of ``shape`` (..., S) that is NaN at the steps not ``ok`` (S,) and left for the
    caller to fill at every ok step (no pass over the ok steps' memory before they are written)."""
    out = np.empty(shape)
    if not ok.all():
        out[..., ~ok] = np.nan
    return out


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


def internal_forces(model: Model, lam, undetermined, units) -> tuple[dict, dict, dict]:
    """Return (variables, coords, undefined columns): ``link_force`` (tension positive, from each link's distance
    row), ``slider_force`` (the guide's normal force) and, under redundancy, which are unique."""
    scene, force_unit = model.scene, units["force"]
    n_links = len(scene.links)
    n_dist = len(model.dist_a)
    row_of_link, r = {}, 0
    for li in range(n_links):
        if r < n_dist and model.dist_a[r] == model.link_a[li] and model.dist_b[r] == model.link_b[li]:
            row_of_link[li] = r
            r += 1
    link_force = np.full((lam.shape[0], n_links), np.nan)
    for li, r in row_of_link.items():
        link_force[:, li] = lam[:, r]
    out, coords = {"link_force": (("step", "link"), link_force, force_unit)}, {}
    # a link without a distance row (between two fixed points) carries no computed force
    undefined = {"link_force": ~np.isin(np.arange(n_links), list(row_of_link))}
    if undetermined.any():  # redundant constraints: the minimum-norm choice, not the answer
        unique = np.ones(n_links, dtype=np.int8)
        for li, r in row_of_link.items():
            unique[li] = 0 if undetermined[r] else 1
        out["link_force_unique"] = (("link",), unique, "1")
    if not scene.sliders:
        return out, coords, undefined
    first = n_dist + 2 * len(model.loc_a)
    fixed_i = [i for i, x in enumerate(scene.sliders) if not x.moving]
    moving_i = [i for i, x in enumerate(scene.sliders) if x.moving]
    rows = [first + k for k in range(len(fixed_i) + len(moving_i))]  # fixed guides' rows first
    slider_force = np.full((lam.shape[0], len(scene.sliders)), np.nan)
    for i, r in zip(fixed_i + moving_i, rows):
        slider_force[:, i] = -lam[:, r]
    out["slider_force"] = (("step", "slider"), slider_force, force_unit)
    if undetermined.any():
        unique = np.ones(len(scene.sliders), dtype=np.int8)
        for i, r in zip(fixed_i + moving_i, rows):
            unique[i] = 0 if undetermined[r] else 1
        out["slider_force_unique"] = (("slider",), unique, "1")
    coords["slider"] = [x.name for x in scene.sliders]
    return out, coords, undefined


def reactions(model: Model, lam, point_forces, bodies, X, s, ok, rows=None, only=None):
    """Return ground reactions (S, n_fixed, 2) and pin forces on bodies (S, n_joints, 2).

    Ground: a fixed point is a coordinate held by one more constraint; its multiplier mu follows
    from that coordinate's row of the equations of motion, ``-mu = Phi_X^T lambda - (Q - M Xdd)``
    (``point_forces`` (S, P, 2) holds ``Q - M Xdd`` at every point, fixed ones included).
    Pins: the force the pin at point P exerts on body k is ``(M_k Xdd - Q_k)_P + sum over the
    body's own rows of lambda_r dPhi_r/dX_P`` (``bodies``: {link: {point: M_k Xdd - Q_k (S, 2)}}),
    for the pairs of :func:`joints`. NaN at steps that are not ok. ``rows``: the model's rows
    with per-row constants (:meth:`Model.jacobian_terms`). ``only``: the (link, point) pairs
    wanted (the others stay NaN; no ground reactions): what friction's magnitudes need alone.
    """
    fixed = np.flatnonzero(model.fixed)
    fixed_slot = {int(p): k for k, p in enumerate(fixed)} if only is None else {}
    pairs = joints(model)
    pair_slot = {(li, p): k for k, (li, p) in enumerate(pairs) if only is None or (li, p) in only}
    row_link = body_rows(model).tolist()
    S = X.shape[0]
    R = np.full((S, len(fixed), 2), np.nan)
    F = np.full((S, len(pairs), 2), np.nan)
    idx = np.flatnonzero(ok)
    for lo in range(0, len(idx), CHUNK):  # Phi_X term by term: never formed densely
        ii = idx[lo:lo + CHUNK]
        n = len(ii)
        if only is not None and n and ii[-1] - ii[0] + 1 == n:
            ii = slice(int(ii[0]), int(ii[-1]) + 1)  # contiguous: views, not copies
        lam_c = lam[ii]
        Rc = -point_forces[ii][:, fixed]
        Fc = np.zeros((n, len(pairs), 2))
        rows_c = None if rows is None else rows.take(ii)
        extra = motor_terms(model, X[ii], s[ii], lam_c, rows_c)
        for (li, p), k in pair_slot.items():
            motor = extra.get(li, {}).get(p)
            body = bodies.get(li, {}).get(p)
            if motor is not None and body is not None:
                Fc[:, k] = motor + body[ii]
            elif motor is not None or body is not None:
                Fc[:, k] = motor if body is None else body[ii]
        for r, p, gx, gy in model.jacobian_terms(X[ii], s[ii], rows_c):
            lr = lam_c[:, r]
            k = fixed_slot.get(p)
            if k is not None:
                Rc[:, k, 0] += lr * gx
                Rc[:, k, 1] += lr * gy
            k = pair_slot.get((row_link[r], p))
            if k is not None:
                Fc[:, k, 0] += lr * gx
                Fc[:, k, 1] += lr * gy
        R[ii] = Rc
        F[ii] = Fc
    return R, F


def motor_terms(model: Model, X, s, lam, rows=None) -> dict:
    """Return {link: {point: (S, 2)}}: the part of each relative angle row ``lambda_r dPhi_r/dX`` that
    acts on each of the two links a motor turns against each other (the driven vector's points
    on the first, the reference vector's on the second; ground takes its part through the
    ground reactions). X (S, P, 2), s (S, nd), lam (S, n_rows)."""
    out = {}
    links = {ln.name: li for li, ln in enumerate(model.scene.links)}

    def xy(p):
        return X[:, p, 0], X[:, p, 1]

    for j in np.flatnonzero(model.drv_kind == eq.RELATIVE):
        driver, r = (rows or model.rows).drivers[j], model.n_constraints + j
        terms = list(eq.relative_gradient(driver, xy, np.cos(s[:, j]), np.sin(s[:, j])))
        for name, part in zip(model.scene.drivers[j].bodies, (terms[:2], terms[2:])):
            if name not in links:
                continue  # ground
            li = links[name]
            acc = out.setdefault(li, {})
            for p, gx, gy in part:
                f = acc.setdefault(p, np.zeros((X.shape[0], 2)))
                f[:, 0] += lam[:, r] * gx
                f[:, 1] += lam[:, r] * gy
    return out


def body_rows(model: Model) -> np.ndarray:
    """Return (n_rows,) the link index of each body row, -1 elsewhere.

    Body rows: each link's distance and local rows, and an angle driver whose two points lie on
    one link (its multiplier is the actuator's couple on that body, reacted by the ground).
    Slider rows, coordinate and distance drivers act on points (pins), not on a body (a
    cylinder's force is a load at its two pins); a relative angle acts on two bodies at once
    (:func:`motor_terms`).
    """
    out = np.full(model.n_rows, -1, dtype=np.intp)
    nd = len(model.dist_a)
    out[:nd] = model.dist_link
    out[nd:nd + 2 * len(model.loc_a)] = np.repeat(model.loc_link, 2)
    names = model.point_names
    with_rows = set(out[out >= 0].tolist())
    for j in np.flatnonzero(model.drv_kind == eq.ANGLE):
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
