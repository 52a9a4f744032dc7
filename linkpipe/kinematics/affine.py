"""The sparse engine's affine map of the Jacobian (:class:`.sparse.Engine`): each non-zero
entry's coefficients on the features ``[1, q, cos s, sin s]``, read off the model's own terms
at probe configurations, for K drawings at once (K = 1: the engine's own; a study's variants
that move pivots: the coefficients each variant's own engine has, to the last bit, since the
arithmetic runs elementwise along the drawing axis), and the entries of such variants.
"""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..model import equations as eq


def affine_coefficients(model: Model, angle: np.ndarray, drawings: np.ndarray,
                        rows: eq.Rows | None = None):
    """``(keys, C (K, n_features, e), keep (K, e))`` of drawings (K, n_points, 2) (only their
    fixed points count) and, with ``rows``, the K drawings' own constants of the model's rows
    (:class:`.equations.Rows` of (K,) arrays: a study's variants of other link lengths):
    ``keys`` the (row, column) of every structural entry outside the relative angle rows,
    sorted; C each entry's coefficients, rounding noise cleaned; keep where an entry has a
    non-zero coefficient."""
    n, nd, na = model.n_q, model.n_drivers, len(angle)
    K, n_probes = drawings.shape[0], 1 + n + 2 * na
    probe_q = np.zeros((n_probes, n))
    probe_q[1:1 + n] = np.eye(n)
    probe_s = np.zeros((n_probes, nd))
    for k, j in enumerate(angle):
        probe_s[1 + n + k, j] = np.pi
        probe_s[1 + n + na + k, j] = np.pi / 2
    X = np.repeat(model.positions(probe_q)[None], K, axis=0)
    fixed = np.flatnonzero(model.fixed)
    X[:, :, fixed] = drawings[:, None, fixed]
    slot = {int(p): k for k, p in enumerate(model.moving)}
    relative_rows = {model.n_constraints + int(j)
                     for j in np.flatnonzero(model.drv_kind == eq.RELATIVE)}
    per_row = None if rows is None else rows.take(np.repeat(np.arange(K), n_probes))

    def probed(X):  # (row, col) -> (K n_probes,), terms added in the model's order
        values: dict = {}
        terms = model.jacobian_terms(X.reshape(K * n_probes, model.n_points, 2),
                                     np.tile(probe_s, (K, 1)), per_row)
        for r, p, gx, gy in terms:
            if p not in slot:
                continue
            for col, g in ((2 * slot[p], gx), (2 * slot[p] + 1, gy)):
                values[(r, col)] = values[(r, col)] + g if (r, col) in values else (
                    np.zeros(K * n_probes) + g)
        return values

    values = probed(X)
    keys = sorted(k for k in values if k[0] not in relative_rows)
    V = np.array([values[k] for k in keys]).reshape(len(keys), K, n_probes).transpose(1, 2, 0)
    # the coefficients on q with the fixed points at the origin: an entry is affine in q and
    # in the fixed coordinates separately (no products of the two), so they are the same, but
    # read off the difference of two probes of size 1 instead of two of the drawing's distance
    # from the origin (at 1e4 x the size that difference lost 8 digits, squared by q there)
    X[:, :, fixed] = 0.0
    zero = probed(X)
    Vq = np.array([zero.get(k, np.zeros(K * n_probes)) for k in keys]).reshape(
        len(keys), K, n_probes).transpose(1, 2, 0)
    J0 = V[:, 0]
    C = np.zeros((K, 1 + n + 2 * na, len(keys)))
    base = J0.copy()
    for k in range(na):
        bc = 0.5 * (J0 - V[:, 1 + n + k])
        C[:, 1 + n + k] = bc
        C[:, 1 + n + na + k] = V[:, 1 + n + na + k] - J0 + bc
        base = base - bc
    C[:, 0] = base
    C[:, 1:1 + n] = Vq[:, 1:1 + n] - Vq[:, :1]
    # clean rounding noise: entries are exact small rationals of the lengths
    top = np.abs(C).max(axis=(1, 2)) if C.size else np.zeros(K)
    C[np.abs(C) < (1e-14 * np.maximum(1.0, top))[:, None, None]] = 0.0
    keep = np.abs(C).max(axis=1) > 0 if C.size else np.zeros((K, len(keys)), dtype=bool)
    return keys, C, keep


def same_pattern(eng, drawings: np.ndarray, rows: eq.Rows | None = None) -> np.ndarray:
    """(K,) True where a drawing's engine (with its own ``rows``' constants, as
    :func:`affine_coefficients` takes them) would have the engine's own entries and non-zero
    feature coefficients (then :func:`entries_at` gives its entries to the last bit; the
    constant term may differ: it is added after the first feature's product either way)."""
    keys, C, keep = affine_coefficients(eng.model, eng.angle, drawings, rows)
    _, C0, keep0 = affine_coefficients(eng.model, eng.angle, eng.model.start_position[None])
    return (keep == keep0).all(axis=1) & ((C[:, 1:] != 0) == (C0[:, 1:] != 0)).all(axis=(1, 2))


def entries_at(eng, X: np.ndarray, s: np.ndarray, rows: eq.Rows | None = None) -> np.ndarray:
    """The engine's Jacobian entries (nnz, S) at positions X (S, n_points, 2) whose fixed
    points may differ row by row, values s (S, nd), and the model's rows with per-row
    constants ``rows`` (or the model's own): each row's own drawing's and constants'
    coefficients (:func:`affine_coefficients`) on the engine's pattern, summed in
    :meth:`Engine.entries_T`'s order; the relative angle rows from the equations."""
    model = eng.model
    fixed = np.flatnonzero(model.fixed)
    per_row = [] if rows is None else rows.arrays()
    n_fixed = 2 * len(fixed)
    runs, which, first = _runs(np.column_stack([X[:, fixed].reshape(X.shape[0], -1)] + per_row))
    drawings = runs[:, :n_fixed]
    full = np.repeat(model.start_position[None], len(drawings), axis=0)
    full[:, fixed] = drawings.reshape(len(drawings), -1, 2)
    keys, C, _ = affine_coefficients(model, eng.angle, full,
                                     None if rows is None else rows.take(first))
    column = {k: e for e, k in enumerate(keys)}
    qT = np.ascontiguousarray(model.q_of(X).T)
    sT = np.ascontiguousarray(s.T)
    feats = [None] + list(qT)
    if len(eng.angle):
        th = sT[eng.angle]
        feats += list(np.cos(th)) + list(np.sin(th))
    E = np.empty((len(eng.rows), X.shape[0]))
    relative_entries(eng, E, lambda p: (X[:, p, 0], X[:, p, 1]), sT, rows)
    for e, (_, terms) in enumerate(eng._terms):
        if e in eng._direct:
            continue
        c = C[:, :, column[(int(eng.rows[e]), int(eng.cols[e]))]][which]  # (S, n_features)
        row = E[e]
        if not terms:
            row[:] = c[:, 0]
            continue
        f = terms[0][0]
        np.multiply(feats[f], c[:, f], out=row)
        row += c[:, 0]
        for f, _ in terms[1:]:
            row += feats[f] * c[:, f]
    return E


def _runs(F: np.ndarray):
    """``(values (K, f), which (S,), first (K,))`` of rows F (S, f) in runs of equal rows (a
    study's variants: each variant's steps in a row): each run's value, every row's run and
    each run's first row."""
    new = np.ones(F.shape[0], dtype=bool)
    new[1:] = (F[1:] != F[:-1]).any(axis=1)
    return F[new], np.cumsum(new) - 1, np.flatnonzero(new)


def relative_entries(eng, E: np.ndarray, xy, sT: np.ndarray, rows: eq.Rows | None = None) -> None:
    """Fill the engine's entries E (nnz, S) of the relative angle rows from the equations, the
    points read through ``xy(p) -> (x, y)`` (fixed points as floats or row by row; ``rows``:
    the model's rows with per-row constants, or its own)."""
    md = eng.model
    drivers = (rows or md.rows).drivers
    slot = {int(p): k for k, p in enumerate(md.moving)}
    for j in eng.relative:
        r = md.n_constraints + j
        c, sn = np.cos(sT[j]), np.sin(sT[j])
        for e in eng._relative_slots[j]:
            E[e] = 0.0
        for _, p, gx, gy in eq.driver_jacobian_terms(drivers[j], r, xy, c, sn):
            if p in slot:
                E[eng.entry_of[(r, 2 * slot[p])]] += gx
                E[eng.entry_of[(r, 2 * slot[p] + 1)]] += gy
