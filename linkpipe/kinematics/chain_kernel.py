"""The closed-form dyads (:mod:`.dyads`) as compiled loops (numba): positions, velocities,
accelerations, the dyads' root gaps and branch margins and the links' directions and rates,
dyad by dyad over each chunk's steps on columns (loops the compiler vectorises, as numpy's
passes are, without their temporaries).

It is :func:`.dyads.solve_chain`'s arithmetic in its order, operation by operation (``dyads``
writes each formula once over arrays; here over one step's numbers), with the one
transcendental function it takes, cos and sin of the angle drivers, computed by numpy
beforehand, and the links' arctan2 by numpy afterwards: so the numbers are numpy's to the bit
(``tests/test_chain_kernel.py`` proves it on every shipped dyad scene and on families of them;
a zero's sign may differ where numpy skips a term that is exactly zero). The residual max |Phi|
stays :mod:`linkpipe.model.equations`' own, evaluated by numpy once over the segment's columns.

The chain is encoded as arrays (:func:`encode`): one row per dyad in ``ops_i`` / ``ops_f``
(columns below) and its targets in ``tg_*``. What the compiled loops do not take (a study's
per-row constants or per-row pivots, runs of variants) stays on numpy (:func:`.dyads.solve_chain`).
Importing this module imports numba and loads (or, the first time, compiles) the loops:
:mod:`.dyads` imports it only where :func:`.compiled.wanted` said so.
"""
from __future__ import annotations

import numpy as np

from .compiled import jit
from .branches import BRANCH_MARGIN
from .decompose import DyadChain, Line
from .linalg import CHUNK

KINDS = {"angle": 0, "linear": 1, "circles": 2, "circle_line": 3, "lines": 4}
LINE_KINDS = {"fixed": 0, "coord": 1, "moving": 2}
# ops_i columns: kind, first target, targets, a (angle: pin c; linear: i; else c1),
# b (angle: driver; linear: j; else c2), r1_driver, r2_driver, line 1 (kind, d, e, driver,
# axis), line 2 (the same), the dyad's index among those with two roots (-1: none)
# ops_f columns: r1, r2, sign, line 1 (ox, oy, tx, ty), line 2 (the same)


def _line(line: Line | None) -> tuple[list, list]:
    if line is None:
        return [-1, -1, -1, -1, -1], [0.0, 0.0, 0.0, 0.0]
    return ([LINE_KINDS[line.kind], line.d, line.e, line.driver, line.axis],
            [float(line.o[0]), float(line.o[1]), float(line.t[0]), float(line.t[1])])


def encode(chain: DyadChain):
    """The chain as arrays: (ops_i (K, 18) int64, ops_f (K, 11), tg_p (T,) int64, tg_u (T,),
    tg_v (T,), gap_points (G,) int64: each two-root dyad's point, in order)."""
    ops_i, ops_f, tg_p, tg_u, tg_v, gap_points = [], [], [], [], [], []
    for st in chain.steps:
        kind = KINDS[st.kind]
        pairs = st.w if st.kind == "angle" else st.ab if st.kind == "linear" else []
        first = len(tg_p)
        for k, p in enumerate(st.targets):
            tg_p.append(p)
            u, v = pairs[k] if pairs else (0.0, 0.0)
            tg_u.append(float(u))
            tg_v.append(float(v))
        a, b = ((st.c, st.driver) if st.kind == "angle" else (st.i, st.j) if st.kind == "linear"
                else (st.c1, st.c2))
        g = -1
        if st.kind in ("circles", "circle_line"):
            g = len(gap_points)
            gap_points.append(st.targets[0])
        l1i, l1f = _line(st.line1)
        l2i, l2f = _line(st.line2)
        ops_i.append([kind, first, len(st.targets), a, b, st.r1_driver, st.r2_driver,
                      *l1i, *l2i, g])
        ops_f.append([float(st.r1), float(st.r2), float(st.sign), *l1f, *l2f])
    return (np.array(ops_i, dtype=np.int64).reshape(-1, 18),
            np.array(ops_f, dtype=float).reshape(-1, 11), np.array(tg_p, dtype=np.int64),
            np.array(tg_u, dtype=float), np.array(tg_v, dtype=float),
            np.array(gap_points, dtype=np.int64))


def solve(chain: DyadChain, s, s_dot, s_ddot, order: int, gaps: bool, max_abs_phi,
          carry: dict | None, links: bool, chunk: int = CHUNK):
    """:func:`.dyads.solve_chain` (its arguments) by the compiled loops, chunk by chunk as
    numpy's (its branch margins see the same chunks; the residual, elementwise, is taken once
    over the segment): the fields of its :class:`.dyads.ChainSweep`, in their order, the steps
    without assembly not yet NaN (``solve_chain`` does that for both paths)."""
    model = chain.model
    S, P, L = s.shape[0], model.n_points, len(model.link_a)
    X0 = model.start_position
    ops_i, ops_f, tg_p, tg_u, tg_v, gap_points = encode(chain)
    G = len(gap_points)
    moving = np.asarray(model.moving, dtype=np.int64)
    fixed = np.asarray(model.fixed, dtype=np.uint8)
    link_a, link_b = (np.asarray(x, dtype=np.int64) for x in (model.link_a, model.link_b))
    nd = model.n_drivers
    angle_drivers = sorted({int(r[4]) for r in ops_i if r[0] == KINDS["angle"]})
    X = np.empty((S, P, 2))
    V = np.empty((S, P, 2)) if order >= 1 else np.empty((0, P, 2))
    A = np.empty((S, P, 2)) if order >= 2 else np.empty((0, P, 2))
    ok = np.ones(S, dtype=bool)
    gap = np.full(S, np.inf) if gaps else np.empty(0)
    miss = np.full(S, np.inf) if gaps else np.empty(0)
    residual = np.empty(S) if max_abs_phi is not None else None
    angle = np.empty((S, L)) if links else None
    w = np.empty((S, L)) if links and order >= 1 else np.empty((0, L))
    al = np.empty((S, L)) if links and order >= 2 else np.empty((0, L))
    prev = np.zeros((G, 3))
    has_prev = np.zeros(G, dtype=np.uint8)
    carry = {} if carry is None else carry
    for k, p in enumerate(gap_points):
        if int(p) in carry:
            prev[k] = carry[int(p)]
            has_prev[k] = 1
    m = min(S, chunk)
    # one chunk's columns (point, step): positions, rates, the dyads' rows, the roots' gaps
    cols = [np.empty((P, m)) for _ in range(6)]
    geo, g2, total = np.empty((P, 5, m)), np.empty((G, m)), np.empty(m)
    rt, lc = np.empty((2, m)), np.empty((4, L, m))  # driven radii's terms; links' columns
    cosv, sinv = np.zeros((nd, m)), np.zeros((nd, m))
    s_rows = np.ascontiguousarray(s.T)  # (nd, S)
    trig_all = {j: (np.cos(s_rows[j]), np.sin(s_rows[j])) for j in angle_drivers}  # numpy's
    XS = np.empty((P, 2, S)) if max_abs_phi is not None else None  # the residual's columns
    zeros = np.zeros((nd, m))
    x0, y0 = X0[:, 0].copy(), X0[:, 1].copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        for lo in range(0, S, chunk):
            hi = min(S, lo + chunk)
            n = hi - lo
            sT = np.ascontiguousarray(s_rows[:, lo:hi])
            sdT = np.ascontiguousarray(s_dot[lo:hi].T) if order >= 1 else zeros[:, :n]
            sddT = np.ascontiguousarray(s_ddot[lo:hi].T) if order >= 2 else zeros[:, :n]
            for j in angle_drivers:
                cosv[j, :n], sinv[j, :n] = trig_all[j][0][lo:hi], trig_all[j][1][lo:hi]
            _steps(ops_i, ops_f, tg_p, tg_u, tg_v, gap_points, x0, y0, fixed, moving, link_a,
                   link_b, sT, sdT, sddT, cosv, sinv, order, 1 if gaps else 0,
                   1 if links else 0, BRANCH_MARGIN, lo == 0, *cols, geo, g2, total, rt, lc, X[lo:hi],
                   V[lo:hi], A[lo:hi], ok[lo:hi], miss[lo:hi], gap[lo:hi], prev, has_prev,
                   w[lo:hi], al[lo:hi])
            if links:  # the links' directions from the kernel's (dx, dy) columns (L, n)
                angle[lo:hi] = np.arctan2(lc[1, :, :n], lc[0, :, :n]).T
            if XS is not None:
                XS[:, 0, lo:hi], XS[:, 1, lo:hi] = cols[0][:, :n], cols[1][:, :n]
        if XS is not None:  # every row's |Phi| is its own step's: one call for the segment
            pts = {int(p): (XS[p, 0], XS[p, 1]) for p in moving}
            residual[:] = max_abs_phi(pts, s_rows if nd else np.zeros((0, S)), trig_all)
    if gaps:
        for k, p in enumerate(gap_points):
            if has_prev[k]:
                carry[int(p)] = tuple(float(x) for x in prev[k])
    return (X, V if order >= 1 else None, A if order >= 2 else None, ok, residual,
            gap if gaps else None, angle,
            (w, al if order >= 2 else None) if links and order >= 1 else None,
            miss if gaps else None, trig_all)


@jit
def _steps(ops_i, ops_f, tg_p, tg_u, tg_v, gap_points, x0, y0, fixed, moving, link_a,
           link_b, sT, sdT, sddT, cosv, sinv, order, gaps, links, margin, first, PX, PY, VX, VY,
           AX, AY, GEO, G2, TOT, RT, LC, X, V, A, ok, miss, gap, prev, has_prev, w, al):
    """One chunk of n steps (``sT``, ``sdT``, ``sddT`` (nd, n)), dyad by dyad, each over the
    chunk's steps (loops the compiler vectorises, as numpy's passes are), on columns (point,
    step) ``PX`` .. ``AY`` (P, >= n; the fixed points' rows filled on the ``first`` chunk),
    ``GEO`` (P, 5, >= n), ``G2`` (G, >= n): writes X, V, A
    (n, P, 2), ok, miss, gap (n,), the links' (dx, dy) into ``LC[0]``, ``LC[1]`` (L, >= n)
    and their rates into w, al (n, L); ``prev`` (G, 3) / ``has_prev`` (G,): each two-root dyad's (x, y, gap^2) at the
    step before the chunk, updated to its last step."""
    n, P = sT.shape[1], x0.shape[0]
    K, G, L = ops_i.shape[0], gap_points.shape[0], link_a.shape[0]
    if first:  # the fixed points' columns: their positions, zero rates (kept chunk to chunk)
        for q in range(P):
            if fixed[q]:
                for i in range(PX.shape[1]):
                    PX[q, i], PY[q, i] = x0[q], y0[q]
                    VX[q, i], VY[q, i], AX[q, i], AY[q, i] = 0.0, 0.0, 0.0, 0.0
    # -------------------------------------------------------------------- positions
    for k in range(K):
        kind, t0, tn, a, b = ops_i[k, 0], ops_i[k, 1], ops_i[k, 2], ops_i[k, 3], ops_i[k, 4]
        if kind == 0:  # angle: b is the driver
            cr, sr, cx, cy = cosv[b], sinv[b], PX[a], PY[a]
            for t in range(t0, t0 + tn):
                wx, wy = tg_u[t], tg_v[t]
                xp, yp, gx, gy = PX[tg_p[t]], PY[tg_p[t]], GEO[tg_p[t], 0], GEO[tg_p[t], 1]
                for i in range(n):
                    rx = cr[i] * wx - sr[i] * wy
                    ry = sr[i] * wx + cr[i] * wy
                    gx[i], gy[i] = rx, ry
                    xp[i] = cx[i] + rx
                    yp[i] = cy[i] + ry
            continue
        if kind == 1:  # linear
            for t in range(t0, t0 + tn):
                _linear(PX[a], PY[a], PX[b], PY[b], tg_u[t], tg_v[t], PX[tg_p[t]], PY[tg_p[t]], n)
            continue
        p = tg_p[t0]
        xp, yp, sg = PX[p], PY[p], ops_f[k, 2]
        d1, d2, r1c, r2c = ops_i[k, 5], ops_i[k, 6], ops_f[k, 0], ops_f[k, 1]
        gr = G2[max(ops_i[k, 17], 0)]
        if kind == 2:  # circles
            c1x, c1y, c2x, c2y = PX[a], PY[a], PX[b], PY[b]
            e0, e1, e2, e3, e4 = GEO[p, 0], GEO[p, 1], GEO[p, 2], GEO[p, 3], GEO[p, 4]
            for i in range(n):
                r1, r2 = _radius(r1c, d1, sT, i), _radius(r2c, d2, sT, i)
                dx, dy = c2x[i] - c1x[i], c2y[i] - c1y[i]
                inv = 1.0 / (dx * dx + dy * dy)
                kk = 0.5 + (0.5 * (r1 * r1 - r2 * r2)) * inv
                h = (r1 * r1) * inv - kk * kk
                gr[i] = 4.0 * h / inv
                h = sg * np.sqrt(h)
                g1x, g1y = kk * dx - h * dy, kk * dy + h * dx
                xp[i] = c1x[i] + g1x
                yp[i] = c1y[i] + g1y
                e0[i], e1[i], e2[i], e3[i], e4[i] = g1x, g1y, g1x - dx, g1y - dy, inv / h
            continue
        if kind == 3:  # circle_line
            cxr, cyr = PX[a], PY[a]
            for i in range(n):
                cx, cy = cxr[i], cyr[i]
                ox, oy, tx, ty = _geometry(ops_i, ops_f, k, 7, 3, PX, PY, sT, i)
                mm = (cx - ox) * (-ty) + (cy - oy) * tx
                r1 = _radius(r1c, d1, sT, i)
                h = r1 * r1 - mm * mm
                gr[i] = 4.0 * h
                h = sg * np.sqrt(h)
                xp[i] = cx + mm * ty + h * tx
                yp[i] = cy - mm * tx + h * ty
            continue
        for i in range(n):  # lines
            o1x, o1y, t1x, t1y = _geometry(ops_i, ops_f, k, 7, 3, PX, PY, sT, i)
            o2x, o2y, t2x, t2y = _geometry(ops_i, ops_f, k, 12, 7, PX, PY, sT, i)
            b1 = -t1y * o1x + t1x * o1y
            b2 = -t2y * o2x + t2x * o2y
            det = (-t1y) * t2x - t1x * (-t2y)
            xp[i] = (b1 * t2x - b2 * t1x) / det
            yp[i] = ((-t1y) * b2 - (-t2y) * b1) / det
    if moving.shape[0]:  # a step is assembled where the sum of its coordinates is finite
        for i in range(n):
            TOT[i] = 0.0
        for q in moving:
            xq, yq = PX[q], PY[q]
            for i in range(n):
                TOT[i] = TOT[i] + xq[i] + yq[i]
        for i in range(n):
            ok[i] = np.isfinite(TOT[i])
    _rows_of(PX, PY, X, n)
    if gaps:
        for g in range(G):  # np.fmin: a NaN gives the other
            gr = G2[g]
            for i in range(n):
                if not (miss[i] <= gr[i]) and not np.isnan(gr[i]):
                    miss[i] = gr[i]
        for g in range(G):
            gr, xq, yq = G2[g], PX[gap_points[g]], PY[gap_points[g]]
            if n and has_prev[g]:  # Python's min at a chunk's first step, as numpy's
                mv = abs(xq[0] - prev[g, 0]) + abs(yq[0] - prev[g, 1])
                gap[0] = _py_min(gap[0], _py_min(prev[g, 2], gr[0]) - (margin * mv) * (margin * mv))
            for i in range(1, n):  # np.minimum within it: a NaN propagates
                mv = abs(xq[i] - xq[i - 1]) + abs(yq[i] - yq[i - 1])
                gap[i] = _nan_min(gap[i], _nan_min(gr[i], gr[i - 1]) - (margin * mv) * (margin * mv))
            if n:
                prev[g, 0], prev[g, 1], prev[g, 2] = xq[n - 1], yq[n - 1], gr[n - 1]
                has_prev[g] = 1
    # -------------------------------------------------------------------- rates
    for o in range(1, min(order, 2) + 1):
        RX, RY = (VX, VY) if o == 1 else (AX, AY)
        for k in range(K):
            kind, t0, tn, a, b = ops_i[k, 0], ops_i[k, 1], ops_i[k, 2], ops_i[k, 3], ops_i[k, 4]
            if kind == 0:
                wr, ar, bx, by = sdT[b], sddT[b], RX[a], RY[a]
                for t in range(t0, t0 + tn):
                    p = tg_p[t]
                    ox, oy, gx, gy = RX[p], RY[p], GEO[p, 0], GEO[p, 1]
                    if o == 1:
                        for i in range(n):
                            ox[i] = bx[i] + -wr[i] * gy[i]
                            oy[i] = by[i] + wr[i] * gx[i]
                    else:
                        for i in range(n):
                            w2 = wr[i] * wr[i]
                            ox[i] = bx[i] + (-ar[i] * gy[i] - w2 * gx[i])
                            oy[i] = by[i] + (ar[i] * gx[i] - w2 * gy[i])
                continue
            if kind == 1:  # linear in the points: the rates by the same map
                for t in range(t0, t0 + tn):
                    _linear(RX[a], RY[a], RX[b], RY[b], tg_u[t], tg_v[t], RX[tg_p[t]],
                            RY[tg_p[t]], n)
                continue
            p = tg_p[t0]
            ox, oy, d1, d2 = RX[p], RY[p], ops_i[k, 5], ops_i[k, 6]
            if kind == 2:
                e0, e1, e2, e3, e4 = GEO[p, 0], GEO[p, 1], GEO[p, 2], GEO[p, 3], GEO[p, 4]
                ra, rb = _radius_terms(RT[0], d1, sT, sdT, sddT, o, n), _radius_terms(
                    RT[1], d2, sT, sdT, sddT, o, n)  # + 0.0 where the radius is fixed
                xa, ya, xb, yb = RX[a], RY[a], RX[b], RY[b]
                if o == 1:
                    for i in range(n):
                        b1 = (e0[i] * xa[i] + e1[i] * ya[i]) + ra[i]
                        b2 = (e2[i] * xb[i] + e3[i] * yb[i]) + rb[i]
                        ox[i] = (b1 * e3[i] - b2 * e1[i]) * e4[i]
                        oy[i] = (b2 * e0[i] - b1 * e2[i]) * e4[i]
                else:
                    vxp, vyp, vxa, vya, vxb, vyb = VX[p], VY[p], VX[a], VY[a], VX[b], VY[b]
                    for i in range(n):
                        ux, uy, zx, zy = vxp[i] - vxa[i], vyp[i] - vya[i], vxp[i] - vxb[i], vyp[i] - vyb[i]
                        b1 = ((e0[i] * xa[i] + e1[i] * ya[i]) - (ux * ux + uy * uy)) + ra[i]
                        b2 = ((e2[i] * xb[i] + e3[i] * yb[i]) - (zx * zx + zy * zy)) + rb[i]
                        ox[i] = (b1 * e3[i] - b2 * e1[i]) * e4[i]
                        oy[i] = (b2 * e0[i] - b1 * e2[i]) * e4[i]
                continue
            for i in range(n):
                if kind == 3:
                    g1x, g1y = PX[p, i] - PX[a, i], PY[p, i] - PY[a, i]
                    b1 = g1x * RX[a, i] + g1y * RY[a, i]
                    if o == 2:
                        b1 = b1 - _speed2(VX, VY, p, a, i)
                    b1 = _radius_rate(b1, d1, sT, sdT, sddT, i, o)
                else:
                    g1x, g1y, b1 = _line_row(ops_i, ops_f, k, 7, 3, p, PX, PY, VX, VY, AX, AY,
                                             sdT, sddT, i, o)
                g2x, g2y, b2 = _line_row(ops_i, ops_f, k, 12 if kind == 4 else 7,
                                         7 if kind == 4 else 3, p, PX, PY, VX, VY, AX, AY,
                                         sdT, sddT, i, o)
                idet = 1.0 / (g1x * g2y - g1y * g2x)
                ox[i] = (b1 * g2y - b2 * g1y) * idet
                oy[i] = (b2 * g1x - b1 * g2x) * idet
        _rows_of(RX, RY, V if o == 1 else A, n)
    # -------------------------------------------------------------------- links
    if links:  # link by link over the steps, into columns (L, m); the rates then into rows
        for j in range(L):
            xa, ya, xb, yb = PX[link_a[j]], PY[link_a[j]], PX[link_b[j]], PY[link_b[j]]
            cx, cy = LC[0, j], LC[1, j]
            for i in range(n):
                cx[i], cy[i] = xb[i] - xa[i], yb[i] - ya[i]
            if order >= 1:
                vxa, vya, vxb, vyb = VX[link_a[j]], VY[link_a[j]], VX[link_b[j]], VY[link_b[j]]
                cw = LC[2, j]
                for i in range(n):
                    dx, dy = cx[i], cy[i]
                    cw[i] = (dx * (vyb[i] - vya[i]) - dy * (vxb[i] - vxa[i])) / (dx * dx + dy * dy)
            if order >= 2:
                axa, aya, axb, ayb = AX[link_a[j]], AY[link_a[j]], AX[link_b[j]], AY[link_b[j]]
                ca = LC[3, j]
                for i in range(n):
                    dx, dy, wj = cx[i], cy[i], cw[i]
                    n2 = dx * dx + dy * dy
                    ca[i] = ((dx * (ayb[i] - aya[i]) - dy * (axb[i] - axa[i])) / n2
                             - (wj * 2.0) * (dx * (vxb[i] - vxa[i]) + dy * (vyb[i] - vya[i])) / n2)
        if order >= 1:
            for i in range(n):
                for j in range(L):
                    w[i, j] = LC[2, j, i]
        if order >= 2:
            for i in range(n):
                for j in range(L):
                    al[i, j] = LC[3, j, i]


@jit(inline=True)
def _linear(ix, iy, jx, jy, u, v, ox, oy, n):
    """A point of a body from two of its points (or its rates from theirs: the map is linear):
    ``o = i + u d + v perp(d)``, d = j - i (:func:`.dyads._position`'s ``linear``)."""
    for i in range(n):
        dx, dy = jx[i] - ix[i], jy[i] - iy[i]
        ox[i] = ix[i] + (u * dx - v * dy)
        oy[i] = iy[i] + (u * dy + v * dx)


@jit(inline=True)
def _rows_of(CX, CY, R, n):
    """Columns (P, >= n) into rows R (n, P, 2)."""
    for i in range(n):
        for q in range(CX.shape[0]):
            R[i, q, 0], R[i, q, 1] = CX[q, i], CY[q, i]


@jit(inline=True)
def _radius_terms(out, driver, sT, sdT, sddT, o, n):
    """A distance row's right-hand side term of a driven radius r = s at the chunk's steps
    (r r' for order 1, r r'' + r'^2 for 2: :func:`.dyads._plus_radius_rate`), zeros for a fixed
    radius, into ``out`` (>= n,)."""
    if driver < 0:
        for i in range(n):
            out[i] = 0.0
        return out
    r, rd, rdd = sT[driver], sdT[driver], sddT[driver]
    for i in range(n):
        out[i] = r[i] * rd[i] if o == 1 else r[i] * rdd[i] + rd[i] * rd[i]
    return out


@jit(inline=True)
def _radius(r, driver, sT, i):
    """A circle's radius: fixed, or a distance driver's value: :func:`.dyads._radius`."""
    return r if driver < 0 else sT[driver, i]


@jit(inline=True)
def _geometry(ops_i, ops_f, k, ci, cf, PX, PY, sT, i):
    """(ox, oy, tx, ty) of the dyad's line (columns from ``ci`` of ops_i, ``cf`` of ops_f)
    at step i: :func:`.dyads._line_geometry`."""
    kind = ops_i[k, ci]
    if kind == 0:
        return ops_f[k, cf], ops_f[k, cf + 1], ops_f[k, cf + 2], ops_f[k, cf + 3]
    if kind == 1:
        v = sT[ops_i[k, ci + 3], i]
        if ops_i[k, ci + 4] == 0:
            return v, 0.0, 0.0, 1.0
        return 0.0, v, 1.0, 0.0
    d, e = ops_i[k, ci + 1], ops_i[k, ci + 2]
    dx, dy = PX[d, i], PY[d, i]
    wx, wy = PX[e, i] - dx, PY[e, i] - dy
    nn = 1.0 / np.sqrt(wx * wx + wy * wy)
    return dx, dy, wx * nn, wy * nn


@jit(inline=True)
def _line_row(ops_i, ops_f, k, ci, cf, p, PX, PY, VX, VY, AX, AY, sdT, sddT, i, o):
    """The line's row for point p at step i: (gx, gy, the right-hand side of order o):
    :func:`.dyads._rows_line`."""
    kind = ops_i[k, ci]
    if kind == 0:
        return -ops_f[k, cf + 3], ops_f[k, cf + 2], 0.0
    if kind == 1:
        b = sdT[ops_i[k, ci + 3], i] if o == 1 else sddT[ops_i[k, ci + 3], i]
        if ops_i[k, ci + 4] == 0:
            return 1.0, 0.0, b
        return 0.0, 1.0, b
    d, e = ops_i[k, ci + 1], ops_i[k, ci + 2]
    wx, wy = PX[e, i] - PX[d, i], PY[e, i] - PY[d, i]
    fx, fy = PX[p, i] - PX[d, i], PY[p, i] - PY[d, i]
    vdx, vdy = VX[d, i], VY[d, i]
    wdx, wdy = VX[e, i] - vdx, VY[e, i] - vdy
    if o == 1:
        return -wy, wx, (wx * vdy - wy * vdx) - (wdx * fy - wdy * fx)
    vpx, vpy = VX[p, i], VY[p, i]
    adx, ady = AX[d, i], AY[d, i]
    wddx, wddy = AX[e, i] - adx, AY[e, i] - ady
    return -wy, wx, ((wx * ady - wy * adx) - (wddx * fy - wddy * fx)
                     - 2.0 * (wdx * (vpy - vdy) - wdy * (vpx - vdx)))


@jit(inline=True)
def _speed2(VX, VY, p, c, i):
    """|v_p - v_c|^2 at step i: :func:`.dyads._minus_rel_speed2`'s term."""
    rvx, rvy = VX[p, i] - VX[c, i], VY[p, i] - VY[c, i]
    return rvx * rvx + rvy * rvy


@jit(inline=True)
def _radius_rate(b, driver, sT, sdT, sddT, i, o):
    """:func:`.dyads._plus_radius_rate` at step i."""
    if driver < 0:
        return b
    r, rd = sT[driver, i], sdT[driver, i]
    if o == 1:
        return b + r * rd
    return b + (r * sddT[driver, i] + rd * rd)


@jit(inline=True)
def _nan_min(a, b):
    """np.minimum of two numbers: a NaN in either gives NaN."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@jit(inline=True)
def _py_min(a, b):
    """Python's min(a, b): a unless b < a."""
    return b if b < a else a
