"""One step's constraint Jacobian as a sparse LU (scipy.sparse, SuperLU), for large mechanisms.

The sequential continuation (every sweep under 1000 steps, and the coarse nodes of longer
ones) works one step at a time. On a small mechanism that is a dense ``(n, n)`` Jacobian, its
inverse (the exact condition) and dense solves: cheap below a few dozen unknowns, but
``O(n^2)`` memory and ``O(n^3)`` work per step, which made a chain of 64 four-bar loops spend
most of its positions stage there (issue 16). From :data:`SPARSE_FROM` unknowns
(``[solver] linear_algebra = "auto"``; ``"sparse"`` / ``"dense"`` force either) a step's
Jacobian is instead:

* its non-zero entries only, from the sparse engine's affine map (:class:`.sparse.Engine`:
  read off :meth:`Model.jacobian_terms`, the one definition of the rows), as one sparse
  product ``C f`` (``f = [1, q, cos s, sin s]``; relative angle rows from the equations);
* factorised by SuperLU in a fill-reducing column order computed once per model (COLAMD on
  the pattern; a chain's Jacobian is block-banded, so the factors stay ``O(n)``);
* its condition ``|J|_1 |J^-1|_1`` estimated from a few solves
  (:func:`.linalg.estimate_inverse_norm1`), and taken exactly (``J^-1`` from ``n`` solves)
  wherever the estimate comes within 1000x of a threshold a decision rests on;
* the sign of its determinant (the assembly mode) from the factors' diagonal and the parity
  of the two permutations.

Results agree with the dense path to rounding (``tests/test_scale.py``); a Jacobian SuperLU
finds exactly singular is solved densely (minimum norm), as the dense path does.
"""
from __future__ import annotations

import numpy as np

from ..model import Model, content_key, derived
from .linalg import EXACT_WITHIN, estimated_condition, lin_solve
from .sparse import engine

#: unknowns from which ``linear_algebra = "auto"`` takes the sparse LU for one-step work
#: (measured on chains of four-bar loops, 300 steps step by step: dense and sparse positions
#: take the same time at 64 unknowns, 2-3x less dense at 16, 1.5x less sparse at 96)
SPARSE_FROM = 64



def uses_sparse(model: Model) -> bool:
    """Whether one-step linear algebra of this model runs on the sparse LU: ``[solver]
    linear_algebra`` "sparse", or "auto" from :data:`SPARSE_FROM` unknowns; only a model with
    a square, structurally regular Jacobian (one with a sparse engine) can."""
    choice = model.scene.solver.linear_algebra
    if choice == "dense" or model.n_q == 0 or engine(model) is None:
        return False
    return choice == "sparse" or model.n_q >= SPARSE_FROM


def linear_algebra_used(model: Model) -> str:
    """One phrase for the summary, the HDF5 attributes and the accuracy ladder: which linear
    algebra the one-step work (continuation, start) ran on, and why."""
    choice = model.scene.solver.linear_algebra
    if uses_sparse(model):
        why = "forced" if choice == "sparse" else f"auto: {model.n_q} >= {SPARSE_FROM} unknowns"
        return f"sparse LU ({why})"
    if choice == "sparse":
        return "dense (no sparse engine: the Jacobian is not square)"
    why = "forced" if choice == "dense" else f"auto: {model.n_q} < {SPARSE_FROM} unknowns"
    return f"dense ({why})"


class StepLU:
    """The model's one-step sparse Jacobian: pattern, column order and value map, built once."""

    def __init__(self, model: Model):
        import scipy.sparse as sp  # here: importing scipy.sparse costs ~0.2 s, small runs skip it
        from scipy.sparse.linalg import splu

        eng = engine(model)
        self.model, self.eng = model, eng
        m, n = model.n_rows, model.n_q
        self.n = n
        self.CT = sp.csr_matrix(eng.CT)  # (nnz, n_features): most entries 1-2 terms
        self.angle = eng.angle
        # the pattern in compressed-column form (data: each entry's number), its columns in
        # COLAMD order, computed once from a factorisation of the pattern with generic values
        # (the engine found it structurally regular; natural order should that one be singular)
        slot = np.arange(1.0, len(eng.rows) + 1)
        pattern = sp.csc_matrix((slot, (eng.rows, eng.cols)), shape=(m, n))
        pattern.sort_indices()
        generic = pattern.copy()
        generic.data = np.random.default_rng(0).uniform(1.0, 2.0, generic.nnz)
        try:
            self.perm_c = splu(generic, permc_spec="COLAMD").perm_c.copy()
        except RuntimeError:
            self.perm_c = np.arange(n)
        # column k of the factorised matrix is column order[k] of J
        order = np.empty(n, dtype=np.intp)
        order[self.perm_c] = np.arange(n)
        ordered = pattern[:, order].tocsc()
        ordered.sort_indices()
        self.order = order
        self.order_sign = _parity(order)  # det J = det(J P) times the sign of P
        self.indices, self.indptr = ordered.indices.copy(), ordered.indptr.copy()
        self.take = ordered.data.astype(np.intp) - 1  # CSC slot -> engine entry
        self.shape = (m, n)

    def entries(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The Jacobian's non-zero entries (nnz,) at q (n,), s (nd,), in the engine's order."""
        na = len(self.angle)
        f = np.empty(self.eng.n_features)
        f[0] = 1.0
        f[1:1 + self.n] = q
        if na:
            f[1 + self.n:1 + self.n + na] = np.cos(s[self.angle])
            f[1 + self.n + na:] = np.sin(s[self.angle])
        E = self.CT @ f
        if len(self.eng.relative):
            E2 = E[:, None].copy()
            self.eng._relative_entries(E2, q[:, None], s[:, None])
            E = E2[:, 0]
        return E

    def factor(self, q: np.ndarray, s: np.ndarray) -> "StepFactor":
        """The factorisation of Phi_q at q (n,), s (nd,)."""
        E = self.entries(np.asarray(q, dtype=float), np.asarray(s, dtype=float))
        return StepFactor(self, E)


class StepFactor:
    """Phi_q at one step, factorised (or found exactly singular): solves, condition, det sign."""

    def __init__(self, plan: StepLU, E: np.ndarray):
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        self.plan, self.E = plan, E
        A = sp.csc_matrix((E[plan.take], plan.indices, plan.indptr), shape=plan.shape)
        self.A = A  # columns in plan.order
        try:
            self.lu = splu(A, permc_spec="NATURAL") if np.isfinite(E).all() else None
        except RuntimeError:  # exactly singular
            self.lu = None

    def dense(self) -> np.ndarray:
        """Phi_q (m, n) densely (a rare path: exactly singular steps)."""
        J = np.zeros(self.plan.shape)
        J[self.plan.eng.rows, self.plan.eng.cols] = self.E
        return J

    def solve(self, b: np.ndarray, trans: bool = False) -> np.ndarray:
        """Solve ``J x = b`` (or ``J^T x = b``) for b (n,) or (n, k)."""
        order = self.plan.order
        if self.lu is None:
            J = self.dense().T if trans else self.dense()
            b2 = b if b.ndim == 2 else b[:, None]
            x = np.stack([lin_solve(J[None], b2[:, k][None])[0] for k in range(b2.shape[1])], 1)
            return x if b.ndim == 2 else x[:, 0]
        if trans:  # J^T y = b: (J P)^T y = P^T b, P the column order
            return self.lu.solve(np.ascontiguousarray(b[order]), trans="T")
        y = self.lu.solve(np.ascontiguousarray(b))
        x = np.empty_like(y)
        x[order] = y
        return x

    def norm1(self) -> float:
        """|J|_1: the largest column sum of |J|."""
        eng = self.plan.eng
        return float(np.bincount(eng.cols, np.abs(self.E), self.plan.n).max()) if len(self.E) else 0.0

    def inverse_norm1(self) -> float:
        """|J^-1|_1 exactly (n solves; inf where exactly singular)."""
        if self.lu is None:
            return np.inf
        with np.errstate(invalid="ignore", over="ignore"):
            inv = self.solve(np.eye(self.plan.n))
            value = float(np.abs(inv).sum(axis=0).max())
        return value if np.isfinite(value) else np.inf

    def condition(self, rcond: float, threshold: float, within: float = EXACT_WITHIN) -> float:
        """``|J|_1 |J^-1|_1``, estimated (:func:`.linalg.estimated_condition`: exact near the
        singular threshold and where the estimate times ``within`` reaches ``threshold``)."""
        if self.lu is None:
            return np.nan if not np.isfinite(self.E).all() else np.inf
        norm1 = self.norm1()
        cond = estimated_condition(
            np.array([norm1]), self.solve, lambda x: self.solve(x, trans=True),
            lambda near: norm1 * self.inverse_norm1(), self.plan.n, 1, rcond, threshold, within)[0]
        return cond if cond == cond else np.inf

    def det_sign(self) -> float:
        """The sign of det Phi_q (0.0 where exactly singular)."""
        if self.lu is None:
            return 0.0
        d = self.lu.U.diagonal()
        if not np.all(d):
            return 0.0
        sign = -1.0 if np.count_nonzero(d < 0) % 2 else 1.0
        return sign * _parity(self.lu.perm_r) * _parity(self.lu.perm_c) * self.plan.order_sign


def _parity(perm: np.ndarray) -> float:
    """+1.0 or -1.0: the sign of a permutation, (-1)^(n - its number of cycles); the cycles
    are the connected components of the graph i -> perm[i] (scipy's, in C: O(n))."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(perm)
    graph = csr_matrix((np.ones(n), (np.arange(n), np.asarray(perm))), shape=(n, n))
    cycles = connected_components(graph, directed=True, connection="weak")[0]
    return -1.0 if (n - cycles) % 2 else 1.0


def step_lu(model: Model) -> StepLU | None:
    """The model's :class:`StepLU` (built once per model), or None where it does not use one."""
    return derived(model, "step_lu", lambda md: StepLU(md) if uses_sparse(md) else None,
                   content_key(model))
