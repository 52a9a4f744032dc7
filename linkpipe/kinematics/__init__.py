"""Stage 1: solve a mechanism over its whole sweep (positions, velocities, accelerations).

One entry, :func:`solve_sweep`, and the registry :data:`METHODS` of the paths it may take
(``[solver] method``: "auto" takes the closed-form dyads where the scene decomposes and every
dyad stays clear of its singular shape, else the vectorised Newton path). Modules:
:mod:`.dyads` (closed-form fast path), :mod:`.vectorised` (coarse continuation + batched
Newton), :mod:`.continuation` (step by step), :mod:`.start` (the first step), :mod:`.newton`
(Newton and the rescues), :mod:`.step` (one-step float kernels), :mod:`.linalg` (sparse and
dense solves, condition), :mod:`.derivatives` (velocities, accelerations, link rates).
"""
from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..model import Model
from .dyads import branch_check, decompose, refine_branches, set_branches, solve_chain
from .start import start_state
from .vectorised import max_abs_phi, solve_newton
from ..status import NO_ASSEMBLY, OK


def solve_sweep(model: Model, s: np.ndarray, s_dot: np.ndarray, s_ddot: np.ndarray, order: int = 0):
    """Solve a sweep's positions (and, on the dyad path, velocities/accelerations) by the scene's method.

    ``[solver] method``: ``auto`` takes the closed-form dyads when the scene decomposes and
    :func:`linkpipe.branch_check` finds that they follow Newton's branch, else the
    general path; ``newton`` the general path (:func:`solve_newton`); ``dyads`` requires the
    fast path (SceneError when the scene does not decompose). Returns a dict: position
    (S, n_points, 2) NaN at failed steps, residual, iterations, status, method ("dyads" or
    "newton"), note (why auto chose what it chose), and on the dyad path velocity and
    acceleration (order >= 1, 2) or None.
    """

    sc = model.scene.solver
    method = sc.method
    note = ""
    S = s.shape[0]
    start = None  # the start state, once assembled (the Newton path reuses it)
    if method in ("auto", "dyads"):
        plan = decompose(model)
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
            start = start_state(model, s[0], tol_abs, sc.max_iter)
            q0, slope0 = start
            set_branches(plan, model.positions(q0[None])[0], s[0])
            if slope0 is not None and S > 1:
                # a start on a dyad's singular shape (a change point) takes that dyad's sign a
                # step along the path the drawing was carried on
                q1 = q0 + slope0 @ (s[1] - s[0])
                refine_branches(plan, model.positions(q0[None])[0], s[0],
                                      model.positions(q1[None])[0], s[1])
            sw = solve_chain(plan, s, s_dot, s_ddot, order=order, gaps=method == "auto",
                             max_abs_phi=max_abs_phi(model))
            if method == "dyads" or branch_check(plan, sw):
                X = sw.position
                residual = sw.residual
                ok = sw.ok
                bad = ok & ~(residual <= 10 * tol_abs)  # a redundant constraint not met
                if bad.any():
                    X[np.ix_(bad, model.moving)] = np.nan
                    for arr in (sw.velocity, sw.acceleration):
                        if arr is not None:
                            arr[np.ix_(bad, model.moving)] = np.nan
                status = np.where(ok & ~bad, OK, NO_ASSEMBLY).astype(np.int8)
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


from .derivatives import (dense_derivatives, derivatives, driver_motion, fd_derivatives,  # noqa: E402
                          link_angles_unwrapped, link_rates)
from .newton import newton  # noqa: E402
from .continuation import solve_positions  # noqa: E402
