"""Writes that fail cleanly and temporaries that say whose they are: what is kept, what is
cleaned, on a real (small) disk where the machine allows mounting one, else on a patched writer."""
import errno
import os
import pathlib
import random
import signal
import subprocess
import sys
import time

import h5py
import pytest
from rerun.chunk import RrdReader

import linkpipe
from linkpipe import stores
from linkpipe.__main__ import main
from linkpipe.stores import hdf5

ROOT = pathlib.Path(__file__).resolve().parents[2]
CRANK_ROCKER = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()


def _scene(tmp_path, name, steps):
    path = tmp_path / f"{name}_{steps}.toml"
    path.write_text(CRANK_ROCKER.replace("steps = 361", f"steps = {steps}")
                    .replace('name = "fourbar_crank_rocker"', f'name = "{name}"'))
    return path


@pytest.fixture
def small_disk(tmp_path):
    """A 3 MiB tmpfs (root only; skipped where mounting is not allowed)."""
    mount = tmp_path / "small"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mount)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here: {done.stderr.decode().strip()}")
    yield mount
    subprocess.run(["umount", str(mount)], capture_output=True)


def test_a_full_disk_is_one_line_exit_1_and_the_other_scenes_run(small_disk, tmp_path, capsys):
    big = _scene(tmp_path, "big", 200_001)
    small = ROOT / "configs" / "shear_press.toml"
    assert main(["run", str(big), str(small), "--out", str(small_disk), "--no-rrd"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert f"{small_disk / 'big.h5'}: not written" in err and "failed: " in err
    assert sorted(p.name for p in small_disk.iterdir() if not p.name.endswith(".lock")) == ["shear_press.h5"]


def test_the_disk_filling_during_the_write_leaves_no_partial_file(small_disk, monkeypatch):
    """The free-space estimate passes (patched), the disk fills while h5py writes: an
    OutputError naming the file, no temporary, no file under the final name."""
    result = linkpipe.solve(linkpipe.parse_scene(CRANK_ROCKER.replace("steps = 361", "steps = 200001"), "big.toml"))
    monkeypatch.setattr(stores, "check_space", lambda path, n: None)
    with pytest.raises(stores.OutputError) as info:
        hdf5.write(result, small_disk / "big.h5")
    assert "big.h5: not written: the disk is full" in str(info.value)
    assert list(small_disk.iterdir()) == []


STREAM_ONTO_FULL_DISK = """
import sys, linkpipe
from linkpipe import stores
from linkpipe.segments import stream
from linkpipe.stores import hdf5
stores.check_space = lambda path, n: None  # the disk fills after the check
scene = linkpipe.parse_scene(open(sys.argv[1]).read(), "big.toml")
try:
    with hdf5.SweepWriter(sys.argv[2], scene.n_steps) as writer:
        stream(scene, [writer], segment=1024)  # parts of ~0.4 MB: several fit the 3 MiB
except stores.OutputError as exc:
    print("OutputError:", exc)
"""


def test_a_disk_filling_between_the_segments_of_a_streamed_write_fails_cleanly(small_disk,
                                                                                  tmp_path):
    """A long sweep streamed in segments onto a disk that fills part-way (several parts
    written, one fails): one OutputError naming the file, exit 0 of the process that caught it
    (HDF5 once crashed it when the file closed: exit 139), no file left on the disk."""
    scene = tmp_path / "big.toml"
    scene.write_text(CRANK_ROCKER.replace("steps = 361", "steps = 200001"))
    done = subprocess.run([sys.executable, "-c", STREAM_ONTO_FULL_DISK, str(scene),
                           str(small_disk / "big.h5")], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "big.h5: not written: the disk is full" in done.stdout
    assert "Traceback" not in done.stderr and "Segmentation" not in done.stderr, done.stderr
    assert list(small_disk.iterdir()) == []


def test_enospc_from_the_library_becomes_an_output_error(tmp_path, monkeypatch):
    """Without a small disk: the writer raising ENOSPC mid-file is caught the same way."""
    result = linkpipe.solve(str(ROOT / "configs" / "shear_press.toml"))

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(hdf5, "_write_variable", full)
    (tmp_path / "shear_press.h5").write_bytes(b"previous")
    with pytest.raises(stores.OutputError):
        hdf5.write(result, tmp_path / "shear_press.h5")
    assert (tmp_path / "shear_press.h5").read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shear_press.h5"]


@pytest.mark.parametrize("slow", [False, True])
def test_a_part_whose_sync_fails_fails_the_streamed_write_cleanly(tmp_path, monkeypatch, slow):
    """The parts are synced on a thread of their own while the next is written: a sync that
    finds the disk full (the writeback's ENOSPC) fails the write all the same, whether it
    fails at once or after the next parts were written (``slow``: collected at a later part
    or at the end): one OutputError naming the file, the previous file kept, no temporary."""
    from linkpipe.segments import stream

    calls = []

    def sync(fd):
        calls.append(fd)
        if slow:
            time.sleep(0.3)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(hdf5, "_sync_data", sync)
    scene = linkpipe.parse_scene(CRANK_ROCKER.replace("steps = 361", "steps = 40001"), "big.toml")
    (tmp_path / "big.h5").write_bytes(b"previous")
    with pytest.raises(stores.OutputError, match="big.h5: not written: the disk is full"):
        with hdf5.SweepWriter(tmp_path / "big.h5", scene.n_steps) as writer:
            stream(scene, [writer], segment=2048)
    assert calls  # the first part's sync, at least, was started (and failed)
    assert (tmp_path / "big.h5").read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.h5"]


def test_stale_temporaries_of_dead_processes_are_removed_live_ones_kept(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".x.h5.{dead}.0123456789ab.tmp"
    live = tmp_path / f".x.h5.{os.getppid()}.0123456789ab.tmp"  # the test runner's parent
    other = tmp_path / ".notes.tmp"
    for p in (stale, live, other):
        p.write_bytes(b"partial")
    hdf5.write(linkpipe.solve(str(ROOT / "configs" / "shear_press.toml")), tmp_path / "shear_press.h5")
    assert not stale.exists() and live.exists() and other.exists()


_WRITER = """
import sys, linkpipe
from linkpipe.stores import hdf5
r = linkpipe.solve(sys.argv[1])
print("solved", flush=True)
while True:
    hdf5.write(r, sys.argv[2])
"""


def test_sigkill_while_writing_keeps_the_previous_file_and_the_next_write_cleans(tmp_path):
    scene = _scene(tmp_path, "big", 100_001)
    target = tmp_path / "big.h5"
    hdf5.write(linkpipe.solve(str(ROOT / "configs" / "shear_press.toml")), target)
    before = target.read_bytes()
    rng = random.Random(5)
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(scene), str(target)],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout.readline().strip() == "solved"
        time.sleep(rng.uniform(0.0, 0.3))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        with h5py.File(target) as f:  # whatever is under the final name is a whole file
            assert "status" in f and f["position"].shape[0] in (9, 100_001)
    hdf5.write(linkpipe.solve(str(ROOT / "configs" / "shear_press.toml")), target)
    assert not list(tmp_path.glob(".big.h5.*.tmp"))
    with h5py.File(target) as f:
        assert f["position"].shape[0] == 9  # the last write is whole
    assert before  # the first file was there to protect


def test_concurrent_runs_into_one_folder_pair_their_files(tmp_path):
    """Two runs write the same name at once (different sweeps): each .h5 beside its own .rrd."""
    out = tmp_path / "out"
    a, b = _scene(tmp_path, "same", 20_001), _scene(tmp_path, "same", 30_001)
    procs = [subprocess.Popen([sys.executable, "-m", "linkpipe", "run", str(s), "--out", str(out),
                               "--quiet"], cwd=ROOT) for s in (a, b)]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    with h5py.File(out / "same.h5") as f:
        steps_h5 = f["step"].shape[0]
    steps_rrd = _steps_in_recording(out / "same.rrd")
    assert steps_h5 == steps_rrd and steps_h5 in (20_001, 30_001)


def _steps_in_recording(path) -> int:
    """The number of steps the recording's solver/residual series holds."""
    store = RrdReader(path).stream().collect()
    df = store.reader(index="step", contents="/solver/residual").to_pandas()
    return int(df["/solver/residual:Scalars:scalars"].notna().sum())


def test_pid_less_temporaries_of_earlier_versions_go_once_an_hour_old(tmp_path):
    old = tmp_path / ".x.h5.0123456789ab.tmp"
    new = tmp_path / ".y.h5.0123456789ab.tmp"
    for p in (old, new):
        p.write_bytes(b"partial")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    removed = stores.remove_stale_temporaries(tmp_path)
    assert removed == [old] and new.exists()
