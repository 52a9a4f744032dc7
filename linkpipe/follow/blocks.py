"""The rows of a growing log solved block by block through the pipeline, each row once final.

A ``[time] log`` scene's drivers follow a cubic spline through the log's samples
(:func:`linkpipe.log_splines.log_spline`), a global fit: a row added at the end moves the
spline's rates and accelerations near the end (the not-a-knot end condition moves), by an
amount that decays by about 2 - sqrt(3) = 0.27 per sample away from the end (the
interpolating spline's influence function). Positions at the samples do not move (the
spline interpolates them). So :class:`Window` holds back the last ``settle`` rows of what
has arrived, and solves the rows before them with a spline through the rows from ``settle``
before the block to the last row arrived: each stored row then has at least ``settle``
samples on either side of it in its spline, where the end conditions reach it damped by
0.268^settle (4e-12 at the default 20; docs/follow.md). At the end
(``final``), the held-back rows are solved with the spline ending at the log's last row,
as a batch ``run`` of the same log ends.

Each block is the scene with its log cut to the window's rows (:func:`window_scene`), solved
by :func:`linkpipe.solve` (the one pipeline: stage 1, forces, statuses, measurements), its
block's rows taken out; link angles are brought to the whole turns of the rows before.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..cache import forget
from ..errors import SceneError
from ..log_splines import forget_spline_values
from ..pipeline import solve
from ..result import Result

#: rows held back at the end and taken before a block: 0.268^20 ~ 4e-12 of the end
#: conditions' change reaches a stored row's rates. Measured (benchmarks/bench_settle.py,
#: docs/follow.md): on the rig's log at 1 kHz, 500 Hz and 100 Hz every stored row equals the
#: batch run's to the last bit with 20 (with 18: 4.5e-10 in the driver's acceleration, with
#: 16: 1.4e-9); a log whose driver column is rounded coarsely (an encoder's 0.001 degree)
#: moves its spline's ends more and needs up to 28 (``--settle``)
SETTLE_ROWS = 20
#: the fewest rows a block solves (smaller ones wait for more, unless the log ends)
MIN_BLOCK_ROWS = 1


def followed_columns(scene) -> tuple[str, ...]:
    """The columns of the ``[time]`` log that drivers and measurements read; a scene that
    ``follow`` cannot follow is a SceneError naming why."""
    if scene.time is None or scene.time.log is None:
        raise SceneError(scene.path, "time", "log", "follow reads a growing log: the steps must "
                         "be its rows", 'give [time] log = "<the log\'s name>"')
    log = scene.time.log
    cols = []
    for d in scene.drivers:
        if d.timed == "law":
            raise SceneError(scene.path, f'drivers "{d.name}"', "law", "a law spans [time], "
                             "which grows while the log is followed", "drive it by log or rate")
        if d.timed == "log" and d.log[0] == log:
            cols.append(d.log[1])
        elif d.timed == "log":
            raise SceneError(scene.path, f'drivers "{d.name}"', "log", f'follow reads the '
                             f'[time] log "{log}" as it grows; "{d.log[0]}" is another log',
                             f'read the column from "{log}"')
    cols += [m.column for m in scene.measurements]
    return tuple(dict.fromkeys(cols))


def window_scene(scene, t: np.ndarray, columns: dict, start_pose: np.ndarray | None = None):
    """``scene`` with its ``[time]`` log holding the rows ``t`` (n,) and ``columns`` {name:
    (n,)} alone: the instants, the log drivers' steps and value ranges, the measurements'
    values. The time origin stays the scene's (a ``rate`` driver counts from it).
    ``start_pose`` (n_points, 2): the pose solved before at the first row, where the start is
    assembled from (instead of carried from the drawing: the same branch, in one Newton)."""
    name = scene.time.log
    n = len(t)
    logs = tuple(replace(log, t=t, columns={c: columns[c] for c in log.columns})
                 if log.name == name else log for log in scene.logs)
    drivers = []
    for d in scene.drivers:
        if d.timed == "log":
            v = columns[d.log[1]] * d.scale
            fin = v[np.isfinite(v)]
            lo, hi = (float(fin.min()), float(fin.max())) if len(fin) else (d.from_value, d.to_value)
            d = replace(d, steps=n, from_value=lo, to_value=hi)
        else:
            d = replace(d, steps=n)
        drivers.append(d)
    measurements = tuple(replace(m, values=columns[m.column] * m.scale)
                         for m in scene.measurements)
    time = replace(scene.time, to_value=float(t[-1]), steps=n, instants=t)
    return replace(scene, logs=logs, drivers=tuple(drivers), measurements=measurements, time=time,
                   start_pose=start_pose)


class Window:
    """The rows arrived and not yet stored (with ``settle`` rows before them), solved block by
    block: :meth:`add` takes new rows; :meth:`block` returns the next block's Result (its
    ``step_numbers`` the log's rows), or None while every arrived row is within ``settle`` of
    the end."""

    def __init__(self, scene, start_row: int = 0, settle: int = SETTLE_ROWS,
                 last_angles: np.ndarray | None = None, threads: int | None = 1):
        self.scene, self.settle, self.threads = scene, settle, threads
        self.columns = followed_columns(scene)
        self.first = start_row  # the log row of self.t[0]
        self.stored = start_row  # the first row not yet stored
        self.t = np.empty(0)
        self.data = {c: np.empty(0) for c in self.columns}
        self.last_angles = last_angles  # (n_links,) of the last stored row (whole turns)
        self.poses = np.empty((0, len(scene.points), 2))  # positions of the last stored rows

    @property
    def arrived(self) -> int:
        """The log rows arrived so far (stored or not)."""
        return self.first + len(self.t)

    def add(self, t: np.ndarray, columns: dict) -> None:
        self.t = np.concatenate([self.t, t])
        for c in self.columns:
            self.data[c] = np.concatenate([self.data[c], columns[c]])

    def skip_to(self, row: int) -> None:
        """Forget rows before ``row - settle`` (resuming after ``row``: rows already stored)."""
        cut = min(max(0, row - self.settle - self.first), len(self.t))
        if cut:
            self.t = self.t[cut:]
            self.data = {c: v[cut:] for c, v in self.data.items()}
            self.first += cut

    def ready(self, final: bool = False) -> int:
        """The rows the next block would store (final: every arrived row)."""
        end = self.arrived if final else self.arrived - self.settle
        return max(0, end - self.stored)

    def block(self, final: bool = False, max_rows: int | None = None) -> Result | None:
        """Solve and return the next block (None: nothing final yet, or fewer than two rows in
        the window for the spline)."""
        n = self.ready(final)
        if n < (1 if final else MIN_BLOCK_ROWS):
            return None
        if max_rows:
            n = min(n, max_rows)
        lo = self.stored
        a = max(self.first, lo - self.settle) - self.first  # window start (local)
        end = self.arrived if final else min(self.arrived, lo + n + self.settle)
        b = end - self.first
        t = self.t[a:b]
        if len(t) < 2:
            return None
        k_pose = (self.first + a) - (self.stored - len(self.poses))  # the first row's pose
        pose = self.poses[k_pose] if 0 <= k_pose < len(self.poses) else None
        sub = window_scene(self.scene, t, {c: v[a:b] for c, v in self.data.items()}, pose)
        whole = solve(sub, threads=self.threads)
        k = lo - self.first - a
        rows = np.arange(k, k + n)
        part = whole.strided(rows)
        part = replace(part, step_numbers=np.arange(lo, lo + n), measurements=_rows_only(
            whole.measurements, rows), kinematics=None)
        part = self._turns(part, whole, k)
        forget(whole.model)  # its engine and kernels refer back to it: freed with the block
        forget_spline_values()  # a window's spline is never read again
        self.stored = lo + n
        self.poses = np.concatenate([self.poses, part.position])[-(self.settle + 1):]
        self.last_angles = part.link_angle[-1].copy()
        self.skip_to(self.stored)
        return part

    def _turns(self, part: Result, whole: Result, k: int) -> Result:
        """Link angles (and torsion springs' angles) in the whole turns of the rows stored
        before: the window's unwrapping starts afresh at its first row."""
        if self.last_angles is None:
            return part
        before = whole.link_angle[k - 1] if k > 0 else part.link_angle[0]
        turns = np.round((self.last_angles - before) / (2 * np.pi))
        turns = np.where(np.isfinite(turns), turns, 0.0)
        if not turns.any():
            return part
        return replace(part, link_angle=part.link_angle + 2 * np.pi * turns)


def _rows_only(measurements: dict | None, rows: np.ndarray) -> dict | None:
    """The measurements' per-step arrays at ``rows`` (their RMS is the whole file's, taken
    when it ends)."""
    if not measurements:
        return measurements
    return {k: (v[rows] if k in ("measured", "residual") else v) for k, v in measurements.items()}
