"""A recording that grows while ``follow`` runs: each block's rows logged as they are stored,
to a gRPC server in this process that keeps the history for viewers that connect late
(``--serve``, Rerun's ``serve_grpc``: its ``server_memory_limit`` bounds what it keeps, the
oldest rows dropped first, static data never) or to a running viewer (``--connect ADDR``).
Alarms and reports go to the ``alarms`` entity (a ``TextLog`` the viewer lists with its time
and level)."""
from __future__ import annotations

import hashlib
import queue
import socket
import threading
import uuid

from dataclasses import replace

import numpy as np
import rerun as rr

from ...errors import LinkpipeError
from ...result import Result
from . import APPLICATION_ID, log_result
from .layout import blueprint

#: what the server keeps for late viewers by default (the oldest rows go first past it)
SERVER_MEMORY = "512MiB"
#: what ends the logging thread
_END = object()
#: the entity of alarms, no_input / no_assembly stretches and the source's faults
ALARMS = "alarms"


class LiveRecording:
    """``serve``: start a gRPC server (``port``, default 9876; its address in
    :attr:`address`); ``connect``: stream to a running viewer at that address; ``file``: also
    write the recording to that ``.rrd`` as it grows (not bounded: the file keeps every row).
    ``template``: a Result of the scene (the layout of the views)."""

    def __init__(self, template, serve: bool = False, connect: str | None = None,
                 port: int | None = None, memory: str = SERVER_MEMORY, file=None,
                 on_sent=None):
        name = template.scene.name
        self.on_sent = on_sent  # on_sent(part): a block's rows are with the sinks (benchmarks)
        self.stream = rr.RecordingStream(APPLICATION_ID,
                                         recording_id=f"{name}-follow-{uuid.uuid4().hex}")
        self.address = None
        sinks = []
        if serve:
            _check_port(port or 9876)
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
        self._static = _UnchangedStaticSkipped(self.stream)
        # the blocks are logged on a thread of their own while the next block solves (a
        # bounded queue: a viewer slower than the log holds the solver back, never memory)
        self._queue: queue.Queue = queue.Queue(maxsize=16)
        self._failed: BaseException | None = None
        self._thread = threading.Thread(target=self._work, name="linkpipe-live-rrd", daemon=True)
        self._thread.start()

    def add(self, part) -> None:
        """Log the rows of one stored block (every entity ``run``'s recording has)."""
        self._put((self._block, (part,)))

    def note(self, step: int, time: float | None, text: str, level: str = "WARN") -> None:
        """One line in the ``alarms`` entity at ``step`` (and ``time``)."""
        self._put((self._note, (step, time, text, level)))

    def _put(self, item) -> None:
        if self._failed is not None:
            raise self._failed
        self._queue.put(item)

    def _work(self) -> None:
        """Log what comes, in order; blocks waiting one after another go out as one (a
        block's logging costs mostly per call: a viewer behind catches up)."""
        pending = None
        while True:
            item, pending = (pending if pending is not None else self._queue.get()), None
            if item is _END:
                return
            if item[0] == self._block:
                parts = [item[1][0]]
                while pending is None:
                    try:
                        following = self._queue.get_nowait()
                    except queue.Empty:
                        break
                    if following is not _END and following[0] == self._block:
                        parts.append(following[1][0])
                    else:
                        pending = following  # a note, or the end: after these blocks
                item = (self._block, (_joined(parts),))
            if self._failed is None:
                try:
                    item[0](*item[1])
                except BaseException as exc:  # noqa: BLE001 (raised in the caller's thread)
                    self._failed = exc

    def _block(self, part) -> None:
        log_result(self._static, part)
        self.stream.flush()
        if self.on_sent is not None:
            self.on_sent(part)

    def _note(self, step: int, time: float | None, text: str, level: str) -> None:
        self.stream.set_time("step", sequence=int(step))
        if time is not None and np.isfinite(time):
            self.stream.set_time("time", duration=np.timedelta64(int(round(time * 1e9)), "ns"))
        self.stream.log(ALARMS, rr.TextLog(text, level=level))
        self.stream.reset_time()

    def close(self) -> None:
        """Flush every row to the sinks and end them (the server with them)."""
        self._queue.put(_END)
        self._thread.join()
        self.stream.flush()
        self.stream.disconnect()


class _UnchangedStaticSkipped:
    """``stream`` whose static ``log`` calls go out only when the entity's content (its
    components' Arrow data) differs from what was last sent to that path: a static component
    is overwritten by the next, so an unchanged one sent again shows nothing new, yet costs a
    call, its encoding and its bytes on every block. Every other call goes to ``stream``.
    :attr:`logged` and :attr:`skipped` count the static calls sent and left out."""

    def __init__(self, stream: rr.RecordingStream):
        self._stream = stream
        self._sent: dict[tuple, bytes] = {}  # (path, components) -> digest of their data
        self.logged = self.skipped = 0

    def __getattr__(self, name):
        return getattr(self._stream, name)

    def log(self, entity, archetype, *extra, static: bool = False, **kwargs) -> None:
        if not static or extra or kwargs or not hasattr(archetype, "as_component_batches"):
            self._stream.log(entity, archetype, *extra, static=static, **kwargs)
            return
        batches = archetype.as_component_batches()
        key = (str(entity), tuple(str(b.component_descriptor()) for b in batches))
        digest = _digest(batches)
        if self._sent.get(key) == digest:
            self.skipped += 1
            return
        self._stream.log(entity, archetype, static=True)
        self._sent[key] = digest
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
