"""Linear algebra of the constraint Jacobian: the sparse block-triangular :class:`Engine`
(whole sweeps), the dense one-step solve and the condition estimates.

:class:`Engine` (one per model, built once): the constraint Jacobian in natural coordinates is
affine in ``q`` and in ``cos``/``sin`` of the angle drivers (``Phi`` is at most quadratic), so its
non-zero entries at every step are one matrix product ``C^T f`` of a small feature vector
``f = [1, q, cos s, sin s]``. ``C`` is read off :meth:`Model.jacobian` itself, so the model stays
the one definition of the rows (tests/test_kernels.py checks the reconstruction). The sparsity
pattern is put in block-triangular order once (a maximum matching and the strongly connected
components: Dulmage-Mendelsohn), so ``Phi_q x = b`` at every step is a forward substitution
through 1x1 and 2x2 blocks (Cramer's rule) over contiguous per-coordinate arrays.
A model whose Jacobian is not square (redundant constraints) has no engine: the dense path
serves it, by declaration (``engine`` returns None).
"""
from __future__ import annotations

import threading

import numpy as np

from ..model import Model, content_key, derived
from ..model import equations as eq
from .graph import _components, _matching
from .affine import affine_coefficients, relative_entries


#: what an engine's rows' structure alone decides (:meth:`Engine._blocks`; the affine form
#: :meth:`Engine._check` confirms is the rows' kinds', whatever their numbers), kept per
#: structure for the next model with the same rows on other numbers (a fit's trials): those
#: engines read their coefficients ``C`` off their own model and take these as they are
_STRUCTURAL = ("blocks", "entry_of", "col_entries", "_relative_slots", "_direct")
_STRUCTURES: dict[tuple, dict] = {}
STRUCTURES_KEPT = 16
_STRUCTURES_LOCK = threading.Lock()  # a study's worker threads build engines too


class EngineUnavailable(Exception):
    """The model's Jacobian is not square and structurally regular (use the dense path)."""


class Engine:
    """The model's Jacobian as sparse affine entries in block-triangular order (see module doc)."""

    def __init__(self, model: Model):
        self.model = model
        m, n = model.n_rows, model.n_q
        if m != n or n == 0:
            raise EngineUnavailable("the Jacobian is not square (redundant constraints, or fewer rows than unknowns)")
        self.angle = np.flatnonzero(model.drv_kind == eq.ANGLE)  # cos, sin among the features
        self.trig_drivers = np.flatnonzero(model.drv_angle)  # every driver whose value is an angle
        # relative angle rows are bilinear in (cos s, sin s) and q: their entries are evaluated
        # from the equations at every step (the driver's few terms), not read off features
        self.relative = np.flatnonzero(model.drv_kind == eq.RELATIVE)
        na = len(self.angle)
        self.n_features = 1 + n + 2 * na
        self.rows, self.cols, self.C = self._coefficients()  # entries row-major; (n_features, nnz)
        self.CT = np.ascontiguousarray(self.C.T)
        self._terms = [(float(col[0]), [(int(f), float(col[f])) for f in np.flatnonzero(col) if f > 0])
                       for col in self.C.T]  # per entry: constant, [(feature, coefficient)]
        self._rows_setup()
        key = self._structure_key()
        known = _STRUCTURES.get(key)
        if known is None:
            self._blocks()
            self._check()
            with _STRUCTURES_LOCK:
                _STRUCTURES[key] = {name: getattr(self, name) for name in _STRUCTURAL}
                while len(_STRUCTURES) > STRUCTURES_KEPT:
                    _STRUCTURES.pop(next(iter(_STRUCTURES)))
        else:  # the same rows on other numbers (a fit's trial): its order and checked form
            self.__dict__.update(known)

    def _structure_key(self) -> tuple:
        """Everything the block-triangular order and the affine check read: the rows' kinds
        and points, the unknowns, the entries' pattern (numbers left out)."""
        md = self.model
        arrays = (md.fixed, md.dist_a, md.dist_b, md.loc_a, md.loc_b, md.loc_p, md.sfix_p,
                  md.smov_p, md.smov_d, md.smov_e, md.drv_kind, md.drv_a, md.drv_b, md.drv_axis,
                  md.drv_c, md.drv_d, self.rows, self.cols)
        return (md.n_rows, md.n_q) + tuple(a.tobytes() for a in arrays)

    # ------------------------------------------------------------------ the affine map
    def _coefficients(self):
        """Return (rows, cols, C (n_features, nnz)): each non-zero entry's affine coefficients,
        read off the model's own Jacobian terms at 1 + n + 2 na probe configurations at once
        (q = 0; q = e_k; an angle driver at pi and pi/2: :func:`.affine.affine_coefficients`),
        entry by entry: never a dense (n_features, m, n) array. Relative angle rows get their
        structural pattern only (their entries come from the equations at every step)."""
        model = self.model
        keys, C, keep = affine_coefficients(model, self.angle, model.start_position[None])
        C, keep = C[0], keep[0]
        slot = {int(p): k for k, p in enumerate(model.moving)}
        entries = {k: C[:, e] for e, k in enumerate(keys) if keep[e]}
        for j in self.relative:  # structural pattern: the driver's moving points
            r = model.n_constraints + int(j)
            _, a, b, _, c, d, _ = model.rows.drivers[j]
            for p in (a, b, c, d):
                if p in slot:
                    for col in (2 * slot[p], 2 * slot[p] + 1):
                        entries[(r, col)] = np.zeros(self.n_features)
        order = sorted(entries)
        rows = np.array([r for r, _ in order], dtype=np.intp)
        cols = np.array([c for _, c in order], dtype=np.intp)
        Cs = np.array([entries[k] for k in order]).reshape(len(order), self.n_features).T
        return rows, cols, np.ascontiguousarray(Cs)

    def features(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return the features (n_features, S) of positions q (S, n_q) and driver values s (S, nd)."""
        S = q.shape[0]
        F = np.empty((self.n_features, S))
        F[0] = 1.0
        F[1:1 + q.shape[1]] = q.T
        na = len(self.angle)
        if na:
            th = s[:, self.angle].T
            F[1 + q.shape[1]:1 + q.shape[1] + na] = np.cos(th)
            F[1 + q.shape[1] + na:] = np.sin(th)
        return F

    def entries(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return the Jacobian's non-zero entries (nnz, S) at positions q (S, n_q), values s (S, nd)."""
        return self.entries_T(np.ascontiguousarray(q.T), np.ascontiguousarray(s.T))

    def entries_of(self, X: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return the entries (nnz, S) at positions X (S, n_points, 2), values s (S, nd):
        :meth:`entries` without its copies of ``q`` (:meth:`Model.qT_of`)."""
        return self.entries_T(self.model.qT_of(X), np.ascontiguousarray(s.T))

    def dense(self, E: np.ndarray) -> np.ndarray:
        """Return the dense Jacobians (S, m, n) from entries (nnz, S) (for checks)."""
        S = E.shape[1]
        J = np.zeros((S, self.model.n_rows, self.model.n_q))
        J[:, self.rows, self.cols] = E.T
        return J

    def _check(self):
        rng = np.random.default_rng(7)
        model = self.model
        for _ in range(3):
            q = rng.normal(size=(1, model.n_q)) * model.size
            s = rng.uniform(-4, 4, size=(1, model.n_drivers))
            J = model.jacobian(model.positions(q), s)
            Je = self.dense(self.entries(q, s))
            if not np.allclose(J, Je, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(J).max())):
                raise EngineUnavailable("the Jacobian is not affine in the features")

    # ------------------------------------------------------------------ SoA evaluations
    # The model's Phi, Phi_s and gamma with coordinates first and steps last (contiguous per
    # coordinate), for chunks of steps; checked against the model's own at construction.
    def points(self, qT: np.ndarray) -> np.ndarray:
        """Return all points (P, 2, S) from moving coordinates qT (n_q, S)."""
        md = self.model
        S = qT.shape[1]
        X2 = np.empty((md.n_points, 2, S))
        X2[md.fixed] = md.start_position[md.fixed][:, :, None]
        X2[md.moving] = qT.reshape(-1, 2, S)
        return X2

    def phi(self, X2: np.ndarray, sT: np.ndarray, trig: dict | None = None) -> np.ndarray:
        """Return Phi (m, S) at points X2 (P, 2, S) and driver values sT (nd, S).

        ``X2`` may also be a dict {moving point index: (x (S,), y (S,))}. ``trig``: optional
        {driver: (cos s, sin s)} already computed by the caller.
        """
        S = self._n_steps(X2, sT)
        out = np.empty((self.model.n_rows, S))
        for r, row in enumerate(self._phi_rows(X2, sT, trig)):
            out[r] = row
        return out

    def max_abs_phi(self, X2, sT: np.ndarray, trig: dict | None = None,
                    rows: eq.Rows | None = None) -> np.ndarray:
        """Return max |Phi| over the rows (S,), arguments as :meth:`phi`, without forming Phi
        (``rows``: the model's rows with per-row constants, :meth:`Model.phi`).

        NaN anywhere in a step gives NaN (``np.maximum`` propagates it).
        """
        res = np.zeros(self._n_steps(X2, sT))
        for row in self._phi_rows(X2, sT, trig, rows):
            if isinstance(row, np.ndarray):
                np.maximum(res, np.abs(row, out=row), out=res)  # every row is a fresh array
            else:  # a row between fixed points only: a constant
                np.maximum(res, abs(row), out=res)
        return res

    @staticmethod
    def _n_steps(X2, sT) -> int:
        if isinstance(X2, dict):
            return len(next(iter(X2.values()))[0]) if X2 else sT.shape[1]
        return X2.shape[2]

    def _phi_rows(self, X2, sT: np.ndarray, trig: dict | None, rows: eq.Rows | None = None):
        """Yield Phi's rows in order (:func:`linkpipe.model.equations.phi_rows`), each an (S,)
        array (or a float when it is constant), on contiguous coordinate arrays; fixed points
        enter as scalars."""
        fx = self._fixed_xy
        if isinstance(X2, dict):  # {point: (x (S,), y (S,))}: moving (and per-row fixed) points
            def xy(p):
                return X2[p] if p in X2 else fx[p]
        else:
            def xy(p):
                return fx[p] if p in fx else (X2[p, 0], X2[p, 1])
        cos_s, sin_s = self._trig(sT, trig)
        return eq.phi_rows(rows or self.model.rows, xy, sT, cos_s, sin_s)

    def _trig(self, sT, trig=None):
        """Return the drivers' cos and sin (lists by driver; None for coordinate drivers)."""
        cos_s, sin_s = [None] * len(sT), [None] * len(sT)
        for j in self.trig_drivers:
            cos_s[j], sin_s[j] = trig[j] if trig and j in trig else (np.cos(sT[j]), np.sin(sT[j]))
        return cos_s, sin_s

    def _rows_setup(self):
        X0 = self.model.start_position
        self._fixed_xy = {int(p): (float(X0[p, 0]), float(X0[p, 1]))
                          for p in np.flatnonzero(self.model.fixed)}

    def phi_s(self, X2: np.ndarray, sT: np.ndarray) -> np.ndarray:
        """Return dPhi_driver/ds (nd, S)."""
        md = self.model
        out = np.empty((md.n_drivers, X2.shape[2]))
        cos_s, sin_s = self._trig(sT)
        for j, row in enumerate(eq.phi_s_rows(md.rows, lambda p: (X2[p, 0], X2[p, 1]), sT, cos_s,
                                              sin_s)):
            out[j] = row
        return out

    def entries_T(self, qT: np.ndarray, sT: np.ndarray) -> np.ndarray:
        """Return the Jacobian's entries (nnz, S) from qT (n_q, S) and sT (nd, S).

        Entry by entry over its few non-zero coefficients (most entries are constants or one
        coordinate over a length): a fraction of a dense product's work.
        """
        n, S = qT.shape
        na = len(self.angle)
        feats = [None] + list(qT)
        if na:
            th = sT[self.angle]
            feats += list(np.cos(th)) + list(np.sin(th))
        E = np.empty((len(self.rows), S))
        tmp = np.empty(S)
        self._relative_entries(E, qT, sT)
        for e, (c0, terms) in enumerate(self._terms):
            row = E[e]
            if not terms:
                if e not in self._direct:
                    row.fill(c0)
                continue
            f, c = terms[0]
            np.multiply(feats[f], c, out=row)
            if c0:
                row += c0
            for f, c in terms[1:]:
                np.multiply(feats[f], c, out=tmp)
                row += tmp
        return E

    def _relative_entries(self, E: np.ndarray, qT: np.ndarray, sT: np.ndarray) -> None:
        """Fill the entries of the relative angle rows from :mod:`linkpipe.model.equations`."""
        if not len(self.relative):
            return
        md, fx = self.model, self._fixed_xy
        X2 = qT.reshape(-1, 2, qT.shape[1])
        slot = {int(p): k for k, p in enumerate(md.moving)}

        def xy(p):
            return fx[p] if p in fx else (X2[slot[p], 0], X2[slot[p], 1])

        relative_entries(self, E, xy, sT)

    # ------------------------------------------------------------------ block-triangular order
    def _blocks(self):
        m = self.model.n_rows
        row_cols = [[] for _ in range(m)]
        for r, c in zip(self.rows, self.cols):
            row_cols[int(r)].append(int(c))
        match = _matching(row_cols, m)  # row -> column
        if match is None:
            raise EngineUnavailable("the Jacobian is structurally singular")
        row_of = [0] * m
        for r, c in enumerate(match):
            row_of[c] = r  # column -> its row
        # column c(r) depends on the other columns of row r
        src, dst = [], []
        for r, c in zip(self.rows, self.cols):
            if c != match[r]:
                src.append(int(c))
                dst.append(int(match[r]))
        succ = [[] for _ in range(m)]
        for a, b in zip(src, dst):
            succ[a].append(b)
        comps = _components(succ)  # strongly connected, dependencies first
        order = list(range(len(comps)))
        self.blocks = []
        entry_of = {(int(r), int(c)): e for e, (r, c) in enumerate(zip(self.rows, self.cols))}
        self.entry_of = entry_of
        for k in order:
            cols = sorted(int(c) for c in comps[k])
            rows = [int(row_of[c]) for c in cols]
            inner = [[entry_of.get((r, c), -1) for c in cols] for r in rows]
            outer = [[(e, int(self.cols[e])) for e in np.flatnonzero(self.rows == r)
                      if int(self.cols[e]) not in cols] for r in rows]
            self.blocks.append((rows, cols, inner, outer))
        self.col_entries = [np.flatnonzero(self.cols == c) for c in range(m)]
        self._relative_slots = {j: [e for e in np.flatnonzero(self.rows == self.model.n_constraints + j)]
                                for j in self.relative}
        self._direct = {int(e) for slots in self._relative_slots.values() for e in slots}

    # ------------------------------------------------------------------ solves
    def solve(self, E: np.ndarray, b, inverses: dict | None = None) -> list:
        """Solve ``J x = b`` at every step: E (nnz, S) entries, b a list of m arrays (..., S).

        Returns x as a list of n_q arrays (..., S). Exactly singular blocks give inf or NaN.
        ``inverses``: :meth:`block_inverses` of E, for many solves with one E.
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._solve(E, b, inverses or {})

    def block_inverses(self, E: np.ndarray) -> dict:
        """{block: its inverse (S, k, k)} of every diagonal block of more than two unknowns
        (NaN where singular): a dozen solves with the same entries (the condition estimate)
        then multiply instead of factorising each block every time."""
        out = {}
        for i, (_, cols, inner, _) in enumerate(self.blocks):
            if len(cols) > 2:
                M = _dense_block(E, inner)
                try:
                    out[i] = np.linalg.inv(M)
                except np.linalg.LinAlgError:
                    out[i] = np.full_like(M, np.nan)
        return out

    def block_inverses_steps_last(self, E: np.ndarray) -> dict:
        """:meth:`block_inverses` by Gauss-Jordan elimination with partial pivoting, vectorised
        over the steps (each block read from the entries' contiguous rows: no per-step LAPACK
        call), returned as (S, k, k) views of (k, k, S) memory, so that a solve reads each
        entry over the steps as one row. A singular step is NaN or inf alone (not its whole
        chunk). For the force stage's several right-hand sides with one E (friction's load
        cases); stage 1 keeps :meth:`block_inverses` (its condition estimates' thresholds)."""
        out = {}
        for i, (_, cols, inner, _) in enumerate(self.blocks):
            k = len(cols)
            if k > 2:
                A = np.zeros((k, 2 * k, E.shape[1]))
                for r in range(k):
                    A[r, k + r] = 1.0
                    for c in range(k):
                        if inner[r][c] >= 0:
                            A[r, c] = E[inner[r][c]]
                with np.errstate(divide="ignore", invalid="ignore"):
                    out[i] = _gauss_jordan(A).transpose(2, 0, 1)
        return out

    def _solve(self, E, b, inverses: dict):
        x = [None] * self.model.n_q
        for i, (rows, cols, inner, outer) in enumerate(self.blocks):
            rhs = []
            for r, out in zip(rows, outer):
                acc = b[r]
                for e, c in out:
                    acc = acc - E[e] * x[c]
                rhs.append(acc)
            k = len(cols)
            if k == 1:
                x[cols[0]] = rhs[0] / E[inner[0][0]]
            elif k == 2:
                x[cols[0]], x[cols[1]] = _cramer2(*_block2(E, inner), *rhs)
            elif i in inverses:
                inv = inverses[i]
                for a, c in enumerate(cols):
                    x[c] = sum(inv[:, a, j] * rhs[j] for j in range(k))
            else:
                S = E.shape[1]
                M = _dense_block(E, inner)
                shp = np.broadcast_shapes(*(np.shape(r) for r in rhs), (S,))
                R = np.stack([np.broadcast_to(r, shp).reshape(-1, S) for r in rhs])  # (k, r, S)
                try:
                    sol = np.linalg.solve(M, R.transpose(2, 0, 1))  # (S, k, r)
                except np.linalg.LinAlgError:
                    sol = np.full((S, k, R.shape[1]), np.nan)
                for a, c in enumerate(cols):
                    x[c] = sol[:, a, :].T.reshape(shp)
        return x

    def solve_transpose(self, E: np.ndarray, b, inverses: dict | None = None) -> list:
        """Solve ``J^T y = b`` at every step: b a list of n_q arrays (S,); returns m arrays.

        Back substitution through the blocks in reverse order (J^T is block upper triangular).
        ``inverses``: as :meth:`solve`.
        """
        inverses = inverses or {}
        with np.errstate(divide="ignore", invalid="ignore"):
            y = [None] * self.model.n_rows
            for i in reversed(range(len(self.blocks))):
                rows, cols, inner, _ = self.blocks[i]
                rhs = []
                for c in cols:
                    acc, tmp = b[c], None
                    for e in self.col_entries[c]:
                        r = int(self.rows[e])
                        if r not in rows:  # b - E y - ...: in place after the first
                            if tmp is None:
                                acc = acc - E[e] * y[r]
                                tmp = np.empty_like(acc)
                            else:
                                acc -= np.multiply(E[e], y[r], out=tmp)
                    rhs.append(acc)
                k = len(cols)
                if k == 1:
                    y[rows[0]] = rhs[0] / E[inner[0][0]]
                elif k == 2:  # the block transposed: [[a, c], [b, d]]
                    a, b_, c, d = _block2(E, inner)
                    y[rows[0]], y[rows[1]] = _cramer2(a, c, b_, d, *rhs)
                elif i in inverses:  # (M^T)^-1 = (M^-1)^T, summed in place in its order
                    inv = inverses[i]
                    shape = np.broadcast_shapes(*(np.shape(x) for x in rhs), inv.shape[:1])
                    tmp = np.empty(shape)
                    for a, r in enumerate(rows):
                        y[r] = np.multiply(inv[:, 0, a], rhs[0], out=np.empty(shape))
                        for j in range(1, k):
                            y[r] += np.multiply(inv[:, j, a], rhs[j], out=tmp)
                else:
                    S = E.shape[1]
                    M = _dense_block(E, inner).transpose(0, 2, 1)
                    R = np.stack([np.broadcast_to(r, (S,)) for r in rhs], axis=1)
                    try:
                        sol = np.linalg.solve(M, R[..., None])[..., 0]
                    except np.linalg.LinAlgError:
                        sol = np.full((S, k), np.nan)
                    for a, r in enumerate(rows):
                        y[r] = sol[:, a]
            return y

    def matvec(self, E: np.ndarray, x: list) -> list:
        """Return ``J x`` as a list of m arrays: E (nnz, S), x a list of n_q arrays (S,)."""
        out = [0.0] * self.model.n_rows
        for e, (r, c) in enumerate(zip(self.rows, self.cols)):
            out[r] = out[r] + E[e] * x[c]
        return out

    def norm1(self, E: np.ndarray) -> np.ndarray:
        """Return the 1-norm (largest column sum of |J|) at every step (S,): each column's
        entries added in order (as ``|E|[entries].sum(axis=0)`` adds them), in place."""
        out, acc, tmp = None, np.empty(E.shape[1]), np.empty(E.shape[1])
        for ce in self.col_entries:  # no |E| of every entry at once: two scratch columns
            np.abs(E[ce[0]], out=acc)
            for e in ce[1:]:
                acc += np.abs(E[e], out=tmp)
            out = acc.copy() if out is None else np.maximum(out, acc, out=out)
        return out

    def inverse(self, E: np.ndarray) -> np.ndarray:
        """Return J^-1 as (n, m, S): one block solve per unit right-hand side."""
        eye = np.eye(self.model.n_rows)
        return np.stack(self.solve(E, [eye[r][:, None] for r in range(self.model.n_rows)]))

    def condition(self, E: np.ndarray, inverse: np.ndarray | None = None) -> np.ndarray:
        """Return the 1-norm condition ``|J|_1 |J^-1|_1`` (S,) (inf where not finite), as
        :func:`condition` measures it densely; without ``inverse``, the inverse's column sums
        come from :meth:`inverse_column_sums` (the same numbers, without forming it)."""
        with np.errstate(invalid="ignore"):
            sums = (self.inverse_column_sums(E) if inverse is None else
                    np.abs(inverse).sum(axis=0))
            cond = self.norm1(E) * sums.max(axis=0)
        return np.where(np.isfinite(cond), cond, np.inf)

    def inverse_column_sums(self, E: np.ndarray) -> np.ndarray:
        """Return ``|J^-1|``'s column sums (m, S): :meth:`inverse`'s block solves of the unit
        right-hand sides, each block only for the unit columns of its own and earlier blocks'
        rows (the inverse of a block-triangular matrix is block-triangular: the others are
        exact zeros in :meth:`inverse`). The sums are its sums, in its order, bit for bit
        (``tests/test_kernels.py``), without forming or reading the inverse."""
        S = E.shape[1]
        order = [r for rows, _, _, _ in self.blocks for r in rows]  # unit columns, by block
        at = {r: i for i, r in enumerate(order)}
        x: list = [None] * self.model.n_q  # x[c]: (columns up to its block's end, S)
        scratch = np.empty((len(order), S))  # E[e] x[c], then Cramer's products: in place
        with np.errstate(divide="ignore", invalid="ignore"):
            end = 0
            for rows, cols, inner, outer in self.blocks:
                end += len(rows)
                rhs = []
                for r, out in zip(rows, outer):
                    acc = np.zeros((end, S))
                    acc[at[r]] = 1.0
                    for e, c in out:  # as _solve: b[r] - E[e] x[c] - ..., in its order
                        xc = x[c]
                        tmp = scratch[:len(xc)]
                        acc[:len(xc)] -= np.multiply(E[e], xc, out=tmp)
                    rhs.append(acc)
                k = len(cols)
                if k == 1:
                    sol = [np.divide(rhs[0], E[inner[0][0]], out=rhs[0])]
                elif k == 2:
                    sol = _cramer2_into(*_block2(E, inner), *rhs, scratch[:end])
                else:  # larger blocks: the general solve on these columns
                    M = _dense_block(E, inner)
                    R = np.stack(rhs)  # (k, end, S)
                    try:
                        out_ = np.linalg.solve(M, R.transpose(2, 0, 1))  # (S, k, end)
                    except np.linalg.LinAlgError:
                        out_ = np.full((S, k, end), np.nan)
                    sol = [out_[:, a, :].T for a in range(k)]
                for c, xc in zip(cols, sol):
                    x[c] = xc
            sums = np.zeros((self.model.n_rows, S))  # by block; summed over the unknowns
            for xc in x:                              # in their order, as inverse's rows
                sums[:len(xc)] += np.abs(xc, out=scratch[:len(xc)])
        out = np.empty_like(sums)
        out[order] = sums
        return out


def _gauss_jordan(W: np.ndarray) -> np.ndarray:
    """The inverses (k, k, S) of k x k matrices given as ``W`` = [A | I] (k, 2k, S), by
    Gauss-Jordan elimination with partial pivoting at every step at once (``W`` is overwritten)."""
    k = W.shape[0]
    for j in range(k):
        if j < k - 1:  # the largest pivot candidate of column j, swapped into row j
            p = j + np.argmax(np.abs(W[j:, j]), axis=0)
            for i in range(j + 1, k):
                m = p == i
                if m.any():
                    row = W[j].copy()
                    np.copyto(W[j], W[i], where=m)
                    np.copyto(W[i], row, where=m)
        W[j] *= 1.0 / W[j, j]
        for i in range(k):
            if i != j:
                W[i] -= W[i, j].copy() * W[j]
    return W[:, k:]


def _cramer2(a, b, c, d, r0, r1):
    """Solve [[a, b], [c, d]] x = [r0, r1] by Cramer's rule, elementwise over steps."""
    idet = 1.0 / (a * d - b * c)
    return (r0 * d - r1 * b) * idet, (a * r1 - c * r0) * idet


def _cramer2_into(a, b, c, d, r0, r1, tmp):
    """:func:`_cramer2`'s numbers to the bit, into ``r0`` and ``r1`` themselves (arrays of
    one shape, overwritten) with ``tmp`` of their shape as scratch: no temporary per product
    (the determinant's, of the entries (S,), is as small as the entries)."""
    idet = 1.0 / (a * d - b * c)
    x0 = np.multiply(r0, d)                    # r0 d - r1 b
    x0 -= np.multiply(r1, b, out=tmp)
    x0 *= idet
    np.multiply(a, r1, out=r1)                 # a r1 - c r0
    r1 -= np.multiply(c, r0, out=tmp)
    r1 *= idet
    return x0, r1


def _block2(E: np.ndarray, inner) -> tuple:
    """Return the entries (a, b, c, d) of a 2x2 diagonal block [[a, b], [c, d]] (0.0 where empty)."""
    return tuple(E[e] if e >= 0 else 0.0 for e in (inner[0][0], inner[0][1], inner[1][0], inner[1][1]))


def _dense_block(E: np.ndarray, inner) -> np.ndarray:
    """Return a k x k diagonal block as dense matrices (S, k, k) from the entries E (nnz, S)."""
    k = len(inner)
    M = np.zeros((E.shape[1], k, k))
    for i in range(k):
        for j in range(k):
            if inner[i][j] >= 0:
                M[:, i, j] = E[inner[i][j]]
    return M


def engine(model: Model) -> Engine | None:
    """Return the model's engine (built once per model), or None when it has none."""
    return derived(model, "engine", _build_engine, content_key(model))[0]


def no_engine_reason(model: Model) -> str:
    """Why the model has no sparse engine ("" when it has one): a declared path, not a
    silent fallback; the run's ``solver_note`` says it."""
    return derived(model, "engine", _build_engine, content_key(model))[1]


def _build_engine(model: Model) -> tuple[Engine | None, str]:
    try:
        return Engine(model), ""
    except EngineUnavailable as exc:
        return None, str(exc)


def _rows(a: np.ndarray) -> list:
    """(S, k) -> list of k contiguous arrays."""
    return list(np.ascontiguousarray(a.T))


