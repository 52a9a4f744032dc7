"""Sweep speed of linkpipe against a hand-written closed form and pylinkage+numba, in one run.

    .venv/bin/python benchmarks/bench_sweep.py            # everything (about 30 s on a quiet machine)
    .venv/bin/python benchmarks/bench_sweep.py --write-docs  # and into docs/performance.md
    .venv/bin/python benchmarks/bench_sweep.py --quick    # 36k steps only, no pipeline runs

Part 1, the crank-rocker of ``configs/fourbar_crank_rocker.toml`` (crank 1, coupler 3.5, rocker
3, ground 4, coupler point P), one crank turn at 10 rad/s in 36k and 360k steps; every tool
returns positions, velocities and accelerations of all five points, arrays (S, 5, 2):

* linkpipe dyads kernel: ``linkpipe.kinematics.solve_sweep`` with ``method = "auto"`` (the
  positions part of stage 1 only: the dyad chain, the start assembly, the branch check, the
  residuals, the statuses, and the dyads' velocities and accelerations; no link angles, no
  condition, no link rates, no forces, statuses or Result);
* linkpipe stage 1: ``linkpipe.stage1.Stage1(...).whole()``, what ``run`` and ``solve`` run
  for stage 1 (the kernel above, then link angles unwrapped, the condition and the link rates);
* linkpipe ``run`` end to end: ``python -m linkpipe run SCENE --no-h5 --no-rrd`` (its
  ``main``, in this process: the scene read and checked, stage 1, statuses, the summary),
  the marginal of the sweep: the run at S steps less the same run at 361 steps;
* linkpipe general path: ``linkpipe.kinematics.solve_sweep`` with ``method = "newton"`` and
  ``linkpipe.kinematics.derivatives`` (coarse sequential continuation, then batched Newton from
  Hermite predictions; velocities and accelerations by sparse solves);
* the closed form: Norton's four-bar written out in plain numpy for this one mechanism (circle
  intersection, then the 2x2 velocity and acceleration systems by Cramer's rule), whole arrays;
* hand-written numpy stage 1: every array ``run`` stores for this sweep (positions, velocities,
  accelerations, link angles unwrapped and their rates, the residual of the six rows, the exact
  1-norm condition of the 6x6 Jacobian by its 2x2 blocks, statuses), written out in plain
  numpy for this one mechanism, in cache-sized chunks (a reference for what specialised numpy
  costs; not a bound: at 36k steps linkpipe's general run is faster than it);
* numba-compiled stage 1: the same arrays as one compiled loop over the steps, when numba is
  installed (the ``bench`` extra): what a compiled kernel of this one mechanism costs;
* pylinkage 1.3 ``step_fast_with_kinematics`` (numba), when installed (``pip install -e .[bench]``).

Times are the best of several calls after a warm-up; errors are the largest deviation from the
closed form (itself exact to rounding), relative to the largest magnitude of that quantity.

The targets of issue 29 print beside them: ``run``'s marginal at 360k steps against
pylinkage+numba's warm kernel (>= 2x), and the .h5 write's marginal (a run with the .h5 less
one without) against the disk's own floor for the same bytes (write, fsync, rename of a file
of that size in the same folder, in this run: <= 1.25x).

Part 2, the whole pipeline in a fresh process per case (seconds per stage after the imports,
peak resident memory): the crank-rocker with 100,000 steps and every effect on, and the Jansen
linkage (``configs/jansen.toml`` when present), each written to .h5 and .rrd; and
``python -m linkpipe run configs/*.toml`` from a cold process.
"""
from __future__ import annotations

import argparse
import atexit
import datetime
import json
import math
import os
import pathlib
import platform
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

A_, B_, C_, D_ = 1.0, 3.5, 3.0, 4.0  # crank, coupler, rocker, ground
U_, V_ = 1.5, 0.8  # coupler point in the coupler's frame
OMEGA = 10.0
POINTS = ("O2", "A", "B", "O4", "P")  # the scene's point order


# ------------------------------------------------------------------------------------ tools

def scratch(prefix: str = "linkpipe_bench_") -> pathlib.Path:
    """A new temporary folder, removed when this process exits (a benchmark's outputs reach
    gigabytes: a 10M-step .h5 is 3.6 GB)."""
    folder = pathlib.Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, folder, True)
    return folder

def closed_form(theta: np.ndarray, omega: float = OMEGA, alpha: float = 0.0):
    """Return X, V, A (S, 5, 2) of the crank-rocker at crank angles theta: plain numpy."""
    a, b, c, d, u, v = A_, B_, C_, D_, U_, V_
    S = len(theta)
    ct, st = np.cos(theta), np.sin(theta)
    Ax, Ay = a * ct, a * st
    VAx, VAy = -a * omega * st, a * omega * ct
    AAx, AAy = -a * omega**2 * ct - a * alpha * st, -a * omega**2 * st + a * alpha * ct
    # B: circle(A, b) and circle(O4, c), on the left of A -> O4
    dx, dy = d - Ax, -Ay
    d2 = dx * dx + dy * dy
    k = 0.5 + 0.5 * (b * b - c * c) / d2
    h = np.sqrt(b * b / d2 - k * k)
    Bx, By = Ax + k * dx - h * dy, Ay + k * dy + h * dx
    # velocity: (B - A).(VB - VA) = 0, (B - O4).VB = 0
    e1x, e1y, e2x, e2y = Bx - Ax, By - Ay, Bx - d, By
    det = e1x * e2y - e1y * e2x
    b1 = e1x * VAx + e1y * VAy
    VBx, VBy = b1 * e2y / det, -b1 * e2x / det
    rvx, rvy = VBx - VAx, VBy - VAy
    g1 = e1x * AAx + e1y * AAy - (rvx * rvx + rvy * rvy)
    g2 = -(VBx * VBx + VBy * VBy)
    ABx, ABy = (g1 * e2y - g2 * e1y) / det, (e1x * g2 - e2x * g1) / det
    # P on the coupler
    al, be = u / b, v / b
    Px, Py = Ax + al * e1x - be * e1y, Ay + al * e1y + be * e1x
    VPx, VPy = VAx + al * rvx - be * rvy, VAy + al * rvy + be * rvx
    rax, ray = ABx - AAx, ABy - AAy
    APx, APy = AAx + al * rax - be * ray, AAy + al * ray + be * rax
    X = np.zeros((S, 5, 2))
    V = np.zeros((S, 5, 2))
    A = np.zeros((S, 5, 2))
    X[:, 3, 0] = d
    for arr, cols in ((X, (Ax, Ay, Bx, By, Px, Py)), (V, (VAx, VAy, VBx, VBy, VPx, VPy)),
                      (A, (AAx, AAy, ABx, ABy, APx, APy))):
        for n, (i, j) in enumerate(((1, 0), (1, 1), (2, 0), (2, 1), (4, 0), (4, 1))):
            arr[:, i, j] = cols[n]
    return X, V, A


def closed_form_chunked(theta, chunk=8192):
    """The same closed form in cache-sized chunks (what linkpipe's fast path does)."""
    S = len(theta)
    X, V, A = (np.empty((S, 5, 2)) for _ in range(3))
    for lo in range(0, S, chunk):
        x, v, a = closed_form(theta[lo:lo + chunk])
        X[lo:lo + chunk], V[lo:lo + chunk], A[lo:lo + chunk] = x, v, a
    return X, V, A


def _crank_rocker_motion(th, omega):
    """The crank-rocker's closed form at crank angles ``th`` (an array, or one float in the
    compiled loop) and constant rate ``omega``: (cos, sin, then A, its velocity and
    acceleration, the coupler and rocker vectors, B's, the relative velocity, P's, ...), the
    one source of :func:`numpy_stage1`'s and :func:`compiled_stage1`'s kinematics."""
    a, b, c, d, u, v = A_, B_, C_, D_, U_, V_
    al, be = u / b, v / b
    ct, st = np.cos(th), np.sin(th)
    Ax, Ay = a * ct, a * st
    VAx, VAy = -omega * Ay, omega * Ax
    w2 = omega * omega
    AAx, AAy = -w2 * Ax, -w2 * Ay
    dx, dy = d - Ax, -Ay
    inv = 1.0 / (dx * dx + dy * dy)
    k = 0.5 + 0.5 * (b * b - c * c) * inv
    h = np.sqrt(b * b * inv - k * k)
    e1x, e1y = k * dx - h * dy, k * dy + h * dx
    Bx, By = Ax + e1x, Ay + e1y
    e2x, e2y = Bx - d, By
    idet = 1.0 / (e1x * e2y - e1y * e2x)
    b1 = e1x * VAx + e1y * VAy
    VBx, VBy = b1 * e2y * idet, -b1 * e2x * idet
    rvx, rvy = VBx - VAx, VBy - VAy
    g1 = e1x * AAx + e1y * AAy - (rvx * rvx + rvy * rvy)
    g2 = -(VBx * VBx + VBy * VBy)
    ABx, ABy = (g1 * e2y - g2 * e1y) * idet, (e1x * g2 - e2x * g1) * idet
    Px, Py = Ax + al * e1x - be * e1y, Ay + al * e1y + be * e1x
    VPx, VPy = VAx + al * rvx - be * rvy, VAy + al * rvy + be * rvx
    rax, ray = ABx - AAx, ABy - AAy
    APx, APy = AAx + al * rax - be * ray, AAy + al * ray + be * rax
    return (ct, st, Ax, Ay, VAx, VAy, AAx, AAy, e1x, e1y, Bx, By, e2x, e2y, VBx, VBy, rvx, rvy,
            ABx, ABy, Px, Py, VPx, VPy, rax, ray, APx, APy)


#: :func:`_crank_rocker_motion` compiled (set by :func:`_compiled` before the loop that calls it)
_motion_compiled = None


def numpy_stage1(theta, omega=OMEGA, chunk=8192):
    """Every array ``run`` stores for the crank-rocker's sweep at constant crank rate, in plain
    numpy written for this one mechanism, in cache-sized chunks: positions, velocities and
    accelerations (S, 5, 2), the three links' angles unwrapped, angular velocities and
    accelerations (S, 3), the residual max |Phi| of the six rows, the exact 1-norm condition of
    the 6x6 Jacobian (block-triangular inverse by 2x2 blocks), and each step's status."""
    S = len(theta)
    a, b, c, d, u, v = A_, B_, C_, D_, U_, V_
    al, be = u / b, v / b
    X = np.empty((S, 5, 2)); V = np.empty((S, 5, 2)); A = np.empty((S, 5, 2))
    for arr in (X, V, A):
        arr[:, 0] = 0.0; arr[:, 3] = 0.0
    X[:, 3, 0] = d
    ang = np.empty((S, 3)); W = np.empty((S, 3)); AL = np.empty((S, 3))
    res = np.empty(S); cond = np.empty(S); status = np.empty(S, np.int8)
    for lo in range(0, S, chunk):
        hi = min(S, lo + chunk)
        th = theta[lo:hi]
        (ct, st, Ax, Ay, VAx, VAy, AAx, AAy, e1x, e1y, Bx, By, e2x, e2y, VBx, VBy, rvx, rvy,
         ABx, ABy, Px, Py, VPx, VPy, rax, ray, APx, APy) = _crank_rocker_motion(th, omega)
        for arr, cols in ((X, (Ax, Ay, Bx, By, Px, Py)), (V, (VAx, VAy, VBx, VBy, VPx, VPy)),
                          (A, (AAx, AAy, ABx, ABy, APx, APy))):
            blk = arr[lo:hi]
            blk[:, 1, 0], blk[:, 1, 1], blk[:, 2, 0], blk[:, 2, 1], blk[:, 4, 0], blk[:, 4, 1] = cols
        # link angles and rates: crank (O2 A), coupler (A B), rocker (O4 B)
        an = ang[lo:hi]; wn = W[lo:hi]; aln = AL[lo:hi]
        an[:, 0] = np.arctan2(Ay, Ax); an[:, 1] = np.arctan2(e1y, e1x); an[:, 2] = np.arctan2(e2y, e2x)
        wn[:, 0] = omega
        aln[:, 0] = 0.0
        for j, (ex, ey, vx, vy, ax_, ay_) in ((1, (e1x, e1y, rvx, rvy, rax, ray)),
                                               (2, (e2x, e2y, VBx, VBy, ABx, ABy))):
            il2 = 1.0 / (ex * ex + ey * ey)
            wj = (ex * vy - ey * vx) * il2
            wn[:, j] = wj
            aln[:, j] = (ex * ay_ - ey * ax_) * il2 - 2.0 * (ex * vx + ey * vy) * il2 * wj
        # residual: the six rows
        r = np.abs(Ax * Ax + Ay * Ay - a * a)
        np.maximum(r, np.abs(Ay * ct - Ax * st), out=r)
        np.maximum(r, np.abs(e1x * e1x + e1y * e1y - b * b), out=r)
        np.maximum(r, np.abs(e2x * e2x + e2y * e2y - c * c), out=r)
        res[lo:hi] = r  # P's two rows hold by construction here; a general code evaluates them
        # condition: J = [[DA, 0, 0], [NB, DB, 0], [NPA, NPB, I]] (rows: crank length, crank
        # angle; coupler length, rocker length; P's two local rows), unknowns A, B, P
        # DA = [[2Ax, 2Ay], [-st, ct]], NB = [[-2e1x, -2e1y], [0, 0]], DB = [[2e1x, 2e1y], [2e2x, 2e2y]]
        # NPA = -(1 - al) I - be Rp, NPB = -al I + be Rp (Rp = [[0, -1], [1, 0]])
        dA = 1.0 / (2 * Ax * ct + 2 * Ay * st)
        iA = ((ct * dA, -2 * Ay * dA), (st * dA, 2 * Ax * dA))          # DA^-1
        dB = 1.0 / (4 * (e1x * e2y - e1y * e2x))
        iB = ((2 * e2y * dB, -2 * e1y * dB), (-2 * e2x * dB, 2 * e1x * dB))  # DB^-1
        # block (B, A) of J^-1: -DB^-1 NB DA^-1 (NB's second row is zero)
        t0 = -2 * e1x * iA[0][0] - 2 * e1y * iA[1][0]
        t1 = -2 * e1x * iA[0][1] - 2 * e1y * iA[1][1]  # NB DA^-1, first row
        xBA = ((-iB[0][0] * t0, -iB[0][0] * t1), (-iB[1][0] * t0, -iB[1][0] * t1))
        # block (P, A): -(NPA DA^-1 + NPB xBA); block (P, B): -NPB DB^-1
        def mul(M, N):
            return ((M[0][0] * N[0][0] + M[0][1] * N[1][0], M[0][0] * N[0][1] + M[0][1] * N[1][1]),
                    (M[1][0] * N[0][0] + M[1][1] * N[1][0], M[1][0] * N[0][1] + M[1][1] * N[1][1]))
        NPA = ((-(1 - al), be), (-be, -(1 - al)))
        NPB = ((-al, -be), (be, -al))
        m1, m2 = mul(NPA, iA), mul(NPB, xBA)
        xPA = tuple(tuple(-(m1[i][j] + m2[i][j]) for j in range(2)) for i in range(2))
        m3 = mul(NPB, iB)
        xPB = tuple(tuple(-m3[i][j] for j in range(2)) for i in range(2))
        inv1 = None
        for j in range(2):  # columns of A's block
            s_ = np.abs(iA[0][j]) + np.abs(iA[1][j]) + np.abs(xBA[0][j]) + np.abs(xBA[1][j]) \
                + np.abs(xPA[0][j]) + np.abs(xPA[1][j])
            inv1 = s_ if inv1 is None else np.maximum(inv1, s_)
        for j in range(2):
            np.maximum(inv1, np.abs(iB[0][j]) + np.abs(iB[1][j]) + np.abs(xPB[0][j]) + np.abs(xPB[1][j]), out=inv1)
        np.maximum(inv1, 1.0, out=inv1)  # P's identity block
        # |J|_1: column sums
        n1 = 2 * np.abs(Ax) + np.abs(st) + 2 * np.abs(e1x) + abs(1 - al) + be
        np.maximum(n1, 2 * np.abs(Ay) + np.abs(ct) + 2 * np.abs(e1y) + be + abs(1 - al), out=n1)
        np.maximum(n1, 2 * np.abs(e1x) + 2 * np.abs(e2x) + al + be, out=n1)
        np.maximum(n1, 2 * np.abs(e1y) + 2 * np.abs(e2y) + be + al, out=n1)
        np.maximum(n1, 1.0, out=n1)
        cn = n1 * inv1
        cond[lo:hi] = cn
        status[lo:hi] = np.where(np.isfinite(cn) & (cn * 1e-12 < 1.0), 0, 2)
    ang[:] = np.unwrap(ang, axis=0)
    return X, V, A, ang, W, AL, res, cond, status


def stage1_condition_error(theta) -> float:
    """The hand-written stage 1's condition against numpy's dense 1-norm condition (``np.linalg.cond(J, 1)``)
    of the same Jacobians, largest relative difference: its block inverse is right."""
    out = numpy_stage1(theta)
    X = out[0]; cond = out[7]
    b = B_
    al, be = U_ / b, V_ / b
    J = np.zeros((len(theta), 6, 6))
    Ax, Ay = X[:, 1, 0], X[:, 1, 1]
    e1 = X[:, 2] - X[:, 1]; e2 = X[:, 2] - X[:, 3]
    ct, st = np.cos(theta), np.sin(theta)
    J[:, 0, 0], J[:, 0, 1] = 2 * Ax, 2 * Ay
    J[:, 1, 0], J[:, 1, 1] = -st, ct
    J[:, 2, 0], J[:, 2, 1], J[:, 2, 2], J[:, 2, 3] = -2 * e1[:, 0], -2 * e1[:, 1], 2 * e1[:, 0], 2 * e1[:, 1]
    J[:, 3, 2], J[:, 3, 3] = 2 * e2[:, 0], 2 * e2[:, 1]
    NPA = np.array([[-(1 - al), be], [-be, -(1 - al)]]); NPB = np.array([[-al, -be], [be, -al]])
    J[:, 4:6, 0:2] = NPA; J[:, 4:6, 2:4] = NPB; J[:, 4:6, 4:6] = np.eye(2)
    ref = np.linalg.cond(J, 1)
    return float(np.max(np.abs(cond / ref - 1)))

def _compiled_stage1_kernel(theta, omega, X, V, A, ang, W, AL, res, cond, status):
    a, b, c, d, u, v = 1.0, 3.5, 3.0, 4.0, 1.5, 0.8
    al, be = u / b, v / b
    S = theta.shape[0]
    prev = np.zeros(3); corr = np.zeros(3)
    for i in range(S):
        th = theta[i]
        (ct, st, Ax, Ay, VAx, VAy, AAx, AAy, e1x, e1y, Bx, By, e2x, e2y, VBx, VBy, rvx, rvy,
         ABx, ABy, Px, Py, VPx, VPy, rax, ray, APx, APy) = _motion_compiled(th, omega)
        X[i, 0, 0] = 0.0; X[i, 0, 1] = 0.0; X[i, 3, 0] = d; X[i, 3, 1] = 0.0
        X[i, 1, 0] = Ax; X[i, 1, 1] = Ay; X[i, 2, 0] = Bx; X[i, 2, 1] = By; X[i, 4, 0] = Px; X[i, 4, 1] = Py
        for p in (0, 3):
            V[i, p, 0] = 0.0; V[i, p, 1] = 0.0; A[i, p, 0] = 0.0; A[i, p, 1] = 0.0
        V[i, 1, 0] = VAx; V[i, 1, 1] = VAy; V[i, 2, 0] = VBx; V[i, 2, 1] = VBy; V[i, 4, 0] = VPx; V[i, 4, 1] = VPy
        A[i, 1, 0] = AAx; A[i, 1, 1] = AAy; A[i, 2, 0] = ABx; A[i, 2, 1] = ABy; A[i, 4, 0] = APx; A[i, 4, 1] = APy
        raw0 = math.atan2(Ay, Ax); raw1 = math.atan2(e1y, e1x); raw2 = math.atan2(e2y, e2x)
        for j, r in ((0, raw0), (1, raw1), (2, raw2)):
            if i > 0:
                dd = r - prev[j]
                if not abs(dd) < math.pi:
                    m = (dd + math.pi) % (2 * math.pi) - math.pi
                    corr[j] += m - dd
            prev[j] = r
            ang[i, j] = r + corr[j]
        W[i, 0] = omega; AL[i, 0] = 0.0
        il2 = 1.0 / (e1x * e1x + e1y * e1y)
        wj = (e1x * rvy - e1y * rvx) * il2
        W[i, 1] = wj; AL[i, 1] = (e1x * ray - e1y * rax) * il2 - 2.0 * (e1x * rvx + e1y * rvy) * il2 * wj
        il2 = 1.0 / (e2x * e2x + e2y * e2y)
        wj = (e2x * VBy - e2y * VBx) * il2
        W[i, 2] = wj; AL[i, 2] = (e2x * ABy - e2y * ABx) * il2 - 2.0 * (e2x * VBx + e2y * VBy) * il2 * wj
        r = abs(Ax * Ax + Ay * Ay - a * a)
        r = max(r, abs(Ay * ct - Ax * st)); r = max(r, abs(e1x * e1x + e1y * e1y - b * b))
        r = max(r, abs(e2x * e2x + e2y * e2y - c * c))
        res[i] = r
        dA = 1.0 / (2 * Ax * ct + 2 * Ay * st)
        iA00, iA01, iA10, iA11 = ct * dA, -2 * Ay * dA, st * dA, 2 * Ax * dA
        dB = 1.0 / (4 * (e1x * e2y - e1y * e2x))
        iB00, iB01, iB10, iB11 = 2 * e2y * dB, -2 * e1y * dB, -2 * e2x * dB, 2 * e1x * dB
        t0 = -2 * e1x * iA00 - 2 * e1y * iA10
        t1 = -2 * e1x * iA01 - 2 * e1y * iA11
        x00, x01, x10, x11 = -iB00 * t0, -iB00 * t1, -iB10 * t0, -iB10 * t1
        n00, n01, n10, n11 = -(1 - al), be, -be, -(1 - al)
        q00, q01, q10, q11 = -al, -be, be, -al
        m00 = n00 * iA00 + n01 * iA10 + q00 * x00 + q01 * x10
        m01 = n00 * iA01 + n01 * iA11 + q00 * x01 + q01 * x11
        m10 = n10 * iA00 + n11 * iA10 + q10 * x00 + q11 * x10
        m11 = n10 * iA01 + n11 * iA11 + q10 * x01 + q11 * x11
        p00 = -(q00 * iB00 + q01 * iB10); p01 = -(q00 * iB01 + q01 * iB11)
        p10 = -(q10 * iB00 + q11 * iB10); p11 = -(q10 * iB01 + q11 * iB11)
        c0 = abs(iA00) + abs(iA10) + abs(x00) + abs(x10) + abs(m00) + abs(m10)
        c1 = abs(iA01) + abs(iA11) + abs(x01) + abs(x11) + abs(m01) + abs(m11)
        c2 = abs(iB00) + abs(iB10) + abs(p00) + abs(p10)
        c3 = abs(iB01) + abs(iB11) + abs(p01) + abs(p11)
        inv1 = max(max(c0, c1), max(max(c2, c3), 1.0))
        n1 = 2 * abs(Ax) + abs(st) + 2 * abs(e1x) + abs(1 - al) + be
        n1 = max(n1, 2 * abs(Ay) + abs(ct) + 2 * abs(e1y) + be + abs(1 - al))
        n1 = max(n1, 2 * abs(e1x) + 2 * abs(e2x) + al + be)
        n1 = max(n1, 2 * abs(e1y) + 2 * abs(e2y) + be + al)
        n1 = max(n1, 1.0)
        cn = n1 * inv1
        cond[i] = cn
        status[i] = 0 if (cn * 1e-12 < 1.0) else 2


def compiled_stage1(theta, omega: float = OMEGA):
    """What :func:`numpy_stage1` computes, as one numba-compiled loop over the steps (the
    rocker's and coupler's angles unwrapped as it goes): what a compiled stage 1 of this one
    mechanism costs (a reference for issue 29, no target). None without numba."""
    kernel = _compiled()
    if kernel is None:
        return None
    S = len(theta)
    out = (np.empty((S, 5, 2)), np.empty((S, 5, 2)), np.empty((S, 5, 2)), np.empty((S, 3)),
           np.empty((S, 3)), np.empty((S, 3)), np.empty(S), np.empty(S), np.empty(S, np.int8))
    kernel(theta, omega, *out)
    return out


_COMPILED = []


def _compiled():
    if not _COMPILED:
        try:
            import numba
        except ImportError:
            _COMPILED.append(None)
        else:
            global _motion_compiled
            _motion_compiled = numba.njit(cache=True)(_crank_rocker_motion)
            _COMPILED.append(numba.njit(cache=True)(_compiled_stage1_kernel))
    return _COMPILED[0]


def linkpipe_model(S: int, method: str = "auto"):
    import dataclasses as dc

    import linkpipe
    from linkpipe.model import build_model

    scene = linkpipe.load_scene(str(ROOT / "configs" / "fourbar_crank_rocker.toml"))
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=S, step=None) for d in scene.drivers),
                       solver=dc.replace(scene.solver, method=method))
    model = build_model(scene)
    assert model.point_names == POINTS
    return model


def linkpipe_fast(model, theta):
    from linkpipe import kinematics as kin

    S = len(theta)
    out = kin.solve_sweep(model, theta[:, None], np.full((S, 1), OMEGA), np.zeros((S, 1)), order=2)
    assert out.method == "dyads"
    return out.position, out.velocity, out.acceleration


def linkpipe_newton(model, theta):
    from linkpipe import kinematics as kin

    S = len(theta)
    s, s_dot, s_ddot = theta[:, None], np.full((S, 1), OMEGA), np.zeros((S, 1))
    out = kin.solve_sweep(model, s, s_dot, s_ddot, order=2)  # positions, as the pipeline runs them
    assert out.method == "newton"
    der = kin.derivatives(model, out.position, s, s_dot, s_ddot, out.status, True)
    return out.position, der["velocity"], der["acceleration"]


def linkpipe_stage1(model, theta):
    """Stage 1 as ``run`` and ``solve`` run it (``model``'s scene, its own sweep of len(theta)
    steps from 0 to 360 deg at 10 rad/s): positions, velocities, accelerations."""
    from linkpipe.spine import Stages
    from linkpipe.stage1 import Stage1

    k = Stage1(model.scene, model, Stages.of(model.scene)).whole()
    assert k.sweep.method == "dyads"
    return k.sweep.position, k.velocity, k.acceleration


def scene_file(S: int, folder: pathlib.Path) -> pathlib.Path:
    """The crank-rocker's scene with S steps (velocities and accelerations as it asks for)."""
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    path = folder / f"crank_rocker_{S}.toml"
    path.write_text(text.replace("steps = 361", f"steps = {S}").replace(
        'name = "fourbar_crank_rocker"', f'name = "crank_rocker_{S}"'))
    return path


def run_once(S: int, folder: pathlib.Path, h5: bool) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``python -m linkpipe run`` (its ``main`` in this process) on
    the crank-rocker of S steps, without the .rrd, with or without the .h5 (CPU:
    ``time.process_time``, every thread of this process), measured on the same run."""
    from linkpipe.__main__ import main

    argv = ["run", str(scene_file(S, folder)), "--out", str(folder / "out"), "--quiet", "--no-rrd"]
    argv += [] if h5 else ["--no-h5"]
    c0, t0 = time.process_time(), time.perf_counter()
    assert main(argv) == 0
    return time.perf_counter() - t0, time.process_time() - c0


def run_cli(S: int, folder: pathlib.Path, h5: bool, repeats: int, cpu: bool = False):
    """Best seconds of :func:`run_once` over ``repeats`` runs; with ``cpu``, (best wall
    seconds, best CPU seconds)."""
    runs = [run_once(S, folder, h5) for _ in range(repeats)]
    best = min(w for w, _ in runs)
    return (best, min(c for _, c in runs)) if cpu else best


def disk_write(n_bytes: int, folder: pathlib.Path):
    """A function that writes ``n_bytes`` to a new file in ``folder``, fsyncs it and renames it
    into place (over the last one, as a run's file replaces its last)."""
    data = np.random.default_rng(0).bytes(n_bytes)

    def once():
        tmp, final = folder / ".floor.tmp", folder / "floor.bin"
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, final)

    return once


class _Compiled:
    """``LINKPIPE_COMPILED`` set to ``flag`` (None: unset) while inside (the process's choice
    of stage 1's compiled loops: linkpipe.kinematics.compiled)."""

    def __init__(self, flag):
        self.flag = flag

    def __enter__(self):
        self.before = os.environ.pop("LINKPIPE_COMPILED", None)
        if self.flag is not None:
            os.environ["LINKPIPE_COMPILED"] = self.flag

    def __exit__(self, *exc):
        os.environ.pop("LINKPIPE_COMPILED", None)
        if self.before is not None:
            os.environ["LINKPIPE_COMPILED"] = self.before


def run_targets(S: int, repeats: int, pylinkage_seconds: float | None,
                pylinkage_cpu: float | None = None, floor_cpu: float | None = None):
    """Issue 29's targets at S steps: run's marginal against pylinkage's warm kernel, the .h5
    write's marginal against the disk's floor. The runs with and without the .h5 alternate
    (pairs of one each): the write's marginal is the median of the pairs' differences, and
    their spread says how far the machine's noise reaches.

    Two marginals, as a user meets them: with numpy's stage 1 (LINKPIPE_COMPILED=0: what a
    process that has not loaded the compiled loops runs for a sweep shorter than
    ``compiled.COLD_FROM``), and with the compiled loops loaded (as after any long sweep in the
    process, the comparison with pylinkage's warm kernel: both leave their one-time load out,
    and both loads are printed)."""
    from linkpipe.kinematics import compiled

    folder = scratch()
    with _Compiled("0"):
        numpy_cpu = run_cli(S, folder, False, repeats, cpu=True)[1]
    was_loaded = compiled.loaded()
    with _Compiled("1"):
        t0 = time.perf_counter()
        run_cli(361, folder, False, 1)  # the first call loads them (numba, its cache)
        load = time.perf_counter() - t0
    # linkpipe's own choice once the loops are loaded (a sweep shorter than WARM_FROM, as
    # --quick's, would keep numpy: the loops asked for there)
    with _Compiled(None if S >= compiled.WARM_FROM else "1"):
        assert compiled.wanted(S), "the compiled loops should be loaded now"
        # the short and the long run alternately, each run's wall and CPU seconds together:
        # the best of each in the same minutes (the machine's noise drifts)
        # (and pylinkage's warm kernel beside them, where it is installed: the ratio's two
        # sides from the same minutes)
        with_pyl = pylinkage_seconds is not None
        runs, pyl = [], []
        for _ in range(2 * repeats + 1):
            runs.append((run_once(361, folder, False), run_once(S, folder, False)))
            if with_pyl:
                pyl.append(pylinkage_run(S, cpu=True)[-2:])
        small, small_cpu = min(a[0] for a, _ in runs), min(a[1] for a, _ in runs)
        big_cpu = min(b[1] for _, b in runs)
        if with_pyl:
            pylinkage_seconds = min(w for w, _ in pyl)
            pylinkage_cpu = min(c for _, c in pyl)
        run_cli(S, folder, True, 1)  # warm: the file's folder, the writer's thread
        n_bytes = (folder / "out" / f"crank_rocker_{S}.h5").stat().st_size
        write = disk_write(n_bytes, folder)
        write()
        # triples in the same minutes: the run without and with its file, and the disk's own
        # durable write of as many bytes; each compared by its median
        triples = [(run_cli(S, folder, False, 1), run_cli(S, folder, True, 1), best_of(write, 1)[0])
                   for _ in range(max(5, 2 * repeats + 1))]
    bare, with_h5 = min(p[0] for p in triples), min(p[1] for p in triples)
    diffs = sorted(h - b for b, h, _ in triples)
    floors = sorted(f for _, _, f in triples)
    floor = floors[len(floors) // 2]
    bare = min(bare, min(b[0] for _, b in runs))
    return dict(steps=S, run_361=small, run=bare, run_361_cpu=small_cpu, run_cpu=big_cpu,
                numpy_cpu=numpy_cpu, load=None if was_loaded else load,
                pylinkage_cpu=pylinkage_cpu, floor_cpu=floor_cpu, run_h5=with_h5, h5_bytes=n_bytes,
                floor=floor, floor_best=floors[0], pylinkage=pylinkage_seconds,
                write=diffs[len(diffs) // 2], write_spread=(diffs[0], diffs[-1]),
                n_triples=len(triples))


def fresh_runs(steps=(360_000, 5_000_000)) -> list[tuple]:
    """``python -m linkpipe run`` of the crank-rocker with S steps (--no-h5 --no-rrd), each in
    a fresh process (imports and loads included, wall and CPU seconds of the process), with
    linkpipe's own choice of path and with each path forced: what one command costs."""
    folder = scratch("linkpipe_fresh_")
    out = []
    for S in steps:
        scene = scene_file(S, folder)
        for flag in (None, "0", "1"):
            env = {k: v for k, v in os.environ.items() if k != "LINKPIPE_COMPILED"}
            if flag is not None:
                env["LINKPIPE_COMPILED"] = flag
            best = (math.inf, math.inf)
            for _ in range(2):
                r0 = os.times()
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "linkpipe", "run", str(scene), "--out",
                                str(folder / "out"), "--quiet", "--no-h5", "--no-rrd"],
                               check=True, env=env, cwd=ROOT)
                wall = time.perf_counter() - t0
                r1 = os.times()
                cpu = (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)
                best = min(best, (wall, cpu))
            out.append((S, flag, *best))
    return out


def print_fresh_runs(rows) -> str:
    what = {None: "linkpipe's choice", "0": "numpy (LINKPIPE_COMPILED=0)",
            "1": "compiled (LINKPIPE_COMPILED=1)"}
    lines = ["One `run --no-h5 --no-rrd` of the crank-rocker in a fresh process (best of 2; "
             "imports, numba's start and cache load included):", "",
             "| steps | stage 1 | wall s | CPU s |", "|---:|---|---:|---:|"]
    lines += [f"| {S:,} | {what[flag]} | {wall:.2f} | {cpu:.2f} |" for S, flag, wall, cpu in rows]
    return "\n".join(lines)


def print_run_targets(r) -> str:
    S = r["steps"]
    marginal = r["run"] - r["run_361"]
    write = r["write"]
    lines = [f"`run` end to end, crank-rocker {S:,} steps, positions + velocities + "
             f"accelerations (`main([...])` in this process, best of several):", "",
             "| what is timed | seconds |", "|---|---:|",
             f"| run --no-h5 --no-rrd, 361 steps | {r['run_361']:.4f} |",
             f"| run --no-h5 --no-rrd, {S:,} steps | {r['run']:.4f} |",
             f"| run --no-rrd (.h5 written, {r['h5_bytes'] / 2**20:.1f} MiB), {S:,} steps | "
             f"{r['run_h5']:.4f} |",
             f"| the sweep's marginal (run at {S:,} less run at 361) | {marginal:.4f} |",
             f"| the sweep's marginal in CPU seconds (process_time, best of each) | "
             f"{r['run_cpu'] - r['run_361_cpu']:.4f} |",
             f"| the .h5 write's marginal (with .h5 less without: median of {r['n_triples']} "
             f"alternating pairs; spread {r['write_spread'][0]:+.4f} .. "
             f"{r['write_spread'][1]:+.4f}) | {write:.4f} |",
             f"| the disk's floor: write + fsync + rename of {r['h5_bytes'] / 2**20:.1f} MiB "
             f"(median of as many, one beside each pair; best {r['floor_best']:.4f}) | "
             f"{r['floor']:.4f} |", ""]
    if r["pylinkage"] is not None and r.get("pylinkage_cpu") is not None:
        # judged in CPU seconds: both are one thread here, and a loaded machine's wall clock
        # counts other jobs' time (one tool's best of a few may fall in a quiet moment, the
        # other's not: 2-4x either way was seen at a load of 5)
        cpu_marginal = r["run_cpu"] - r["run_361_cpu"]
        xc = r["pylinkage_cpu"] / cpu_marginal
        x = r["pylinkage"] / marginal
        lines.append(f"- pylinkage+numba's warm kernel (timed between these runs) / run's "
                     f"marginal with the compiled loops loaded, CPU seconds "
                     f"({r['pylinkage_cpu']:.4f} / {cpu_marginal:.4f}) = {xc:.2f}x (target >= 2x): "
                     f"{'met' if xc >= 2 else 'MISSED'}" + ("" if xc >= 2 else f", by {2 / xc:.1f}x")
                     + f" (wall seconds, not judged: {r['pylinkage']:.4f} / {marginal:.4f} = {x:.2f}x)")
    elif r["pylinkage"] is not None:
        x = r["pylinkage"] / marginal
        lines.append(f"- pylinkage+numba's warm kernel ({r['pylinkage']:.4f} s) / run's marginal = "
                     f"{x:.2f}x (target >= 2x): {'met' if x >= 2 else 'MISSED'}"
                     + ("" if x >= 2 else f", by {2 / x:.1f}x"))
    else:
        lines.append("- run's marginal vs pylinkage+numba: pylinkage not installed, not measured")
    if r["pylinkage"] is not None and r.get("pylinkage_cpu") is not None:
        numpy_marginal = r["numpy_cpu"] - r["run_361_cpu"]
        lines.append(f"- the same with numpy's stage 1 (a process that has not loaded them, "
                     f"LINKPIPE_COMPILED=0), CPU seconds ({r['pylinkage_cpu']:.4f} / "
                     f"{numpy_marginal:.4f}) = {r['pylinkage_cpu'] / numpy_marginal:.2f}x "
                     f"(no target)")
    if r.get("load") is not None:
        lines.append(f"- loading the compiled loops (numba's import and start, its cached "
                     f"machine code), once per process: {r['load']:.2f} s (pylinkage's first "
                     f"call is printed above)")
    if r.get("floor_cpu"):
        cpu_marginal = r["run_cpu"] - r["run_361_cpu"]
        lines.append(f"- run's marginal / hand-written numpy stage 1, CPU seconds "
                     f"({cpu_marginal:.4f} / {r['floor_cpu']:.4f}) = "
                     f"{cpu_marginal / r['floor_cpu']:.2f}x (a reference, no target)")
    y = write / r["floor"]
    lo, hi = r["write_spread"]
    resolved = hi - lo < 0.5 * r["floor"]
    lines.append(f"- .h5 write's marginal / the disk's floor = {y:.2f}x (target <= 1.25x): "
                 + (("met" if y <= 1.25 else "MISSED") if resolved else
                    "not resolved (the pairs' spread is more than half the floor: "
                    "re-run on a quiet machine)"))
    return "\n".join(lines)


def pylinkage_available() -> str:
    try:
        import numba  # noqa: F401
        import pylinkage
    except ImportError as err:
        return f"not installed ({err.name}); pip install -e '.[bench]'"
    return f"pylinkage {pylinkage.__version__}, numba {numba.__version__}"


def pylinkage_run(S: int, cpu: bool = False):
    """Return X, V, A (S, 5, 2) from pylinkage's numba solver, in the scene's point order, and
    its kernel's wall seconds (and, with ``cpu``, its CPU seconds: ``time.process_time``)."""
    import pylinkage as pl

    dth = 2 * math.pi / (S - 1)
    O2 = pl.Ground(0.0, 0.0, name="O2")
    O4 = pl.Ground(D_, 0.0, name="O4")
    # the crank advances before each step: start one increment early so step 0 is at 0 rad
    crank = pl.Crank(anchor=O2, radius=A_, angular_velocity=dth, initial_angle=-dth, name="A")
    B = pl.RRRDyad(anchor1=crank.output, anchor2=O4, distance1=B_, distance2=C_,
                   x=3.0417, y=2.8428, name="B")
    P = pl.FixedDyad(anchor1=crank.output, anchor2=B, distance=math.hypot(U_, V_),
                     angle=math.atan2(V_, U_), name="P")
    lk = pl.Linkage([O2, O4, crank, B, P])
    lk.set_input_velocity(crank, omega=OMEGA, alpha=0.0)
    lk.compile()
    t0, c0 = time.perf_counter(), time.process_time()
    pos, vel, acc = lk.step_fast_with_kinematics(iterations=S)
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    order = [0, 2, 3, 1, 4]  # pylinkage's (O2, O4, A, B, P) -> (O2, A, B, O4, P)
    return (pos[:, order], vel[:, order], acc[:, order], seconds) + ((cpu_seconds,) if cpu else ())


def best_cpu_of(fn, repeats: int) -> float:
    """Best CPU seconds (``time.process_time``) of ``fn()`` over ``repeats`` calls."""
    best = math.inf
    for _ in range(repeats):
        c0 = time.process_time()
        fn()
        best = min(best, time.process_time() - c0)
    return best


def best_of(fn, repeats: int):
    """Return (best seconds, last result) of ``repeats`` calls after one warm-up call."""
    result = fn()
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def rel_errors(got, ref):
    return [float(np.nanmax(np.abs(g - r)) / np.abs(r).max()) for g, r in zip(got, ref)]


# ------------------------------------------------------------------------------------ part 1
def part1(sizes, repeats):
    rows = []
    pyl = pylinkage_available()
    first_call = None
    if pyl.startswith("pylinkage"):
        t0 = time.perf_counter()
        pylinkage_run(1000)  # numba: compile, or load the on-disk cache
        first_call = time.perf_counter() - t0
    for S in sizes:
        theta = np.linspace(0.0, 2 * math.pi, S)
        ref = closed_form(theta)
        t_cf, _ = best_of(lambda: closed_form(theta), repeats)
        t_cfc, _ = best_of(lambda: closed_form_chunked(theta), repeats)
        t_floor, got_floor = best_of(lambda: numpy_stage1(theta), repeats)
        cpu_floor = best_cpu_of(lambda: numpy_stage1(theta), repeats)
        compiled = compiled_stage1(theta[:10]) is not None  # compiled (or its cache loaded)
        t_nb, got_nb = best_of(lambda: compiled_stage1(theta), repeats) if compiled else (None, None)
        cpu_nb = best_cpu_of(lambda: compiled_stage1(theta), repeats) if compiled else None
        m_fast = linkpipe_model(S)
        with _Compiled("0"):  # numpy's stage 1: a process that has not loaded the compiled loops
            t_fast, got_fast = best_of(lambda: linkpipe_fast(m_fast, theta), repeats)
            t_stage1, got_stage1 = best_of(lambda: linkpipe_stage1(m_fast, theta), repeats)
        with _Compiled("1"):  # the compiled loops (the first call loads them: not timed)
            linkpipe_stage1(linkpipe_model(100), np.linspace(0.0, 2 * math.pi, 100))
            t_fastc, got_fastc = best_of(lambda: linkpipe_fast(m_fast, theta), repeats)
            t_stage1c, got_stage1c = best_of(lambda: linkpipe_stage1(m_fast, theta), repeats)
        for a, b in zip(got_stage1c + got_fastc, got_stage1 + got_fast):
            np.testing.assert_array_equal(a, b)  # the two paths' numbers: the same to the bit
        m_newton = linkpipe_model(S, "newton")
        t_newton, got_newton = best_of(lambda: linkpipe_newton(m_newton, theta), repeats)
        row = dict(steps=S, closed_form=t_cf, closed_form_chunked=t_cfc, fast=t_fast, newton=t_newton,
                   stage1=t_stage1, fast_compiled=t_fastc, stage1_compiled=t_stage1c, floor=t_floor, floor_cpu=cpu_floor, compiled=t_nb,
                   compiled_cpu=cpu_nb,
                   err_compiled=None if got_nb is None else [
                       rel_errors(got_nb[i:i + 1], got_floor[i:i + 1])[0] for i in range(8)],
                   err_floor=rel_errors(got_floor[:3], ref),
                   floor_condition=stage1_condition_error(theta[:2000]),
                   err_fast=rel_errors(got_fast, ref),
                   err_stage1=rel_errors(got_stage1, ref), err_newton=rel_errors(got_newton, ref))
        if pyl.startswith("pylinkage"):
            best, best_cpu, got = math.inf, math.inf, None
            for _ in range(repeats):
                *got, sec, cpu = pylinkage_run(S, cpu=True)
                best, best_cpu = min(best, sec), min(best_cpu, cpu)
            row["pylinkage"], row["pylinkage_cpu"] = best, best_cpu
            row["err_pylinkage"] = rel_errors(got, ref)
        rows.append(row)
    return rows, pyl, first_call


def print_part1(rows, pyl, first_call):
    lines = []
    lines.append("Crank-rocker sweep, positions + velocities + accelerations of all 5 points "
                 "(configurations/s, best of several; errors relative to the closed form: "
                 "position / velocity / acceleration)")
    lines.append("")
    lines.append("| tool | steps | seconds | configurations/s | vs closed form | max error (x / v / a) |")
    lines.append("|---|---:|---:|---:|---:|---|")
    for r in rows:
        S = r["steps"]
        items = [("linkpipe dyads kernel (kinematics.solve_sweep: positions and rates only), numpy",
                  r["fast"], r["err_fast"]),
                 ("the same, compiled loop (numba; bit for bit the numpy row's numbers)",
                  r["fast_compiled"], r["err_fast"]),
                 ("linkpipe stage 1 as run runs it (Stage1: + link angles, condition, link "
                  "rates), numpy", r["stage1"], r["err_stage1"]),
                 ("the same, compiled loops (as run takes them once loaded in the process)",
                  r["stage1_compiled"], r["err_stage1"]),
                 ("linkpipe general path kernel (Newton positions + kinematics.derivatives)",
                  r["newton"], r["err_newton"]),
                 ("closed form, plain numpy (reference)", r["closed_form"], [0.0, 0.0, 0.0]),
                 ("closed form, numpy in cache-sized chunks", r["closed_form_chunked"], None),
                 ("hand-written numpy stage 1 (every array run stores, for this one "
                  "mechanism, chunked)", r["floor"], r["err_floor"])]
        if r.get("compiled") is not None:
            items.append(("numba-compiled stage 1 (the same arrays, one loop over the steps)",
                          r["compiled"], r["err_compiled"][:3]))
        if "pylinkage" in r:
            items.append(("pylinkage + numba (step_fast_with_kinematics)", r["pylinkage"], r["err_pylinkage"]))
        for name, sec, err in items:
            e = " / ".join(f"{x:.1e}" for x in err) if err is not None else "same as above"
            lines.append(f"| {name} | {S:,} | {sec:.4f} | {S / sec / 1e6:.2f} M | "
                         f"{r['closed_form'] / sec:.2f}x | {e} |")
    lines.append("")
    lines.append(f"pylinkage: {pyl}" + (f"; first call (numba JIT or cache load): {first_call:.2f} s"
                                         if first_call is not None else ""))
    lines.append("")
    big = max(rows, key=lambda r: r["steps"])
    S = big["steps"]
    if S >= 360_000:
        lines.append(f"Targets at {S:,} steps (same run):")
    else:
        lines.append(f"Targets (judged at 360,000 steps; this run's largest sweep is {S:,} steps, "
                     "so the verdicts below are indicative only):")
    cps = {k: S / big[k] for k in ("fast", "stage1", "newton", "closed_form", "closed_form_chunked",
                                   "pylinkage", "fast_compiled", "stage1_compiled") if k in big}
    def verdict(ok):
        return "met" if ok else "MISSED"
    if "pylinkage" in cps:
        x = cps["fast"] / cps["pylinkage"]
        lines.append(f"- dyads kernel / pylinkage+numba = {x:.2f}x (the kernel alone; target >= 2x): "
                     f"{verdict(x >= 2)}")
        x = cps["stage1_compiled"] / cps["pylinkage"]
        lines.append(f"- stage 1 as run runs it, compiled loops loaded / pylinkage+numba = "
                     f"{x:.2f}x (target >= 2x): {verdict(x >= 2)} (numpy's stage 1: "
                     f"{cps['stage1'] / cps['pylinkage']:.2f}x; the dyads kernel compiled: "
                     f"{cps['fast_compiled'] / cps['pylinkage']:.2f}x)")
    else:
        lines.append("- fast path / pylinkage+numba: pylinkage not installed, not measured")
    x = cps["fast"] / cps["closed_form"]
    lines.append(f"- dyads kernel / closed form = {x:.2f}x (target >= 0.8x): {verdict(x >= 0.8)}"
                 f" (against the chunked closed form: {cps['fast'] / cps['closed_form_chunked']:.2f}x)")
    if "pylinkage_cpu" in big:
        x = big["pylinkage_cpu"] / big["floor_cpu"]
        lines.append(
            f"- pylinkage+numba / hand-written numpy stage 1, CPU seconds "
            f"({big['pylinkage_cpu']:.4f} / {big['floor_cpu']:.4f}) = {x:.2f}x (a reference, no "
            f"target; its condition agrees with numpy's dense 1-norm condition to "
            f"{big['floor_condition']:.1e})")
        if big.get("compiled_cpu") is not None:
            x = big["pylinkage_cpu"] / big["compiled_cpu"]
            worst = max(big["err_compiled"])
            lines.append(
                f"- pylinkage+numba / numba-compiled stage 1, CPU seconds "
                f"({big['pylinkage_cpu']:.4f} / {big['compiled_cpu']:.4f}) = {x:.2f}x (a "
                f"reference, no target; its arrays equal the hand-written numpy ones to "
                f"{worst:.1e} of each array's largest value)")
    e = max(big["err_fast"])
    lines.append(f"- dyads kernel max relative error {e:.1e} (target <= 1e-12): {verdict(e <= 1e-12)}")
    x = cps["newton"]
    lines.append(f"- general path {x / 1e6:.2f} M configurations/s (target >= 1 M): {verdict(x >= 1e6)};"
                 f" max relative error {max(big['err_newton']):.1e}: {verdict(max(big['err_newton']) <= 1e-12)}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ part 2
EFFECTS = '''
[analysis]
effects = ["springs", "gravity", "inertia", "damping", "loads"]

[gravity]
g = [0.0, -9.81]

[[masses]]
link = "crank"
mass = 1.0
center = [0.5, 0.0]
inertia = 0.1

[[masses]]
link = "coupler"
mass = 3.0
center = "P"
inertia = 3.2

[[masses]]
link = "rocker"
mass = 2.5
center = [1.5, 0.0]
inertia = 1.9

[[springs]]
name = "return"
between = ["P", "O4"]
k = 200.0
free_length = 2.0
damping = 5.0

[[loads]]
name = "tool"
point = "B"
force = [-50.0, 20.0]

[[loads]]
name = "brake"
link = "rocker"
torque = -15.0

'''


def scene_text(case: str) -> tuple[str, str]:
    """Return (file name, TOML text) of a pipeline case."""
    if case == "crank_rocker_100k":
        text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
        text = text.replace("steps = 361", "steps = 100000")
        text = text.replace("[outputs]", EFFECTS + "[outputs]")
        text = text.replace('name = "fourbar_crank_rocker"', 'name = "crank_rocker_100k"')
        return "crank_rocker_100k.toml", text
    path = ROOT / "configs" / "jansen.toml"
    if not path.exists():
        raise SystemExit("configs/jansen.toml is missing")
    text = path.read_text()
    if case == "jansen_100k":
        import re

        text = re.sub(r"\nsteps = \d+", "\nsteps = 100000", text, count=1)
        text = re.sub(r"\nstep = [0-9.]+", "\nsteps = 100000", text, count=1)
        text = text.replace('name = "jansen"', 'name = "jansen_100k"', 1)
    return f"{case}.toml", text


def peak_rss_mb() -> float:
    """Return this process's peak resident memory (VmHWM; ru_maxrss survives exec on Linux)."""
    try:
        for line in pathlib.Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def pipeline_child(case: str) -> None:
    """Run one case in this (fresh) process and print a JSON line."""
    import tracemalloc

    t0 = time.perf_counter()
    import linkpipe
    from linkpipe.stores import hdf5, rrd

    imports = time.perf_counter() - t0
    rss0 = peak_rss_mb()
    name, text = scene_text(case)
    out = scratch()
    trace = os.environ.get("BENCH_TRACEMALLOC") == "1"
    if trace:
        tracemalloc.start()
    t0 = time.perf_counter()
    scene = linkpipe.parse_scene(text, str(out / name))
    result = linkpipe.solve(scene)
    seconds = dict(result.seconds)
    t1 = time.perf_counter()
    hdf5.write(result, out / f"{scene.name}.h5")
    seconds["hdf5"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    rrd.write(result, out / f"{scene.name}.rrd")
    seconds["rrd"] = time.perf_counter() - t1
    total = time.perf_counter() - t0
    peak_traced = tracemalloc.get_traced_memory()[1] / 2**20 if trace else None
    rss = peak_rss_mb()
    sizes = {p.suffix: p.stat().st_size / 2**20 for p in out.iterdir()}
    print(json.dumps(dict(case=case, steps=result.n_steps, method=result.solver_method_used,
                          message=result.message, imports=imports, seconds=seconds, total=total,
                          rss_after_imports_mb=rss0, peak_rss_mb=rss, peak_traced_mb=peak_traced,
                          file_mb=sizes)))


def run_child(case: str) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", case], capture_output=True, text=True,
                          cwd=ROOT)
    if proc.returncode:
        raise SystemExit(proc.stderr)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def cli_cold() -> float:
    out = str(scratch("linkpipe_cli_"))
    configs = sorted(str(p) for p in (ROOT / "configs").glob("*.toml"))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "linkpipe", "run", *configs, "--out", out, "--quiet"],
                          capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode:
        raise SystemExit(proc.stderr)
    return wall, len(configs)


def print_part2(runs, cli):
    lines = ["Whole pipeline, one fresh process per case (seconds after the imports; peak RSS of "
             "the process, interpreter and imports included)", ""]
    stages = ["model", "positions", "jacobian", "forces", "hdf5", "rrd"]
    lines.append("| case | steps | path | " + " | ".join(stages) + " | total | imports | peak RSS |")
    lines.append("|---|---:|---|" + "---:|" * (len(stages) + 3))
    for r in runs:
        sec = r["seconds"]
        cells = [f"{sec[s]:.3f}" if s in sec else "–" for s in stages]
        lines.append(f"| {r['case']} | {r['steps']:,} | {r['method']} | " + " | ".join(cells)
                     + f" | **{r['total']:.2f} s** | {r['imports']:.2f} s | {r['peak_rss_mb']:.0f} MB |")
    lines.append("")
    for r in runs:
        if r["case"] == "crank_rocker_100k":
            ok = r["total"] <= 1.5
            mem = r["peak_rss_mb"] <= 1024
            lines.append(f"- crank-rocker 100k with forces, .h5 and .rrd: {r['total']:.2f} s "
                         f"(target <= 1.5 s): {'met' if ok else 'MISSED'}; peak memory "
                         f"{r['peak_rss_mb']:.0f} MB (target <= 1 GB): {'met' if mem else 'MISSED'}")
    if cli is not None:
        wall, n = cli
        lines.append(f"- `python -m linkpipe run configs/*.toml` ({n} scenes) from a cold process: "
                     f"{wall:.2f} s wall (target <= 3 s): {'met' if wall <= 3 else 'MISSED'}")
    return "\n".join(lines)


#: where ``--write-docs`` puts this benchmark's output in docs/performance.md
DOCS = ROOT / "docs" / "performance.md"
BEGIN, END = "<!-- bench_sweep.py output: begin -->", "<!-- bench_sweep.py output: end -->"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="36k steps only, no pipeline runs")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--write-docs", action="store_true",
                   help="also put this run's output into docs/performance.md (between its markers)")
    args = p.parse_args(argv)
    if args.child:
        return pipeline_child(args.child)
    printed = []

    def say(text=""):
        print(text, flush=True)
        printed.append(text)

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    say(f"linkpipe sweep benchmark, {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} "
        f"UTC, Python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} cores, "
        f"{platform.machine()}, load average {load:.1f} at the start")
    say()
    sizes = (36_000,) if args.quick else (36_000, 360_000)
    rows, pyl, first = part1(sizes, args.repeats)
    say(print_part1(rows, pyl, first))
    say()
    big = max(rows, key=lambda r: r["steps"])
    say(print_run_targets(run_targets(big["steps"], args.repeats, big.get("pylinkage"),
                                      big.get("pylinkage_cpu"), big.get("floor_cpu"))))
    if not args.quick:
        say()
        cases = ["crank_rocker_100k"]
        if (ROOT / "configs" / "jansen.toml").exists():
            cases += ["jansen", "jansen_100k"]
        else:
            say("(configs/jansen.toml is missing: no Jansen case)")
        runs = [run_child(c) for c in cases]
        say(print_part2(runs, cli_cold()))
        say()
        say(print_fresh_runs(fresh_runs()))
    if args.write_docs:
        text = DOCS.read_text()
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        DOCS.write_text(head + BEGIN + "\n\n" + "\n".join(printed).strip() + "\n\n" + END + tail)
        print(f"(written into {DOCS.relative_to(ROOT)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
