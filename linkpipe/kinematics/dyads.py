"""Stage 1's fast path: the mechanism as an ordered chain of closed-form dyads, all steps at once.

A scene *decomposes* when its moving points can be found one after another, each from points
already known, by one of these closed forms (found once, from the scene's graph):

``angle``     a body pinned at a known point and turned by an angle driver on two of its points:
              every point of it is ``c + R(theta) w`` (the driver fixes the direction).
``linear``    a body with two known points: its other points by their local coordinates
              (two linear equations each, as the model's ``local`` rows).
``circles``   a point shared by two bodies, each pinned at one known point: circle-circle
              intersection (the RRR dyad).
``circle_line`` a point of a pinned body that also lies on a known line (a fixed guide, a guide
              through two known points, or ``x = s`` / ``y = s`` of a coordinate driver):
              circle-line intersection (the RRP dyad).
``lines``     a point on two known lines: their intersection.

The two roots of ``circles`` and ``circle_line`` are the dyad's branches; each dyad keeps the
branch (sign) it has in the assembled start configuration at every step. Steps where a dyad has
no real root give NaN (``no_assembly``).

Consequence of the fixed sign: where a dyad passes *through* its singular configuration (the
two roots meet: a parallelogram's change point, a toggle at the end of an assembly range), the
fixed-sign solution turns a corner onto the other geometric branch, whereas Newton continuation
may carry on smoothly. :func:`branch_check` finds the steps where that can happen (a dyad's two
roots closer than a few steps' motion) and ``method = "auto"`` then uses the general Newton
path for the scene (also when any step has no assembly, since Newton's re-entry after a gap
follows its own rules).

Velocities and accelerations come from the dyads' own derivatives: each point's two
constraint rows differentiated once (``g1 . v = b1, g2 . v = b2``) and twice, solved by
Cramer's rule; the same linear algebra as ``Phi_q qd = -Phi_t`` in block-triangular order.
All arithmetic runs on contiguous per-coordinate arrays in cache-sized chunks of steps.
numpy only.
"""
from __future__ import annotations

import numpy as np

from dataclasses import dataclass

from .branches import BRANCH_MARGIN
from .decompose import Dyad, DyadChain, Line
from .angles import link_rate_columns
from .linalg import CHUNK


class _Chunk:
    """Per-coordinate arrays of one chunk of steps: x[p], y[p] (float for fixed points)."""

    __slots__ = ("px", "py", "vx", "vy", "ax", "ay", "s", "sd", "sdd", "_target", "gap2", "trig", "geo",
                 "period")


def _rows_line(line: Line, px, py, ch, order):
    """Return the line row of point p: gradient (gx, gy) and the velocity or acceleration RHS.

    ``order`` 0: (gx, gy) only; 1: (gx, gy, b_v); 2: (gx, gy, b_a) (needs the point's velocity).
    """
    if line.kind == "fixed":
        nx, ny = -line.t[1], line.t[0]
        return nx, ny, 0.0
    if line.kind == "coord":
        gx, gy = (1.0, 0.0) if line.axis == 0 else (0.0, 1.0)
        if order == 0:
            return gx, gy, None
        return gx, gy, (ch.sd if order == 1 else ch.sdd)[line.driver]
    d, e = line.d, line.e
    wx, wy = ch.px[e] - ch.px[d], ch.py[e] - ch.py[d]
    gx, gy = -wy, wx
    if order == 0:
        return gx, gy, None
    fx, fy = px - ch.px[d], py - ch.py[d]
    vdx, vdy = ch.vx[d], ch.vy[d]
    wdx, wdy = _sub(ch.vx[e], vdx), _sub(ch.vy[e], vdy)
    if order == 1:
        # cross(w, v_p) = cross(w, v_d) - cross(w', f)
        return gx, gy, _crs(wx, wy, vdx, vdy) - _crs(wdx, wdy, fx, fy)
    p = ch._target
    vpx, vpy = ch.vx[p], ch.vy[p]
    adx, ady = ch.ax[d], ch.ay[d]
    wddx, wddy = _sub(ch.ax[e], adx), _sub(ch.ay[e], ady)
    # cross(w, a_p) = cross(w, a_d) - cross(w'', f) - 2 cross(w', v_p - v_d)
    return gx, gy, (_crs(wx, wy, adx, ady) - _crs(wddx, wddy, fx, fy)
                    - 2.0 * _crs(wdx, wdy, _sub(vpx, vdx), _sub(vpy, vdy)))


def _sub(a, b):
    if b is None:
        return a
    if a is None:
        return -b
    return a - b


def _crs(ax, ay, bx, by):
    if ax is None or bx is None:
        return 0.0
    return ax * by - ay * bx


def _dot(ax, ay, bx, by):
    if bx is None:
        return 0.0
    return ax * bx + ay * by


def _position(st: Dyad, ch: _Chunk) -> None:
    px, py = ch.px, ch.py
    if st.kind == "angle":
        th = ch.s[st.driver]
        c, s = np.cos(th), np.sin(th)
        ch.trig[st.driver] = (c, s)
        cx, cy = px[st.c], py[st.c]
        for p, (wx, wy) in zip(st.targets, st.w):
            rx, ry = c * wx - s * wy, s * wx + c * wy
            ch.geo[p] = (rx, ry)  # the arm from the pin, for the derivatives
            px[p] = cx + rx
            py[p] = cy + ry
        return
    if st.kind == "linear":
        ix, iy = px[st.i], py[st.i]
        dx, dy = px[st.j] - ix, py[st.j] - iy
        for p, (al, be) in zip(st.targets, st.ab):
            px[p] = ix + (al * dx - be * dy)
            py[p] = iy + (al * dy + be * dx)
        return
    p = st.targets[0]
    if st.kind == "circles":
        r1, r2 = _radius(st.r1, st.r1_driver, ch), _radius(st.r2, st.r2_driver, ch)
        c1x, c1y = px[st.c1], py[st.c1]
        dx, dy = px[st.c2] - c1x, py[st.c2] - c1y
        inv = 1.0 / (dx * dx + dy * dy)
        k = 0.5 + (0.5 * (r1 * r1 - r2 * r2)) * inv
        h = (r1 * r1) * inv - k * k
        if ch.gap2 is not None:  # squared distance between the two roots: (2 h |d|)^2
            ch.gap2.append((p, 4.0 * h / inv))
        h = np.sqrt(h) if st.sign > 0 else -np.sqrt(h)
        g1x, g1y = k * dx - h * dy, k * dy + h * dx  # p - c1
        px[p] = c1x + g1x
        py[p] = c1y + g1y
        # the derivatives' rows: g1 = p - c1, g2 = p - c2 = g1 - d, and their determinant
        # cross(g1, g2) = cross(d, g1) = h |d|^2 (no cancellation near the singular h = 0)
        ch.geo[p] = (g1x, g1y, g1x - dx, g1y - dy, inv / h)
        return
    if st.kind == "circle_line":
        cx, cy = px[st.c1], py[st.c1]
        ox, oy, tx, ty = _line_geometry(st.line1, ch)
        # signed distance of the centre from the line along n = perp(t), then the half chord
        m = (cx - ox) * (-ty) + (cy - oy) * tx
        r1 = _radius(st.r1, st.r1_driver, ch)
        h = r1 * r1 - m * m
        if ch.gap2 is not None:  # squared distance between the two roots: (2 half-chord)^2
            ch.gap2.append((p, 4.0 * h))
        h = np.sqrt(h) if st.sign > 0 else -np.sqrt(h)
        px[p] = cx + m * ty + h * tx
        py[p] = cy - m * tx + h * ty
        return
    # lines: n1 . p = n1 . o1, n2 . p = n2 . o2
    o1x, o1y, t1x, t1y = _line_geometry(st.line1, ch)
    o2x, o2y, t2x, t2y = _line_geometry(st.line2, ch)
    b1 = -t1y * o1x + t1x * o1y
    b2 = -t2y * o2x + t2x * o2y
    det = (-t1y) * t2x - t1x * (-t2y)
    px[p] = (b1 * t2x - b2 * t1x) / det
    py[p] = ((-t1y) * b2 - (-t2y) * b1) / det


def _radius(r: float, driver: int, ch: _Chunk):
    """A circle's radius: fixed, or a distance driver's value at each step of the chunk."""
    return r if driver < 0 else ch.s[driver]


def _plus_radius_rate(b, driver: int, ch: _Chunk, order: int):
    """A distance row's right-hand side with a driven radius r = s: g . (v_p - v_c) = r r' and
    g . (a_p - a_c) + |v_p - v_c|^2 = r r'' + r'^2 (b holds the rest)."""
    if driver < 0:
        return b
    r, rd = ch.s[driver], ch.sd[driver]
    if order == 1:
        return b + r * rd
    return b + (r * ch.sdd[driver] + rd * rd)


def _line_geometry(line: Line, ch: _Chunk):
    """Return (ox, oy, tx, ty): a point on the line and its unit direction, chunk-wise."""
    if line.kind == "fixed":
        return line.o[0], line.o[1], line.t[0], line.t[1]
    if line.kind == "coord":
        s = ch.s[line.driver]
        return (s, 0.0, 0.0, 1.0) if line.axis == 0 else (0.0, s, 1.0, 0.0)
    dx, dy = ch.px[line.d], ch.py[line.d]
    wx, wy = ch.px[line.e] - dx, ch.py[line.e] - dy
    n = 1.0 / np.sqrt(wx * wx + wy * wy)
    return dx, dy, wx * n, wy * n


def _derivative(st: Dyad, ch: _Chunk, order: int) -> None:
    """Velocities (order 1) or accelerations (order 2) of the step's targets."""
    px, py = ch.px, ch.py
    if order == 1:
        ox, oy = ch.vx, ch.vy
    else:
        ox, oy = ch.ax, ch.ay
    if st.kind == "angle":
        w = ch.sd[st.driver]
        bx, by = ox[st.c], oy[st.c]
        if order == 1:
            for p in st.targets:
                rx, ry = ch.geo[p]
                ox[p] = _add(bx, -w * ry)
                oy[p] = _add(by, w * rx)
        else:
            al = ch.sdd[st.driver]
            w2 = w * w
            for p in st.targets:
                rx, ry = ch.geo[p]
                if isinstance(al, float) and al == 0.0:  # constant rate: centripetal only
                    ox[p] = _add(bx, -w2 * rx)
                    oy[p] = _add(by, -w2 * ry)
                else:
                    ox[p] = _add(bx, -al * ry - w2 * rx)
                    oy[p] = _add(by, al * rx - w2 * ry)
        return
    if st.kind == "linear":
        bx, by = ox[st.i], oy[st.i]
        dx, dy = _sub(ox[st.j], bx), _sub(oy[st.j], by)
        for p, (al, be) in zip(st.targets, st.ab):
            if dx is None:
                ox[p], oy[p] = bx, by
            else:
                ox[p] = _add(bx, al * dx - be * dy)
                oy[p] = _add(by, al * dy + be * dx)
        return
    p = st.targets[0]
    ch._target = p
    if st.kind == "circles":  # rows and determinant from the position pass
        g1x, g1y, g2x, g2y, idet = ch.geo[p]
        b1 = _dot(g1x, g1y, ox[st.c1], oy[st.c1])
        b2 = _dot(g2x, g2y, ox[st.c2], oy[st.c2])
        if order == 2:
            b1 = _minus_rel_speed2(b1, ch, p, st.c1)
            b2 = _minus_rel_speed2(b2, ch, p, st.c2)
        b1 = _plus_radius_rate(b1, st.r1_driver, ch, order)
        b2 = _plus_radius_rate(b2, st.r2_driver, ch, order)
        ox[p] = _cramer(b1, g2y, b2, g1y, idet)
        oy[p] = _cramer(b2, g1x, b1, g2x, idet)
        return
    if st.kind == "circle_line":  # a distance row from the centre, then the line's row
        c = st.c1
        gx, gy = px[p] - px[c], py[p] - py[c]
        b = _dot(gx, gy, ox[c], oy[c])
        if order == 2:
            b = _minus_rel_speed2(b, ch, p, c)
        b = _plus_radius_rate(b, st.r1_driver, ch, order)
        (g1x, g1y, b1), (g2x, g2y, b2) = (gx, gy, b), _rows_line(st.line1, px[p], py[p], ch, order)
    else:  # lines
        (g1x, g1y, b1), (g2x, g2y, b2) = (_rows_line(st.line1, px[p], py[p], ch, order),
                                          _rows_line(st.line2, px[p], py[p], ch, order))
    idet = 1.0 / (g1x * g2y - g1y * g2x)
    ox[p] = _cramer(b1, g2y, b2, g1y, idet)
    oy[p] = _cramer(b2, g1x, b1, g2x, idet)


def _derivative_pass(plan: DyadChain, ch: _Chunk, order: int, moving, buf: np.ndarray, n: int):
    """Velocities (order 1) or accelerations (2) of every step of the chunk, into ``buf[:n]``."""
    for st in plan.steps:
        _derivative(st, ch, order)
    xs, ys = (ch.vx, ch.vy) if order == 1 else (ch.ax, ch.ay)
    for p in moving:
        buf[:n, p, 0] = _val(xs[p])
        buf[:n, p, 1] = _val(ys[p])
    return buf[:n]


def _minus_rel_speed2(b, ch: _Chunk, p: int, c: int):
    """Return b - |v_p - v_c|^2 (a distance row's acceleration RHS); b when both are at rest."""
    rvx, rvy = _sub(ch.vx[p], ch.vx[c]), _sub(ch.vy[p], ch.vy[c])
    return b if rvx is None else b - (rvx * rvx + rvy * rvy)


def _cramer(a, b, c, d, idet):
    """Return (a b - c d) idet, where a or c may be the scalar 0.0 (a point with no load)."""
    if isinstance(c, float) and c == 0.0:
        return a * b * idet
    if isinstance(a, float) and a == 0.0:
        return -(c * d) * idet
    return (a * b - c * d) * idet


def _val(a):
    return 0.0 if a is None else a


def _add(a, b):
    return b if a is None else a + b


@dataclass
class ChainSweep:
    """What :func:`solve_chain` returns. Arrays step-axis first; velocity/acceleration None when not asked.

    ``ok`` (S,) every point finite; ``residual`` (S,) max |Phi| when ``max_abs_phi`` was given;
    ``gap`` (S,) with ``gaps=True``: the smallest over the dyads and the step pairs (i-1, i)
    and (i, i+1) of ``d^2 - (BRANCH_MARGIN m)^2``, d the distance between a dyad's two roots,
    m its point's move (|dx| + |dy|) between the two steps (positive: safe; see branch_check).
    """

    position: np.ndarray
    velocity: np.ndarray | None
    acceleration: np.ndarray | None
    ok: np.ndarray
    residual: np.ndarray | None = None
    gap: np.ndarray | None = None
    #: with ``links``: each link's direction (S, n_links) and (angular velocity, angular
    #: acceleration or None) (S, n_links), from the pass itself
    link_angle: np.ndarray | None = None
    link_rates: tuple | None = None
    #: (S,) with ``gaps=True``: the smallest over the dyads of the squared distance between a
    #: dyad's two roots at the step; negative where a dyad has no real root (its circles, or its
    #: circle and line, miss each other), by as much as the chord they would need
    miss: np.ndarray | None = None
    #: {angle driver: (cos, sin) (S,)} of the driver values the angle dyads turned by
    #: (numpy's: the condition's entries take them, :func:`linkpipe.kinematics.derivatives`)
    trig: dict | None = None


def solve_chain(plan: DyadChain, s: np.ndarray, s_dot: np.ndarray | None = None, s_ddot: np.ndarray | None = None,
          order: int = 2, gaps: bool = False, max_abs_phi=None, chunk: int = CHUNK,
          fixed_position: np.ndarray | None = None, period: int = 0, rows=None,
          carry: dict | None = None, links: bool = False, compiled: bool = False) -> ChainSweep:
    """Solve every step: positions, and velocities (order >= 1) and accelerations (order 2).

    ``s``, ``s_dot``, ``s_ddot`` (S, n_drivers) in internal units. Steps where a dyad has no real
    root are NaN in every moving point. ``gaps=True`` also returns each step's smallest
    distance between a dyad's two roots and its motion (for :func:`branch_check`).
    ``max_abs_phi``: an optional ``f(points {moving p: (x (n,), y (n,))}, s (nd, n), trig) -> (n,)``,
    max |Phi| over all the model's constraint rows, for the residual at every step (``trig``:
    {driver: (cos, sin)} of the angle drivers, already computed).

    ``fixed_position`` (S, n_points, 2): the fixed points' positions row by row (a study's
    variants that move pivots, on one (variant, step) row axis; ``max_abs_phi`` then also gets
    the fixed points); default the model's drawing. ``period``: the rows are runs of this many
    steps (variants): no step pair across two runs counts in ``gap``. The dyads' constants
    may be given per row too (a study's variants of other link lengths: arrays (S,),
    :func:`.decompose.chain_at`), and ``rows`` the model's rows with their per-row constants
    (:class:`linkpipe.model.equations.Rows`, for ``max_abs_phi``). ``carry``: a sweep solved
    in segments of steps (:mod:`linkpipe.segments`): one dict kept across the calls (each dyad
    point's last step before), so the step pair across two segments counts in ``gap`` as it
    does within one call.

    ``links``: also each link's direction (``model.link_angles``) and, with order >= 1, its
    angular velocity (and acceleration: :func:`.angles.link_rate_rows`), from each chunk's
    buffers while they are in cache: the same formulas, so the same numbers as the separate
    passes over the whole arrays at every step whose points are all finite (the others are
    the caller's to recompute from the final arrays).

    ``compiled`` (:func:`.compiled.wanted` of the sweep's length): the same numbers by the
    compiled loop (:mod:`.chain_kernel`) where it takes the solve (plain constants: not a
    study's per-row numbers, pivots or runs of variants).
    """
    if compiled and fixed_position is None and not period and rows is None and all(
            st.take(slice(0, 1)) is st for st in plan.steps):
        from . import chain_kernel  # imports numba: only where the compiled loop is taken

        return _unassembled_as_nan(ChainSweep(*chain_kernel.solve(
            plan, s, s_dot, s_ddot, order, gaps, max_abs_phi, carry, links, chunk)), plan.model)
    model = plan.model
    S = s.shape[0]
    P = model.n_points
    X0 = model.start_position
    fixed = model.fixed
    X = np.empty((S, P, 2))
    V = np.empty((S, P, 2)) if order >= 1 else None
    A = np.empty((S, P, 2)) if order >= 2 else None
    # each chunk is written into cache-resident (chunk, P, 2) buffers, then copied whole into
    # the outputs (one contiguous copy instead of strided writes over the full arrays); the
    # buffers hold the fixed points (their positions, zero rates) from the start
    m = min(S, chunk)
    bufs = [np.empty((m, P, 2)) for _ in range(1 + min(order, 2))]  # moving points: each chunk's
    bufs[0][:, fixed] = X0[fixed]
    for rates in bufs[1:]:
        rates[:, fixed] = 0.0
    L = len(model.link_a)
    angle = np.empty((S, L)) if links else None
    w = np.empty((S, L)) if links and order >= 1 else None
    al = np.empty((S, L)) if links and order >= 2 else None
    ok = np.ones(S, dtype=bool)
    gap = np.full(S, np.inf) if gaps else None  # margin: gap^2 - (BRANCH_MARGIN move)^2
    miss = np.full(S, np.inf) if gaps else None
    residual = np.empty(S) if max_abs_phi is not None else None
    moving = [int(p) for p in model.moving]
    fixed_set = {int(p) for p in np.flatnonzero(fixed)}
    nd = model.n_drivers
    cols = [np.ascontiguousarray(s[:, j]) for j in range(nd)]
    dcols = [np.ascontiguousarray(s_dot[:, j]) for j in range(nd)] if order >= 1 else None
    ddcols = [np.ascontiguousarray(s_ddot[:, j]) for j in range(nd)] if order >= 2 else None
    dcols, ddcols = _scalar_if_constant(dcols), _scalar_if_constant(ddcols)
    ch = _Chunk()
    ch.gap2 = [] if gaps else None
    ch.period = period
    fixed_at = _fixed_columns(fixed_position, fixed)
    prev = {} if carry is None else carry  # dyad point -> (x, y, gap^2) at the step before
    trig = {st.driver: (np.empty(S), np.empty(S)) for st in plan.steps if st.kind == "angle"}
    with np.errstate(invalid="ignore", divide="ignore"):
        for lo in range(0, S, chunk):
            hi = min(S, lo + chunk)
            n = hi - lo
            ch.s = [c[lo:hi] for c in cols]
            part = plan.take(slice(lo, hi))  # per-row constants cut to the chunk
            total = _position_pass(part, ch, fixed_at, lo, hi, bufs[0], moving)
            X[lo:hi] = bufs[0][:n]
            for j, (c, sn) in ch.trig.items():
                trig[j][0][lo:hi], trig[j][1][lo:hi] = c, sn
            if moving:
                ok[lo:hi] = np.isfinite(total)
            if gaps:
                for _, g2 in ch.gap2:  # NaN downstream of a dyad without a root: fmin skips it
                    np.fmin(miss[lo:hi], g2, out=miss[lo:hi])
                _branch_margins(ch, gap, prev, lo, hi)
            if max_abs_phi is not None:
                pts = {p: (ch.px[p], ch.py[p]) for p in moving + list(fixed_at)}
                sT = np.stack(ch.s) if nd else np.zeros((0, n))
                residual[lo:hi] = (max_abs_phi(pts, sT, ch.trig) if rows is None else
                                   max_abs_phi(pts, sT, ch.trig, rows.take(slice(lo, hi))))
            if order >= 1:
                ch.sd = [c if isinstance(c, float) else c[lo:hi] for c in dcols]
                ch.vx, ch.vy = [None] * P, [None] * P
                V[lo:hi] = _derivative_pass(part, ch, 1, moving, bufs[1], n)
            if order >= 2:
                ch.sdd = [c if isinstance(c, float) else c[lo:hi] for c in ddcols]
                ch.ax, ch.ay = [None] * P, [None] * P
                A[lo:hi] = _derivative_pass(part, ch, 2, moving, bufs[2], n)
            if links:  # from the chunk's own columns (the buffers' numbers, unstrided)
                link_rate_columns(
                    model.link_a, model.link_b, lambda p: (ch.px[p], ch.py[p]),
                    lambda p: (_val(ch.vx[p]), _val(ch.vy[p])),
                    (lambda p: (_val(ch.ax[p]), _val(ch.ay[p]))) if al is not None else None,
                    None if w is None else w[lo:hi], None if al is None else al[lo:hi],
                    still=fixed_set, angle=angle[lo:hi])
    return _unassembled_as_nan(ChainSweep(X, V, A, ok, residual, gap, angle,
                                          None if w is None else (w, al), miss, trig), model)


def _unassembled_as_nan(sw: ChainSweep, model) -> ChainSweep:
    """``sw`` with every moving point's position and rates, and the residual, NaN at the steps
    without assembly (``~sw.ok``), in place."""
    bad = ~sw.ok
    if bad.any():
        at = np.ix_(bad, model.moving)
        for arr in (sw.position, sw.velocity, sw.acceleration):
            if arr is not None:
                arr[at] = np.nan
        if sw.residual is not None:
            sw.residual[bad] = np.nan
    return sw


def _position_pass(plan: DyadChain, ch: _Chunk, fixed_at: dict, lo: int, hi: int,
                   buf: np.ndarray, moving: list):
    """Positions of the chunk's steps ``lo .. hi`` (driver values ``ch.s`` set) into
    ``buf[:n]``, the per-row pivots ``fixed_at`` too; returns the sum of the moving points'
    coordinates (n,) (NaN at a step without assembly)."""
    model, n = plan.model, hi - lo
    X0, fixed = model.start_position, model.fixed
    ch.px = [float(X0[p, 0]) if fixed[p] else None for p in range(model.n_points)]
    ch.py = [float(X0[p, 1]) if fixed[p] else None for p in range(model.n_points)]
    for p, (x, y) in fixed_at.items():  # per-row pivots: columns of the chunk's rows
        ch.px[p], ch.py[p] = x[lo:hi], y[lo:hi]
        buf[:n, p, 0], buf[:n, p, 1] = ch.px[p], ch.py[p]
    ch.trig = {}
    ch.geo = {}
    for st in plan.steps:
        _position(st, ch)
    total = 0.0
    for p in moving:
        buf[:n, p, 0] = ch.px[p]
        buf[:n, p, 1] = ch.py[p]
        total = total + ch.px[p] + ch.py[p]  # NaN anywhere stays NaN
    return total


def _fixed_columns(fixed_position, fixed) -> dict:
    """{fixed point: (x (S,), y (S,))} contiguous columns of per-row pivots ({} for none)."""
    if fixed_position is None:
        return {}
    return {int(p): (np.ascontiguousarray(fixed_position[:, p, 0]),
                     np.ascontiguousarray(fixed_position[:, p, 1])) for p in np.flatnonzero(fixed)}


def _scalar_if_constant(columns):
    """Constant rates (the usual sweep) stay scalars: zero terms can be skipped."""
    if columns is None:
        return None
    return [float(c[0]) if c.size and (c == c[0]).all() else c for c in columns]


def _branch_margins(ch: _Chunk, gap: np.ndarray, prev: dict, lo: int, hi: int) -> None:
    """Lower ``gap[lo:hi]`` to each dyad's margin in this chunk: a step pair (i-1, i) is safe
    when both steps' roots are farther apart than BRANCH_MARGIN times the dyad point's move
    between them (|dx| + |dy| >= the move). ``prev``: each dyad point's last step of the chunk
    before (x, y, gap^2), updated here."""
    for p, g2 in ch.gap2:
        x, y = ch.px[p], ch.py[p]
        mv = np.abs(x[1:] - x[:-1]) + np.abs(y[1:] - y[:-1])
        g = np.minimum(g2[1:], g2[:-1]) - (BRANCH_MARGIN * mv) ** 2
        if ch.period:  # a pair of two variants' rows is no step of either
            g[(np.arange(lo + 1, hi) % ch.period) == 0] = np.inf
        np.minimum(gap[lo + 1:hi], g, out=gap[lo + 1:hi])
        if p in prev and not (ch.period and lo % ch.period == 0):
            x0, y0, g0 = prev[p]
            m0 = BRANCH_MARGIN * (abs(x[0] - x0) + abs(y[0] - y0))
            gap[lo] = min(gap[lo], min(g0, g2[0]) - m0 * m0)  # a product, as the arrays' ** 2
        prev[p] = (x[-1], y[-1], g2[-1])
    ch.gap2 = []


def branch_check(plan: DyadChain, sweep: ChainSweep) -> bool:
    """Return True when fixed-sign dyads surely follow the same branch as Newton continuation.

    Newton continuation from step i-1 lands in the basin of the root on its side of the dyad's
    centre line (half the roots' distance from either root); a guess less than one step's motion
    from the root (even without a predictor) stays there as long as the two roots are farther
    apart than ``BRANCH_MARGIN`` steps' motion. A step without assembly also returns False
    (Newton's re-entry after a gap follows its own rules). Needs ``solve_chain(..., gaps=True)``.
    """
    if not sweep.ok.all():
        return False
    if any(st.ambiguous for st in plan.steps):
        return False
    if sweep.gap is None:
        return True
    return bool((sweep.gap > 0).all())
