"""One step's Phi and Phi_q on Python floats, for the sequential continuation (numpy's
per-call overhead would dominate a single step of a few rows)."""
from __future__ import annotations

import numpy as np

from ..model import Model, content_key, derived
from ..model import equations as eq
from .linalg import lin_solve
from .newton import ONE, iterate
from .sparse_lu import step_lu



class _Step:
    """One step's Phi, Phi_q and driver check on Python floats (sequential continuation).

    The rows are :mod:`linkpipe.model.equations`' own, evaluated on floats: numpy's per-call
    overhead would dominate a single step of a few rows (``tests/test_kernels.py`` checks that
    they equal ``Model.phi`` / ``Model.jacobian`` to the last bit). Built once per model.
    """

    def __init__(self, model: Model):
        md = self.model = model
        self.n, self.m = md.n_q, md.n_rows
        self.nc = md.n_constraints
        self.rows = md.rows
        self.x0 = md.start_position.reshape(-1).tolist()
        self.qpos = [int(2 * p + c) for p in md.moving for c in (0, 1)]
        self.col = [-1] * (2 * md.n_points)  # point coordinate -> column of q (-1: fixed)
        for k, pc in enumerate(self.qpos):
            self.col[pc] = k
        self.angle = np.flatnonzero(md.drv_angle)
        self.lu = step_lu(model)  # large mechanisms: Phi_q as a sparse LU (None: dense)

    def _xy(self, q):
        X = self.points(q)
        return lambda p: (X[2 * p], X[2 * p + 1])

    def jac(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi_q (m, n) at q (n,) and s (nd,), as :meth:`Model.jacobian` computes it."""
        n, col = self.n, self.col
        J = [0.0] * (self.m * n)
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        for r, p, gx, gy in eq.jacobian_terms(self.rows, self._xy(q), cs, sn):
            c = col[2 * p]
            if c >= 0:
                J[r * n + c] += gx
            c = col[2 * p + 1]
            if c >= 0:
                J[r * n + c] += gy
        return np.array(J, dtype=float).reshape(self.m, n)

    def points(self, q) -> list:
        X = list(self.x0)
        for k, v in zip(self.qpos, q.tolist()):
            X[k] = v
        return X

    def phi(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi (m,) at q (n,) and s (nd,), as :meth:`Model.phi` computes it."""
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        return np.array(list(eq.phi_rows(self.rows, self._xy(q), s.tolist(), cs, sn)), dtype=float)

    def aligned(self, q: np.ndarray, s: np.ndarray) -> bool:
        """:func:`drivers_aligned` at one step."""
        if not len(self.angle):
            return True
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        return all(value > 0 for _, value in eq.alignment_rows(self.rows, self._xy(q), cs, sn))

    def phi_s(self, q: np.ndarray, s: np.ndarray) -> list:
        """:meth:`Model.phi_s` at one step, as a list (nd,)."""
        cs, sn = np.cos(s).tolist(), np.sin(s).tolist()
        return list(eq.phi_s_rows(self.rows, self._xy(q), s.tolist(), cs, sn))

    def fd_jac(self, q: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Return Phi_q (m, n) by central differences (step cbrt(eps) x the size): the
        ``jacobian = "finite_difference"`` knob."""
        h = np.cbrt(np.finfo(float).eps) * self.model.size
        cols = []
        for k in range(self.n):
            dq = np.zeros(self.n)
            dq[k] = h
            cols.append((self.phi(q + dq, s) - self.phi(q - dq, s)) / (2 * h))
        return np.stack(cols, axis=1) if cols else np.zeros((self.m, 0))

    def newton(self, q: np.ndarray, s: np.ndarray, tol_abs: float, max_iter: int,
               jacobian: str = "analytic"):
        """:func:`linkpipe.kinematics.newton.iterate` at one step (q (n,), s (nd,)); returns
        (q (1, n), residual (1,), iterations (1,), converged (1,))."""
        jac = self.jac if jacobian == "analytic" else self.fd_jac

        def residual(qc):
            return self.phi(qc, s)

        def correction(qc, F):
            if self.lu is not None and jacobian == "analytic":
                return self.lu.factor(qc, s).solve(-F)
            return lin_solve(jac(qc, s)[None], -F[None])[0]

        q, res, its, conv = iterate(residual, correction, np.array(q, dtype=float).reshape(-1),
                                    tol_abs, max_iter, self.model.size, layout=ONE)
        return (q[None], np.array([res]), np.array([its], dtype=np.int32), np.array([conv]))


def _step_kernels(model: Model) -> _Step:
    """Return the model's one-step kernels (built once per model, kept beside it)."""
    return derived(model, "step_kernels", _Step, content_key(model))
