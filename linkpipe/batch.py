"""Whole-sweep linear algebra and the vectorised general (Newton) path of stage 1.

:class:`Engine` (one per model, built once): the constraint Jacobian in natural coordinates is
affine in ``q`` and in ``cos``/``sin`` of the angle drivers (``Phi`` is at most quadratic), so its
non-zero entries at every step are one matrix product ``C^T f`` of a small feature vector
``f = [1, q, cos s, sin s]``. ``C`` is read off :meth:`Model.jacobian` itself (and checked
against it), so the model stays the one definition of the rows. The sparsity pattern is put in
block-triangular order once (a maximum matching and the strongly connected components:
Dulmage-Mendelsohn), so ``Phi_q x = b`` at every step is a forward substitution through 1x1
and 2x2 blocks (Cramer's rule) over contiguous per-coordinate arrays, in cache-sized chunks.

:func:`derivatives` is :func:`linkpipe.kinematics.derivatives` on that engine (same condition
number, singular flags, inverse and residuals), for any number of steps.

:func:`solve_newton` is the general path, vectorised: a coarse sequential continuation
(:func:`linkpipe.kinematics.solve_positions` on every k-th step, which pins the branch), then
every other step at once by Newton from a cubic Hermite prediction between its two coarse
neighbours (their positions and slopes); a step that does not converge in a few iterations or
moves far from its prediction sends its whole interval back to the sequential continuation.
"""
from __future__ import annotations

import numpy as np

from . import kinematics as kin
from .model import Model
from .model import equations as eq

CHUNK = 8192
COARSE_NODES = 128  # sequential continuation on at most about this many steps
VECTORISE_FROM = 1000  # shorter sweeps run the sequential continuation on every step
NEWTON_ITERATIONS = 4  # per fine step before its interval goes back to the sequential path
OFF_BRANCH = 0.01  # a fine step may move at most this part of its interval's motion (or
OFF_BRANCH_ABS = 1e-6  # this times the size) from its prediction; farther is another branch


class EngineUnavailable(Exception):
    """The model's Jacobian is not square and structurally regular (use the dense path)."""


class Engine:
    """The model's Jacobian as sparse affine entries in block-triangular order (see module doc)."""

    def __init__(self, model: Model):
        self.model = model
        m, n = model.n_rows, model.n_q
        if m != n or n == 0:
            raise EngineUnavailable("the Jacobian is not square")
        self.angle = np.flatnonzero(model.drv_angle)
        na = len(self.angle)
        self.n_features = 1 + n + 2 * na
        C = self._coefficients()  # (n_features, m, n)
        nz = np.abs(C).max(axis=0) > 0
        self.rows, self.cols = np.nonzero(nz)  # entries, row-major
        self.C = np.ascontiguousarray(C[:, self.rows, self.cols])  # (n_features, nnz)
        self.CT = np.ascontiguousarray(self.C.T)
        self._terms = [(float(col[0]), [(int(f), float(col[f])) for f in np.flatnonzero(col) if f > 0])
                       for col in self.C.T]  # per entry: constant, [(feature, coefficient)]
        self._check()
        self._rows_setup()
        self._blocks()

    # ------------------------------------------------------------------ the affine map
    def _jac(self, q, s):
        model = self.model
        return model.jacobian(model.positions(q[None]), s[None])[0]

    def _coefficients(self):
        model = self.model
        n, nd = model.n_q, model.n_drivers
        q0, s0 = np.zeros(n), np.zeros(nd)
        J0 = self._jac(q0, s0)
        C = np.zeros((self.n_features,) + J0.shape)
        base = J0.copy()
        for k, j in enumerate(self.angle):
            sp = s0.copy()
            sp[j] = np.pi
            Jpi = self._jac(q0, sp)
            sp[j] = np.pi / 2
            Jh = self._jac(q0, sp)
            bc = 0.5 * (J0 - Jpi)
            C[1 + n + k] = bc
            C[1 + n + len(self.angle) + k] = Jh - J0 + bc
            base = base - bc
        C[0] = base
        for k in range(n):
            e = np.zeros(n)
            e[k] = 1.0
            C[1 + k] = self._jac(e, s0) - J0
        # clean rounding noise: entries are exact small rationals of the lengths
        C[np.abs(C) < 1e-14 * max(1.0, np.abs(C).max())] = 0.0
        return C

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

    def max_abs_phi(self, X2, sT: np.ndarray, trig: dict | None = None) -> np.ndarray:
        """Return max |Phi| over the rows (S,), arguments as :meth:`phi`, without forming Phi.

        NaN anywhere in a step gives NaN (``np.maximum`` propagates it).
        """
        res = np.zeros(self._n_steps(X2, sT))
        for row in self._phi_rows(X2, sT, trig):
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

    def _phi_rows(self, X2, sT: np.ndarray, trig: dict | None):
        """Yield Phi's rows in order (:func:`linkpipe.model.equations.phi_rows`), each an (S,)
        array (or a float when it is constant), on contiguous coordinate arrays; fixed points
        enter as scalars."""
        fx = self._fixed_xy
        if isinstance(X2, dict):  # {moving point: (x (S,), y (S,))}: no copy into (P, 2, S)
            def xy(p):
                return fx[p] if p in fx else X2[p]
        else:
            def xy(p):
                return fx[p] if p in fx else (X2[p, 0], X2[p, 1])
        cos_s, sin_s = self._trig(sT, trig)
        return eq.phi_rows(self.model.rows, xy, sT, cos_s, sin_s)

    def _trig(self, sT, trig=None):
        """Return the drivers' cos and sin (lists by driver; None for coordinate drivers)."""
        cos_s, sin_s = [None] * len(sT), [None] * len(sT)
        for j in self.angle:
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
        for j, row in enumerate(eq.phi_s_rows(md.rows, lambda p: (X2[p, 0], X2[p, 1]), cos_s, sin_s)):
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
        for e, (c0, terms) in enumerate(self._terms):
            row = E[e]
            if not terms:
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

    # ------------------------------------------------------------------ solves
    def solve(self, E: np.ndarray, b) -> list:
        """Solve ``J x = b`` at every step: E (nnz, S) entries, b a list of m arrays (..., S).

        Returns x as a list of n_q arrays (..., S). Exactly singular blocks give inf or NaN.
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            return self._solve(E, b)

    def _solve(self, E, b):
        x = [None] * self.model.n_q
        for rows, cols, inner, outer in self.blocks:
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
                a, b_, c, d = _block2(E, inner)
                idet = 1.0 / (a * d - b_ * c)
                x[cols[0]] = (rhs[0] * d - rhs[1] * b_) * idet
                x[cols[1]] = (a * rhs[1] - c * rhs[0]) * idet
            else:
                S = E.shape[1]
                M = _dense_block(E, inner)
                shp = np.broadcast_shapes(*(np.shape(r) for r in rhs), (S,))
                R = np.stack([np.broadcast_to(r, shp).reshape(-1, S) for r in rhs])  # (k, r, S)
                try:
                    sol = np.linalg.solve(M, R.transpose(2, 0, 1))  # (S, k, r)
                except np.linalg.LinAlgError:
                    sol = np.full((S, k, R.shape[1]), np.nan)
                for i, c in enumerate(cols):
                    x[c] = sol[:, i, :].T.reshape(shp)
        return x

    def solve_transpose(self, E: np.ndarray, b) -> list:
        """Solve ``J^T y = b`` at every step: b a list of n_q arrays (S,); returns m arrays.

        Back substitution through the blocks in reverse order (J^T is block upper triangular).
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            y = [None] * self.model.n_rows
            for rows, cols, inner, _ in reversed(self.blocks):
                rhs = []
                for c in cols:
                    acc = b[c]
                    for e in self.col_entries[c]:
                        r = int(self.rows[e])
                        if r not in rows:
                            acc = acc - E[e] * y[r]
                    rhs.append(acc)
                k = len(cols)
                if k == 1:
                    y[rows[0]] = rhs[0] / E[inner[0][0]]
                elif k == 2:  # the block transposed: [[a, c], [b, d]]
                    a, b_, c, d = _block2(E, inner)
                    idet = 1.0 / (a * d - b_ * c)
                    y[rows[0]] = (rhs[0] * d - rhs[1] * c) * idet
                    y[rows[1]] = (a * rhs[1] - b_ * rhs[0]) * idet
                else:
                    S = E.shape[1]
                    M = _dense_block(E, inner).transpose(0, 2, 1)
                    R = np.stack([np.broadcast_to(r, (S,)) for r in rhs], axis=1)
                    try:
                        sol = np.linalg.solve(M, R[..., None])[..., 0]
                    except np.linalg.LinAlgError:
                        sol = np.full((S, k), np.nan)
                    for i, r in enumerate(rows):
                        y[r] = sol[:, i]
            return y

    def matvec(self, E: np.ndarray, x: list) -> list:
        """Return ``J x`` as a list of m arrays: E (nnz, S), x a list of n_q arrays (S,)."""
        out = [0.0] * self.model.n_rows
        for e, (r, c) in enumerate(zip(self.rows, self.cols)):
            out[r] = out[r] + E[e] * x[c]
        return out

    def norm1(self, E: np.ndarray) -> np.ndarray:
        """Return the 1-norm (largest column sum of |J|) at every step (S,)."""
        absE = np.abs(E)
        return np.max(np.stack([absE[ce].sum(axis=0) for ce in self.col_entries]), axis=0)


def _matching(row_cols: list, n: int):
    """Return a perfect matching row -> column of a bipartite pattern (Kuhn), or None."""
    col_row = [-1] * n

    def augment(r, seen):
        for c in row_cols[r]:
            if not seen[c]:
                seen[c] = True
                if col_row[c] < 0 or augment(col_row[c], seen):
                    col_row[c] = r
                    return True
        return False

    for r in range(len(row_cols)):
        if not augment(r, [False] * n):
            return None
    match = [0] * len(row_cols)
    for c, r in enumerate(col_row):
        match[r] = c
    return match


def _components(succ: list) -> list:
    """Return the strongly connected components of a graph (Tarjan), each after its predecessors."""
    n = len(succ)
    index, low, on, stack, out = [None] * n, [0] * n, [False] * n, [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on[v] = True
        for w in succ[v]:
            if index[w] is None:
                visit(w)
                low[v] = min(low[v], low[w])
            elif on[w]:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on[w] = False
                comp.append(w)
                if w == v:
                    break
            out.append(comp)

    for v in range(n):
        if index[v] is None:
            visit(v)
    return out[::-1]  # Tarjan emits sinks first: reversed, every component follows its sources


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
    """Return the model's engine (cached on the model), or None when it has none."""
    cache = model.__dict__.get("_linkpipe_engine", False)
    if cache is False:
        try:
            cache = Engine(model)
        except EngineUnavailable:
            cache = None
        object.__setattr__(model, "_linkpipe_engine", cache)
    return cache


def _rows(a: np.ndarray) -> list:
    """(S, k) -> list of k contiguous arrays."""
    return list(np.ascontiguousarray(a.T))


# --------------------------------------------------------------------------------------------
# Derivatives (the jacobian stage) on the engine


def derivatives(model: Model, X: np.ndarray, s, s_dot, s_ddot, status, need_acceleration: bool,
                velocity: np.ndarray | None = None, acceleration: np.ndarray | None = None,
                need_inverse: bool = True, chunk: int = CHUNK):
    """Return what :func:`linkpipe.kinematics.derivatives` returns, computed on the engine.

    Condition ``|J|_1 |J^-1|_1`` and SINGULAR flags as there; velocities and accelerations from
    the inverse (or the given ``velocity``/``acceleration``, e.g. the dyads', NaN where singular).
    ``need_inverse=False`` leaves ``jacobian_inverse`` None (no force stage). Falls back to
    :func:`linkpipe.kinematics.derivatives` when the model has no engine.
    """
    eng = engine(model)
    if eng is None:
        return kin.derivatives(model, X, s, s_dot, s_ddot, status, need_acceleration)
    S = X.shape[0]
    n, m = model.n_q, model.n_rows
    status = status.copy()
    condition = np.full(S, np.nan)
    Jinv = np.full((S, n, m), np.nan) if need_inverse else None
    V = np.full((S, model.n_points, 2), np.nan)
    A = np.full((S, model.n_points, 2), np.nan) if need_acceleration else None
    vres = np.full(S, np.nan)
    ares = np.full(S, np.nan) if need_acceleration else None
    rcond = model.scene.solver.singular_rcond
    eye = np.eye(m)
    mv = model.moving
    for lo in range(0, S, chunk):
        hi = min(S, lo + chunk)
        idx = lo + np.flatnonzero(status[lo:hi] == kin.OK)
        if not len(idx):
            continue
        Xc, sc_ = X[idx], s[idx]
        q = model.q_of(Xc)
        E = eng.entries(q, sc_)
        inv = eng.solve(E, [eye[r][:, None] for r in range(m)])  # n arrays (m, k)
        invs = np.stack(inv)  # (n, m, k)
        with np.errstate(invalid="ignore"):
            ni = np.abs(invs).sum(axis=0).max(axis=0)
            cond = eng.norm1(E) * ni
        cond = np.where(np.isfinite(cond), cond, np.inf)
        condition[idx] = cond
        sing = ~(cond * rcond < 1.0)
        status[idx[sing]] = kin.SINGULAR
        good = ~sing
        gi = idx[good]
        if not len(gi):
            continue
        invg = invs[:, :, good]  # (n, m, g)
        if Jinv is not None:
            Jinv[gi] = np.moveaxis(invg, 2, 0)
        Eg = E[:, good]
        Xg, sg = Xc[good], sc_[good]
        phit = -model.phi_t(Xg, sg, s_dot[gi])  # (g, m)
        if velocity is None:
            qd = np.einsum("imk,km->ik", invg, phit)  # (n, g)
        else:
            qd = model.q_of(velocity[gi]).T
        res = eng.matvec(Eg, list(qd))
        vres[gi] = np.abs(np.stack(res) - phit.T).max(axis=0)
        Vg = model.velocities(qd.T)
        V[gi] = Vg
        if need_acceleration:
            g = model.gamma(Xg, Vg, sg, s_dot[gi], s_ddot[gi])  # (g, m)
            if acceleration is None:
                qdd = np.einsum("imk,km->ik", invg, g)
            else:
                qdd = model.q_of(acceleration[gi]).T
            res = eng.matvec(Eg, list(qdd))
            ares[gi] = np.abs(np.stack(res) - g.T).max(axis=0)
            A[gi] = model.velocities(qdd.T)
    V[:, model.fixed] = 0.0
    if A is not None:
        A[:, model.fixed] = 0.0
    return dict(velocity=V, acceleration=A, condition=condition, velocity_residual=vres,
                acceleration_residual=ares, status=status, jacobian_inverse=Jinv)


# --------------------------------------------------------------------------------------------
# The general path, vectorised


def _hermite_T(q0, d0, q1, d1, t):
    """Cubic Hermite on [0, 1], coordinates first: q0, q1 values and d0, d1 slopes per unit t,
    each (n, k); t (k,). Returns (n, k)."""
    t2 = t * t
    t3 = t2 * t
    h00 = 2 * t3 - 3 * t2 + 1
    h10 = t3 - 2 * t2 + t
    h01 = -2 * t3 + 3 * t2
    h11 = t3 - t2
    return h00 * q0 + h10 * d0 + h01 * q1 + h11 * d1


def _colmax(a: np.ndarray) -> np.ndarray:
    """Return ``a.max(axis=0)`` of a (m, k) array (NaN propagates) row by row: no strided reduce."""
    out = a[0].copy()
    for row in a[1:]:
        np.maximum(out, row, out=out)
    return out


def solve_newton(model: Model, s: np.ndarray, coarse: int = COARSE_NODES, chunk: int = CHUNK,
                 start=None):
    """Solve the sweep by the general path, vectorised; return a dict.

    Keys: q (S, n_q) NaN at failed steps, residual, iterations, status (as
    :func:`linkpipe.kinematics.solve_positions`), ``sequential`` (S,) bool where the sequential
    continuation solved the step. Falls back to the sequential
    path for every step when the model has no engine, the scene asks for a finite-difference
    Jacobian, or the driver values are not evenly spaced. ``start``: the
    :func:`linkpipe.kinematics.start_state` at ``s[0]`` when the caller has it already.
    """
    sc = model.scene.solver
    S = s.shape[0]
    eng = engine(model)
    k = max(1, int(np.ceil((S - 1) / max(1, coarse))))
    even = S < 3 or np.allclose(np.diff(s, axis=0), (s[-1] - s[0]) / (S - 1),
                                rtol=0, atol=1e-9 * max(1.0, float(np.abs(s).max())))
    out = {}
    if eng is None or sc.jacobian != "analytic" or S < VECTORISE_FROM or not even:
        q0, slope0 = start if start is not None else (None, None)
        q, res, it, st = kin.solve_positions(model, s, q_start=q0, start_slope=slope0)
        out.update(q=q, residual=res, iterations=it, status=st, sequential=np.ones(S, bool))
        return out
    tol_abs = sc.tol * model.size
    nodes = np.r_[np.arange(0, S - 1, k), S - 1]
    if start is None:  # (q, slope): the coarse run starts there, and any re-run from step 0
        start = kin.start_state(model, s[0], tol_abs, sc.max_iter)
    qn, resn, itn, stn = kin.solve_positions(model, s[nodes], q_start=start[0], start_slope=start[1])
    qn, resn = _polish(eng, qn, s[nodes], stn == kin.OK, resn)
    q = np.full((S, model.n_q), np.nan)
    residual = np.full(S, np.nan)
    iterations = np.zeros(S, dtype=np.int32)
    status = np.zeros(S, dtype=np.int8)
    sequential = np.zeros(S, dtype=bool)
    q[nodes], residual[nodes], iterations[nodes], status[nodes] = qn, resn, itn, stn
    sequential[nodes] = True
    # slopes dq/dstep at the nodes, from the engine
    ds = (s[-1] - s[0]) / (S - 1)  # driver increment per step (nd,)
    okn = stn == kin.OK
    slope = np.full_like(qn, np.nan)
    if okn.any():
        Xn = model.positions(qn[okn])
        E = eng.entries(qn[okn], s[nodes][okn])
        rhs = -model.phi_t(Xn, s[nodes][okn], np.broadcast_to(ds, (okn.sum(), len(ds))))
        slope[okn] = np.stack(eng.solve(E, _rows(rhs)), axis=1)
        with np.errstate(invalid="ignore"):
            cond = eng.norm1(E) * np.abs(np.stack(eng.solve(E, [np.eye(model.n_rows)[r][:, None]
                                                               for r in range(model.n_rows)]))
                                         ).sum(axis=0).max(axis=0)
        near_singular = ~(cond * model.scene.solver.singular_rcond < 1e-3)
        okn[np.flatnonzero(okn)[near_singular]] = False
    okn &= np.isfinite(slope).all(axis=1)
    # fine steps of intervals between two regular nodes
    interval_ok = okn[:-1] & okn[1:]
    bad_interval = ~interval_ok
    lengths = np.diff(nodes)
    seg = np.repeat(np.arange(len(nodes) - 1), lengths)  # interval of steps 0..S-2
    fine = np.ones(S, dtype=bool)
    fine[nodes] = False
    steps = np.flatnonzero(fine & np.r_[interval_ok[seg], False])
    # per interval, coordinates first (the chunks below work on contiguous (n_q, k) arrays):
    # the Hermite data (values and slopes per unit t) and the largest motion of a coordinate
    h_int = lengths[:, None].astype(float)
    hermite_T = [np.ascontiguousarray(a.T) for a in (qn[:-1], slope[:-1] * h_int, qn[1:],
                                                        slope[1:] * h_int)]
    span_int = (np.abs(qn[1:] - qn[:-1]).max(axis=1) if model.n_q else np.zeros(len(lengths)))
    for lo in range(0, len(steps), chunk):
        ii = steps[lo:lo + chunk]
        g = seg[ii]
        t = (ii - nodes[g]) / lengths[g]
        predT = _hermite_T(*(np.take(a, g, axis=1) for a in hermite_T), t)
        sT = np.ascontiguousarray(s[ii].T)
        qT, res, its, conv, _ = _newton_soa(eng, predT.copy(), sT, tol_abs,
                                            min(NEWTON_ITERATIONS, sc.max_iter))
        moved = _colmax(np.abs(qT - predT)) if qT.shape[0] else np.zeros(len(ii))
        span = span_int[g]
        accept = conv & (moved <= np.maximum(OFF_BRANCH * span, OFF_BRANCH_ABS * model.size))
        accept &= _aligned(eng, qT, sT)
        ia = ii[accept]
        for c in range(qT.shape[0]):  # one coordinate at a time: cheaper than a 2-D fancy write
            q[ia, c] = qT[c, accept]
        residual[ii] = res
        iterations[ii] = its
        bad_interval[np.unique(g[~accept])] = True
    # runs of intervals the vectorised refinement could not do: the sequential continuation,
    # from the run's first node (or the last assembled step before it)
    last = len(nodes) - 1
    bad = np.flatnonzero(bad_interval)
    runs = np.split(bad, np.flatnonzero(np.diff(bad) > 1) + 1) if len(bad) else []
    for run in runs:
        j0, j1 = run[0], run[-1]
        a, b = nodes[j0], nodes[j1 + 1]
        qs, rs, its, sts = _sequential_from_before(model, s, q, a, b, start)
        q[a + 1:b + 1], residual[a + 1:b + 1] = qs[1:], rs[1:]
        iterations[a + 1:b + 1], status[a + 1:b + 1] = its[1:], sts[1:]
        sequential[a + 1:b + 1] = True
        if j1 + 1 < last and not _same(qs[-1], qn[j1 + 1], model):
            # the coarse continuation went elsewhere at this node: continue sequentially
            qs, rs, its, sts = _sequential_from_before(model, s, q, b, S - 1, start)
            q[b + 1:], residual[b + 1:], iterations[b + 1:], status[b + 1:] = qs[1:], rs[1:], its[1:], sts[1:]
            sequential[b + 1:] = True
            break
    out.update(q=q, residual=residual, iterations=iterations, status=status, sequential=sequential)
    return out


def _aligned(eng, qT, sT):
    """kinematics.drivers_aligned on SoA arrays: every angle driver's vector along its angle."""
    md = eng.model
    X2 = eng.points(qT)
    ok = np.ones(qT.shape[1], dtype=bool)
    for j in np.flatnonzero(md.drv_angle):
        d = X2[md.drv_b[j]] - X2[md.drv_a[j]]
        ok &= d[0] * np.cos(sT[j]) + d[1] * np.sin(sT[j]) > 0
    return ok


def _newton_soa(eng, qT, sT, tol_abs, max_iter: int = NEWTON_ITERATIONS):
    """Newton on a chunk from predictions qT (n_q, k); return (qT, residual, its, converged, E).

    At most ``max_iter`` iterations (the scene's cap, if lower than NEWTON_ITERATIONS). E: the
    Jacobian's entries at the returned positions (for the derivatives)."""
    k = qT.shape[1]
    its = np.zeros(k, dtype=np.int32)
    res = np.full(k, np.inf)
    E = None
    step = np.full(k, np.inf)  # the last correction: Newton goes on while it is not tiny
    small = 1e-8 * eng.model.size  # (quadratic convergence: the next one is at rounding level)
    for it in range(max_iter + 1):
        F = eng.phi(eng.points(qT), sT)
        r = _colmax(np.abs(F)) if F.shape[0] else np.zeros(k)
        res = r
        keep = (r > tol_abs) | (step > small)  # NaN: not kept, not converged
        keep &= np.isfinite(r)
        if it == max_iter or not keep.any():
            break
        E = eng.entries_T(qT, sT)
        dq = np.stack(eng.solve(E, list(-F)))
        if keep.all():
            qT += dq
        else:
            qT[:, keep] += dq[:, keep]
        step = np.where(keep, _colmax(np.abs(dq)) if dq.shape[0] else 0.0, 0.0)
        its[keep] += 1
    return qT, res, its, res <= tol_abs, eng.entries_T(qT, sT)


def _polish(eng, q, s, ok, residual):
    """One more Newton step at the steps ``ok`` (the sequential path stops at ``tol``, up to
    ~1e-12 of the size away); kept where it lowers the residual."""
    idx = np.flatnonzero(ok & np.isfinite(q).all(axis=1))
    if not len(idx):
        return q, residual
    qT = np.ascontiguousarray(q[idx].T)
    sT = np.ascontiguousarray(s[idx].T)
    F = eng.phi(eng.points(qT), sT)
    qn = qT + np.stack(eng.solve(eng.entries_T(qT, sT), list(-F)))
    rn = np.abs(eng.phi(eng.points(qn), sT)).max(axis=0) if F.shape[0] else np.zeros(len(idx))
    better = rn < np.abs(F).max(axis=0)
    q, residual = q.copy(), residual.copy()
    q[idx[better]] = qn.T[better]
    residual[idx[better]] = rn[better]
    return q, residual


def _same(a, b, model) -> bool:
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return bool(np.isfinite(a).all() == np.isfinite(b).all())
    return bool(np.abs(a - b).max() <= 1e-8 * model.size)


def _sequential_from_before(model, s, q, a, b, start):
    """Run the sequential continuation over steps a..b from the last assembled step at or before a.

    ``start``: :func:`linkpipe.kinematics.start_state` at step 0 (its slope is the first
    predictor when the run starts there)."""
    prev = np.flatnonzero(np.isfinite(q[:a + 1]).all(axis=1))
    p = prev[-1] if len(prev) else 0
    slope = start[1] if p == 0 else None
    qs, rs, its, sts = kin.solve_positions(model, s[p:b + 1], q_start=q[p] if len(prev) else None,
                                           start_slope=slope)
    return qs[a - p:], rs[a - p:], its[a - p:], sts[a - p:]


def residuals(model: Model, X: np.ndarray, s: np.ndarray, chunk: int = CHUNK) -> np.ndarray:
    """Return max |Phi| (S,) at positions X (S, n_points, 2), in cache-sized chunks."""
    S = X.shape[0]
    out = np.empty(S)
    for lo in range(0, S, chunk):
        hi = min(S, lo + chunk)
        F = model.phi(X[lo:hi], s[lo:hi])
        out[lo:hi] = np.abs(F).max(axis=1) if F.shape[1] else 0.0
    return out


def max_abs_phi(model: Model):
    """Return ``f(points {moving p: (x (S,), y (S,))}, sT (nd, S), trig=None) -> (S,)``: max |Phi|.

    The engine's in-place row accumulation when the model has an engine, else the dense
    :func:`residuals` on the points put back into (S, n_points, 2).
    """
    eng = engine(model)
    if eng is not None:
        return eng.max_abs_phi
    return lambda pts, sT, trig=None: residuals(model, _points_array(model, pts, sT.shape[1]), sT.T)


def _points_array(model: Model, pts: dict, S: int) -> np.ndarray:
    """Return positions (S, P, 2) from {moving point: (x (S,), y (S,))}."""
    X = np.broadcast_to(model.start_position, (S, model.n_points, 2)).copy()
    for p, (x, y) in pts.items():
        X[:, p, 0] = x
        X[:, p, 1] = y
    return X


def stage1(model: Model, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray, order: int = 0):
    """Solve a sweep's positions (and, on the dyad path, velocities/accelerations) by the scene's method.

    ``[solver] method``: ``auto`` takes the closed-form dyads when the scene decomposes and
    :func:`linkpipe.dyads.branch_check` finds that they follow Newton's branch, else the
    general path; ``newton`` the general path (:func:`solve_newton`); ``dyads`` requires the
    fast path (SceneError when the scene does not decompose). Returns a dict: position
    (S, n_points, 2) NaN at failed steps, residual, iterations, status, method ("dyads" or
    "newton"), note (why auto chose what it chose), and on the dyad path velocity and
    acceleration (order >= 1, 2) or None.
    """
    from . import dyads
    from .errors import SceneError

    sc = model.scene.solver
    method = sc.method
    note = ""
    S = s.shape[0]
    start = None  # the start state, once assembled (the Newton path reuses it)
    if method in ("auto", "dyads"):
        plan = dyads.decompose(model)
        if not plan.ok:
            if method == "dyads":
                raise SceneError(model.scene.path, "solver", "method",
                                 f'method = "dyads" but the mechanism does not decompose into '
                                 f"closed-form dyads: {plan.reason}",
                                 'use method = "auto" (closed-form dyads where the scene '
                                 'decomposes, else Newton) or "newton"')
            note = f"auto: {plan.reason}; general Newton path"
        elif method == "auto" and sc.jacobian != "analytic":
            note = f"auto: jacobian = {sc.jacobian!r} asks for Newton; general Newton path"
        else:
            tol_abs = sc.tol * model.size
            start = kin.start_state(model, s[0], tol_abs, sc.max_iter)
            q0, slope0 = start
            dyads.set_branches(plan, model.positions(q0[None])[0], s[0])
            if slope0 is not None and S > 1:
                # a start on a dyad's singular shape (a change point) takes that dyad's sign a
                # step along the path the drawing was carried on
                q1 = q0 + slope0 @ (s[1] - s[0])
                dyads.refine_branches(plan, model.positions(q0[None])[0], s[0],
                                      model.positions(q1[None])[0], s[1])
            sw = dyads.solve(plan, s, s_dot, s_ddot, order=order, gaps=method == "auto",
                             max_abs_phi=max_abs_phi(model))
            if method == "dyads" or dyads.branch_check(plan, sw):
                X = sw.position
                residual = sw.residual
                ok = sw.ok
                bad = ok & ~(residual <= 10 * tol_abs)  # a redundant constraint not met
                if bad.any():
                    X[np.ix_(bad, model.moving)] = np.nan
                    for arr in (sw.velocity, sw.acceleration):
                        if arr is not None:
                            arr[np.ix_(bad, model.moving)] = np.nan
                status = np.where(ok & ~bad, kin.OK, kin.NO_ASSEMBLY).astype(np.int8)
                return dict(position=X, residual=residual, iterations=np.zeros(S, dtype=np.int32),
                            status=status, method="dyads", note=note or plan.describe(),
                            velocity=sw.velocity, acceleration=sw.acceleration)
            note = ("auto: a dyad passes near its singular configuration or cannot be assembled "
                    "at some step; general Newton path")
    out = solve_newton(model, s, start=start)
    q = out["q"]
    fin = np.isfinite(q).all(axis=1)
    X = model.positions(np.where(np.isfinite(q), q, 0.0))
    X[~fin] = np.nan
    X[:, model.fixed] = model.start_position[model.fixed]
    return dict(position=X, residual=out["residual"], iterations=out["iterations"],
                status=out["status"], method="newton", note=note, velocity=None, acceleration=None)
