"""The general (Newton) path, vectorised: a coarse sequential continuation (every k-th step,
which pins the branch), then every other step at once by Newton from a cubic Hermite
prediction between its two coarse neighbours (their positions and slopes); a step that does
not converge in a few iterations or moves far from its prediction sends its whole interval
back to the sequential continuation. Also the constraint residual of whole sweeps."""
from __future__ import annotations

import numpy as np

from ..model import Model
from ..model import equations as eq
from .continuation import solve_positions
from .linalg import POLISH_FROM, POLISH_WITHIN, is_singular
from .rates import engine_condition
from .sparse_lu import uses_sparse
from .sparse import _rows, engine
from .newton import _colmax, iterate
from .start import start_state
from ..status import OK
from .linalg import CHUNK




COARSE_NODES = 128  # sequential continuation on at most about this many steps


VECTORISE_FROM = 1000  # shorter sweeps run the sequential continuation on every step


NEWTON_ITERATIONS = 4  # per fine step before its interval goes back to the sequential path


OFF_BRANCH = 0.01  # a fine step may move at most this part of its interval's motion (or


OFF_BRANCH_ABS = 1e-6  # this times the size) from its prediction; farther is another branch


MAX_NODE_SHARE = 0.25  # drivers that turn back at more than this share of the steps (a
#                        noisy log): the sequential continuation on every step


def solve_newton(model: Model, s: np.ndarray, coarse: int = COARSE_NODES, chunk: int = CHUNK,
                 start=None, skip: np.ndarray | None = None):
    """Solve the sweep by the general path, vectorised; return a dict.

    Keys: q (S, n_q) NaN at failed steps, residual, iterations, status (as
    :func:`linkpipe.kinematics.solve_positions`), ``sequential`` (S,) bool where the sequential
    continuation solved the step. Falls back to the sequential
    path for every step when the model has no engine, the scene asks for a finite-difference
    Jacobian, or the drivers turn back at more than MAX_NODE_SHARE of the steps (every
    turn is a coarse node). Any spacing of the driver values is fine: the prediction is a
    Hermite cubic in the driver value (:func:`_parameter`). ``start``: the
    :func:`linkpipe.kinematics.start_state` at ``s[0]`` when the caller has it already.
    ``skip`` (S,) bool: steps known not to assemble (:func:`linkpipe.kinematics.beyond_reach`),
    not solved inside a gap (:func:`.continuation.solve_positions`).
    """
    sc = model.scene.solver
    S = s.shape[0]
    eng = engine(model)
    k = max(1, int(np.ceil((S - 1) / max(1, coarse))))
    nodes = _nodes(s, k) if S >= VECTORISE_FROM else None
    out = {}
    if start is None:  # (q, slope): the runs start there, and any re-run from step 0
        start = start_state(model, s[0], model.tolerance(), sc.max_iter)
    if (eng is None or sc.jacobian != "analytic" or S < VECTORISE_FROM
            or len(nodes) > MAX_NODE_SHARE * S):
        q, res, it, st = solve_positions(model, s, q_start=start[0], start_slope=start[1],
                                         skip=skip)
        out.update(q=q, residual=res, iterations=it, status=st, sequential=np.ones(S, bool))
        return out
    qn, resn, itn, stn = solve_positions(model, s[nodes], q_start=start[0], start_slope=start[1],
                                         skip=None if skip is None else skip[nodes])
    qn, resn = _one_more_newton_step(eng, qn, s[nodes], stn == OK, resn)
    out = dict(q=np.full((S, model.n_q), np.nan), residual=np.full(S, np.nan),
               iterations=np.zeros(S, dtype=np.int32), status=np.zeros(S, dtype=np.int8),
               sequential=np.zeros(S, dtype=bool))
    out["q"][nodes], out["residual"][nodes] = qn, resn
    out["iterations"][nodes], out["status"][nodes] = itn, stn
    out["sequential"][nodes] = True
    chord = np.diff(s[nodes], axis=0)  # each interval's driver increment (n_nodes - 1, nd)
    slopes, regular = _node_slopes(model, eng, qn, s[nodes], chord, stn == OK)
    bad_interval = _refine_between_nodes(model, eng, out, s, nodes, qn, slopes, regular, chunk)
    _rerun_sequentially(model, out, s, nodes, qn, bad_interval, start, skip)
    return out


def _nodes(s: np.ndarray, k: int) -> np.ndarray:
    """The coarse nodes: every k-th step, the last, and every step where a driver turns back
    (its increments change sign, or start or stop being zero), so that between two nodes
    every driver moves one way and the Hermite parameter of :func:`_parameter` is monotonic."""
    S = s.shape[0]
    sign = np.sign(np.diff(s, axis=0))  # (S - 1, nd)
    turns = np.flatnonzero((sign[1:] != sign[:-1]).any(axis=1)) + 1
    return np.union1d(np.r_[np.arange(0, S - 1, k), S - 1], turns)


def _parameter(s: np.ndarray, s_a: np.ndarray, chord: np.ndarray) -> np.ndarray:
    """Where each step lies on its interval's chord, 0 at its first node and 1 at its next:
    ``(s - s_a) . c / c . c`` (per step: s, s_a, chord (k, nd)); 0 where the drivers do not
    move over the interval. With one driver (or drivers moving along a straight line, as
    drivers with one law do) this is exact; the Hermite cubic in it is then a cubic in the
    driver value, whatever the spacing of the steps."""
    cc = np.einsum("kj,kj->k", chord, chord)
    dot = np.einsum("kj,kj->k", s - s_a, chord)
    return np.divide(dot, cc, out=np.zeros_like(dot), where=cc > 0)


def _node_slopes(model: Model, eng, qn, s_nodes, chord, ok):
    """Return each node's slope along the interval after it and along the interval before it,
    ``dq/ds . chord`` (two (n_nodes, n_q) arrays: the Hermite data per interval), from the
    engine, and which nodes are regular (ok, finite slopes, condition clear of the singular
    threshold: estimated on the sparse path, :func:`.sparse_lu.uses_sparse`)."""
    after, before = np.full_like(qn, np.nan), np.full_like(qn, np.nan)
    ok = ok.copy()
    if ok.any():
        Xn = model.positions(qn[ok])
        E = eng.entries(qn[ok], s_nodes[ok])
        zero = np.zeros((1, chord.shape[1]))
        for slope, c in ((after, np.r_[chord, zero]), (before, np.r_[zero, chord])):
            rhs = -model.phi_t(Xn, s_nodes[ok], c[ok])
            slope[ok] = np.stack(eng.solve(E, _rows(rhs)), axis=1)
        rcond = model.scene.solver.singular_rcond
        # large mechanisms: the condition estimated (exact near the thresholds), not from the
        # inverse (n block solves per node)
        cond = (engine_condition(eng, E, rcond, POLISH_FROM, POLISH_WITHIN) if uses_sparse(model)
                else eng.condition(E))
        near_singular = is_singular(cond, rcond, POLISH_FROM)
        ok[np.flatnonzero(ok)[near_singular]] = False
    regular = ok & np.isfinite(after).all(axis=1) & np.isfinite(before).all(axis=1)
    return (after, before), regular


def _refine_between_nodes(model: Model, eng, out: dict, s, nodes, qn, slopes, regular, chunk):
    """Every fine step of an interval between two regular nodes, at once: Newton from the
    cubic Hermite prediction; a step that does not converge, or lands farther from its
    prediction than a small part of its interval's motion, marks its interval bad (returned,
    (n_nodes - 1,) bool)."""
    sc, S = model.scene.solver, s.shape[0]
    tol_abs = model.tolerance()
    interval_ok = regular[:-1] & regular[1:]
    bad_interval = ~interval_ok
    lengths = np.diff(nodes)
    seg = np.repeat(np.arange(len(nodes) - 1), lengths)  # interval of steps 0..S-2
    fine = np.ones(S, dtype=bool)
    fine[nodes] = False
    steps = np.flatnonzero(fine & np.r_[interval_ok[seg], False])
    # where each step lies on its interval (0 at its first node, 1 at the next); an interval
    # where that is not monotonic within [0, 1] (drivers on a curved path) goes sequentially
    chord = np.diff(s[nodes], axis=0)
    t_all = np.zeros(S)
    t_all[steps] = _parameter(s[steps], s[nodes][seg[steps]], chord[seg[steps]])
    t_next = np.r_[t_all[1:], 1.0]  # the next step's parameter (1 at the next node)
    t_next[nodes[1:] - 1] = 1.0
    wrong = (t_all[steps] < 0) | (t_next[steps] > 1) | (t_next[steps] < t_all[steps])
    bad_interval[np.unique(seg[steps[wrong]])] = True
    steps = steps[~bad_interval[seg[steps]]]
    # per interval, coordinates first (the chunks below work on contiguous (n_q, k) arrays):
    # the Hermite data (values and slopes per unit parameter) and a coordinate's largest motion
    after, before = slopes
    hermite_T = [np.ascontiguousarray(a.T) for a in (qn[:-1], after[:-1], qn[1:], before[1:])]
    span_int = (np.abs(qn[1:] - qn[:-1]).max(axis=1) if model.n_q else np.zeros(len(lengths)))
    for lo in range(0, len(steps), chunk):
        ii = steps[lo:lo + chunk]
        g = seg[ii]
        t = t_all[ii]
        predT = _hermite_T(*(np.take(a, g, axis=1) for a in hermite_T), t)
        sT = np.ascontiguousarray(s[ii].T)
        qT, res, its, conv, _ = _newton_soa(eng, predT.copy(), sT, tol_abs,
                                            min(NEWTON_ITERATIONS, sc.max_iter))
        moved = _colmax(np.abs(qT - predT)) if qT.shape[0] else np.zeros(len(ii))
        accept = conv & (moved <= np.maximum(OFF_BRANCH * span_int[g], OFF_BRANCH_ABS * model.size))
        accept &= _aligned(eng, qT, sT)
        ia = ii[accept]
        for c in range(qT.shape[0]):  # one coordinate at a time: cheaper than a 2-D fancy write
            out["q"][ia, c] = qT[c, accept]
        out["residual"][ii] = res
        out["iterations"][ii] = its
        bad_interval[np.unique(g[~accept])] = True
    return bad_interval


def _rerun_sequentially(model: Model, out: dict, s, nodes, qn, bad_interval, start, skip=None):
    """Runs of intervals the vectorised refinement could not do go to the sequential
    continuation, from the run's first node (or the last assembled step before it); where it
    arrives elsewhere than the coarse run at a node, it continues to the end."""
    S, last = s.shape[0], len(nodes) - 1
    bad = np.flatnonzero(bad_interval)
    runs = np.split(bad, np.flatnonzero(np.diff(bad) > 1) + 1) if len(bad) else []
    keys = ("q", "residual", "iterations", "status")
    for run in runs:
        j0, j1 = run[0], run[-1]
        a, b = nodes[j0], nodes[j1 + 1]
        solved = _sequential_from_before(model, s, out["q"], a, b, start, skip)
        for key, arr in zip(keys, solved):
            out[key][a + 1:b + 1] = arr[1:]
        out["sequential"][a + 1:b + 1] = True
        if j1 + 1 < last and not _same(solved[0][-1], qn[j1 + 1], model):
            # the coarse continuation went elsewhere at this node: continue sequentially
            solved = _sequential_from_before(model, s, out["q"], b, S - 1, start, skip)
            for key, arr in zip(keys, solved):
                out[key][b + 1:] = arr[1:]
            out["sequential"][b + 1:] = True
            break


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


def _aligned(eng, qT, sT):
    """kinematics.drivers_aligned on SoA arrays: every angle driver's vector along its angle."""
    X2 = eng.points(qT)
    ok = np.ones(qT.shape[1], dtype=bool)
    cos_s, sin_s = eng._trig(sT)
    for _, value in eq.alignment_rows(eng.model.rows, lambda p: (X2[p, 0], X2[p, 1]), cos_s, sin_s):
        ok &= value > 0
    return ok


def _newton_soa(eng, qT, sT, tol_abs, max_iter: int = NEWTON_ITERATIONS):
    """:func:`linkpipe.kinematics.newton.iterate` on a chunk from predictions qT (n_q, k) on the
    sparse engine, polishing one quadratic step past the tolerance; return (qT, residual, its,
    converged, E), E the Jacobian's entries at the returned positions (for the derivatives).

    At most ``max_iter`` iterations (the scene's cap, if lower than NEWTON_ITERATIONS)."""
    def residual(q):
        return eng.phi(eng.points(q), sT)

    def correction(q, F):
        return np.stack(eng.solve(eng.entries_T(q, sT), list(-F)))

    qT, res, its, conv = iterate(residual, correction, qT, tol_abs, max_iter, eng.model.size,
                                 polish=True)
    return qT, res, its, conv, eng.entries_T(qT, sT)


def _one_more_newton_step(eng, q, s, ok, residual):
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


def _sequential_from_before(model, s, q, a, b, start, skip=None):
    """Run the sequential continuation over steps a..b from the last assembled step at or before a.

    ``start``: :func:`linkpipe.kinematics.start_state` at step 0 (its slope is the first
    predictor when the run starts there)."""
    prev = np.flatnonzero(np.isfinite(q[:a + 1]).all(axis=1))
    p = prev[-1] if len(prev) else 0
    slope = start[1] if p == 0 else None
    qs, rs, its, sts = solve_positions(model, s[p:b + 1], q_start=q[p] if len(prev) else start[0],
                                           start_slope=slope,
                                           skip=None if skip is None else skip[p:b + 1])
    return qs[a - p:], rs[a - p:], its[a - p:], sts[a - p:]


def residuals(model: Model, X: np.ndarray, s: np.ndarray, chunk: int = CHUNK,
              rows=None) -> np.ndarray:
    """Return max |Phi| (S,) at positions X (S, n_points, 2), in cache-sized chunks (``rows``:
    the model's rows with per-row constants, :meth:`Model.phi`)."""
    S = X.shape[0]
    out = np.empty(S)
    for lo in range(0, S, chunk):
        hi = min(S, lo + chunk)
        F = model.phi(X[lo:hi], s[lo:hi], None if rows is None else rows.take(slice(lo, hi)))
        out[lo:hi] = np.abs(F).max(axis=1) if F.shape[1] else 0.0
    return out


def max_abs_phi(model: Model):
    """Return ``f(points {moving p: (x (S,), y (S,))}, sT (nd, S), trig=None, rows=None) -> (S,)``:
    max |Phi| (``rows``: the model's rows with per-row constants).

    The engine's in-place row accumulation when the model has an engine, else the dense
    :func:`residuals` on the points put back into (S, n_points, 2).
    """
    eng = engine(model)
    if eng is not None:
        return eng.max_abs_phi
    return lambda pts, sT, trig=None, rows=None: residuals(
        model, _points_array(model, pts, sT.shape[1]), sT.T, rows=rows)


def _points_array(model: Model, pts: dict, S: int) -> np.ndarray:
    """Return positions (S, P, 2) from {moving point: (x (S,), y (S,))}."""
    X = np.broadcast_to(model.start_position, (S, model.n_points, 2)).copy()
    for p, (x, y) in pts.items():
        X[:, p, 0] = x
        X[:, p, 1] = y
    return X
