"""The one Newton loop: every path's Newton-Raphson iterations, with one set of rules.

The sequential continuation iterates one step at a time on the float kernels
(:meth:`linkpipe.kinematics.step._Step.newton`); the vectorised path refines thousands of
steps at once on the sparse engine (:func:`linkpipe.kinematics.vectorised._newton_soa`). Both
run :func:`iterate`, which holds every problem to the same rules:

* converged: the residual ``max |Phi|`` is at most ``tol_abs`` (with ``polish``: and the last
  correction is below ``POLISH_STEP`` of the size, one more quadratic step once the tolerance
  is met: the batched refinement has no later polish of its own);
* given up: a residual that is not finite, or ``NEWTON_STALL`` iterations without progress (a
  new best residual, or half the previous one): Newton wandering where there is no solution;
* a correction longer than ``STEP_CAP`` of the size is shortened to it (a step near a fold
  must not jump across the mechanism);
* at most ``max_iter`` corrections.

Like the equations (:mod:`linkpipe.model.equations`), the loop is written once and evaluated
in two layouts: :data:`ONE` (one problem, its bookkeeping on Python floats: numpy's per-call
overhead would dominate a step of a few rows) and :data:`COLUMNS` (one problem per column of
``q`` (n, k), bookkeeping on (k,) arrays).
"""
from __future__ import annotations

import math

import numpy as np

NEWTON_STALL = 8  # Newton iterations without a new best residual before a step is given up
STEP_CAP = 0.5  # the longest correction, as a part of the mechanism's size
POLISH_STEP = 1e-8  # with polish: go on while the last correction exceeds this part of the size


class _One:
    """One problem: q (n,), Phi (m,); the bookkeeping on Python floats and bools."""

    @staticmethod
    def full(q, value):
        return value

    @staticmethod
    def max_abs(a, q):
        return float(np.abs(a).max()) if a.shape[0] else 0.0

    @staticmethod
    def where(cond, a, b):
        return a if cond else b

    @staticmethod
    def fmin(a, b):
        return b if b < a else a  # a NaN b does not replace a

    not_ = staticmethod(lambda x: not x)
    isfinite = staticmethod(math.isfinite)
    any = staticmethod(bool)

    @staticmethod
    def add(q, dq, active):
        return q + dq if active else q


class _Columns:
    """Problems in the columns of q (n, k), Phi (m, k); bookkeeping on (k,) arrays."""

    @staticmethod
    def full(q, value):
        return np.full(q.shape[1], value)

    @staticmethod
    def max_abs(a, q):
        return _colmax(np.abs(a)) if a.shape[0] else np.zeros(q.shape[1])

    where = staticmethod(np.where)
    fmin = staticmethod(np.fmin)
    not_ = staticmethod(np.logical_not)
    isfinite = staticmethod(np.isfinite)
    any = staticmethod(np.any)

    @staticmethod
    def add(q, dq, active):
        if active.all():
            q += dq
        else:
            q[:, active] += dq[:, active]
        return q


ONE, COLUMNS = _One(), _Columns()


def iterate(residual, correction, q: np.ndarray, tol_abs: float, max_iter: int, size: float,
            polish: bool = False, layout=COLUMNS):
    """Newton from ``q`` ((n,) with :data:`ONE`; (n, k), one problem per column, with
    :data:`COLUMNS`, updated in place). ``residual(q) -> Phi`` ((m,) or (m, k));
    ``correction(q, Phi) -> dq``, the solution of ``Phi_q dq = -Phi`` (NaN where none).
    Returns (q, residual, iterations, converged): floats and bools with ONE, (k,) arrays with
    COLUMNS.
    """
    ops = layout
    its = stall = ops.full(q, 0) if ops is ONE else np.zeros(q.shape[1], dtype=np.int32)
    best = prev = step = res = ops.full(q, np.inf)
    active = ops.full(q, True)
    cap, small = STEP_CAP * size, POLISH_STEP * size
    for it in range(max_iter + 1):
        F = residual(q)
        res = ops.max_abs(F, q)
        progress = (res < best) | (res < 0.5 * prev)
        stall = ops.where(progress, 0, stall + 1)
        best = ops.fmin(best, res)
        prev = res
        done = ops.not_(res > tol_abs)
        if polish:
            done = done & ops.not_(step > small)
        active = active & ops.not_(done | ops.not_(ops.isfinite(res)) | (stall >= NEWTON_STALL))
        if it == max_iter or not ops.any(active):
            break
        dq = correction(q, F)
        big = ops.max_abs(dq, q)
        over = big > cap
        if ops.any(over):
            dq = dq * ops.where(over, cap / ops.where(over, big, 1.0), 1.0)
            big = ops.where(over, cap, big)
        q = ops.add(q, dq, active)
        step = ops.where(active, big, 0.0)
        its = its + active
    return q, res, its, res <= tol_abs


def _colmax(a: np.ndarray) -> np.ndarray:
    """Return ``a.max(axis=0)`` of a (m, k) array (NaN propagates) row by row: no strided reduce."""
    out = a[0].copy()
    for row in a[1:]:
        np.maximum(out, row, out=out)
    return out
