"""The links' angles unwrapped along a segment of steps (:func:`.angles.unwrap_runs`) as two
compiled loops (numba), link by link over the steps, where no angle is NaN: numpy's numbers to
the bit (``tests/test_unwrap_kernel.py``). The first loop finds the steps whose change is half
a turn or more (a link passing +-pi: a few per turn); numpy takes its own ``mod`` of those
few; the second adds the running sum of their corrections, in numpy's order of additions.
Importing this module imports numba: :mod:`.angles` imports it only where
:func:`.compiled.wanted` said so.
"""
from __future__ import annotations

import numpy as np

from .compiled import jit


def unwrap(ang: np.ndarray, last: np.ndarray, correction: np.ndarray):
    """``(unwrapped (S, L), last (L,), correction (L,))`` of angles ``ang`` (S, L) after a
    carry's ``last`` angle (NaN: none) and summed ``correction`` per link, as
    :func:`.angles.unwrap_runs`; None where an angle is NaN (numpy's path handles the gaps)."""
    S, L = ang.shape
    room = 64  # jumps are a few per turn: room for them, more only where a segment has more
    while True:
        at_step, at_link, dd = np.empty(room, np.int64), np.empty(room, np.int64), np.empty(room)
        n = _jumps(ang, last, at_step, at_link, dd)
        if n < 0:
            return None
        if n <= room:
            break
        room = n
    d = dd[:n]
    ddmod = np.mod(d - (-np.pi), 2 * np.pi) + (-np.pi)  # np.unwrap's, as unwrap_runs takes it
    np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (d > 0))
    out, summed = np.empty_like(ang), correction.astype(float).copy()
    _summed(ang, at_step[:n], at_link[:n], ddmod - d, summed, out)
    return out, ang[-1].copy() if S else last.copy(), summed


@jit
def _jumps(ang, last, at_step, at_link, dd):
    """The steps (and links) where an angle changes from the one before (the carry's last, or
    the first step itself where there is none) by pi or more: their count, the first
    ``len(dd)`` of them and their differences into ``at_step``, ``at_link``, ``dd``; -1 where
    an angle is NaN."""
    S, L = ang.shape
    n = 0
    for j in range(L):
        prev = last[j]
        if prev != prev and S:
            prev = ang[0, j]
        for i in range(S):
            a = ang[i, j]
            if a != a:
                return -1
            d = a - prev
            if not (abs(d) < np.pi):
                if n < dd.shape[0]:
                    at_step[n], at_link[n], dd[n] = i, j, d
                n += 1
            prev = a
    return n


@jit
def _summed(ang, at_step, at_link, corrections, summed, out):
    """out = ang + each link's running sum of its corrections (from ``summed``, updated)."""
    S, L = ang.shape
    k = 0
    for j in range(L):
        c = summed[j]
        for i in range(S):
            if k < at_step.shape[0] and at_link[k] == j and at_step[k] == i:
                c = c + corrections[k]
                k += 1
            out[i, j] = ang[i, j] + c
        summed[j] = c
