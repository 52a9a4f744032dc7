"""The drawing assembled at its own driver values: the scene's start configuration where its
points are a guess (the start's carry, link angles' whole turns, springs' preloads)."""
from __future__ import annotations

import numpy as np

from ..cache import derived
from ..model import Model, content_key
from .roots import newton
from .step import _step_kernels


def assembled_drawing(model: Model) -> np.ndarray | None:
    """The drawing assembled (n_points, 2): Newton from the drawn pose at the driver values the
    drawing itself has (fixed points as drawn), computed once per model; None without unknowns
    or drivers, or where the drawing does not assemble at its own driver values (the start is
    then solved at the sweep's first values directly). The scene's "start configuration" where
    its points are a guess: a spring's ``preload`` is its tension here."""
    return derived(model, "assembled_drawing", _assembled_drawing, content_key(model))


def drawn_start(model: Model):
    """``(q0 (1, n_q), drawn driver values (nd,))`` of the drawing as written, the start of
    every assembly of it; None without unknowns or drivers, or where the drawing gives no
    finite driver value."""
    if not model.n_q or not model.n_drivers:
        return None
    X0 = model.start_position[None]
    drawn = model.driver_values_at(X0)[0]
    if not np.isfinite(drawn).all():
        return None
    return model.q_of(X0), drawn


def _assembled_drawing(model: Model) -> np.ndarray | None:
    start = drawn_start(model)
    if start is None:
        return None
    q0, drawn = start
    tol_abs = model.tolerance()
    fast = _step_kernels(model)
    q, _, _, conv = (fast.newton(q0[0], drawn, tol_abs, 50) if fast is not None
                     else newton(model, q0, drawn[None], tol_abs, 50))
    if not conv[0]:
        return None
    X = model.positions(np.asarray(q, dtype=float).reshape(1, -1))[0]
    X.setflags(write=False)
    return X
