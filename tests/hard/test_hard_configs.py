"""The hard-case example scenes are valid scenes the CLI runs with exit status 0 (their speed is
the benchmark's business, benchmarks/bench_sweep.py: tests check correctness only)."""
import h5py
import numpy as np

from hard_scenes import CONFIG_DIR, HARD_DIR
from linkpipe.__main__ import main

SCENES = sorted(HARD_DIR.glob("*.toml")) + [CONFIG_DIR / "jansen.toml"]


def test_check_accepts_every_hard_scene(capsys):
    assert main(["check", *map(str, SCENES)]) == 0
    out = capsys.readouterr().out
    assert out.count("is valid") == len(SCENES)


def test_run_writes_h5_and_rrd_with_exit_status_0(tmp_path, capsys):
    assert main(["run", *map(str, SCENES), "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert "error" not in captured.err and "Traceback" not in captured.err
    for path in SCENES:
        name = path.stem
        assert (tmp_path / f"{name}.h5").stat().st_size > 0
        assert (tmp_path / f"{name}.rrd").stat().st_size > 0
        with h5py.File(tmp_path / f"{name}.h5") as f:
            status = f["status"][:]
            assert len(status) == len(f["step"][:]) and set(np.unique(status)) <= {0, 1, 2}
