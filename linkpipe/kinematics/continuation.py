"""The sequential continuation: the sweep step by step, from a predicted start (the previous
step's position plus its velocity times the driver increment), so the solver stays on the
assembly branch it starts on. A step that cannot be solved gets NaN and a status; the sweep
goes on."""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..status import NO_ASSEMBLY, NOT_CONVERGED
from .linalg import _cond_inverse, _lin_solve, jacobian_condition
from .newton import _classify_failure, _converging_at_cap, _lm_root, _mirror_root, _null_line_roots, _polish, aim_drivers, drivers_aligned, newton
from .start import start_state
from .step import _step_kernels


SUBSTEPS, SUBDIVIDE = 8, 2  # a failing step's retry: 8 sub-steps, at most 2 levels deep


def solve_positions(model: Model, s: np.ndarray, tol: float | None = None,
                    max_iter: int | None = None, predictor: str | None = None,
                    jacobian: str | None = None, q_start: np.ndarray | None = None,
                    start_slope: np.ndarray | None = None, stop_on_failure: bool = False,
                    subdivide: int = SUBDIVIDE):
    """Solve every step's positions in sweep order with branch-keeping continuation.

    ``s`` (S, nd) driver values in internal units. Returns q (S, n_q) with NaN rows at failed
    steps, residual (S,), iterations (S,), status (S,) int8 (OK / NO_ASSEMBLY / NOT_CONVERGED).
    ``predictor`` is "none", "first" (q + dq/ds * ds) or "second" (adds the curvature term).
    ``q_start`` (n_q,): continue from this assembled configuration instead of assembling the
    scene's start (the vectorised general path re-runs single intervals of a sweep this way),
    with ``start_slope`` (n_q, nd) as the first predictor's dq/ds (see :func:`start_state`).
    ``stop_on_failure``: return at the first step that fails (the rest stay NaN, status 0).
    ``subdivide``: how many levels of ``SUBSTEPS`` sub-steps a step that fails right after an
    assembled one is retried in before it counts as failed.

    After a step without assembly the next one starts by damped least squares from the last
    assembled shape (a gap in the assembly range); after a not_converged step (``max_iter``
    reached on a step that has a root) the sweep predicts on from the root that told the two
    failures apart, with the slope from before: a low cap costs steps, and the step it stopped
    is reported as not_converged, never finished by other iterations.
    """
    sc = model.scene.solver
    tol = sc.tol if tol is None else tol
    max_iter = sc.max_iter if max_iter is None else max_iter
    predictor = sc.predictor if predictor is None else predictor
    jacobian = sc.jacobian if jacobian is None else jacobian
    tol_abs = tol * model.size
    S = s.shape[0]
    nq = model.n_q
    q = np.full((S, nq), np.nan)
    residual = np.full(S, np.nan)
    iterations = np.zeros(S, dtype=np.int32)
    status = np.zeros(S, dtype=np.int8)

    if q_start is None:
        q_start, start_slope = start_state(model, s[0], tol_abs, max_iter)
    last_q = q_start
    last_s = s[0]
    # dq/ds along the sweep (n_q, nd); without a predictor the start slope is not used either
    # (a singular start is then left by trying either side, below)
    last_dq = start_slope if predictor != "none" else None
    last_d2q = None
    rcond = model.scene.solver.singular_rcond
    square = model.n_rows == nq
    # one-step kernels: the same Newton, Phi and checks with less overhead per step
    # (the finite-difference Jacobian knob changes Newton's iteration matrix only: the condition
    # and the slopes below use the analytic one either way)
    fast = _step_kernels(model) if nq else None
    last_sign = 0.0  # sign of det(Phi_q) at the last regular step: the assembly mode
    gap = False  # a failed step since the last assembled one
    mode_pending = False  # a failed step since the last regular one: its mode to be kept
    gap_shape = None  # least-squares shape of the last failed step
    for i in range(S):
        ds = s[i] - last_s
        guess = last_q.copy()
        if predictor != "none" and last_dq is not None:
            guess += last_dq @ ds
            if predictor == "second" and last_d2q is not None:
                guess += 0.5 * np.einsum("qij,i,j->q", last_d2q, ds, ds)
        if last_dq is None:
            guess = aim_drivers(model, guess, s[i])
        it_lm = 0
        if gap and nq:
            # after a failed step most steps fail too: damped least squares, which stops as soon
            # as the residual stops falling, decides first (Newton only polishes a root it finds).
            # It starts from the last assembled shape and, failing that, from the previous
            # step's least-squares shape, which moves on through the gap and may become a root
            # where the sweep re-enters the range (either can sit in a local minimum alone)
            q_lm, r_lm, it_lm = _lm_root(model, guess, s[i], tol_abs)
            if not r_lm <= 10 * tol_abs and gap_shape is not None:
                q2, r2, it2 = _lm_root(model, aim_drivers(model, gap_shape, s[i]), s[i], tol_abs)
                it_lm += it2
                if r2 < r_lm or not np.all(np.isfinite(q_lm)):
                    q_lm, r_lm = q2, r2
            if np.all(np.isfinite(q_lm)):
                gap_shape = q_lm
            if not r_lm <= 10 * tol_abs:
                residual[i], iterations[i], status[i] = r_lm, it_lm, NO_ASSEMBLY
                continue
            guess = q_lm
        conv = np.zeros(1, dtype=bool)
        iterations[i] = it_lm
        if last_dq is None and not gap and nq and np.any(s[i] != last_s):
            # leaving a singular shape without a slope (a start at a dead centre or change
            # point): which side Newton takes from it is up to rounding, so start on either side
            # of it instead, the side nearer the start configuration as written first
            Jg = model.jacobian(model.positions(last_q[None]), s[i][None])
            if not jacobian_condition(Jg)[0] * rcond < 1.0:
                v, roots = _null_line_roots(model, last_q[None], s[i])
                written = model.q_of(model.start_position[None])[0]
                for t in sorted(roots, key=lambda t: np.abs(last_q + t * v - written).max()):
                    qc, res, itc, convc = newton(model, (last_q + t * v)[None], s[i][None], tol_abs,
                                                 max_iter, jacobian)
                    iterations[i] += itc[0]
                    residual[i] = res[0]
                    if convc[0] and drivers_aligned(model, qc, s[i][None])[0]:
                        qi, conv = qc, convc
                        break
        capped = False  # Newton reached max_iter while converging (see _converging_at_cap)
        if not conv[0]:
            if fast is not None:
                qi, res, it, conv = fast.newton(guess, s[i], tol_abs, max_iter, jacobian)
            else:
                qi, res, it, conv = newton(model, guess[None], s[i][None], tol_abs, max_iter, jacobian)
            residual[i] = res[0]
            iterations[i] += it[0]
            capped = _converging_at_cap(model, fast, guess, s[i], it[0], res[0], conv[0], max_iter)
            if conv[0] and not (fast.aligned(qi[0], s[i]) if fast is not None
                                else drivers_aligned(model, qi, s[i][None])[0]):
                # the angle constraint's other root (vector pointing backwards): not this step's
                # mechanism; retry with the driven point aimed along the driven direction
                qi, res, it2, conv = newton(model, aim_drivers(model, guess, s[i])[None],
                                            s[i][None], tol_abs, max_iter, jacobian)
                iterations[i] += it2[0]
                residual[i] = res[0]
                conv = conv & drivers_aligned(model, qi, s[i][None])
                capped = _converging_at_cap(model, fast, aim_drivers(model, guess, s[i]), s[i],
                                            it2[0], res[0], conv[0], max_iter)
        lm_residual = None
        if not conv[0] and nq and not capped:
            # Newton gave up (it stalled, failed, or wandered to the cap): slow or wandering at
            # a singular root, or no root at all. Damped least squares from the same guess tells
            # which, and reaches a singular root. A Newton run that reached max_iter while
            # converging is not rescued this way: the step is not_converged, as max_iter says.
            q_lm, lm_residual, it_lm = _lm_root(model, guess, s[i], tol_abs)
            iterations[i] += it_lm
            if lm_residual <= tol_abs and drivers_aligned(model, q_lm[None], s[i][None])[0]:
                qi, conv, residual[i] = q_lm[None], np.ones(1, dtype=bool), lm_residual
        if not conv[0] and nq and not gap and subdivide > 0 and i > 0:
            # failing from an assembled step, the step may just be too long for the continuation
            # (a dyad that moves fast there): retry it in sub-steps (each Newton run capped at
            # max_iter too) before calling it a failure
            sub = last_s + np.linspace(0.0, 1.0, SUBSTEPS + 1)[:, None] * (s[i] - last_s)
            sub[-1] = s[i]
            qs, rs, its, _ = solve_positions(model, sub, tol, max_iter, predictor, jacobian,
                                             q_start=last_q, start_slope=last_dq,
                                             stop_on_failure=True, subdivide=subdivide - 1)
            iterations[i] += int(its.sum())
            if np.isfinite(qs[-1]).all() and rs[-1] <= tol_abs:
                qi, conv, residual[i] = qs[-1][None], np.ones(1, dtype=bool), rs[-1]
                lm_residual, capped = None, False
        if conv[0]:
            X = None if fast is not None else model.positions(qi)
            J = fast.jac(qi[0], s[i])[None] if fast is not None else model.jacobian(X, s[i][None])
            inv = None
            if fast is not None and square:
                cond, inv = _cond_inverse(J[0])
            else:
                cond = jacobian_condition(J)[0]
            if not cond * rcond < 1e-3:
                # within 1000 of the singular threshold: at a double root Newton stops at tol on
                # a slow (linear) approach, with the Jacobian less singular than at the root;
                # iterate on to rounding level before deciding
                qi, residual[i], extra = _polish(model, qi, s[i], max_iter)
                iterations[i] += extra
                X = model.positions(qi)
                J = model.jacobian(X, s[i][None])
                cond, inv = jacobian_condition(J)[0], None
            regular = bool(cond * rcond < 1.0)  # as dense_derivatives() decides
            if square and regular and mode_pending and last_sign:
                # re-entering after a gap: no path connects the two sides, so keep the assembly
                # mode (sign of det Phi_q) of the last regular step, if it exists here
                if np.linalg.slogdet(J[0])[0] != last_sign:
                    def same_mode(qq, si=s[i]):
                        Jq = model.jacobian(model.positions(qq), si[None])
                        return bool(np.linalg.slogdet(Jq[0])[0] == last_sign
                                    and jacobian_condition(Jq)[0] * rcond < 1.0)

                    alt, extra = _mirror_root(model, qi, s[i], tol_abs, max_iter, jacobian,
                                              same_mode, guesses=(guess,))
                    iterations[i] += extra
                    if alt is not None:
                        qi, X = alt, model.positions(alt)
                        J = model.jacobian(X, s[i][None])
                        inv = None
                        residual[i] = float(np.abs(model.phi(X, s[i][None])).max())
            gap, gap_shape = False, None
            if cond * rcond < 1e-4:
                # well clear of a limit (condition below 100 at the default rcond): the mode is
                # settled. A re-entry on or next to the limit
                # (its two modes about to meet) leaves the check to the steps after it
                mode_pending = False
            if square and regular:
                last_sign = np.linalg.slogdet(J[0])[0]
            q[i] = qi[0]
            # influence coefficients dq/ds_j, one column per driver
            if inv is not None:
                # Phi_q dq_j = -Phi_t with unit rate of driver j: only driver row j is non-zero
                ps = fast.phi_s(qi[0], s[i])
                dq = inv[:, fast.nc:] * -np.array(ps)[None, :]
            else:
                if X is None:
                    X = model.positions(qi)
                cols = []
                for j in range(model.n_drivers):
                    e = np.zeros((1, model.n_drivers))
                    e[0, j] = 1.0
                    cols.append(_velocity_one(model, X, s[i][None], e, J))
                dq = np.stack(cols, axis=1)
            if regular and np.all(np.isfinite(dq)) and np.abs(dq).max() < 1e8 * model.size:
                if predictor == "second":
                    # curvature along the sweep: gamma with unit driver rate, zero acceleration
                    if X is None:
                        X = model.positions(qi)
                    d2 = np.zeros((nq, model.n_drivers, model.n_drivers))
                    for j in range(model.n_drivers):
                        e = np.zeros((1, model.n_drivers))
                        e[0, j] = 1.0
                        V = model.velocities(dq[:, j][None])
                        g = model.gamma(X, V, s[i][None], e, np.zeros_like(e))
                        d2[:, j, j] = _lin_solve(J, g)[0]
                    last_d2q = d2
                last_dq = dq
            # else a singular step (change point, dead centre): its tangent is undefined, so keep
            # the slope from before it; predicting across with that slope keeps the branch
            last_q, last_s = qi[0], s[i]
        else:
            root = None
            if lm_residual is None:
                tries = (guess, qi, last_q) if capped else (guess,)
                status[i], root = _classify_failure(model, tries, s[i], tol_abs)
            else:
                status[i] = NOT_CONVERGED if lm_residual <= 10 * tol_abs else NO_ASSEMBLY
            if stop_on_failure:
                break
            if status[i] == NOT_CONVERGED and capped:
                # a root exists, the cap stopped Newton: the step stays not_converged (NaN), and
                # the sweep goes on predicting from that root (found to tell the two failures
                # apart) with the slope from before, not by a least-squares restart
                if root is not None:
                    last_q, last_s = root, s[i]
                continue
            gap = mode_pending = True
            if lm_residual is not None and np.all(np.isfinite(q_lm)):
                gap_shape = q_lm
            last_dq, last_d2q = None, None  # after a gap, restart from the last assembled shape
    return q, residual, iterations, status


def _velocity_one(model, X, s, s_dot, J=None):
    """Return qdot (n_q,) at one step (for the predictor)."""
    if J is None:
        J = model.jacobian(X, s)
    rhs = -model.phi_t(X, s, s_dot)
    return _lin_solve(J, rhs)[0]
