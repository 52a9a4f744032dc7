"""Faults at the command line: what is kept, what is cleaned, and that nothing hangs.

Each test runs the real CLI (in-process through ``main`` or as a subprocess when a signal is
involved) on real files and checks the exit status, the one-line message, the files left.
"""
import os
import pathlib
import signal
import subprocess
import sys
import time

import h5py
import pytest

from linkpipe.__main__ import main

ROOT = pathlib.Path(__file__).resolve().parents[2]
CRANK_ROCKER = ROOT / "configs" / "fourbar_crank_rocker.toml"


#: steps of a run that lasts past the last signal's delay on any machine CI runs on (the
#: crank-rocker, streamed in segments: 16M steps about 10 s here; 8M finished in 5 s after the
#: 2026-11-24 speed-ups, before the 4.5 s signal below)
LONG_STEPS = 16_000_000


def _long_scene(tmp_path, steps=LONG_STEPS):
    """The crank-rocker with a long sweep (seconds of work) and a name of its own."""
    text = CRANK_ROCKER.read_text().replace("steps = 361", f"steps = {steps}")
    text = text.replace('name = "fourbar_crank_rocker"', 'name = "long"')
    path = tmp_path / "long.toml"
    path.write_text(text)
    return path


def test_two_scenes_with_one_name_stop_before_any_work(tmp_path, capsys):
    copy = tmp_path / "copy.toml"
    copy.write_text(CRANK_ROCKER.read_text())
    out = tmp_path / "out"
    assert main(["run", str(CRANK_ROCKER), str(copy), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(CRANK_ROCKER) in err and str(copy) in err and "fourbar_crank_rocker" in err
    assert "Traceback" not in err
    assert not out.exists()  # nothing solved, nothing written


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
def test_a_path_that_is_no_regular_file_is_refused_without_reading(tmp_path, capsys, kind):
    path = {"device": pathlib.Path("/dev/zero"), "folder": tmp_path}.get(kind, tmp_path / "f.toml")
    if kind == "fifo":
        os.mkfifo(path)  # opening it to read would block forever
    t0 = time.monotonic()
    for command in ("run", "check"):
        assert main([command, str(path), "--out", str(tmp_path / "out")][:2 if command == "check" else 4]) == 2
    assert time.monotonic() - t0 < 5
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "Traceback" not in err and str(path) in err


def test_an_output_folder_that_cannot_be_made_is_one_line_exit_1(tmp_path, capsys):
    """A folder the machine will not make (/proc takes no new entries, root or not): an
    output not written, exit 1. A file in the way (/dev/null) is a wrong --out: exit 2,
    naming the file."""
    assert main(["run", str(CRANK_ROCKER), "--out", "/proc/linkpipe_out", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("error: --out /proc/linkpipe_out: cannot be made: ")
    assert "internal error" not in err
    assert main(["run", str(CRANK_ROCKER), "--out", "/dev/null/outputs", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == ("error: --out /dev/null/outputs: cannot be the output folder: "
                           "/dev/null is a file, not a folder — give --out a folder (made if "
                           "missing)")


@pytest.mark.parametrize("signum, code, delay_s", [(signal.SIGINT, 130, 3.0), (signal.SIGTERM, 130, 3.0),
                                                   (signal.SIGINT, 130, 1.7), (signal.SIGINT, 130, 4.5)])
def test_a_signal_stops_the_run_at_once_and_keeps_earlier_outputs(tmp_path, signum, code, delay_s):
    """Sent during the imports' end, the solve or the writers (delays), the run stops within a
    few seconds with one line and exit 130, and keeps the previous output (or, when the .h5
    was already complete, the new one whole: never a part of it), and no .rrd."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "long.h5").write_bytes(b"the previous run's file")
    scene = _long_scene(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "linkpipe", "run", str(scene), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    time.sleep(delay_s)  # imports done, deep in the sweep or the writers
    t0 = time.monotonic()
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=30)
    assert time.monotonic() - t0 < 5
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1, stderr
    if (out / "long.h5").read_bytes() != b"the previous run's file":
        # the signal came while the .rrd was written: the .h5 was complete and renamed before
        with h5py.File(out / "long.h5") as f:
            assert f["position"].shape[0] == LONG_STEPS and f.attrs["steps_ok"] == LONG_STEPS
    left = sorted(p.name for p in out.iterdir() if not p.name.endswith(".lock"))
    assert left == ["long.h5"]  # no temporaries, no .rrd (an advisory lock file may stay)


_SIGNAL_INSIDE = """
import os, signal, sys
from linkpipe.stores import hdf5, rrd
where = sys.argv[3]
if where == "rrd":  # the .h5 published, the recording started
    write = rrd.write
    def rrd_write(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return write(*args, **kwargs)
    rrd.write = rrd_write
else:  # the .h5 writer's own thread, at its third part: the main thread is solving
    write_rows, parts = hdf5.SweepWriter._write_rows, []
    def write_rows_then_stop(self, *args):
        parts.append(1)
        if len(parts) == 3:
            os.kill(os.getpid(), signal.SIGINT)
        return write_rows(self, *args)
    hdf5.SweepWriter._write_rows = write_rows_then_stop
from linkpipe.__main__ import main
sys.exit(main(["run", sys.argv[1], "--out", sys.argv[2]]))
"""


@pytest.mark.parametrize("where", ["hdf5", "rrd"])
def test_a_signal_inside_a_writer_keeps_whole_files_only(tmp_path, where):
    """Ctrl-C raised from inside the .h5 writer's thread (while the main thread solves the next
    segment) or inside the recording's writer: exit 130, one line; the previous .h5 kept (the
    .h5 writer) or the new one whole (the recording's: it was published first); no .rrd, no
    temporary file."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "long.h5").write_bytes(b"the previous run's file")
    steps = 200_001  # a dozen segments
    scene = _long_scene(tmp_path, steps)
    proc = subprocess.run([sys.executable, "-c", _SIGNAL_INSIDE, str(scene), str(out), where],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    if where == "hdf5":
        assert (out / "long.h5").read_bytes() == b"the previous run's file"
    else:
        with h5py.File(out / "long.h5") as f:
            assert f["position"].shape[0] == steps and f.attrs["steps_ok"] == steps
    left = sorted(p.name for p in out.iterdir() if not p.name.endswith(".lock"))
    assert left == ["long.h5"]


def test_the_other_scenes_run_after_one_fails_and_the_summary_names_it(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(CRANK_ROCKER.read_text().replace("[[links]]", "[[linkz]]", 1))
    out = tmp_path / "out"
    assert main(["run", str(bad), str(CRANK_ROCKER), "--out", str(out), "--no-rrd"]) == 2
    captured = capsys.readouterr()
    assert "fourbar_crank_rocker: all 361 steps ok" in captured.out
    assert f"failed: {bad}" in captured.err
    with h5py.File(out / "fourbar_crank_rocker.h5") as f:
        assert (f["status"][()] == 0).all()


def test_a_scene_nested_too_deeply_is_one_message_exit_2(tmp_path, capsys):
    """5,000 nested arrays (the TOML reader recurses past Python's limit): run and check each
    say so in one line naming the file, exit 2, no traceback, nothing written."""
    deep = tmp_path / "deep.toml"
    deep.write_text(CRANK_ROCKER.read_text() + "\n[extra]\nx = " + "[" * 5000 + "]" * 5000 + "\n")
    out = tmp_path / "out"
    for argv in (["run", str(deep), "--out", str(out)], ["check", str(deep)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"error: {deep}: ")
        assert "nested more deeply than the TOML reader can follow" in err
        assert "Traceback" not in err and "RecursionError" not in err
    assert not out.exists()


def test_a_scene_name_too_long_for_a_file_name_is_one_message_exit_2(tmp_path, capsys):
    """A [scene] name of 300 characters: its lock, outputs and temporaries would pass the file
    system's 255-byte limit on a file name. run, check and fit refuse it in one line naming
    [scene] name and the longest name allowed, exit 2, nothing written; a name of exactly that
    length runs and leaves its files (and no lock)."""
    from linkpipe.stores import longest_output_name

    out = tmp_path / "out"
    longest, limit = longest_output_name(out)
    assert limit == os.pathconf(tmp_path, "PC_NAME_MAX")

    def named(n):
        path = tmp_path / f"name{n}.toml"
        path.write_text(CRANK_ROCKER.read_text().replace('name = "fourbar_crank_rocker"',
                                                         f'name = "{"n" * n}"'))
        return path

    for argv in (["run", str(named(300)), "--out", str(out)], ["check", str(named(300))],
                 ["fit", str(named(300)), "--out", str(out)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "[scene] name: 300 bytes long" in err
        assert f"at most {longest} bytes" in err and "Traceback" not in err
    assert not out.exists()
    assert main(["run", str(named(longest)), "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["n" * longest + ".h5", "n" * longest + ".rrd"]


def test_a_run_leaves_no_lock_file(tmp_path):
    """The advisory lock on an output name is removed by its holder: after a run (and after one
    that failed) the output folder holds the outputs alone."""
    out = tmp_path / "out"
    assert main(["run", str(CRANK_ROCKER), "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["fourbar_crank_rocker.h5",
                                                      "fourbar_crank_rocker.rrd"]


def test_the_lock_on_a_name_is_held_by_one_run_at_a_time_although_its_file_goes(tmp_path):
    """Runs that wait on a name while its holder removes the lock file each lock it afresh:
    never two holders at once (four threads, each with its own open file, flock's unit), and
    no lock file once all are done."""
    import threading

    from linkpipe.stores import output_lock

    holders, most, turns = [], [0], []

    def run(k):
        for _ in range(20):
            with output_lock(tmp_path, "same"):
                holders.append(k)
                most[0] = max(most[0], len(holders))
                time.sleep(0.001)
                turns.append(k)
                holders.remove(k)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert most[0] == 1 and len(turns) == 80
    assert not (tmp_path / ".same.lock").exists()
