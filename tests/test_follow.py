"""``follow``: a real logger process appends to a real file while ``python -m linkpipe follow``
runs in its own process; the final ``.h5`` is compared with a batch ``run`` of the complete
log, read while it grows by this (second) process, killed and resumed, and fed each fault of
a live source.

Exact answers: the batch run of the same complete log (linkpipe's own v2 pipeline, right to
1e-9 against references); a followed row's spline has at least SETTLE_ROWS (20) samples on
either side of it (or the log's end, as the batch's), so its values agree with the batch's to
rounding (0.268^20 ~ 4e-12 of the end condition's change reaches it; measured on this rig's
log: equal to the last bit, benchmarks/bench_settle.py): 1e-9 in the scene's units (m,
rad, N) is a bound far above that and far below any modelling difference. Rows stored at an
earlier end, whose spline ended there, keep those values (docs/follow.md): their positions
agree to 1e-9, their rates as the settling bound says.
"""
from __future__ import annotations

import pathlib
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from linkpipe.__main__ import main
from linkpipe.follow.blocks import SETTLE_ROWS

ROOT = pathlib.Path(__file__).resolve().parent.parent
LOGGER = ROOT / "configs" / "logged" / "rig_logger.py"
SCENE = ROOT / "configs" / "logged" / "fourbar_live.toml"
#: agreement with the batch run (m, m/s, rad, N, ...): see the module's docstring
TOL = 1e-9


@pytest.fixture
def rig(tmp_path):
    """(scene path, log path, out folder) in a fresh folder."""
    (tmp_path / "logs").mkdir()
    scene = tmp_path / "fourbar_live.toml"
    shutil.copy(SCENE, scene)
    return scene, tmp_path / "logs" / "live_rig.csv", tmp_path / "out"


def _logger(log, *args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(LOGGER), str(log), *map(str, args)])


def _follow(scene, out, *args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "linkpipe", "follow", str(scene), "--out",
                             str(out), *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT)


def _batch(scene, tmp_path) -> h5py.File:
    """The batch ``run`` of the scene on its (now complete) log."""
    batch = tmp_path / "batch"
    assert main(["run", str(scene), "--out", str(batch), "--no-rrd", "--quiet"]) == 0
    return h5py.File(batch / "fourbar_live.h5", "r")


def _assert_equal_to_batch(path, batch, rows: slice = slice(None), tol: float = TOL) -> None:
    with h5py.File(path, "r") as f:
        assert f.attrs["complete"] == 1
        np.testing.assert_array_equal(f["step"][()], np.arange(len(batch["step"])))
        for name, ds in batch.items():
            if ds.dtype.kind == "f" and ds.dims[0] and ds.ndim and len(ds.dims[0]) \
                    and ds.dims[0][0].name == "/step":
                np.testing.assert_allclose(f[name][rows], ds[rows], rtol=0, atol=tol,
                                           err_msg=name)
            elif ds.dtype.kind in "iu" and ds.ndim == 1 and len(ds) == len(batch["step"]):
                np.testing.assert_array_equal(f[name][rows], ds[rows], err_msg=name)
        for key in ("steps_ok", "steps_failed", "newton_iterations_max"):
            assert f.attrs[key] == batch.attrs[key], key
        np.testing.assert_allclose(f["measured_residual"].attrs["rms"],
                                   batch["measured_residual"].attrs["rms"], rtol=1e-12)


def _wait_for(predicate, seconds=60.0, every=0.05):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(every)
    raise AssertionError("timed out")


def _rows(path) -> int:
    """The rows a second process reads in the growing file (0 before it exists)."""
    try:
        with h5py.File(path, "r", swmr=True) as f:
            return int(f["step"].shape[0])
    except (OSError, KeyError):
        return 0


def test_a_followed_log_is_read_while_it_grows_and_ends_equal_to_a_batch_run(rig, tmp_path):
    scene, log, out = rig
    # 8 s of logging: follow starts in a second or three on a busy machine, then reads along
    writer = _logger(log, "--rate", 500, "--seconds", 8, "--burst", 5, "--jam-at", 4)
    follower = _follow(scene, out, "--idle", 1.5)
    h5 = out / "fourbar_live.h5"
    seen = []  # (rows, complete, position rows finite) read by this process while it grows
    while follower.poll() is None and len(seen) < 50:
        try:
            with h5py.File(h5, "r", swmr=True) as f:
                n = int(f["step"].shape[0])
                if n and (not seen or n > seen[-1][0]):
                    assert f["position"].shape[0] >= n  # the block being written, or equal
                    seen.append((n, int(f.attrs["complete"]), bool(np.isfinite(
                        f["position"][n - 1]).all()), f["time"][n - 1]))
        except (OSError, KeyError):
            pass
        time.sleep(0.1)
    assert writer.wait(30) == 0
    stdout, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    growing = [s for s in seen if s[1] == 0]
    assert len(growing) >= 3, seen  # read at least three times while it grew
    assert all(ok for _, _, ok, _ in growing)
    assert [n for n, *_ in growing] == sorted({n for n, *_ in growing})
    with _batch(scene, tmp_path) as batch:
        _assert_equal_to_batch(h5, batch)
        # the times read while it grew are the log's rows (nothing shifted)
        t = batch["time"][()]
        for n, _, _, last in growing:
            assert last == t[n - 1]
        # the alarm: the rocker encoder slips 2 degrees (40 sigma) at t = 4 s, to the end
        r = batch["measured_residual"][:, 0] / np.radians(0.05)
        expected = int((np.abs(r) > 4.0).sum())
    assert f"rocker_angle {expected:,} row(s)" in stdout
    assert "alarm rocker_angle from step 2000 (t = 4 s)" in stdout


def test_sigkill_then_restart_loses_and_duplicates_no_row(rig, tmp_path):
    scene, log, out = rig
    writer = _logger(log, "--rate", 1000, "--seconds", 4, "--burst", 20)
    follower = _follow(scene, out)
    h5 = out / "fourbar_live.h5"
    _wait_for(lambda: _rows(h5) > 500)
    follower.send_signal(signal.SIGKILL)
    follower.wait(10)
    killed_rows = _rows(h5)
    with pytest.raises(OSError):  # a killed SWMR writer's file: SWMR reads only
        h5py.File(h5, "r").close()
    time.sleep(0.3)
    again = _follow(scene, out, "--idle", 1.5)
    assert writer.wait(30) == 0
    stdout, stderr = again.communicate(timeout=60)
    assert again.returncode == 0, stderr
    assert f"after its {killed_rows:,} stored rows" in stdout
    with _batch(scene, tmp_path) as batch:
        _assert_equal_to_batch(h5, batch)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_ends_follow_with_every_row_and_a_complete_file(rig, tmp_path, signum):
    scene, log, out = rig
    writer = _logger(log, "--rate", 1000, "--seconds", 1.5, "--burst", 10)
    follower = _follow(scene, out)  # no --idle: only the signal ends it
    assert writer.wait(30) == 0
    h5 = out / "fourbar_live.h5"
    _wait_for(lambda: _rows(h5) >= 1500 - SETTLE_ROWS)  # every row but the settling window
    follower.send_signal(signum)
    stdout, stderr = follower.communicate(timeout=30)
    assert follower.returncode == 0, stderr
    assert "Traceback" not in stderr and "ended: stopped" in stdout
    with _batch(scene, tmp_path) as batch:
        _assert_equal_to_batch(h5, batch)


def test_follow_resumes_after_a_clean_end_and_the_rows_stored_then_keep_their_values(rig, tmp_path):
    scene, log, out = rig
    assert _logger(log, "--rate", 1000, "--seconds", 1, "--fast").wait(30) == 0
    first = _follow(scene, out, "--idle", 0.5)
    assert first.wait(60) == 0
    h5 = out / "fourbar_live.h5"
    with h5py.File(h5, "r") as f:
        assert f.attrs["complete"] == 1 and f["step"].shape == (1000,)
    assert _logger(log, "--rate", 1000, "--seconds", 1, "--fast", "--append").wait(30) == 0
    second = _follow(scene, out, "--idle", 0.5)
    stdout, stderr = second.communicate(timeout=60)
    assert second.returncode == 0, stderr
    assert "after its 1,000 stored rows" in stdout
    with _batch(scene, tmp_path) as batch:
        # rows before the first end's settling window, and every row after it: the batch's
        _assert_equal_to_batch(h5, batch, slice(0, 1000 - SETTLE_ROWS))
        _assert_equal_to_batch(h5, batch, slice(1000, None))
        # the settling window of the first end: positions exact, rates as their spline gave
        with h5py.File(h5, "r") as f:
            window = slice(1000 - SETTLE_ROWS, 1000)
            np.testing.assert_allclose(f["position"][window], batch["position"][window],
                                       rtol=0, atol=TOL)
            dv = np.abs(f["driver_velocity"][window] - batch["driver_velocity"][window])
            assert dv[-1].max() > TOL  # the end condition did move the last row's rate
            assert dv[0].max() < TOL   # and SETTLE_ROWS rows before, not measurably


def test_a_resume_onto_a_log_of_another_run_is_one_message_and_keeps_the_rows(rig, tmp_path):
    """The rig restarted with other noise (another seed) writes a log whose time stamps match
    the stored rows' but whose values do not: following it again is one message, exit 1, the
    stored rows and their file untouched; the same run logged again (the same seed: the same
    bytes) is the same log and is followed on."""
    scene, log, out = rig
    assert _logger(log, "--rate", 1000, "--seconds", 1, "--fast").wait(30) == 0
    assert _follow(scene, out, "--idle", 0.5).wait(60) == 0
    h5 = out / "fourbar_live.h5"
    before = h5.read_bytes()
    assert _logger(log, "--rate", 1000, "--seconds", 2, "--fast", "--seed", 11).wait(30) == 0
    again = _follow(scene, out, "--idle", 0.5)
    stdout, stderr = again.communicate(timeout=60)
    assert again.returncode == 1, stderr
    said = stdout + stderr
    assert "its first row is not the one" in said and "the log was replaced" in said
    assert "Traceback" not in said and h5.read_bytes() == before
    assert _logger(log, "--rate", 1000, "--seconds", 2, "--fast").wait(30) == 0  # seed 3 again
    same = _follow(scene, out, "--idle", 0.5)
    stdout, stderr = same.communicate(timeout=60)
    assert same.returncode == 0, stderr
    assert "after its 1,000 stored rows" in stdout
    with h5py.File(h5, "r") as f:
        assert f["step"].shape == (2000,) and f.attrs["complete"] == 1


# ------------------------------------------------------------------------------- faults
HEADER = "t,crank_deg,rocker_deg,p_height_mm\n"


def _row(i: int, t: float | None = None) -> str:
    t = i * 0.002 if t is None else t
    return f"{t:.6f},{720.0 * t:.6f},{100.0:.3f},{1700.0:.3f}\n"


def _fault_writer(log, fault: str) -> subprocess.Popen:
    """A logger that writes 300 good rows (0.002 s apart), then, once the file ``<log>.go``
    exists (follow has stored what it can), the ``fault``."""
    code = textwrap.dedent(f"""
        import os, sys, time
        rows = {[_row(i) for i in range(300)]!r}
        log = {str(log)!r}
        with open(log, "w") as f:
            f.write({HEADER!r})
            for k in range(0, 300, 50):
                f.write("".join(rows[k:k + 50])); f.flush(); time.sleep(0.05)
        while not os.path.exists(log + ".go"):
            time.sleep(0.02)
        fault = {fault!r}
        if fault == "backwards":
            open(log, "a").write({_row(0, 0.3)!r})
        elif fault == "column":
            open(log, "a").write("0.602000,433.44,100.0\\n")
        elif fault == "rotated":
            os.replace(log, log + ".1")
            open(log, "w").write({HEADER + _row(0) + _row(1)!r})
        elif fault == "truncated":
            open(log, "r+").truncate(100)
        elif fault == "mid-line":
            f = open(log, "a"); f.write("0.602000,433.4"); f.flush()
            time.sleep(30)
    """)
    return subprocess.Popen([sys.executable, "-c", code])


@pytest.mark.parametrize("fault, code, said", [
    ("backwards", 1, "row 301 (line 302 of the file): time 0.3 s goes backwards"),
    ("column", 1, "row 301 (line 302 of the file) has 3 fields, the header 4: a column disappeared"),
    ("rotated", 1, "was replaced by another file (a rotation)"),
    ("truncated", 1, "was truncated to 100 bytes"),
    ("mid-line", 0, "the log ends mid-line (14 bytes without an end of line, not taken)"),
])
def test_each_fault_of_a_live_source_is_one_message_and_a_clean_end(rig, tmp_path, fault, code,
                                                                   said):
    scene, log, out = rig
    writer = _fault_writer(log, fault)
    _wait_for(lambda: log.exists())
    follower = _follow(scene, out, "--idle", 2.5)
    h5 = out / "fourbar_live.h5"
    _wait_for(lambda: _rows(h5) >= 300 - SETTLE_ROWS)  # all but the settling window stored
    pathlib.Path(str(log) + ".go").touch()
    stdout, stderr = follower.communicate(timeout=90)
    writer.kill()
    writer.wait()
    assert follower.returncode == code, stderr
    assert said in (stderr + stdout)
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) <= 1
    with h5py.File(h5, "r") as f:  # every good row stored, the file complete
        assert f.attrs["complete"] == 1
        np.testing.assert_array_equal(f["step"][()], np.arange(300))
        np.testing.assert_allclose(f["time"][()], np.arange(300) * 0.002, atol=1e-12)


PARQUET_WRITERS = {
    # a new file per 100 rows, each written under a temporary name and renamed
    "files": """
        for k, lo in enumerate(range(0, len(frame), 100)):
            tmp = logs + f"/.part_{k:03d}.tmp"
            frame.iloc[lo:lo + 100].to_parquet(tmp, index=False)
            os.replace(tmp, logs + f"/part_{k:03d}.parquet")
            time.sleep(0.1)
    """,
    # one file, written again with one row group of 100 rows more each time
    "row_groups": """
        import pyarrow as pa, pyarrow.parquet as pq
        table = pa.Table.from_pandas(frame, preserve_index=False)
        for k in range(1, (len(frame) + 99) // 100 + 1):
            with pq.ParquetWriter(logs + "/.run.tmp", table.schema) as w:
                for g in range(k):
                    w.write_table(table.slice(100 * g, 100))
            os.replace(logs + "/.run.tmp", logs + "/run.parquet")
            time.sleep(0.1)
    """,
}


@pytest.mark.parametrize("how, file", [("files", "logs/part_*.parquet"),
                                       ("row_groups", "logs/run.parquet")])
def test_a_parquet_log_growing_equals_the_batch_run_of_its_rows(tmp_path, how, file):
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    logs = tmp_path / "logs"
    logs.mkdir()
    text = SCENE.read_text().replace('file = "logs/live_rig.csv"', f'file = "{file}"')
    scene = tmp_path / "fourbar_live.toml"
    scene.write_text(text)
    csv = tmp_path / "all.csv"
    assert _logger(csv, "--rate", 500, "--seconds", 2, "--fast").wait(30) == 0
    frame = pd.read_csv(csv)
    code = "import os, time, pandas as pd\n" + f"frame = pd.read_csv({str(csv)!r})\n" + \
        f"logs = {str(logs)!r}\n" + textwrap.dedent(PARQUET_WRITERS[how])
    writer = subprocess.Popen([sys.executable, "-c", code])
    _wait_for(lambda: list(logs.glob("*.parquet")))
    follower = _follow(scene, tmp_path / "out", "--idle", 1.5)
    assert writer.wait(60) == 0
    stdout, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    batch_scene = tmp_path / "batch.toml"
    batch_scene.write_text(text.replace(f'file = "{file}"', f'file = "{csv}"'))
    with _batch(batch_scene, tmp_path) as batch:
        assert len(batch["step"]) == len(frame)
        _assert_equal_to_batch(tmp_path / "out" / "fourbar_live.h5", batch)


def test_alarms_and_stretches_go_to_the_recording(rig, tmp_path):
    from test_rrd import Recording

    scene, log, out = rig
    assert _logger(log, "--rate", 500, "--seconds", 2, "--fast", "--jam-at", 1).wait(30) == 0
    follower = _follow(scene, out, "--idle", 0.5, "--rrd")
    stdout, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    rec = Recording(out / "fourbar_live.rrd")
    assert "/alarms" in rec.entities
    frame = rec.steps("/alarms").dropna(subset=["/alarms:TextLog:text"])
    texts = [str(t[0]) for t in frame["/alarms:TextLog:text"]]
    assert any(t.startswith("alarm rocker_angle from step 500 (t = 1 s)") for t in texts)
    assert list(frame["step"]) == [500]
    assert "/mechanism/points" in rec.entities
    assert len(rec.steps("/mechanism/points").dropna(subset=["step"])) == 1000


def test_a_scene_without_a_time_log_is_a_scene_error(tmp_path, capsys):
    assert main(["follow", str(ROOT / "configs" / "fourbar_crank_rocker.toml"), "--out",
                 str(tmp_path), "--idle", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "[time] log" in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.h5"))


ALARM = "sigma = 0.0005                     # 0.5 mm\nalarm = 4.0"


@pytest.mark.parametrize("written, said", [
    ("alarm = 4.0", "alarm = 4 is a number of sigmas: it needs a positive value and the "
                    "measurement's sigma"),
    ("sigma = 0.0005\nalarm = -1.0", "alarm = -1 is a number of sigmas"),
])
def test_an_alarm_needs_the_measurement_sigma_and_a_positive_value(rig, written, said):
    from linkpipe import SceneError, parse_scene

    scene, log, out = rig
    assert _logger(log, "--rate", 100, "--seconds", 0.1, "--fast").wait(30) == 0
    text = scene.read_text()
    assert text.count(ALARM) == 1
    with pytest.raises(SceneError) as err:
        parse_scene(text.replace(ALARM, written), str(scene))
    assert said in str(err.value) and err.value.key == "alarm"
    assert err.value.table == 'measurements "p_height"'


def test_a_port_in_use_is_one_message_before_any_file(rig, capsys):
    import socket

    scene, log, out = rig
    assert _logger(log, "--rate", 100, "--seconds", 0.1, "--fast").wait(30) == 0
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["follow", str(scene), "--out", str(out), "--serve", "--port", str(port),
                     "--idle", "0.1"]) == 2
    err = capsys.readouterr().err
    assert f"--serve: port {port} is in use" in err and "Traceback" not in err
    assert not list(out.glob("*.h5"))


def test_a_connect_address_rerun_cannot_take_is_one_message_before_any_file(rig, capsys):
    scene, log, out = rig
    assert _logger(log, "--rate", 100, "--seconds", 0.1, "--fast").wait(30) == 0
    with pytest.raises(SystemExit) as stop:  # the option's own check: usage and one line
        main(["follow", str(scene), "--out", str(out), "--connect", "127.0.0.1:9876",
              "--idle", "0.1"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "expected a viewer's address like rerun+http://127.0.0.1:9876/proxy, got " \
           "'127.0.0.1:9876'" in err and "Traceback" not in err
    assert not list(out.glob("*.h5"))


def test_a_connect_address_where_no_viewer_listens_is_one_message_before_any_file(rig, capsys):
    """Nothing listens there: one message at once, exit 1, no file (follow had hung on the
    recording's flush, deaf to SIGTERM, its .h5 left with the held-back rows unstored)."""
    import socket

    scene, log, out = rig
    assert _logger(log, "--rate", 100, "--seconds", 0.1, "--fast").wait(30) == 0
    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    t0 = time.monotonic()
    assert main(["follow", str(scene), "--out", str(out), "--connect",
                 f"rerun+http://127.0.0.1:{port}/proxy", "--idle", "0.1"]) == 1
    assert time.monotonic() - t0 < 10
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and f"no viewer listens at 127.0.0.1:{port}" in err
    assert "Traceback" not in err and not list(out.glob("*.h5"))


def test_a_viewer_that_takes_nothing_holds_follow_at_most_close_seconds(rig, capsys, monkeypatch):
    """A peer that accepts the connection and never answers (a hung viewer): follow stores
    every row, ends its .h5 complete, then waits at most CLOSE_SECONDS for the recording and
    stops it: one message, exit 1 (it had waited for the peer for minutes, deaf to SIGTERM)."""
    import socket
    import threading

    from linkpipe.stores.rrd import live

    monkeypatch.setattr(live, "CLOSE_SECONDS", 3.0)
    scene, log, out = rig
    assert _logger(log, "--rate", 200, "--seconds", 2, "--fast").wait(30) == 0
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held, done = [], threading.Event()

    def accept():  # take every connection, read nothing, answer nothing
        server.settimeout(0.2)
        while not done.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                pass

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        t0 = time.monotonic()
        code = main(["follow", str(scene), "--out", str(out), "--idle", "0.5", "--connect",
                     f"rerun+http://127.0.0.1:{server.getsockname()[1]}/proxy"])
        took = time.monotonic() - t0
    finally:
        done.set()
        thread.join()
        for c in held:
            c.close()
        server.close()
    assert code == 1 and took < 30
    captured = capsys.readouterr()
    assert captured.err.count("error:") == 1 and "took none of the last rows for 3 s" in captured.err
    assert "Traceback" not in captured.err
    with h5py.File(out / "fourbar_live.h5", "r") as f:
        assert f.attrs["complete"] == 1 and f["step"].shape == (400,)


def test_a_window_resumed_after_stored_rows_takes_the_rows_in_any_pieces(rig):
    """Resuming after 700 stored rows, the log read in pieces of 37 rows (fewer than the rows
    stored): the blocks are the batch's rows 700.. (the window keeps the settling rows before
    them, and the rows it forgets are never needed)."""
    import linkpipe
    from linkpipe.follow.blocks import Window

    scene, log, out = rig
    assert _logger(log, "--rate", 1000, "--seconds", 1, "--fast").wait(30) == 0
    whole = linkpipe.load_scene(str(scene))
    batch = linkpipe.solve(whole)
    data = whole.logs[0]
    window = Window(whole, last_angles=batch.link_angle[699])
    window.stored = 700
    parts = []
    for lo in range(0, 1000, 37):
        window.add(data.t[lo:lo + 37], {c: data.columns[c][lo:lo + 37] for c in window.columns})
        window.skip_to(window.stored)
        while (part := window.block()) is not None:
            parts.append(part)
    while (part := window.block(final=True)) is not None:
        parts.append(part)
    steps = np.concatenate([p.step_numbers for p in parts])
    np.testing.assert_array_equal(steps, np.arange(700, 1000))
    from linkpipe import log_splines
    assert not log_splines._SPLINE_VALUES  # the windows' splines are not kept (memory)
    for name in ("position", "velocity", "acceleration", "link_angle", "driver_acceleration"):
        got = np.concatenate([getattr(p, name) for p in parts])
        np.testing.assert_allclose(got, getattr(batch, name)[700:], rtol=0, atol=TOL, err_msg=name)
    got = np.concatenate([p.forces["input_force"][1] for p in parts])
    np.testing.assert_allclose(got, batch.forces["input_force"][1][700:], rtol=0, atol=TOL)


def test_a_reader_holding_the_file_does_not_keep_it_from_completing(rig, tmp_path):
    scene, log, out = rig
    assert _logger(log, "--rate", 1000, "--seconds", 1, "--fast").wait(30) == 0
    follower = _follow(scene, out, "--idle", 1.0)
    h5 = out / "fourbar_live.h5"
    _wait_for(lambda: _rows(h5) > 0)
    with h5py.File(h5, "r", swmr=True) as held:  # held open across follow's end
        assert held.attrs["complete"] == 0
        import linkpipe

        growing = linkpipe.read(h5, "dataframe")  # linkpipe.read of a growing file too
        np.testing.assert_array_equal(growing.index, np.arange(len(growing)))
        assert len(growing) >= 1 and np.isfinite(growing["position.P.y"]).all()
        assert linkpipe.read(h5).sizes["step"] >= len(growing)
        stdout, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    with _batch(scene, tmp_path) as batch:
        _assert_equal_to_batch(h5, batch)


def test_a_no_input_stretch_is_reported_as_it_happens(rig, tmp_path):
    """Ten empty crank readings (rows 300..309) written by the logger mid-run: follow says
    when the no_input stretch begins and ends, with its steps and times, and the statuses
    equal the batch run's."""
    scene, log, out = rig
    code = textwrap.dedent(f"""
        import time
        with open({str(log)!r}, "w") as f:
            f.write({HEADER!r})
            for i in range(600):
                t = i * 0.002
                crank = "" if 300 <= i < 310 else f"{{720.0 * t:.6f}}"
                f.write(f"{{t:.6f}},{{crank}},100.0,1700.0\\n")
                if i % 50 == 49:
                    f.flush(); time.sleep(0.05)
    """)
    writer = subprocess.Popen([sys.executable, "-c", code])
    _wait_for(lambda: log.exists())
    follower = _follow(scene, out, "--idle", 1.0)
    assert writer.wait(30) == 0
    stdout, stderr = follower.communicate(timeout=60)
    assert follower.returncode == 0, stderr
    assert "no_input from step 300 (t = 0.6 s)" in stdout
    assert "no_input ended at step 310 (t = 0.62 s): 10 step(s) from step 300 (t = 0.6 s)" in stdout
    with _batch(scene, tmp_path) as batch:
        assert (batch["status"][300:310] == 4).all()
        _assert_equal_to_batch(out / "fourbar_live.h5", batch)


def test_a_file_that_run_wrote_is_not_followed_into(rig, tmp_path, capsys):
    scene, log, out = rig
    assert _logger(log, "--rate", 100, "--seconds", 0.5, "--fast").wait(30) == 0
    assert main(["run", str(scene), "--out", str(out), "--no-rrd", "--quiet"]) == 0
    before = (out / "fourbar_live.h5").read_bytes()
    assert main(["follow", str(scene), "--out", str(out), "--idle", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "was written by run, not follow" in err and "Traceback" not in err
    assert (out / "fourbar_live.h5").read_bytes() == before


_NUMBER = st.one_of(
    st.floats(-1e9, 1e9, allow_nan=False).map(lambda v: f"{v:.6f}"),
    st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: f"{v:.12f}"),
    st.integers(-10**15, 10**15).map(str),
    st.floats(-1e300, 1e300, allow_nan=False).map(repr),  # exponents, 17 digits: pandas reads
    st.sampled_from(["0", "-0.0", "-0.000", ".5", "5.", "+3.25", "", " 7.5"]))


@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.tuples(_NUMBER, _NUMBER), min_size=1, max_size=40),
       pieces=st.lists(st.integers(1, 7), min_size=1, max_size=12))
def test_the_tail_reads_the_bits_the_batch_reader_reads(tmp_path_factory, values, pieces):
    """CsvTail's rows, read a few lines at a time (its own number reader for plain decimals of
    up to 15 digits, pandas for the rest), equal bit for bit pandas.read_csv of the whole file
    (the batch run's log reader): the same floats, whichever reader took a line."""
    import pandas as pd

    from linkpipe.follow.tail import CsvTail

    path = tmp_path_factory.mktemp("tail") / "log.csv"
    lines = [f"{i * 0.001:.3f},{a},{b}" for i, (a, b) in enumerate(values)]
    path.write_text("t,a,b\n")
    tail = CsvTail(path, "t", ["a", "b"])
    got, at, k = {"t": [], "a": [], "b": []}, 0, 0
    while at < len(lines):
        step = pieces[k % len(pieces)]
        with open(path, "a") as f:
            f.write("".join(line + "\n" for line in lines[at:at + step]))
        at, k = at + step, k + 1
        rows = tail.poll()
        assert rows.fault is None
        got["t"].append(rows.t)
        for c in ("a", "b"):
            got[c].append(rows.columns[c])
    tail.close()
    ref = pd.read_csv(path, skipinitialspace=True, index_col=False, engine="c")
    for c in got:
        mine = np.concatenate(got[c])
        want = pd.to_numeric(ref[c], errors="coerce").to_numpy(dtype=float)
        assert mine.tobytes() == want.tobytes(), c


def test_follow_connects_to_a_running_viewer_and_every_row_arrives(rig, tmp_path):
    """``follow --connect ADDR`` streams to a Rerun server already running (the rerun binary
    itself, listening and saving what it receives, as test_rrd's ``run --connect`` test): a
    logger writes in real time while follow runs; the server gets every stored row once on
    the ``step`` timeline, the alarm, and every entity of the ``.rrd`` follow writes beside."""
    from test_rrd import _stream_entities, saving_rerun_server

    scene, log, out = rig
    saved = tmp_path / "streamed.rrd"
    with saving_rerun_server(saved) as port:
        writer = _logger(log, "--rate", 500, "--seconds", 2, "--burst", 5, "--jam-at", 1)
        follower = _follow(scene, out, "--connect", f"rerun+http://127.0.0.1:{port}/proxy",
                           "--idle", 1.5, "--rrd")
        assert writer.wait(30) == 0
        stdout, stderr = follower.communicate(timeout=60)
        assert follower.returncode == 0, stderr
        assert "1,000 rows (1,000 new), complete" in stdout
    import warnings

    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a streamed file has no footer: expected
        store = RrdReader(saved).stream().collect()
    points = store.reader(index="step", contents="/mechanism/points").to_pandas()
    np.testing.assert_array_equal(np.sort(points["step"].to_numpy()), np.arange(1000))
    alarms = store.reader(index="step", contents="/alarms").to_pandas()
    texts = [str(t[0]) for t in alarms["/alarms:TextLog:text"].dropna()]
    assert any(t.startswith("alarm rocker_angle from step 500 (t = 1 s)") for t in texts)
    assert _stream_entities(saved) == _stream_entities(out / "fourbar_live.rrd")


def test_a_coarsely_rounded_log_settles_with_more_rows_given_by_settle(rig, tmp_path):
    """The rows that settle a stored row depend on the log: the crank's angle rounded to 0.001
    degree (an encoder's resolution) moves the spline's end more with each new row than the
    demo logger's 1e-9 degree. Fed in blocks of 5 rows (as at 1 kHz), the default
    SETTLE_ROWS leaves the driver's acceleration beyond 1e-9 of the batch run's (measured
    2.8e-8 rad/s^2; benchmarks/bench_settle.py), 28 rows bring every array within it; and
    ``follow --settle 28`` stores that many in the file's ``follow_settle_rows``."""
    import pandas as pd

    import linkpipe
    from linkpipe.follow.blocks import Window

    scene, log, out = rig
    assert _logger(log, "--rate", 1000, "--seconds", 2, "--fast").wait(30) == 0
    frame = pd.read_csv(log)
    frame["crank_deg"] = frame["crank_deg"].round(3)
    frame.to_csv(log, index=False, float_format="%.9f")
    whole = linkpipe.load_scene(str(scene))
    batch = linkpipe.solve(whole)
    data = whole.logs[0]

    def worst(settle: int) -> float:
        window, parts = Window(whole, settle=settle), []
        for lo in range(0, len(data.t), 5):
            window.add(data.t[lo:lo + 5], {c: data.columns[c][lo:lo + 5] for c in window.columns})
            while (part := window.block()) is not None:
                parts.append(part)
        while (part := window.block(final=True)) is not None:
            parts.append(part)
        got = np.concatenate([p.driver_acceleration for p in parts])
        return float(np.abs(got - batch.driver_acceleration).max())

    assert worst(SETTLE_ROWS) > TOL
    assert worst(28) <= TOL
    assert main(["follow", str(scene), "--out", str(out), "--idle", "0.3", "--settle", "28",
                 "--quiet"]) == 0
    with h5py.File(out / "fourbar_live.h5", "r") as f:
        assert f.attrs["follow_settle_rows"] == 28
    with _batch(scene, tmp_path) as b:
        _assert_equal_to_batch(out / "fourbar_live.h5", b)


def test_the_recording_process_ends_with_a_killed_follow_and_frees_the_port(rig, tmp_path):
    """The recording (and with --serve its gRPC server) runs in a process of its own: when
    follow's process is SIGKILLed it ends by itself (its pipe closes), so the port is free
    again and the next ``follow --serve`` on it starts and ends cleanly."""
    import socket

    from test_rrd import _free_port

    scene, log, out = rig
    port = _free_port()
    writer = _logger(log, "--rate", 1000, "--seconds", 3, "--burst", 20)
    follower = _follow(scene, out, "--serve", "--port", port)
    h5 = out / "fourbar_live.h5"
    _wait_for(lambda: _rows(h5) > 300)

    def listening() -> bool:
        with socket.socket() as sock:
            return sock.connect_ex(("127.0.0.1", port)) == 0

    _wait_for(listening, seconds=30)  # the server is up (in the recording's process)
    follower.send_signal(signal.SIGKILL)
    follower.wait(10)
    _wait_for(lambda: not listening(), seconds=30)  # its recording process went with it
    again = _follow(scene, out, "--serve", "--port", port, "--idle", 1.5)
    assert writer.wait(30) == 0
    stdout, stderr = again.communicate(timeout=60)
    assert again.returncode == 0, stderr
    assert f"serving the recording: rerun rerun+http://127.0.0.1:{port}/proxy" in stdout
    with _batch(scene, tmp_path) as batch:
        _assert_equal_to_batch(h5, batch)
