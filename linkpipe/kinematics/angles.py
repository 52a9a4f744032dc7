"""Link angles along a sweep: each link's direction unwrapped across steps, gaps and segments,
its whole turns taken from the drawing (or from the angle driver that turns it); the links'
angular velocities and accelerations (:func:`link_rates`)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..cache import derived
from ..model import Model, content_key
from ..workers import for_chunks
from .drawing import assembled_drawing
from .linalg import CHUNK


def link_angles_unwrapped(model: Model, X: np.ndarray, period: int = 0,
                          carry: "AngleCarry | None" = None, s: np.ndarray | None = None,
                          drawings: np.ndarray | None = None, raw: np.ndarray | None = None,
                          compiled: bool = False):
    """Return link angles (S, n_links) in radians, unwrapped along the sweep across NaN gaps.

    One vectorised pass: each gap is filled with the link's last angle before it (the first
    one, before its first), so the jump across the gap is unwrapped as between neighbours and
    the filled steps add zero corrections; the gaps are NaN again afterwards. ``period``: the
    rows are runs of this many steps (a study's variants), each unwrapped on its own.

    Whole turns: a link's first finite angle is taken within half a turn of its direction in
    the drawing (:func:`drawn_link_angles`), not of (-pi, pi] at that step, so the same pose
    reads the same angle whichever way a sweep runs through it. ``s`` (S, n_drivers), the
    drivers' values in radians: a link that an absolute angle driver turns (it carries both
    of the driver's points) takes its whole turns from the driver's value, which the scene
    gives unwrapped (905.9 deg is legal), plus its fixed offset from the driver's direction
    (:func:`driven_links`), so a sweep of more than half a turn per step keeps them.

    ``drawings`` (V, n_points, 2), with ``period``: each run's own drawing (a study's
    variants that move pivots or drawn points), the reference of its whole turns and its
    plates' offsets (default: the model's drawing for every run).

    ``carry``: a sweep solved in segments of steps (:mod:`linkpipe.segments`): the
    :class:`AngleCarry` of the segments before (None for the first); then the return is
    ``(angles, carry for the next segment)``, and the segments' angles equal the whole sweep's
    to the last bit (``tests/test_segments.py``).

    ``raw`` (S, n_links): the links' directions in (-pi, pi] where the caller has them
    (``model.link_angles(X)`` row by row: the closed-form dyads' own pass), else computed here.
    ``compiled`` (with ``carry``): the segment's unwrapping by compiled loops
    (:mod:`.unwrap_kernel`, the same numbers)."""
    ang = raw
    if ang is None:
        ang = np.empty((X.shape[0], len(model.link_a)))

        def work(lo: int, hi: int) -> None:
            ang[lo:hi] = model.link_angles(X[lo:hi])

        for_chunks(work, X.shape[0], CHUNK)
    drawn = drawn_link_angles(model) if drawings is None else model.link_angles(drawings)
    got = None
    if carry is not None and compiled and drawings is None:
        from . import unwrap_kernel  # imports numba: only where the compiled loops are taken

        # a segment without NaN; where the whole turns are known (every segment after the
        # first), the same pass adds them and the driven links' (the numbers of the steps below)
        known = not np.isnan(carry.shift).any()
        got = unwrap_kernel.unwrap(ang, carry.last, carry.correction,
                                   carry.shift if known else None,
                                   driven_links(model) if known and s is not None else (), s)
        if got is not None and known:
            out, last, summed = got
            return out, AngleCarry(last, summed, np.where(np.isnan(last), np.nan, carry.shift))
    if carry is not None:
        out, after = (unwrap_runs(ang, carry) if got is None else
                      (got[0], AngleCarry(got[1], got[2])))
        shift = (carry.shift if not np.isnan(carry.shift).any() else  # set: no pass over out
                 np.where(np.isnan(carry.shift), _turns_towards(drawn, out), carry.shift))
        after = dataclasses.replace(after, shift=np.where(np.isnan(after.last), np.nan, shift))
        out += np.nan_to_num(shift)
    elif period:
        runs = unwrap_runs(ang.reshape(-1, period, ang.shape[-1]))[0]  # (V, period, L)
        out = (runs + np.nan_to_num(_turns_towards(drawn, runs))[:, None, :]).reshape(ang.shape)
        after = None
    else:
        out, after = unwrap_runs(ang)[0], None
        out += np.nan_to_num(_turns_towards(drawn, out))
    if s is not None:
        for li, j, offset in driven_links(model, drawings):
            if np.ndim(offset):  # one per run (drawings)
                offset = np.repeat(offset, period)
            turns = np.round((s[:, j] + offset - ang[:, li]) / (2 * np.pi))
            out[:, li] = ang[:, li] + 2 * np.pi * turns
    return (out, after) if carry is not None else out


def _turns_towards(drawn: np.ndarray, unwrapped: np.ndarray) -> np.ndarray:
    """The whole turns (radians, (..., n_links)) that bring each link's first finite angle of
    ``unwrapped`` (..., S, n_links) within half a turn of its ``drawn`` angle (NaN: no finite
    angle yet)."""
    fin = np.isfinite(unwrapped)
    first = np.take_along_axis(unwrapped, np.argmax(fin, axis=-2)[..., None, :], axis=-2)[..., 0, :]
    turns = 2 * np.pi * np.round((drawn - first) / (2 * np.pi))
    return np.where(fin.any(axis=-2), turns, np.nan)


def drawn_link_angles(model: Model) -> np.ndarray:
    """Each link's direction (first to second point) in the drawing, in (-pi, pi] (n_links,):
    the drawing assembled at its own driver values where it assembles there (its points may
    be a guess), else as drawn. The reference a link's whole turns are taken from."""
    return derived(model, "drawn_link_angles", _drawn_link_angles, content_key(model))


def _drawn_link_angles(model: Model) -> np.ndarray:
    X = assembled_drawing(model)
    X = model.start_position if X is None else X
    return model.link_angles(X[None])[0]


#: an offset within this of half a turn is half a turn (+pi): the drawing's rounding must not
#: decide between +pi and -pi, a whole turn apart in the link's angle
HALF_TURN_WITHIN = 1e-9


def driven_links(model: Model, drawings: np.ndarray | None = None) -> list[tuple]:
    """``(link, driver, offset)`` of each link whose direction an absolute angle driver sets:
    a link that carries both of the driver's points. Its first two points the driver's pair:
    offset 0 (or pi, the pair reversed); else the body's fixed angle from the driver's
    direction to the link's, in the drawing as assembled (:func:`drawn_link_angles`), in
    (-pi, pi] with half a turn always +pi: the cut where a plate point drawn a little either
    side of exactly opposite the driver's direction reads a turn apart. ``drawings``
    (V, n_points, 2): the offset (V,) in each of these drawings instead."""
    out = []
    for j, driver in enumerate(model.scene.drivers):
        if driver.kind != "angle" or driver.relative_to is not None:
            continue
        a, b = (model.point_names.index(p) for p in driver.points)
        for li, (la, lb) in enumerate(zip(model.link_a, model.link_b)):
            if (la, lb) in ((a, b), (b, a)):
                out.append((li, j, 0.0 if (la, lb) == (a, b) else np.pi))
            elif set(driver.points) <= set(model.scene.links[li].points):
                if drawings is None:
                    X = assembled_drawing(model)
                    X = (model.start_position if X is None else X)[None]
                else:
                    X = drawings
                d = X[:, b] - X[:, a]
                offset = model.link_angles(X)[:, li] - np.arctan2(d[:, 1], d[:, 0])
                offset = (offset + np.pi) % (2 * np.pi) - np.pi  # [-pi, pi)
                offset = np.where(np.abs(np.abs(offset) - np.pi) < HALF_TURN_WITHIN, np.pi, offset)
                out.append((li, j, float(offset[0]) if drawings is None else offset))
    return out


@dataclass(frozen=True)
class AngleCarry:
    """What unwrapping a segment of steps takes from the segments before it, per link
    (n_links,): the last finite raw angle (NaN: none yet) and the correction summed up to it."""

    last: np.ndarray
    correction: np.ndarray
    #: the whole turns (radians) added to each link's unwrapped angle, set at its first finite
    #: angle (:func:`link_angles_unwrapped`; NaN: not yet)
    shift: np.ndarray | None = None

    @classmethod
    def start(cls, n_links: int) -> "AngleCarry":
        return cls(np.full(n_links, np.nan), np.zeros(n_links), np.full(n_links, np.nan))


def unwrap_runs(ang: np.ndarray, carry: AngleCarry | None = None):
    """``(unwrapped, carry)`` of angles (..., S, n_links) along the steps axis, NaN gaps as
    :func:`link_angles_unwrapped` says: numpy's ``unwrap`` (period 2 pi) written out so that its
    running sum of corrections can start from a ``carry`` (the steps before; None: none) and
    go on in the next segment in the same order of additions (``np.unwrap`` itself restarts
    it: ``tests/test_segments.py`` checks this against ``np.unwrap`` bit for bit; compiled:
    :mod:`.unwrap_kernel`)."""
    lead = ang.shape[:-2] + ang.shape[-1:]
    before = carry if carry is not None else AngleCarry(np.full(lead, np.nan), np.zeros(lead))
    ext = np.concatenate([before.last[..., None, :], ang], axis=-2)  # (..., S + 1, L)
    fin = np.isfinite(ext)
    gaps = not fin.all()
    if gaps and ang.shape[-2] and fin[..., 1:, :].all():  # only the carry's last is missing:
        first = ext[..., 1, :]                             # the first step stands in for it
        ext[..., 0, :] = np.where(fin[..., 0, :], ext[..., 0, :], first)
        gaps = False
    if gaps:
        rows = np.where(fin, np.arange(ext.shape[-2])[:, None], -1)
        np.maximum.accumulate(rows, axis=-2, out=rows)  # the last finite step at or before each
        first = np.argmax(fin, axis=-2)  # the first finite step (0 where there is none)
        rows = np.where(rows < 0, first[..., None, :], rows)
        ext = np.take_along_axis(ext, rows, axis=-2)
    dd = np.diff(ext, axis=-2)
    # np.unwrap's correction, (dd + pi) mod 2 pi - pi - dd, taken only where it is not zero
    # (|dd| >= pi, or NaN): the same values, without a pass of mod over every step
    correction = np.zeros(dd.shape)
    jumps = ~(np.abs(dd) < np.pi)
    if gaps:  # NaN steps of a link that has no finite angle at all add zero
        jumps &= ~(np.isnan(dd) & ~fin.any(axis=-2)[..., None, :])
    if jumps.any():
        d = dd[jumps]
        ddmod = np.mod(d - (-np.pi), 2 * np.pi) + (-np.pi)  # np.unwrap's steps, in its order
        np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (d > 0))
        correction[jumps] = ddmod - d
    corrections = np.concatenate([before.correction[..., None, :], correction], axis=-2)
    summed = (_running_sums(corrections) if corrections.ndim == 2 and not gaps else
              np.cumsum(corrections, axis=-2))
    out = ext[..., 1:, :] + summed[..., 1:, :]
    seen = np.ones(lead, bool)
    if gaps:
        out[~fin[..., 1:, :]] = np.nan
        seen = fin.any(axis=-2)  # a link with no finite angle yet keeps its carry as it was
    after = AngleCarry(np.where(seen, ext[..., -1, :], before.last),
                       np.where(seen, summed[..., -1, :], before.correction))
    return out, after


def _running_sums(corrections: np.ndarray) -> np.ndarray:
    """``np.cumsum(corrections, axis=0)`` of (S + 1, L) finite corrections, bit for bit, where
    they are mostly zero (a link turns past pi a few times in a sweep): the running sum is
    taken over the non-zero ones alone, in order (adding the zeros between changes no bit),
    and held between them; a column with many turns takes the cumsum itself."""
    out = np.empty_like(corrections)
    S1 = corrections.shape[0]
    # row-major: each column's rows in order (np.nonzero's (row, column) pairs, from the flat
    # 1-D search: numpy's n-dimensional nonzero took ~1 ms a 16k-step segment, this ~0.03)
    at, of = np.divmod(np.flatnonzero(corrections[1:]), corrections.shape[1])
    for j in range(corrections.shape[1]):
        col = corrections[:, j]
        rows = at[of == j] + 1
        if len(rows) > S1 // 64:
            out[:, j] = np.cumsum(col)
            continue
        sums = np.cumsum(np.concatenate([col[:1], col[rows]]))
        out[:, j] = np.repeat(sums, np.diff(np.concatenate([[0], rows, [S1]])))
    return out


#: steps per chunk of :func:`link_rates`: a chunk's dozen (chunk,) columns fit in L2, and few
#: enough chunks that two threads gain (8,192-step chunks were slower on two threads than one)
RATES_CHUNK = 32768


def link_rates(model: Model, X, V, A=None, chunk: int = RATES_CHUNK):
    """Return angular velocity (S, n_links) and, with A, angular acceleration of every link,
    link by link on each chunk's columns (the temporaries stay in cache; only the outputs are
    whole), on the workers' threads (:func:`linkpipe.workers.for_chunks`)."""
    S, n_links = X.shape[0], len(model.link_a)
    w = np.empty((S, n_links))
    al = np.empty((S, n_links)) if A is not None else None

    def work(lo: int, hi: int) -> None:
        link_rate_rows(model.link_a, model.link_b, X[lo:hi], V[lo:hi],
                       A[lo:hi] if A is not None else None, w[lo:hi],
                       al[lo:hi] if al is not None else None)

    for_chunks(work, S, chunk)
    return w, al


def link_rate_rows(link_a, link_b, X, V, A, w, al) -> None:
    """The links' angular velocities into ``w`` (n, n_links) and, with ``A``, accelerations
    into ``al``, of the rows X, V, A (n, n_points, 2): the one formula, link by link on the
    rows' columns (:func:`link_rates` over a sweep; the closed-form dyads on each chunk of
    their own pass, while it is in cache: :func:`.dyads.solve_chain`, through
    :func:`link_rate_columns`)."""
    def cols(Y):
        return None if Y is None else (lambda p: (Y[:, p, 0], Y[:, p, 1]))

    link_rate_columns(link_a, link_b, cols(X), cols(V), cols(A), w, al)


def link_rate_columns(link_a, link_b, x, v, a, w, al, still=(), angle=None) -> None:
    """:func:`link_rate_rows` on columns: ``x(p)``, ``v(p)``, ``a(p)`` -> a point's (x, y)
    columns (n,) of positions, velocities and accelerations (``a`` None: none asked);
    ``still``: points at rest (their rates zero: not read, and ``u - 0.0`` is ``u`` to the
    bit, so the numbers are those of the formula on the full rows). The formula's operations
    in its order, ``(dx dvy - dy dvx) / n2`` and ``(dx day - dy dax) / n2 - 2 w (dx dvx +
    dy dvy) / n2`` with ``n2 = dx dx + dy dy``, into three scratch columns: no temporary per
    operation (``tests/test_kernels.py`` holds it to the bit against the written formula).
    ``angle`` (n, n_links): also each link's direction, ``arctan2(dy, dx)`` of the same
    differences (:meth:`linkpipe.model.Model.link_angles`' formula)."""
    n = (w if w is not None else angle).shape[0]
    t1, t2, t3 = np.empty(n), np.empty(n), np.empty(n)

    def diff(f, p, q):  # f(q) - f(p), two columns (p at rest: f(q) itself, never written)
        xq, yq = f(q)
        if p in still:
            return xq, yq
        xp, yp = f(p)
        return xq - xp, yq - yp

    for j, (pa, pb) in enumerate(zip(link_a, link_b)):
        (xb, yb), (xa, ya) = x(pb), x(pa)
        dx, dy = np.subtract(xb, xa), np.subtract(yb, ya)
        if angle is not None:
            angle[:, j] = np.arctan2(dy, dx)
        if w is None:
            continue
        dvx, dvy = diff(v, pa, pb)
        n2 = np.multiply(dx, dx)
        np.multiply(dy, dy, out=t1)
        n2 += t1
        wj = np.multiply(dx, dvy)
        np.multiply(dy, dvx, out=t1)
        wj -= t1
        wj /= n2
        w[:, j] = wj
        if a is None:
            continue
        dax, day = diff(a, pa, pb)
        np.multiply(dx, day, out=t1)
        np.multiply(dy, dax, out=t2)
        t1 -= t2
        t1 /= n2
        np.multiply(dx, dvx, out=t2)
        np.multiply(dy, dvy, out=t3)
        t2 += t3
        np.multiply(wj, 2, out=t3)
        t3 *= t2
        t3 /= n2
        np.subtract(t1, t3, out=al[:, j])
