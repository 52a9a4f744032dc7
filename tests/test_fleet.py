"""Fleets of logs: ``run`` and ``fit`` of one scene over a glob of logs give, per log, the row
of that scene run on that log alone; a log the scene cannot take is a row with its message."""
import pathlib

import h5py
import numpy as np
import pandas as pd
import pytest

import linkpipe
from linkpipe.__main__ import main
from linkpipe.fit import fit
from linkpipe.stores.study import read_arrays

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENE = ROOT / "configs" / "logged" / "dump_truck_logged.toml"
LOG = ROOT / "configs" / "logged" / "logs" / "tipper_run.csv"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Three logs of the tipper: the shipped one with its pressure scaled (heavier loads)."""
    folder = tmp_path_factory.mktemp("fleet")
    frame = pd.read_csv(LOG)
    for k, factor in enumerate((1.0, 1.05, 1.1)):
        one = frame.copy()
        one["pressure_bar"] = one["pressure_bar"] * factor
        one.to_csv(folder / f"truck_{k}.csv", index=False)
    return folder


def alone(log: pathlib.Path):
    """The scene with its log file replaced in its text, loaded as a scene file."""
    text = SCENE.read_text().replace('file = "logs/tipper_run.csv"', f'file = "{log.as_posix()}"')
    path = log.parent / f"scene_{log.stem}.toml"
    path.write_text(text)
    return linkpipe.load_scene(path)


def test_run_over_a_glob_of_logs(logs, tmp_path, capsys):
    (logs / "bad.csv").write_text("a,b\n1,2\n")
    try:
        assert main(["run", str(SCENE), "--logs", str(logs / "*.csv"), "--out", str(tmp_path)]) == 0
    finally:
        (logs / "bad.csv").unlink()
    f = read_arrays(tmp_path / "dump_truck_logged_fleet.h5")
    assert f["log"].tolist() == ["bad.csv", "truck_0.csv", "truck_1.csv", "truck_2.csv"]
    assert f["log_failed"].tolist() == [1, 0, 0, 0] and 'no column "t_s"' in f["message"][0]
    for i in (1, 2, 3):
        r = linkpipe.solve(alone(logs / f["log"][i]))
        assert f["steps_ok"][i] == r.n_ok and f["n_steps"][i] == r.n_steps
        assert f["peak_input_force"][i, 0] == np.abs(r.forces["input_force"][1]).max()
        assert f["measured_rms"][i, 0] == r.measurements["rms"][0]
    assert np.isnan(f["peak_input_force"][0, 0]) and f["steps_ok"][0] == -1
    with h5py.File(tmp_path / "dump_truck_logged_fleet.h5", "r") as h5:  # the run's own units
        assert h5["peak_input_force"].attrs["units"] == r.forces["input_force"][2]
    out = capsys.readouterr().out
    assert "bad.csv      failed:" in out and "truck_2.csv" in out
    # each figure with its unit: the cylinder's peak force in N, the pressure's rms in N
    line = next(s for s in out.splitlines() if s.strip().startswith("truck_2.csv"))
    peak = f["peak_input_force"][3, 0]
    assert f"peak {r.driver_names[0]} {peak:.6g} N," in line
    assert line.endswith(f"{f['measured_rms'][3, 0]:.4g} N")


def test_fit_over_a_glob_of_logs(logs, tmp_path):
    assert main(["fit", str(SCENE), "--logs", str(logs / "truck_[02].csv"),
                 "--out", str(tmp_path)]) == 0
    f = read_arrays(tmp_path / "dump_truck_logged_fleet_fit.h5")
    assert f["parameter"].tolist() == ["masses.body.mass"]
    assert f["log"].tolist() == ["truck_0.csv", "truck_2.csv"]
    for i, name in enumerate(f["log"]):
        fr = fit(alone(logs / name))
        assert f["fitted"][i, 0] == fr.fitted[0]
        assert f["standard_error"][i, 0] == fr.standard_error[0]
        assert f["rms_after"][i, 0] == fr.after.measurements["rms"][0]
        assert f["reduced_chi_square"][i] == fr.reduced_chi_square  # as each log's own fit
        assert f["warnings"][i] == "\n".join(fr.warnings)
    assert f["fitted"][1, 0] > f["fitted"][0, 0] * 1.05  # 10 % more pressure: a heavier load
    with h5py.File(tmp_path / "dump_truck_logged_fleet_fit.h5", "r") as h5:  # the mass, in kg
        for name in ("fitted", "standard_error"):
            assert h5[name].attrs["units"] == h5[name].attrs["parameter_units"] == "kg"
        assert h5["rms_after"].attrs["measurement_units"] == h5["rms_after"].attrs["units"]


def test_fleet_mistakes_are_one_message(tmp_path, capsys):
    assert main(["run", str(SCENE), "--logs", str(tmp_path / "none*.csv")]) == 2
    assert main(["run", str(ROOT / "configs" / "basketball_goal.toml"), "--logs",
                 str(LOG)]) == 2
    err = capsys.readouterr().err
    assert "no file matches" in err and "this scene reads no log" in err and "add [[logs]]" in err
    assert "Traceback" not in err


def test_fleet_on_dask_gives_the_rows_of_in_process(logs):
    pytest.importorskip("dask.distributed")
    from linkpipe.fleet import run_fleet

    scene = linkpipe.load_scene(SCENE)
    here = run_fleet("run", scene, str(logs / "truck_*.csv"))
    there = run_fleet("run", scene, str(logs / "truck_*.csv"), executor="dask", workers=2)
    assert here[0] == there[0]
    for a, b in zip(here[1], there[1]):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])


def test_logs_of_one_name_in_two_folders_keep_two_labels():
    """Labels are paths from the folder the logs share (a name alone collided across folders)."""
    from linkpipe.fleet import log_labels

    assert log_labels(["rig/a_good.csv", "rig/sub/a_good.csv"]) == ["a_good.csv", "sub/a_good.csv"]
    assert log_labels(["/x/rig/b.csv", "/x/rig/c.csv"]) == ["b.csv", "c.csv"]


def test_a_fleet_needs_no_log_file_of_the_scene_s_own(logs, tmp_path, capsys):
    """The fleet replaces the scene's log file for every log: a scene whose own file is not
    there (a template for the rig's logs) runs over the glob, each row equal to that log run
    alone; run without --logs, the missing file is the scene's mistake (exit 2)."""
    text = SCENE.read_text().replace('file = "logs/tipper_run.csv"', 'file = "not_here.csv"')
    template = tmp_path / "template.toml"
    template.write_text(text)
    assert main(["run", str(template), "--logs", str(logs / "truck_*.csv"),
                 "--out", str(tmp_path / "out"), "--quiet"]) == 0
    f = read_arrays(tmp_path / "out" / "dump_truck_logged_fleet.h5")
    assert f["log"].tolist() == ["truck_0.csv", "truck_1.csv", "truck_2.csv"]
    for i, name in enumerate(f["log"]):
        r = linkpipe.solve(alone(logs / name))
        assert f["peak_input_force"][i, 0] == np.abs(r.forces["input_force"][1]).max()
    capsys.readouterr()
    assert main(["run", str(template), "--out", str(tmp_path / "one")]) == 2  # not a fleet
    assert 'no such log file' in capsys.readouterr().err
