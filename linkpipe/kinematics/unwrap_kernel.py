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


def unwrap(ang: np.ndarray, last: np.ndarray, correction: np.ndarray,
           shift: np.ndarray | None = None, driven=(), s: np.ndarray | None = None):
    """``(unwrapped (S, L), last (L,), correction (L,))`` of angles ``ang`` (S, L) after a
    carry's ``last`` angle (NaN: none) and summed ``correction`` per link, as
    :func:`.angles.unwrap_runs`; None where an angle is NaN (numpy's path handles the gaps).
    With the whole turns ``shift`` (L,) known, they are added in the same pass, and the
    ``driven`` links (``(link, driver, offset)``, :func:`.angles.driven_links`) take theirs
    from the drivers' values ``s`` (S, nd): :func:`.angles.link_angles_unwrapped`'s last
    steps, the same numbers."""
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
    turns = np.zeros(L) if shift is None else np.nan_to_num(shift)
    _summed(ang, at_step[:n], at_link[:n], ddmod - d, summed, turns, out)
    for li, j, offset in driven:
        _driven(ang, np.ascontiguousarray(s[:, j]), float(offset), li, out)
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
def _summed(ang, at_step, at_link, corrections, summed, turns, out):
    """out = (ang + each link's running sum of its corrections (from ``summed``, updated))
    + its whole ``turns``."""
    S, L = ang.shape
    k = 0
    for j in range(L):
        c, tj = summed[j], turns[j]
        for i in range(S):
            if k < at_step.shape[0] and at_link[k] == j and at_step[k] == i:
                c = c + corrections[k]
                k += 1
            out[i, j] = (ang[i, j] + c) + tj
        summed[j] = c


@jit
def _driven(ang, s, offset, li, out):
    """A driven link's angle: its direction plus the whole turns of its driver's value
    ``s`` (S,) and ``offset``, ``ang + 2 pi round((s + offset - ang) / 2 pi)`` (round half
    to even, as numpy's)."""
    tau = 2 * np.pi
    for i in range(ang.shape[0]):
        a = ang[i, li]
        out[i, li] = a + tau * np.rint((s[i] + offset - a) / tau)
