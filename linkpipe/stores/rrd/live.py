"""A recording that grows while ``follow`` runs: each block's rows logged as they are stored,
to a gRPC server in this process that keeps the history for viewers that connect late
(``--serve``, Rerun's ``serve_grpc``: its ``server_memory_limit`` bounds what it keeps, the
oldest rows dropped first, static data never) or to a running viewer (``--connect ADDR``).
Alarms and reports go to the ``alarms`` entity (a ``TextLog`` the viewer lists with its time
and level)."""
from __future__ import annotations

import uuid

import numpy as np
import rerun as rr

from . import APPLICATION_ID, log_result
from .layout import blueprint

#: what the server keeps for late viewers by default (the oldest rows go first past it)
SERVER_MEMORY = "512MiB"
#: the entity of alarms, no_input / no_assembly stretches and the source's faults
ALARMS = "alarms"


class LiveRecording:
    """``serve``: start a gRPC server (``port``, default 9876; its address in
    :attr:`address`); ``connect``: stream to a running viewer at that address; ``file``: also
    write the recording to that ``.rrd`` as it grows (not bounded: the file keeps every row).
    ``template``: a Result of the scene (the layout of the views)."""

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

    def add(self, part) -> None:
        """Log the rows of one stored block (every entity ``run``'s recording has)."""
        log_result(self.stream, part)
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
