"""The sequential continuation: the sweep step by step, from a predicted start (the previous
step's position plus its velocity times the driver increment), so the solver stays on the
assembly branch it starts on. A step that cannot be solved gets NaN and a status; the sweep
goes on."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Model
from ..status import NO_ASSEMBLY, NOT_CONVERGED
from .linalg import EXACT_WITHIN, MODE_SETTLED_BELOW, POLISH_FROM, POLISH_WITHIN, condition, condition_and_inverse_one, is_singular, lin_solve
from .roots import _classify_failure, _converging_at_cap, _lm_root, _mirror_root, _null_line_roots, _polish, aim_drivers, drivers_aligned, newton
from .sparse_lu import StepFactor
from .step import _step_kernels


SUBSTEPS, SUBDIVIDE = 8, 2  # a failing step's retry: 8 sub-steps, at most 2 levels deep
CLASSIFY_ITER = 10  # Newton iterations past a capped run that look for its root (not counted)


def solve_positions(model: Model, s: np.ndarray, q_start: np.ndarray,
                    start_slope: np.ndarray | None = None, tol: float | None = None,
                    max_iter: int | None = None, predictor: str | None = None,
                    jacobian: str | None = None, stop_on_failure: bool = False,
                    subdivide: int = SUBDIVIDE, skip: np.ndarray | None = None):
    """Solve every step's positions in sweep order with branch-keeping continuation.

    ``s`` (S, nd) driver values in internal units. Returns q (S, n_q) with NaN rows at failed
    steps, residual (S,), iterations (S,), status (S,) int8 (OK / NO_ASSEMBLY / NOT_CONVERGED).
    ``predictor`` is "none", "first" (q + dq/ds * ds) or "second" (adds the curvature term).
    ``q_start`` (n_q,): the assembled configuration at ``s[0]`` the sweep continues from (the
    scene's start: :func:`linkpipe.kinematics.start.start_state`; the vectorised general path
    re-runs single intervals of a sweep from one of its steps), with ``start_slope`` (n_q, nd)
    as the first predictor's dq/ds (None: none known).
    ``stop_on_failure``: return at the first step that fails (the rest stay NaN, status 0).
    ``subdivide``: how many levels of ``SUBSTEPS`` sub-steps a step that fails right after an
    assembled one is retried in before it counts as failed.

    ``skip`` (S,) bool: steps known not to assemble (the closed-form dyads'
    :func:`linkpipe.kinematics.beyond_reach`): inside a gap they are no_assembly without a
    solve (0 iterations; the residual max |Phi| of the gap's last least-squares shape at the
    step's driver values), except the last one before a step that may assemble,
    whose damped least squares carries the gap's shape up to it, as every step's did before.

    After a step without assembly the next one starts by damped least squares from the last
    assembled shape (a gap in the assembly range); after a not_converged step (``max_iter``
    reached on a step that has a root) the sweep predicts on from the root that told the two
    failures apart, with the slope from before: a low cap costs steps, and the step it stopped
    is reported as not_converged, never finished by other iterations.
    """
    sc = model.scene.solver
    run = _Continuation(model, sc.tol if tol is None else tol,
                        sc.max_iter if max_iter is None else max_iter,
                        sc.predictor if predictor is None else predictor,
                        sc.jacobian if jacobian is None else jacobian, subdivide)
    return run.sweep(s, q_start, start_slope, stop_on_failure, skip)


@dataclass
class _Path:
    """What the continuation carries from step to step: the last assembled shape ``q`` (n_q,)
    at driver values ``s`` (nd,), its slope ``dq`` (n_q, nd) and curvature ``d2q`` (None: not
    known), the assembly mode ``sign`` (sign of det Φq at the last regular step), whether a
    step failed since the last assembled one (``gap``) or since the last regular one
    (``mode_pending``: its mode to be kept), and the least-squares shape of the last failure."""

    q: np.ndarray
    s: np.ndarray
    dq: np.ndarray | None
    d2q: np.ndarray | None = None
    sign: float = 0.0
    gap: bool = False
    mode_pending: bool = False
    gap_shape: np.ndarray | None = None


@dataclass
class _Attempt:
    """One step's solve: its predicted ``guess``, the root ``q`` (1, n_q) once ``converged``,
    the residual and iterations so far, whether Newton reached ``max_iter`` while converging
    (``capped``), and the damped least squares' residual and shape where that ran."""

    guess: np.ndarray
    q: np.ndarray | None = None
    converged: bool = False
    residual: float = np.nan
    iterations: int = 0
    capped: bool = False
    guess_residual: float = np.nan
    lm_residual: float | None = None
    q_lm: np.ndarray | None = None


#: a drawing within this fraction of the mechanism's size of the singular shape it starts on
#: is on it: it does not say which side the sweep leaves to
ON_THE_SINGULAR_SHAPE = 1e-9


def written_side(model: Model, q: np.ndarray, v: np.ndarray) -> float:
    """+1 or -1: the side of the singular start ``q`` (n_q,) along its null direction ``v``
    that the start configuration is written on; 0 where it is written on the singular shape
    itself (within :data:`ON_THE_SINGULAR_SHAPE` of the size: it does not say)."""
    offset = float((model.q_of(model.start_position[None])[0] - q) @ v) / float(v @ v) ** 0.5
    if abs(offset) > ON_THE_SINGULAR_SHAPE * model.size:
        return 1.0 if offset > 0 else -1.0
    return 0.0


def shape_side(model: Model, candidates: list, s_i) -> int:
    """Which of ``candidates`` (each (q (1, n_q), ...), the roots on either side of a
    singular start drawn on the shape itself) the sweep leaves to: the first where det Phi_q
    is positive (the mode's orientation: unchanged by rotating or moving the drawing or by
    its units, flipped by mirroring it; rounding had decided, and the mode changed with the
    step count and the units), else the first."""
    for k, (qc, *_) in enumerate(candidates):
        J = model.jacobian(model.positions(qc), s_i[None])[0]
        if J.shape[0] == J.shape[1] and np.linalg.det(J) > 0:
            return k
    return 0


class _Continuation:
    """The steps of :func:`solve_positions`: predict, correct, rescue, accept or classify."""

    def __init__(self, model: Model, tol, max_iter, predictor, jacobian, subdivide):
        self.model, self.tol, self.max_iter = model, tol, max_iter
        self.predictor, self.jacobian, self.subdivide = predictor, jacobian, subdivide
        self.tol_abs = model.tolerance(tol)
        self.rcond = model.scene.solver.singular_rcond
        self.square = model.n_rows == model.n_q
        # one-step kernels: the same Newton, Phi and checks with less overhead per step (the
        # finite-difference Jacobian knob changes Newton's iteration matrix only: the
        # condition and the slopes use the analytic one either way)
        self.fast = _step_kernels(model) if model.n_q else None
        # large mechanisms: each step's Phi_q as a sparse LU (sparse_lu; None: dense)
        self.lu = self.fast.lu if self.fast is not None else None

    def sweep(self, s, q_start, start_slope, stop_on_failure, skip=None):
        n_steps, nq = s.shape[0], self.model.n_q
        q = np.full((n_steps, nq), np.nan)
        residual = np.full(n_steps, np.nan)
        iterations = np.zeros(n_steps, dtype=np.int32)
        status = np.zeros(n_steps, dtype=np.int8)
        # without a predictor the start slope is not used either (a singular start is then
        # left by trying either side, in leave_singular_start)
        path = _Path(q_start, s[0], start_slope if self.predictor != "none" else None)
        if skip is not None:  # the last skippable step before one that may assemble is solved
            skip = skip & np.r_[skip[1:], True]
        for i in range(n_steps):
            if skip is not None and skip[i] and path.gap:
                # no_assembly without a solve: 0 iterations, the residual where it stands (the
                # gap's last least-squares shape at this step's driver values)
                status[i], residual[i] = NO_ASSEMBLY, self.standing_residual(path, s[i])
                continue
            att = _Attempt(self.predict(path, s[i]))
            if path.gap and nq and not self.through_gap(att, path, s[i]):
                residual[i], iterations[i], status[i] = att.residual, att.iterations, NO_ASSEMBLY
                continue
            self.leave_singular_start(att, path, s[i])
            if not att.converged:
                self.correct(att, s[i])
            if not att.converged and nq:
                self.rescue(att, path, s[i])
            if att.converged:
                self.accept(att, path, s[i])
                q[i] = att.q[0]
            else:
                status[i] = self.classify(att, path, s[i])
            residual[i], iterations[i] = att.residual, att.iterations
            if not att.converged and stop_on_failure:
                break
        return q, residual, iterations, status

    def standing_residual(self, path: _Path, s_i) -> float:
        """max |Phi| at the gap's last least-squares shape (else the last assembled one) and
        driver values ``s_i``: a skipped step's residual (no iteration moved it)."""
        q = path.gap_shape if path.gap_shape is not None else path.q
        F = (self.fast.phi(q, s_i) if self.fast is not None else
             self.model.phi(self.model.positions(q[None]), s_i[None])[0])
        return float(np.abs(F).max()) if F.size else 0.0

    def predict(self, path: _Path, s_i) -> np.ndarray:
        """The guess: the last shape moved along its slope (and curvature), or aimed."""
        guess = path.q.copy()
        ds = s_i - path.s
        if self.predictor != "none" and path.dq is not None:
            guess += path.dq @ ds
            if self.predictor == "second" and path.d2q is not None:
                guess += 0.5 * np.einsum("qij,i,j->q", path.d2q, ds, ds)
        if path.dq is None:
            guess = aim_drivers(self.model, guess, s_i)
        return guess

    def through_gap(self, att: _Attempt, path: _Path, s_i) -> bool:
        """After a failed step most steps fail too: damped least squares, which stops as soon as
        the residual stops falling, decides first (Newton only polishes a root it finds). It
        starts from the last assembled shape and, failing that, from the previous step's
        least-squares shape, which moves on through the gap and may become a root where the
        sweep re-enters the range (either can sit in a local minimum alone). Returns whether
        the step has a root (then the guess)."""
        model = self.model
        q_lm, r_lm, it_lm = _lm_root(model, att.guess, s_i, self.tol_abs)
        if not r_lm <= 10 * self.tol_abs and path.gap_shape is not None:
            q2, r2, it2 = _lm_root(model, aim_drivers(model, path.gap_shape, s_i), s_i, self.tol_abs)
            it_lm += it2
            if r2 < r_lm or not np.all(np.isfinite(q_lm)):
                q_lm, r_lm = q2, r2
        if np.all(np.isfinite(q_lm)):
            path.gap_shape = q_lm
        att.residual, att.iterations = r_lm, it_lm
        if not r_lm <= 10 * self.tol_abs:
            return False
        att.guess = q_lm
        return True

    def leave_singular_start(self, att: _Attempt, path: _Path, s_i) -> None:
        """Leaving a singular shape without a slope (a start at a dead centre or change point):
        which side Newton takes from it is up to rounding, so start on either side of it
        instead: the side the start configuration is written on (:func:`written_side`), or,
        drawn on the shape itself, the side :func:`shape_side` picks."""
        model = self.model
        if not (path.dq is None and not path.gap and model.n_q and np.any(s_i != path.s)):
            return
        Jg = model.jacobian(model.positions(path.q[None]), s_i[None])
        if not is_singular(condition(Jg)[0], self.rcond):
            return
        v, roots = _null_line_roots(model, path.q[None], s_i)
        side = written_side(model, path.q, v)
        found = []
        for t in sorted(roots, key=lambda t: -t * side):
            qc, res, itc, convc = newton(model, (path.q + t * v)[None], s_i[None], self.tol_abs,
                                         self.max_iter, self.jacobian)
            att.iterations += itc[0]
            att.residual = res[0]
            if convc[0] and drivers_aligned(model, qc, s_i[None])[0]:
                found.append((qc, res[0]))
                if side:  # the side written
                    break
        if found:
            qc, att.residual = found[shape_side(model, found, s_i) if not side else 0]
            att.q, att.converged = qc, True

    def correct(self, att: _Attempt, s_i) -> None:
        """Newton from the guess; a root with an angle driver's vector pointing backwards (the
        angle constraint's other root) is retried with the driven point aimed forwards."""
        model, fast, tol_abs, max_iter = self.model, self.fast, self.tol_abs, self.max_iter
        if fast is not None:
            qi, res, it, conv = fast.newton(att.guess, s_i, tol_abs, max_iter, self.jacobian)
        else:
            qi, res, it, conv = newton(model, att.guess[None], s_i[None], tol_abs, max_iter,
                                       self.jacobian)
        att.q, att.residual, att.converged = qi, res[0], bool(conv[0])
        att.iterations += it[0]
        att.capped, att.guess_residual = _converging_at_cap(model, fast, att.guess, qi, s_i, it[0],
                                                            res[0], conv[0], max_iter)
        aligned = (fast.aligned(qi[0], s_i) if fast is not None
                   else drivers_aligned(model, qi, s_i[None])[0])
        if att.converged and not aligned:
            aimed = aim_drivers(model, att.guess, s_i)
            qi, res, it2, conv = newton(model, aimed[None], s_i[None], tol_abs, max_iter,
                                        self.jacobian)
            att.iterations += it2[0]
            att.q, att.residual = qi, res[0]
            att.converged = bool((conv & drivers_aligned(model, qi, s_i[None]))[0])
            att.capped, att.guess_residual = _converging_at_cap(
                model, fast, aimed, qi, s_i, it2[0], res[0], att.converged, max_iter)

    def rescue(self, att: _Attempt, path: _Path, s_i) -> None:
        """Newton gave up (it stalled, failed, or wandered to the cap): slow or wandering at a
        singular root, or no root at all. Damped least squares from the same guess tells which,
        and reaches a singular root (not after a run that reached max_iter while converging:
        that step is not_converged). Failing right after an assembled step, the step may just be
        too long for the continuation: it is retried in sub-steps, each Newton run in them
        capped at max_iter as well. After a capped run only where the guess was no prediction:
        farther from the constraints than the mechanism's own size (a predictor that overshot,
        next to a limit); a capped run from a real prediction is the cap's doing."""
        model = self.model
        if att.capped and not att.guess_residual > model.size:
            return
        if not att.capped:
            att.q_lm, att.lm_residual, it_lm = _lm_root(model, att.guess, s_i, self.tol_abs)
            att.iterations += it_lm
            if (att.lm_residual <= self.tol_abs
                    and drivers_aligned(model, att.q_lm[None], s_i[None])[0]):
                att.q, att.converged, att.residual = att.q_lm[None], True, att.lm_residual
                return
        if path.gap or self.subdivide <= 0 or path.s is None or not np.any(s_i != path.s):
            return
        sub = path.s + np.linspace(0.0, 1.0, SUBSTEPS + 1)[:, None] * (s_i - path.s)
        sub[-1] = s_i
        inner = _Continuation(model, self.tol, self.max_iter, self.predictor, self.jacobian,
                              self.subdivide - 1)
        qs, rs, its, _ = inner.sweep(sub, path.q, path.dq, stop_on_failure=True)
        att.iterations += int(its.sum())
        if np.isfinite(qs[-1]).all() and rs[-1] <= self.tol_abs:
            att.q, att.converged, att.residual = qs[-1][None], True, rs[-1]

    def accept(self, att: _Attempt, path: _Path, s_i) -> None:
        """A converged step: polish it near a singular shape, keep the assembly mode across a
        gap, and move the path on (with the step's slope where the step is regular)."""
        model = self.model
        # a sparse step's condition is estimated, exact near the thresholds decided below
        qi, J, cond, inv = att.q, *self._condition(att.q, s_i, path.mode_pending)
        if is_singular(cond, self.rcond, POLISH_FROM):
            # within 1000 of the singular threshold: at a double root Newton stops at tol on a
            # slow (linear) approach, with the Jacobian less singular than at the root;
            # iterate on to rounding level before deciding
            qi, att.residual, extra = _polish(model, qi, s_i, self.max_iter)
            att.iterations += extra
            J = model.jacobian(model.positions(qi), s_i[None])
            cond, inv = condition(J)[0], None
        regular = not is_singular(cond, self.rcond)  # as the derivative stage decides
        if self.square and regular and path.mode_pending and path.sign:
            qi, J, inv = self._keep_mode(att, path, qi, J, inv, s_i)
        path.gap, path.gap_shape = False, None
        if not is_singular(cond, self.rcond, MODE_SETTLED_BELOW):
            # well clear of a limit (condition below 100 at the default rcond): the mode is
            # settled; a re-entry on or next to the limit leaves the check to the steps after it
            path.mode_pending = False
        if self.square and regular:
            path.sign = _det_sign(J)
        att.q = qi
        dq = self._slope(qi, J, inv, s_i)
        if regular and np.all(np.isfinite(dq)) and np.abs(dq).max() < 1e8 * model.size:
            if self.predictor == "second":
                path.d2q = self._curvature(qi, J, dq, s_i)
            path.dq = dq
        # else a singular step (change point, dead centre): its tangent is undefined, so keep
        # the slope from before it; predicting across with that slope keeps the branch
        path.q, path.s = qi[0], s_i

    def _condition(self, qi, s_i, mode_pending: bool):
        """(Φq (1, m, n) or its sparse :class:`StepFactor`, its condition, its inverse or None)
        at a root; a sparse condition is estimated, exact near the thresholds :meth:`accept`
        decides at (the mode's, when one is pending)."""
        fast = self.fast
        if self.lu is not None:
            factor = self.lu.factor(qi[0], s_i)
            threshold, within = ((MODE_SETTLED_BELOW, EXACT_WITHIN) if mode_pending
                                 else (POLISH_FROM, POLISH_WITHIN))
            return factor, factor.condition(self.rcond, threshold, within), None
        if fast is not None:
            J = fast.jac(qi[0], s_i)[None]
        else:
            J = self.model.jacobian(self.model.positions(qi), s_i[None])
        if fast is not None and self.square:
            cond, inv = condition_and_inverse_one(J[0])
            return J, cond, inv
        return J, condition(J)[0], None

    def _keep_mode(self, att: _Attempt, path: _Path, qi, J, inv, s_i):
        """Re-entering after a gap: no path connects the two sides, so keep the assembly mode
        (sign of det Φq) of the last regular step, if it exists here."""
        model = self.model
        if _det_sign(J) == path.sign:
            return qi, J, inv

        def same_mode(qq, si=s_i):
            Jq = model.jacobian(model.positions(qq), si[None])
            return bool(np.linalg.slogdet(Jq[0])[0] == path.sign
                        and not is_singular(condition(Jq)[0], self.rcond))

        alt, extra = _mirror_root(model, qi, s_i, self.tol_abs, self.max_iter, self.jacobian,
                                  same_mode, guesses=(att.guess,))
        att.iterations += extra
        if alt is None:
            return qi, J, inv
        X = model.positions(alt)
        att.residual = float(np.abs(model.phi(X, s_i[None])).max())
        return alt, model.jacobian(X, s_i[None]), None

    def _slope(self, qi, J, inv, s_i) -> np.ndarray:
        """The influence coefficients dq/ds_j (n_q, nd), one column per driver."""
        model = self.model
        if inv is not None:  # Φq dq_j = -Φt with unit rate of driver j: only row j is non-zero
            ps = self.fast.phi_s(qi[0], s_i)
            return inv[:, self.fast.nc:] * -np.array(ps)[None, :]
        X = model.positions(qi)
        return np.stack([_velocity_one(model, X, s_i[None], np.eye(model.n_drivers)[j][None], J)
                         for j in range(model.n_drivers)], axis=1)

    def _curvature(self, qi, J, dq, s_i) -> np.ndarray:
        """d2q/ds2 (n_q, nd, nd) along the sweep: γ with unit driver rate, zero acceleration."""
        model = self.model
        X = model.positions(qi)
        d2 = np.zeros((model.n_q, model.n_drivers, model.n_drivers))
        for j in range(model.n_drivers):
            e = np.zeros((1, model.n_drivers))
            e[0, j] = 1.0
            g = model.gamma(X, model.velocities(dq[:, j][None]), s_i[None], e, np.zeros_like(e))
            d2[:, j, j] = _solve_one(J, g[0])
        return d2

    def classify(self, att: _Attempt, path: _Path, s_i) -> int:
        """A failed step: not_converged where a root exists (the cap stopped Newton), else
        no_assembly; the path goes on from that root, or restarts after the gap."""
        root = None
        if att.capped:
            # Newton was converging when the cap stopped it: a few more iterations from where it
            # stopped (not counted: they only tell the two failures apart) usually find the root,
            # far cheaper than damped least squares
            qr, _, _, conv = newton(self.model, att.q, s_i[None], self.tol_abs, CLASSIFY_ITER,
                                    self.jacobian)
            if conv[0] and drivers_aligned(self.model, qr, s_i[None])[0]:
                root = qr[0]
        if root is not None:
            status = NOT_CONVERGED
        elif att.lm_residual is None:
            tries = (att.guess, att.q, path.q) if att.capped else (att.guess,)
            status, root = _classify_failure(self.model, tries, s_i, self.tol_abs)
        else:
            status = NOT_CONVERGED if att.lm_residual <= 10 * self.tol_abs else NO_ASSEMBLY
        if status == NOT_CONVERGED and att.capped:
            # a root exists, the cap stopped Newton: the step stays not_converged (NaN), and the
            # sweep predicts on from that root with the slope from before (no restart)
            if root is not None:
                path.q, path.s = root, s_i
            return status
        path.gap = path.mode_pending = True
        if att.lm_residual is not None and np.all(np.isfinite(att.q_lm)):
            path.gap_shape = att.q_lm
        path.dq, path.d2q = None, None  # after a gap, restart from the last assembled shape
        return status


def _velocity_one(model, X, s, s_dot, J=None):
    """Return qdot (n_q,) at one step (for the predictor)."""
    if J is None:
        J = model.jacobian(X, s)
    rhs = -model.phi_t(X, s, s_dot)
    return _solve_one(J, rhs[0])


def _solve_one(J, b: np.ndarray) -> np.ndarray:
    """Solve Φq x = b (m,) at one step: J dense (1, m, n) or a sparse :class:`StepFactor`."""
    return J.solve(b) if isinstance(J, StepFactor) else lin_solve(J, b[None])[0]


def _det_sign(J) -> float:
    """The sign of det Φq at one step: J dense (1, n, n) or a sparse :class:`StepFactor`."""
    return J.det_sign() if isinstance(J, StepFactor) else np.linalg.slogdet(J[0])[0]
