"""The branch (sign) of each two-root dyad of the fast path, taken from a configuration.

:func:`branch_value` is written on stacks: ``X`` (..., n_points, 2) and ``s`` (..., nd) give
one value per configuration (a study's variants at their first step: :mod:`.pivots`)."""
from __future__ import annotations

import numpy as np

from .decompose import Dyad, DyadChain, Line

BRANCH_MARGIN = 2.0  # a dyad's roots must stay this many steps' motion apart (see branch_check)


def set_branches(plan: DyadChain, X0: np.ndarray, s0: np.ndarray) -> None:
    """Take each dyad's branch (sign) from the configuration ``X0`` (n_points, 2) at driver values s0."""
    size = plan.model.size
    for st in plan.steps:
        val = branch_value(st, X0, s0)
        if val is None:
            continue
        st.sign = 1.0 if val >= 0 else -1.0
        st.ambiguous = bool(abs(val) <= 1e-9 * size)


def refine_branches(plan: DyadChain, X0: np.ndarray, s0: np.ndarray, X1: np.ndarray,
                    s1: np.ndarray) -> None:
    """Re-take the sign of each dyad that starts nearer its singular shape than one step's change.

    ``X1`` at ``s1``: a prediction of the next step along the path the start came by (see
    :func:`linkpipe.kinematics.start_state`). A dyad whose side at ``X0`` is smaller than the
    change of that side over the step starts on (or next to) its singular shape, where the
    start's own side is rounding; the predicted step is on the branch the path continues on.
    Such dyads are marked ambiguous (``method = "auto"`` leaves those sweeps to Newton)."""
    for st in plan.steps:
        v0 = branch_value(st, X0, s0)
        if v0 is None:
            continue
        v1 = branch_value(st, X1, s1)
        if abs(v0) <= abs(v1 - v0):
            st.sign = 1.0 if v1 >= 0 else -1.0
            st.ambiguous = True


def branch_value(st: Dyad, X: np.ndarray, s: np.ndarray):
    """Return the signed side of a two-root dyad's point at configuration X (n_points, 2), s
    (nd,), or at a stack of them (..., n_points, 2), (..., nd) -> (...); None: no branches.
    Its absolute value is half the distance between the dyad's two roots."""
    p = st.targets[0]
    if st.kind == "circles":
        d = X[..., st.c2, :] - X[..., st.c1, :]
        r = X[..., p, :] - X[..., st.c1, :]
        return (d[..., 0] * r[..., 1] - d[..., 1] * r[..., 0]) / np.maximum(
            np.hypot(d[..., 0], d[..., 1]), 1e-300)
    if st.kind == "circle_line":
        _, t = line_at(st.line1, X, s)
        r = X[..., p, :] - X[..., st.c1, :]
        return r @ t if t.ndim == 1 else r[..., 0] * t[..., 0] + r[..., 1] * t[..., 1]
    return None


def line_at(line: Line, X: np.ndarray, s: np.ndarray):
    """Return (point on the line, unit direction) at one configuration (or a stack of them,
    as :func:`branch_value`)."""
    if line.kind == "fixed":
        return np.array(line.o), np.array(line.t)
    if line.kind == "coord":
        o = np.zeros(np.shape(s)[:-1] + (2,))
        o[..., line.axis] = s[..., line.driver]
        return o, np.array(line.t)
    d = X[..., line.e, :] - X[..., line.d, :]
    return X[..., line.d, :], d / np.hypot(d[..., 0], d[..., 1])[..., None]
