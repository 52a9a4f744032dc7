"""``python -m linkpipe follow SCENE.toml``: the loop that follows a growing log.

Poll the log (:mod:`.tail`), solve each block of rows once final (:class:`.blocks.Window`),
append it to ``<name>.h5`` (:class:`linkpipe.stores.growing.GrowingWriter`) and stream it to
the viewer (:class:`linkpipe.stores.rrd.live.LiveRecording`); report alarms and no_input /
no_assembly stretches as they happen (:class:`Reports`). It ends after ``idle`` seconds
without a new row, when ``stop`` is set (Ctrl-C, SIGTERM), or at a fault of the source, each
time with the held-back rows solved and the file complete. Run again, it goes on after the
last stored row.
"""
from __future__ import annotations

import copy
import fcntl
import glob as globbing
import os
import pathlib
import tempfile
import threading
import time as _time
import tomllib
from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import LinkpipeError, SceneError
from ..status import Status
from .blocks import SETTLE_ROWS, Window, followed_columns, window_scene
from .tail import CsvTail, LogFault, ParquetTail

#: seconds between polls of the log when nothing new came
POLL_SECONDS = 0.005
#: the most rows one block solves (a signal is answered within one block)
MAX_BLOCK_ROWS = 16_384
#: seconds a partial last line may wait before follow says so (once)
MID_LINE_NOTICE = 5.0


@dataclass
class Outcome:
    """How a follow ended: ``rows`` stored in all, ``new`` this time, ``why`` it ended,
    ``alarms`` per measurement, ``code`` the exit status, ``address`` the viewer's."""

    path: pathlib.Path
    rows: int = 0
    new: int = 0
    why: str = ""
    alarms: dict = field(default_factory=dict)
    code: int = 0
    address: str | None = None
    #: CPU seconds of the recording's own process (NaN without a viewer or .rrd; benchmarks)
    recording_cpu: float = float("nan")


def _log_entry(scene_path: str, data: dict) -> tuple[int, dict]:
    """The index and table of the ``[[logs]]`` entry ``[time] log`` names."""
    name = (data.get("time") or {}).get("log")
    for i, entry in enumerate(data.get("logs", [])):
        if entry.get("name") == name:
            return i, entry
    raise SceneError(scene_path, "time", "log", "follow reads a growing log: the steps must be "
                     "its rows", 'give [time] log = "<name of a [[logs]] entry>"')


def _log_path(scene_path: str, entry: dict) -> str:
    file = str(entry.get("file", ""))
    base = pathlib.Path(scene_path).parent
    return file if os.path.isabs(file) else str(base / file)


def _first_rows_file(log: str, folder: str, skip_rows: int) -> str | None:
    """A copy of the log's beginning (header and its first complete rows) in ``folder``, for
    the scene to be parsed and checked as ``run`` would (None: not two complete rows yet)."""
    if globbing.has_magic(log) or log.lower().endswith(".parquet"):
        import pyarrow.parquet as pq

        files = sorted(globbing.glob(log)) if globbing.has_magic(log) else [log]
        for name in files:
            try:
                table = pq.read_table(name)
            except Exception:  # noqa: BLE001 (not complete yet)
                return None
            if table.num_rows >= 2:
                target = os.path.join(folder, "first.parquet")
                pq.write_table(table.slice(0, 3), target)
                return target
        return None
    try:
        with open(log, "rb") as f:
            head = f.read(1 << 20)
    except FileNotFoundError:
        return None
    lines = head.split(b"\n")
    need = 1 + skip_rows + 2
    complete = lines[:-1]  # the last piece has no end of line yet
    if len(complete) < need:
        return None
    target = os.path.join(folder, "first" + (pathlib.Path(log).suffix or ".csv"))
    with open(target, "wb") as f:
        f.write(b"\n".join(complete[:need + 1]) + b"\n")
    return target


def load_followed(scene_path: str, wait, say) -> tuple:
    """(scene, tail reader, log path) of ``scene_path``: the scene parsed and checked on the
    log's first rows (waiting for them while ``wait()`` says so)."""
    from ..scene.parse import _Parser, _read_regular_file

    try:
        text = _read_regular_file(pathlib.Path(scene_path)).decode("utf-8")
    except FileNotFoundError:
        raise SceneError(scene_path, "", None, "no such scene file",
                         "check the path (scenes live in configs/*.toml)") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        from ..scene import parse_scene

        parse_scene(text, scene_path)  # its one message for a TOML mistake
        raise
    index, entry = _log_entry(scene_path, data)
    log = _log_path(scene_path, entry)
    skip = int(entry.get("skip_rows", 0))
    told = False
    with tempfile.TemporaryDirectory(prefix="linkpipe-follow-") as folder:
        while True:
            first = _first_rows_file(log, folder, skip)
            if first is not None:
                break
            if not told:
                say(f"waiting for the log {log} (a header and two rows)")
                told = True
            if not wait():
                raise LogFault(f"{log}: no header and two complete rows came; nothing written")
        trial = copy.deepcopy(data)
        trial["logs"][index]["file"] = first
        scene = _Parser(trial, text, scene_path).parse()
    scene = replace(scene, logs=tuple(replace(lg, file=entry["file"], path=log)
                                      if lg.name == entry["name"] else lg for lg in scene.logs))
    wanted = followed_columns(scene)
    scale = float(entry.get("time_scale", 1.0))
    if globbing.has_magic(log) or log.lower().endswith(".parquet"):
        tail = ParquetTail(log, entry["time"], wanted, scale)
    else:
        tail = CsvTail(log, entry["time"], wanted, scale, entry.get("delimiter", ","), skip)
    return scene, tail, log


class Reports:
    """Alarms (a residual beyond ``alarm`` x sigma), no_input and no_assembly stretches: each
    stretch said when it begins and when it ends, printed and logged to the recording."""

    def __init__(self, scene, say, recording=None):
        self.say, self.recording = say, recording
        self.alarms = {m.name: 0 for m in scene.measurements if m.alarm}
        self.limits = [(j, m.name, m.alarm, m.sigma) for j, m in enumerate(scene.measurements)
                       if m.alarm]
        self.open: dict[str, tuple[int, float]] = {}  # what -> (first step, its time)

    def block(self, part) -> None:
        steps = np.asarray(part.step_numbers)
        t = part.time if part.time is not None else np.full(len(steps), np.nan)
        flags = {"no_input": part.status == Status.NO_INPUT,
                 "no_assembly": part.status == Status.NO_ASSEMBLY}
        sigmas = {}
        if self.limits and part.measurements:
            r = part.measurements["residual"]
            for j, name, k, sigma in self.limits:
                with np.errstate(invalid="ignore"):
                    z = np.abs(r[:, j]) / sigma
                beyond = z > k
                self.alarms[name] += int(beyond.sum())
                flags[f"alarm {name}"] = beyond
                sigmas[f"alarm {name}"] = (z, k)
        for what, on in flags.items():
            self._stretches(what, on, steps, t, sigmas.get(what))

    def _stretches(self, what, on, steps, t, z) -> None:
        if not on.any() and what not in self.open:
            return
        change = np.flatnonzero(np.diff(np.r_[what in self.open, on].astype(np.int8)))
        for i in change:  # i: the row where it changes
            if on[i]:
                self.open[what] = (int(steps[i]), float(t[i]))
                extra = (f": |residual| {z[0][i]:.3g} sigma > {z[1]:g}" if z is not None else "")
                self._tell(int(steps[i]), float(t[i]), f"{what} from step {steps[i]}"
                           f"{_at(t[i])}{extra}", "WARN" if what.startswith("alarm") else "ERROR")
            else:
                first, t0 = self.open.pop(what)
                self._tell(int(steps[i]), float(t[i]), f"{what} ended at step {steps[i]}"
                           f"{_at(t[i])}: {steps[i] - first} step(s) from step {first}"
                           f"{_at(t0)}", "INFO")

    def end(self) -> None:
        for what, (first, t0) in list(self.open.items()):
            self.say(f"  {what} still on at the end: from step {first}{_at(t0)}")

    def _tell(self, step, t, text, level) -> None:
        self.say(f"  {text}")
        if self.recording is not None:
            self.recording.note(step, t, text, level)


def _at(t) -> str:
    return f" (t = {t:.6g} s)" if np.isfinite(t) else ""


def _lock(out: pathlib.Path, name: str, path: pathlib.Path):
    """An exclusive lock on the output name (one follow or run at a time writes it)."""
    handle = open(out / f".{name}.lock", "a")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        raise SceneError(path, "scene", "name", f"{out / (name + '.h5')} is being written by "
                         "another linkpipe process", "stop it first, or give --out another "
                         "folder") from None
    return handle


def follow(scene_path: str, out="outputs", serve: bool = False, connect: str | None = None,
           port: int | None = None, idle: float | None = None, stop: threading.Event | None = None,
           say=print, settle: int = SETTLE_ROWS, poll: float = POLL_SECONDS,
           max_block: int = MAX_BLOCK_ROWS, memory: str | None = None,
           on_block=None, rrd: bool = False) -> Outcome:
    """Follow ``scene_path``'s ``[time]`` log into ``out/<name>.h5`` until ``idle`` seconds
    pass without a new row, ``stop`` is set, or the source fails; return the :class:`Outcome`.
    ``on_block(part, where[, at])``: called when a block's rows are in the .h5 (``where``
    "h5", now) and when they are with the viewer's sinks ("viewer", ``at`` the wall time the
    recording's process flushed them; benchmarks); ``rrd``: also write
    ``out/<name>.rrd`` as it grows."""
    from ..stores import output_folder

    stop = stop or threading.Event()
    last_new = [_time.monotonic()]

    def wait() -> bool:
        """Sleep one poll; False when follow should end (stopped, or idle too long)."""
        if stop.wait(poll):
            return False
        return idle is None or _time.monotonic() - last_new[0] < idle

    started = None
    if serve or connect or rrd:  # the recording's process imports while the scene is read
        from ..stores.rrd.live import start_process

        started = start_process()
    try:
        scene, tail, log = load_followed(scene_path, wait, say)
        out = output_folder(out)
        path = out / f"{scene.name}.h5"
        lock = _lock(out, scene.name, pathlib.Path(scene_path))
        try:
            return _follow(scene, tail, log, path, serve, connect, port, idle, stop, say,
                           settle, wait, last_new, max_block, memory, on_block, rrd, started)
        finally:
            tail.close()
            lock.close()
    finally:
        if started is not None and not started.taken:
            started.cancel()


def _follow(scene, tail, log, path, serve, connect, port, idle, stop, say, settle, wait,
            last_new, max_block, memory, on_block, rrd, started=None) -> Outcome:
    from ..pipeline import solve
    from ..stores.growing import GrowingWriter, stored

    before = stored(path)
    if before is not None and not before.followed:
        raise SceneError(scene.path, "scene", "name", f"{path} was written by run, not follow: "
                         "its arrays cannot grow", "move it away, or give --out another folder")
    if before is not None and before.scene_toml and before.scene_toml != scene.text:
        raise SceneError(scene.path, "scene", "name", f"{path} was written by follow from "
                         "another version of this scene (its scene_toml differs)",
                         "move that file away, or give --out another folder")
    start = before.rows if before else 0
    window = Window(scene, 0, settle, before.link_angle if before else None, threads=None)
    window.stored = start
    outcome = Outcome(path, rows=start)
    first = tail.poll()
    while len(first) < 2 and first.fault is None:
        if not wait():
            raise LogFault(f"{log}: no two complete rows came; nothing written")
        more = tail.poll()
        first = type(first)(np.r_[first.t, more.t], {c: np.r_[first.columns[c], more.columns[c]]
                                                    for c in first.columns}, more.fault)
    if len(first) < 2:
        raise first.fault
    first_row = {"t": float(first.t[0]),
                 "columns": {c: float(v[0]) for c, v in first.columns.items()}}
    if before is not None and before.rows and before.first_row is not None \
            and not _same_row(before.first_row, first_row):
        raise LogFault(f"{log}: its first row is not the one {path} was made from (t = "
                       f"{first_row['t']!r} s against {before.first_row['t']!r} s, or other "
                       "values): the log was replaced; the stored rows are kept (move the .h5 "
                       "away to follow the new log)")
    template = solve(window_scene(scene, first.t[:2], {c: v[:2] for c, v in first.columns.items()}))
    recording = None
    if serve or connect or rrd:  # first: a port in use is said before any file is made
        from ..stores.rrd.live import SERVER_MEMORY, LiveRecording

        recording = LiveRecording(template, serve, connect, port, memory or SERVER_MEMORY,
                                  path.with_suffix(".rrd") if rrd else None,
                                  None if on_block is None else
                                  (lambda part, at: on_block(part, "viewer", at)),
                                  started)
        outcome.address = recording.address
        if serve:
            say(f"serving the recording: rerun {recording.address}")
    try:
        writer = GrowingWriter(path, template, before, first_row)
    except BaseException:
        if recording is not None:
            recording.close()
        raise
    reports = Reports(scene, say, recording)
    viewer_error = None
    seconds: dict[str, float] = {}
    checked = before is None or before.rows == 0
    rows, partial_since, told_partial = first, None, False
    fault = None
    say(f"following {log}" + (f" after its {start:,} stored rows" if start else "")
        + f" into {path}")

    def store(part) -> None:
        if recording is not None:  # first: its thread logs the block while the file is written
            recording.add(part)
        writer.add(part)
        if on_block is not None:
            on_block(part, "h5")
        reports.block(part)
        for k, v in part.seconds.items():
            seconds[k] = seconds.get(k, 0.0) + v
        outcome.new += part.n_steps

    pools = threadpool_limits(limits=1, user_api="blas")  # once: each block's solve is small
    try:
        while True:
            if len(rows):
                last_new[0] = _time.monotonic()
                window.add(rows.t, rows.columns)
                if not checked and window.arrived >= start:
                    _check_resume(window, before, log)
                    checked = True
                window.skip_to(window.stored)
            fault = fault or rows.fault
            if fault is not None:
                break
            while not stop.is_set():
                part = window.block(max_rows=max_block)
                if part is None:
                    break
                store(part)
            if stop.is_set():
                outcome.why = "stopped"
                break
            if not len(rows):
                if tail.state.partial:
                    partial_since = partial_since or _time.monotonic()
                    if not told_partial and _time.monotonic() - partial_since > MID_LINE_NOTICE:
                        say(f"  waiting: the log ends mid-line ({len(tail.state.partial)} bytes "
                            f"without an end of line) for {MID_LINE_NOTICE:g} s")
                        told_partial = True
                else:
                    partial_since, told_partial = None, False
                if not wait():
                    outcome.why = "stopped" if stop.is_set() else f"no new row for {idle:g} s"
                    if tail.state.partial and not stop.is_set():
                        outcome.why += (f"; the log ends mid-line ({len(tail.state.partial)} "
                                        "bytes without an end of line, not taken)")
                    break
            rows = tail.poll()
        if not checked and window.arrived < start:
            fault = LogFault(f"{log}: has {window.arrived:,} rows, {path} holds {start:,}: the "
                             "log was replaced or shortened; the stored rows are kept")
        if checked:
            while (part := window.block(final=True, max_rows=max_block)) is not None:
                store(part)
    finally:
        pools.restore_original_limits()
        try:
            writer.finish(seconds, {"follow_log": str(log), "follow_settle_rows": settle})
        finally:
            if recording is not None:
                try:
                    recording.close()
                except LinkpipeError as exc:  # the viewer's end: said with the summary
                    viewer_error = exc
                outcome.recording_cpu = recording.cpu_seconds
    reports.end()
    outcome.rows, outcome.alarms = writer.rows, reports.alarms
    if fault is not None:
        outcome.why, outcome.code = str(fault), 1
    if viewer_error is not None:
        outcome.why = f"{outcome.why}; {viewer_error}" if outcome.why else str(viewer_error)
        outcome.code = max(outcome.code, 1)
    return outcome


def _same_row(a: dict, b: dict) -> bool:
    """Two first rows ({"t", "columns"}) read alike: every number equal, NaN (a missing value)
    where the other is NaN."""
    def same(x, y):
        return x == y or (x != x and y != y)

    return (same(a["t"], b["t"]) and a["columns"].keys() == b["columns"].keys()
            and all(same(v, b["columns"][c]) for c, v in a["columns"].items()))


def _check_resume(window: Window, before, log) -> None:
    """The log holds the rows the file holds: the last stored row's time is the log's."""
    i = before.rows - 1 - window.first
    t = float(window.t[i]) if 0 <= i < len(window.t) else float("nan")
    if before.time == before.time and t != before.time:
        raise LogFault(f"{log}: row {before.rows} is at t = {t!r} s, but the stored file's last "
                       f"row is at t = {before.time!r} s: the log was replaced; the stored rows "
                       "are kept (move the .h5 away to follow the new log)")
