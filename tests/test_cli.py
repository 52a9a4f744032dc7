"""The command line, called as `main(argv)`: exit codes, messages, and the model-level errors."""
import pathlib
import time

import pytest

import linkpipe
from linkpipe.__main__ import main

CONFIGS = pathlib.Path(__file__).parent.parent / "configs"

CRANK_ROCKER = (CONFIGS / "fourbar_crank_rocker.toml").read_text()


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_dof_mismatch_names_both_numbers(tmp_path, capsys):
    # drop the rocker: a five-bar-like chain with 2 degrees of freedom, still 1 driver
    text = CRANK_ROCKER.replace('[[links]]\nname = "rocker"\npoints = ["O4", "B"]\nlengths = { "O4-B" = 3.0 }\n', "")
    p = write(tmp_path, "two_dof.toml", text)
    assert main(["check", str(p)]) == 2
    err = capsys.readouterr().err
    assert "two_dof.toml" in err and "[drivers]" in err
    assert "2 degree(s) of freedom" in err and "but 1 driver(s)" in err
    assert "Traceback" not in err


def test_a_point_on_no_link_is_named(tmp_path, capsys):
    """A stray moving point adds 2 degrees of freedom: the message says which point."""
    text = CRANK_ROCKER.replace("P  = {", "Z  = { x = 9.0, y = 9.0 }\nP  = {")
    p = write(tmp_path, "stray.toml", text)
    assert main(["check", str(p)]) == 2
    err = capsys.readouterr().err
    assert "3 degree(s) of freedom" in err and "but 1 driver(s)" in err
    assert "point(s) Z belong to no link" in err


def test_overconstrained_names_both_numbers(tmp_path, capsys):
    text = CRANK_ROCKER + '\n[[drivers]]\nname = "rocker"\nangle = ["O4", "B"]\nfrom = 10.0\nto = 20.0\nsteps = 361\n'
    p = write(tmp_path, "two_drivers.toml", text)
    assert main(["run", str(p), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "1 degree(s) of freedom" in err and "but 2 driver(s)" in err


def test_start_configuration_that_cannot_assemble(tmp_path, capsys):
    # a coupler longer than crank + rocker + ground can span: no assembly anywhere
    text = CRANK_ROCKER.replace('lengths = { "A-B" = 3.5 }', 'lengths = { "A-B" = 9.5 }')
    p = write(tmp_path, "too_long.toml", text)
    assert main(["run", str(p), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "too_long.toml" in err and "[points]" in err
    assert "cannot be assembled" in err and "check the link lengths" in err
    with pytest.raises(linkpipe.SceneError):
        linkpipe.solve(str(p))
    # `check` finds it too (it assembles the start), with the same message
    assert main(["check", str(p)]) == 2
    assert capsys.readouterr().err == err


def test_tolerance_below_rounding_names_solver_tol(tmp_path, capsys):
    """tol = 1e-17 cannot be met in double precision: the scene error names [solver] tol, not
    the link lengths (the start does assemble, to rounding level)."""
    p = write(tmp_path, "tiny_tol.toml", CRANK_ROCKER.replace("[outputs]", "[solver]\ntol = 1e-17\n\n[outputs]"))
    assert main(["check", str(p)]) == 2
    err = capsys.readouterr().err
    assert "[solver] tol: tol = 1e-17" in err and "below what double precision reaches" in err
    assert "use tol >= 1e-15" in err and "link lengths" not in err


def test_a_sweep_too_big_for_memory_is_a_scene_error(tmp_path, capsys):
    """1e11 steps would need ~5e5 GiB: a scene error naming the driver's steps, before any work
    (run and check alike), instead of a MemoryError or a run the kernel kills half-way."""
    p = write(tmp_path, "huge.toml", CRANK_ROCKER.replace("steps = 361", "steps = 100000000000"))
    for command in (["run", str(p), "--out", str(tmp_path / "out")], ["check", str(p)]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert '[drivers "crank"] steps: 100,000,000,000 steps of 5 points need about' in err
        assert "GiB is available" in err and "use fewer steps" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_out_that_is_a_file(tmp_path, capsys):
    target = tmp_path / "not_a_folder"
    target.write_text("")
    assert main(["run", str(CONFIGS / "shear_press.toml"), "--out", str(target)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    # a folder below a file cannot be made either: every command says so, exit 2
    below = target / "sub"
    study = CONFIGS / "studies" / "basketball_goal.toml"
    fit_scene = CONFIGS / "logged" / "dump_truck_logged.toml"
    for command in (["run", str(CONFIGS / "shear_press.toml")], ["study", str(study)],
                    ["fit", str(fit_scene)], ["accuracy", str(CONFIGS / "shear_press.toml")],
                    ["run", str(fit_scene), "--logs", str(fit_scene.parent / "logs" / "*.csv")]):
        t0 = time.monotonic()
        assert main([*command, "--out", str(below)]) == 2
        err = capsys.readouterr().err.strip()
        assert err == (f"error: --out {below}: cannot be the output folder: {target} is a file, "
                       "not a folder — give --out a folder (made if missing)"), err
        assert time.monotonic() - t0 < 5, command  # said before the work (a fit, a ladder)


def test_bad_scene_does_not_stop_the_others(tmp_path, capsys):
    bad = write(tmp_path, "typo.toml", CRANK_ROCKER.replace("steps = 361", "stepps = 361"))
    good = CONFIGS / "shear_press.toml"
    out = tmp_path / "out"
    assert main(["run", str(bad), str(good), "--out", str(out), "--no-rrd"]) == 2
    captured = capsys.readouterr()
    assert 'did you mean "steps"?' in captured.err and "typo.toml" in captured.err
    assert (out / "shear_press.h5").exists()
    assert "shear_press: all 9 steps ok" in captured.out


def test_run_summary_and_quiet(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(CONFIGS / "basketball_goal.toml"), "--out", str(out), "--no-rrd"]) == 0
    text = capsys.readouterr().out
    assert "basketball_goal: all 25 steps ok (25 steps, 25 ok, 0 failed)" in text
    assert "input force theta3a: -99.6771 .. -98.6229 lbf" in text
    assert "seconds:" in text and "positions" in text and "forces" in text
    assert "(solved steps), closed-form dyads, no iterations" in text and "solver: path dyads" in text
    newton = write(tmp_path, "newton.toml", (CONFIGS / "basketball_goal.toml").read_text()
                   + '\n[solver]\nmethod = "newton"\n')
    assert main(["run", str(newton), "--out", str(out), "--no-rrd"]) == 0
    text = capsys.readouterr().out
    assert "(solved steps), Newton iterations mean" in text and "solver: path newton" in text
    assert main(["run", str(CONFIGS / "shear_press.toml"), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    assert capsys.readouterr().out == ""


def test_check_describes_without_solving(capsys, monkeypatch):
    import linkpipe.kinematics

    def boom(*a, **k):
        raise AssertionError("check must not solve")

    monkeypatch.setattr(linkpipe.kinematics, "solve_positions", boom)
    assert main(["check", str(CONFIGS / "basketball_goal.toml")]) == 0
    text = capsys.readouterr().out
    assert "degrees of freedom: 1" in text and "theta3a (25 steps)" in text
    assert "effects: springs, gravity, inertia" in text
    assert "O2 (fixed)" in text


def test_present_but_off_in_summary(tmp_path, capsys):
    text = (CONFIGS / "basketball_goal.toml").read_text().replace(
        'effects = ["springs", "gravity", "inertia"]', 'effects = ["springs"]')
    p = write(tmp_path, "springs_only.toml", text)
    assert main(["run", str(p), "--out", str(tmp_path), "--no-rrd", "--no-h5"]) == 0
    assert "present but off: gravity, inertia" in capsys.readouterr().out


def test_python_dash_m_runs_as_a_process(tmp_path):
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "linkpipe", "check", str(CONFIGS / "shear_press.toml")],
                          capture_output=True, text=True)
    assert proc.returncode == 0 and "degrees of freedom: 1" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "linkpipe", "check", str(tmp_path / "missing.toml")],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "missing.toml" in proc.stderr and "Traceback" not in proc.stderr


def test_blas_threads_are_limited_while_solving_and_restored_after():
    """threadpoolctl sets the BLAS pool while a scene is solved (default 1, ``threads``), and
    gives the library its own size back afterwards."""
    from threadpoolctl import threadpool_info

    import linkpipe

    def blas_threads():
        return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})

    before = blas_threads()
    assert before, "numpy's BLAS is not visible to threadpoolctl"
    seen = {}
    for threads in (1, 2, None):
        linkpipe.solve(str(CONFIGS / "fourbar_crank_rocker.toml"), threads=threads,
                       progress=lambda stage, t=threads: seen.setdefault(t, blas_threads()))
    assert seen[1] == [1] and seen[2] == [2] and seen[None] == before
    assert blas_threads() == before


def test_threads_option_is_checked(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:  # argparse's own usage error
        main(["run", str(CONFIGS / "fourbar_crank_rocker.toml"), "--threads", "-1",
              "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert "--threads" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_verbose_prints_where_the_time_went(tmp_path, capsys):
    """``-v``: one row per timed stage (the same stages as the .h5's seconds_* attributes),
    "other" for the rest, and a total equal to their sum (rounded to the printed ms)."""
    import h5py

    from linkpipe.__main__ import main as cli

    assert cli(["run", str(CONFIGS / "basketball_goal.toml"), "--out", str(tmp_path), "-v",
                "--no-rrd"]) == 0
    out = capsys.readouterr().out
    table = out[out.index("  stage "):].splitlines()
    rows = {line.split()[0]: float(line.split()[1]) for line in table[1:]}
    with h5py.File(tmp_path / "basketball_goal.h5") as f:
        stages = [k[len("seconds_"):] for k in f.attrs if k.startswith("seconds_")]
    assert list(rows) == stages + ["hdf5", "other", "total"]
    assert abs(sum(v for k, v in rows.items() if k != "total") - rows["total"]) <= 0.0005 * len(rows)


def test_version_is_the_installed_packages(capsys):
    """``--version`` prints the version pip installed (the package's metadata), exit 0."""
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"linkpipe {version('linkpipe')}"
