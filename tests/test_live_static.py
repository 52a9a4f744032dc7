"""The follow stream (stores/rrd/live.py) sends a static entity again only when its content
changed: a recording written block by block with it holds exactly what the recording written
with every static entity re-sent holds (the same entities, archetypes, per-step rows and
latest static values), with fewer ``log`` calls per block (issue 32's viewer latency)."""
from __future__ import annotations

import os
import pathlib
import threading
import time

import numpy as np
import pandas as pd
import pytest

import linkpipe
from linkpipe.stores.rrd.live import BlockLogger, LiveRecording

from test_rrd import Recording

SCENE = pathlib.Path(__file__).resolve().parent.parent / "configs" / "logged" / "fourbar_live.toml"
BLOCK = 30  # rows per block, as at 1 kHz


@pytest.fixture(scope="module")
def blocks():
    result = linkpipe.solve(linkpipe.load_scene(SCENE))
    n = min(result.n_steps, 12 * BLOCK)
    return result, [result.strided(np.arange(a, min(a + BLOCK, n))) for a in range(0, n, BLOCK)]


def _written(path, template, blocks, resend_all: bool):
    """The recording of ``blocks`` logged one after another by follow's :class:`BlockLogger`
    (in this process), with the ``log`` calls it made."""
    logger = BlockLogger(template, file=path)
    if resend_all:  # the stream before the change: every static entity logged with each block
        logger.static = logger.stream
    calls = []
    log = logger.stream.log

    def counted(*args, **kwargs):
        calls.append(args[0])
        return log(*args, **kwargs)

    logger.stream.log = counted
    for part in blocks:
        logger.block(part)
    logger.close()
    return Recording(path), len(calls), logger.static


def _same_recording(new, old) -> None:
    assert new.entities == old.entities and new.archetypes == old.archetypes
    for entity in sorted(old.entities):
        a, b = new.steps(entity), old.steps(entity)
        assert list(a.columns) == list(b.columns), entity
        # every row and every static column (the latest value the viewer shows) equal
        pd.testing.assert_frame_equal(a.astype(str), b.astype(str), obj=entity)


def test_unchanged_static_entities_are_sent_once_and_the_recording_is_the_same(blocks, tmp_path):
    template, parts = blocks
    new, new_calls, static = _written(tmp_path / "new.rrd", template, parts, resend_all=False)
    old, old_calls, _ = _written(tmp_path / "old.rrd", template, parts, resend_all=True)
    _same_recording(new, old)
    # every call left out is a static one skipped, and after the first block (where every
    # static entity goes out) the blocks make less than a quarter of the calls they made
    assert new_calls + static.skipped == old_calls
    per_block = old_calls // len(parts)
    assert per_block * len(parts) == old_calls
    assert (new_calls - per_block) / (len(parts) - 1) < per_block / 4, (new_calls, old_calls)


def test_a_changed_static_entity_is_sent_again(tmp_path):
    """The digest follows the content: a series' new name goes out, the same name does not."""
    import rerun as rr

    from linkpipe.stores.rrd.live import _UnchangedStaticSkipped

    stream = rr.RecordingStream("linkpipe-test")
    stream.set_sinks(rr.FileSink(str(tmp_path / "x.rrd")))
    static = _UnchangedStaticSkipped(stream)
    for name in ("a", "a", "b", "b", "a"):
        static.log("plot/x", rr.SeriesLines(names=name, colors=[[1, 2, 3]]), static=True)
    static.log("plot/x", rr.SeriesLines(names="a", colors=[[1, 2, 4]]), static=True)
    assert (static.logged, static.skipped) == (4, 2)
    stream.set_time("step", sequence=0)  # a row on the step timeline (the reader's index)
    stream.log("plot/x", rr.Scalars(1.0))
    stream.flush()
    stream.disconnect()  # the file's footer
    rec = Recording(tmp_path / "x.rrd")
    frame = rec.steps("/plot/x")
    (names,) = [c for c in frame.columns if c.endswith(":names")]
    (colors,) = [c for c in frame.columns if c.endswith(":colors")]
    assert [str(n) for n in frame[names].iloc[-1]] == ["a"]   # the latest: the last sent
    assert [int(c) for c in frame[colors].iloc[-1]] == [0x010204FF]


def test_the_recording_made_in_its_own_process_is_the_one_made_here(blocks, tmp_path):
    """:class:`LiveRecording` logs in a process of its own (the blocks pickled through a
    pipe): fed the same blocks one at a time, its file holds what :class:`BlockLogger` writes
    in this process, every entity, row and static value; each block is said sent once its
    rows are flushed; a note lands in ``alarms`` at its step; the process is gone after
    close."""
    template, parts = blocks
    here, _, _ = _written(tmp_path / "here.rrd", template, parts, resend_all=False)
    sent = threading.Semaphore(0)
    said = []
    rec = LiveRecording(template, file=tmp_path / "there.rrd",
                        on_sent=lambda part, at: (said.append(part.step_numbers[0]),
                                                  sent.release()))
    pid = rec._process.pid
    assert pid != os.getpid()
    for part in parts:
        rec.add(part)
        assert sent.acquire(timeout=60)
    rec.close()
    assert said == [p.step_numbers[0] for p in parts]
    assert rec._process.poll() == 0  # ended, cleanly
    _same_recording(Recording(tmp_path / "there.rrd"), here)


def test_a_block_the_recording_cannot_log_is_one_error_here(blocks, tmp_path):
    """A failure in the recording's process (a block whose rows it cannot log: here one
    without its scene) comes back as one LinkpipeError at the next call, not a hang."""
    from dataclasses import replace

    from linkpipe.errors import LinkpipeError

    template, parts = blocks
    rec = LiveRecording(template, file=tmp_path / "x.rrd")
    try:
        rec.add(replace(parts[0], scene=None))
        with pytest.raises(LinkpipeError, match="logging to the recording failed"):
            for _ in range(600):
                rec.add(parts[1])
                time.sleep(0.1)
    finally:
        rec.close()
    assert rec._process.poll() == 0
