"""A recording that grows while ``follow`` runs: each block's rows logged as they are stored,
to a gRPC server that keeps the history for viewers that connect late (``--serve``, Rerun's
``serve_grpc``: its ``server_memory_limit`` bounds what it keeps, the oldest rows dropped
first, static data never) or to a running viewer (``--connect ADDR``). Alarms and reports go
to the ``alarms`` entity (a ``TextLog`` the viewer lists with its time and level).

The recording is made in a process of its own (:class:`LiveRecording` starts it; the stream,
its sinks and the gRPC server live there, :class:`BlockLogger`): logging a block (building
its archetypes, ~24 ``send_columns``, the flush) costs about as much CPU as solving it, and
on a thread of follow's process it held the interpreter while the next block solved. The
blocks go to it pickled through a pipe; it says when each one is with the sinks."""
from __future__ import annotations

import hashlib
import json
import multiprocessing.connection
import os
import pickle
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
import uuid

from dataclasses import replace

import numpy as np
import rerun as rr

from ...errors import LinkpipeError
from ...result import Result
from . import APPLICATION_ID, check_listening, log_result
from .layout import blueprint

#: what the server keeps for late viewers by default (the oldest rows go first past it)
SERVER_MEMORY = "512MiB"
#: what ends the sending thread
_END = object()
#: the entity of alarms, no_input / no_assembly stretches and the source's faults
ALARMS = "alarms"
#: the most rows that blocks waiting for the recording are joined into (a viewer behind
#: catches up in fewer, larger calls; each message's pickle stays bounded)
JOIN_ROWS = 4096


class BlockLogger:
    """The stream of one followed recording, in the process that owns it: ``serve``: a gRPC
    server (``port``, default 9876; its address in :attr:`address`); ``connect``: a running
    viewer at that address; ``file``: also the ``.rrd`` as it grows (not bounded: the file
    keeps every row). ``template``: a Result of the scene (the layout of the views)."""

    def __init__(self, template, serve: bool = False, connect: str | None = None,
                 port: int | None = None, memory: str = SERVER_MEMORY, file=None):
        name = template.scene.name
        self.stream = rr.RecordingStream(APPLICATION_ID,
                                         recording_id=f"{name}-follow-{uuid.uuid4().hex}")
        self.address = None
        sinks = []
        if serve:
            server = rr.GrpcServerSink(port=port or 9876, server_memory_limit=memory)
            self.address = server.uri.replace("0.0.0.0", "127.0.0.1")
            sinks.append(server)
        elif connect:
            sinks.append(rr.GrpcSink(connect))
            self.address = connect
        if file is not None:
            sinks.append(rr.FileSink(str(file)))
        self.stream.set_sinks(*sinks, default_blueprint=blueprint(template))
        self.stream.send_recording_name(name)
        # what each block logs, with its static entities (styles, legends, series' names and
        # colours, ...) sent again only when their content changed since the last block
        self.static = _UnchangedStaticSkipped(self.stream)

    def block(self, part) -> None:
        """Log the rows of one stored block (every entity ``run``'s recording has) and wait
        until they are with the sinks."""
        log_result(self.static, part)
        self.stream.flush()

    def note(self, step: int, time: float | None, text: str, level: str = "WARN") -> None:
        """One line in the ``alarms`` entity at ``step`` (and ``time``)."""
        self.stream.set_time("step", sequence=int(step))
        if time is not None and np.isfinite(time):
            self.stream.set_time("time", duration=np.timedelta64(int(round(time * 1e9)), "ns"))
        self.stream.log(ALARMS, rr.TextLog(text, level=level))
        self.stream.reset_time()

    def close(self) -> None:
        """Flush every row to the sinks and end them (the server with them)."""
        self.stream.flush()
        self.stream.disconnect()


#: seconds :meth:`LiveRecording.close` waits for the recording's process to hand its last
#: rows to the sinks and end
CLOSE_SECONDS = 15.0


class LiveRecording:
    """A :class:`BlockLogger` in a process of its own (the same arguments), fed the blocks
    stored: :meth:`add` and :meth:`note` return at once (a thread pickles each block into a
    pipe; a bounded queue: a recording slower than the log holds the solver back, never the
    memory); blocks waiting in the pipe go out as one (a block's logging costs mostly per
    call: a viewer behind catches up). ``on_sent(part, at)``: called with each block once the
    recording's process has flushed it to the sinks, ``at`` the wall time (``time.time()``)
    the flush returned there (benchmarks). The process ignores Ctrl-C
    and SIGTERM (follow ends it, after the last rows) and ends by itself when follow's process
    is gone. A failure there is raised here, at the next :meth:`add` or :meth:`note`.
    ``started``: a process :func:`start_process` started earlier (its imports done while
    follow read the scene and solved its first rows), else one is started here."""

    def __init__(self, template, serve: bool = False, connect: str | None = None,
                 port: int | None = None, memory: str = SERVER_MEMORY, file=None,
                 on_sent=None, started: StartedProcess | None = None):
        try:
            if serve:
                _check_port(port or 9876)
            elif connect:  # a valid address where a viewer listens: said before any file
                check_listening(connect)
        except BaseException:
            if started is not None:
                started.cancel()
                started.taken = True
            raise
        self.on_sent = on_sent
        started = started or start_process()
        started.taken = True  # this recording ends it
        self._process, self._inbox, self._outbox = started.process, started.inbox, started.outbox
        self._opening = ("open", template, serve, connect, port, memory,
                         None if file is None else str(file))
        self._failed: BaseException | None = None
        self._told = False  # _failed raised here already (by add or note)
        self._ready = threading.Event()  # the process said "ready"
        # not waited for: the process starts (imports rerun, opens its sinks) while follow
        # solves its first block; it says "ready" with the address it serves or connects to
        self.address = (f"rerun+http://127.0.0.1:{port or 9876}/proxy" if serve else
                        connect or None)
        #: the CPU seconds the recording's process used (set by :meth:`close`)
        self.cpu_seconds = float("nan")
        self._sent: dict[int, Result] = {}  # blocks sent, waiting for their flush (on_sent)
        self._count = 0
        self._queue: queue.Queue = queue.Queue(maxsize=16)
        self._sender = threading.Thread(target=self._send, name="linkpipe-live-send", daemon=True)
        self._receiver = threading.Thread(target=self._receive, name="linkpipe-live-receive",
                                          daemon=True)
        self._sender.start()
        self._receiver.start()

    def add(self, part) -> None:
        """Log the rows of one stored block (every entity ``run``'s recording has)."""
        self._put(("block", part))

    def note(self, step: int, time: float | None, text: str, level: str = "WARN") -> None:
        """One line in the ``alarms`` entity at ``step`` (and ``time``)."""
        self._put(("note", int(step), None if time is None else float(time), text, level))

    def _put(self, item) -> None:
        if self._failed is not None:
            self._told = True
            raise self._failed
        self._queue.put(item)

    def _send(self) -> None:
        """Pickle what comes into the pipe, in order, until the end: what is waiting in the
        queue goes as one message per run of blocks (joined, up to :data:`JOIN_ROWS` rows),
        and nothing goes before the process is ready (up to :data:`JOIN_ROWS` rows that come
        meanwhile are held, so follow's first blocks do not wait for it; past them the queue
        fills and holds follow back, as a slow viewer does)."""
        try:
            _post(self._outbox, self._opening)  # what to record: the sinks, the views' layout
        except BaseException as exc:  # noqa: BLE001 (raised in the caller's thread)
            self._failed = LinkpipeError(f"the recording's process is gone ({exc!r})")
        while True:
            items = [self._queue.get()]
            rows = _rows_of(items[-1])
            while (not self._ready.is_set() and self._failed is None
                   and items[-1] is not _END):
                if rows >= JOIN_ROWS:
                    self._ready.wait(0.05)
                    continue
                try:
                    items.append(self._queue.get(timeout=0.02))
                    rows += _rows_of(items[-1])
                except queue.Empty:
                    pass
            while items[-1] is not _END and rows < JOIN_ROWS:
                try:
                    items.append(self._queue.get_nowait())
                    rows += _rows_of(items[-1])
                except queue.Empty:
                    break
            for message in self._messages(items):
                if self._failed is None or message[0] == "end":  # the end: after a failure too
                    try:
                        _post(self._outbox, message)
                    except BaseException as exc:  # noqa: BLE001 (raised in the caller's thread)
                        self._failed = self._failed or LinkpipeError(
                            f"the recording's process is gone ({exc!r})")
            if items[-1] is _END:
                return

    def _messages(self, items: list) -> list:
        """The pipe's messages for queued ``items``, in order: each run of consecutive blocks
        one ``("block", [their numbers], the blocks joined)`` of at most :data:`JOIN_ROWS`
        rows (or one block, if larger), notes and the end as they are."""
        out, run, rows = [], [], 0
        for item in items + [None]:
            block = item is not None and item is not _END and item[0] == "block"
            if run and (not block or rows + item[1].n_steps > JOIN_ROWS):
                out.append(("block", [k for k, _ in run], _joined([p for _, p in run])))
                run, rows = [], 0
            if block:
                self._count += 1
                if self.on_sent is not None:
                    self._sent[self._count] = item[1]
                run.append((self._count, item[1]))
                rows += item[1].n_steps
            elif item is _END:
                out.append(("end",))
            elif item is not None:
                out.append(item)
        return out

    def _receive(self) -> None:
        """What the recording's process says: blocks flushed, a failure, the end."""
        while True:
            try:
                message = self._inbox.recv()
            except (EOFError, OSError):
                if self._failed is None:
                    self._failed = LinkpipeError("the recording's process ended unexpectedly "
                                                 f"(exit code {self._process.poll()})")
                return
            if message[0] == "sent":
                for k in message[1]:
                    part = self._sent.pop(k, None)
                    try:
                        if part is not None:
                            self.on_sent(part, message[2])
                    except BaseException as exc:  # noqa: BLE001 (raised in the caller's thread)
                        self._failed = self._failed or exc
            elif message[0] == "ready":
                self.address = message[1] or self.address
                self._ready.set()
            elif message[0] == "failed":
                self._failed = LinkpipeError(message[1])
            elif message[0] == "closed":
                self.cpu_seconds = message[1]
                return

    def close(self) -> None:
        """Flush every row to the sinks and end them (the server with them), and the
        recording's process: within :data:`CLOSE_SECONDS`, else the process is stopped and
        :class:`ViewerTimeout` says so (a viewer that accepted the connection and then took
        nothing had held follow at its end for minutes, deaf to Ctrl-C; the .h5 is finished
        before this is called)."""
        deadline = time.monotonic() + CLOSE_SECONDS

        def left() -> float:
            return max(0.1, deadline - time.monotonic())

        stopped = False
        try:
            self._queue.put(_END, timeout=left())
        except queue.Full:
            stopped = True
        self._sender.join(left())
        try:
            self._process.wait(timeout=left())
        except subprocess.TimeoutExpired:
            stopped = True
        if stopped:
            self._process.kill()
            self._process.wait()
        self._sender.join(5.0)
        self._receiver.join(5.0)
        self._inbox.close()
        self._outbox.close()
        if stopped:
            raise ViewerTimeout(f"the viewer at {self.address} took none of the last rows for "
                                f"{CLOSE_SECONDS:g} s: its stream was stopped (every row is in "
                                "the .h5)")
        if self._failed is not None and not self._told:  # after the last add: said here
            raise self._failed


class ViewerTimeout(LinkpipeError):
    """The viewer did not take follow's last rows in time (exit 1: an output not delivered)."""

    exit_code = 1


class StartedProcess:
    """A recording's process started and waiting to be told what to record (its imports,
    rerun's among them, done meanwhile): :attr:`process` (a ``subprocess.Popen``) and its
    pipes. A fresh interpreter that runs :func:`_record` on two pipes it inherits (not
    ``fork``: this process has threads; not multiprocessing's ``spawn``, which runs the
    calling script's ``__main__`` again in the child), with this process's ``sys.path``, in a
    session of its own (Ctrl-C at a terminal reaches follow, which ends it after the last
    rows)."""

    def __init__(self):
        down_read, down_write = os.pipe()  # here -> the recording's process
        up_read, up_write = os.pipe()      # the recording's process -> here
        code = ("import json, sys; sys.path[:0] = json.loads(sys.argv[3]); "
                "from linkpipe.stores.rrd.live import _record_on; "
                "_record_on(int(sys.argv[1]), int(sys.argv[2]))")
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-c", code, str(down_read), str(up_write),
                 json.dumps([p for p in sys.path if p])],
                pass_fds=(down_read, up_write), stdin=subprocess.DEVNULL,
                start_new_session=True)
        finally:
            os.close(down_read)
            os.close(up_write)
        self.inbox = multiprocessing.connection.Connection(up_read, writable=False)
        self.outbox = multiprocessing.connection.Connection(down_write, readable=False)
        self.taken = False  # a LiveRecording took it (and ends it)

    def cancel(self) -> None:
        """End it unused (follow ended before its recording began)."""
        try:
            _post(self.outbox, ("end",))
        except OSError:
            pass
        try:
            self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.terminate()
            self.process.wait()
        self.inbox.close()
        self.outbox.close()


def start_process() -> StartedProcess:
    """Start a recording's process now, to be handed to :class:`LiveRecording` later."""
    return StartedProcess()


def _record_on(down: int, up: int) -> None:
    """The recording's process (:class:`StartedProcess`): :func:`_record` on the pipes'
    file descriptors it inherited."""
    _record(multiprocessing.connection.Connection(down, writable=False),
            multiprocessing.connection.Connection(up, readable=False))


def _record(inbox, outbox) -> None:
    """The recording's process: told what to record by the first message on ``inbox``
    (``("open", template, serve, connect, port, memory, file)``: a :class:`BlockLogger`),
    then fed ``("block", [k, ...], part)``, ``("note", step, time, text, level)`` and
    ``("end",)``; saying on ``outbox`` when it is ready (its address), each block flushed
    (``("sent", [k, ...], the wall time)``), a failure, and ``("closed", its CPU seconds)``
    once every row is with the sinks."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
    try:
        opening = _take(inbox)
    except (EOFError, OSError):
        return
    if opening[0] != "open":  # ended unused
        return
    try:
        logger = BlockLogger(*opening[1:])
    except BaseException as exc:  # noqa: BLE001 (said in follow's process)
        outbox.send(("failed", f"the recording could not start: {exc}"))
        return
    outbox.send(("ready", logger.address))
    failed, waiting = False, None
    while True:
        try:
            message, waiting = waiting or _take(inbox), None
        except (EOFError, OSError):  # follow's process is gone: end the recording cleanly
            message = ("end",)
        if message[0] == "end":
            break
        if failed:
            continue
        try:
            if message[0] == "block":
                numbers, parts = list(message[1]), [message[2]]
                rows = parts[0].n_steps
                while waiting is None and rows < JOIN_ROWS and inbox.poll(0):  # as one
                    following = _take(inbox)
                    if following[0] == "block":
                        numbers += following[1]
                        parts.append(following[2])
                        rows += following[2].n_steps
                    else:
                        waiting = following  # a note, or the end: after these blocks
                logger.block(_joined(parts))
                outbox.send(("sent", numbers, time.time()))
            else:
                logger.note(*message[1:])
        except (EOFError, OSError):
            waiting = ("end",)
        except BaseException as exc:  # noqa: BLE001 (said in follow's process)
            failed = True
            where = traceback.extract_tb(exc.__traceback__)[-1]
            try:
                outbox.send(("failed", f"logging to the recording failed: {exc!r} (in "
                             f"{where.filename}, line {where.lineno})"))
            except OSError:
                pass
    try:
        logger.close()
    except BaseException as exc:  # noqa: BLE001 (said in follow's process, not a traceback here)
        try:
            outbox.send(("failed", f"the viewer's stream did not end cleanly: {exc}"))
        except OSError:
            pass
    try:
        outbox.send(("closed", time.process_time()))
    except OSError:
        pass


class _UnchangedStaticSkipped:
    """``stream`` whose static ``log`` calls go out only when the entity's content (its
    components' Arrow data) differs from what was last sent to that path: a static component
    is overwritten by the next, so an unchanged one sent again shows nothing new, yet costs a
    call, its encoding and its bytes on every block. Every other call goes to ``stream``.
    :attr:`logged` and :attr:`skipped` count the static calls sent and left out."""

    def __init__(self, stream: rr.RecordingStream):
        self._stream = stream
        self._sent: dict[tuple, bytes] = {}  # (path, components) -> digest of their data
        self._last: dict[str, object] = {}  # path -> the archetype object last sent there
        self.logged = self.skipped = 0

    def __getattr__(self, name):
        return getattr(self._stream, name)

    def log(self, entity, archetype, *extra, static: bool = False, **kwargs) -> None:
        if not static or extra or kwargs or not hasattr(archetype, "as_component_batches"):
            self._stream.log(entity, archetype, *extra, static=static, **kwargs)
            return
        if self._last.get(str(entity)) is archetype:  # the very object sent there last
            self.skipped += 1  # (a style built once, series.series_style): nothing to encode
            return
        batches = archetype.as_component_batches()
        key = (str(entity), tuple(str(b.component_descriptor()) for b in batches))
        digest = _digest(batches)
        if self._sent.get(key) == digest:
            self.skipped += 1
            return
        self._stream.log(entity, archetype, static=True)
        self._sent[key] = digest
        self._last[str(entity)] = archetype
        self.logged += 1


def _digest(batches) -> bytes:
    """A digest of component batches' Arrow data: types, lengths, offsets and every buffer
    (children's too), so equal digests mean equal contents."""
    h = hashlib.blake2b(digest_size=20)
    for batch in batches:
        array = batch.as_arrow_array()
        h.update(f"{batch.component_descriptor()}|{array.type}|{len(array)}|{array.offset}|"
                 .encode())
        for buffer in array.buffers():
            h.update(b"-" if buffer is None else b"+%d:" % buffer.size)
            if buffer is not None:
                h.update(memoryview(buffer))
    return h.digest()


def _post(connection, message) -> None:
    """Send ``message`` (a tuple holding blocks' arrays) with pickle protocol 5, the arrays'
    buffers sent from where they are (out of band): no pickled copy of a block's arrays is
    made here (a 16,384-row block's was ~16 MB, whose repeated allocation grew follow's
    memory through the C allocator's heap)."""
    buffers: list = []
    head = pickle.dumps(message, protocol=5, buffer_callback=buffers.append)
    connection.send_bytes(len(buffers).to_bytes(4, "little") + head)
    for buffer in buffers:
        connection.send_bytes(buffer.raw())


def _take(connection):
    """The message :func:`_post` sent (its arrays in writable buffers of their own)."""
    data = connection.recv_bytes()
    count = int.from_bytes(data[:4], "little")
    buffers = [bytearray(connection.recv_bytes()) for _ in range(count)]
    return pickle.loads(data[4:], buffers=buffers)


def _rows_of(item) -> int:
    """The rows of a queued block (0 for a note or the end)."""
    return item[1].n_steps if item is not _END and item[0] == "block" else 0


def _check_port(port: int) -> None:
    """One message (exit 2) where ``port`` is taken: Rerun's server would log the failure to
    listen and shut down at the first row."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("0.0.0.0", port))
        except OSError:
            raise LinkpipeError(f"--serve: port {port} is in use (another viewer or server "
                                "listens there); give --port another one") from None


def _joined(parts: list) -> Result:
    """Consecutive blocks as one Result (rows, forces, measurements concatenated)."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    rows = {name: np.concatenate([getattr(p, name) for p in parts])
            for name in Result.PER_STEP if getattr(first, name) is not None}
    forces = None
    if first.forces:
        forces = {name: (dims, np.concatenate([p.forces[name][1] for p in parts])
                         if dims[:1] == ("step",) else data, unit)
                  for name, (dims, data, unit) in first.forces.items()}
    measurements = first.measurements
    if measurements:
        measurements = {k: (np.concatenate([p.measurements[k] for p in parts])
                            if k in ("measured", "residual") else v)
                        for k, v in measurements.items()}
    return replace(first, **rows, forces=forces, measurements=measurements,
                   step_numbers=np.concatenate([p.step_numbers for p in parts]))
