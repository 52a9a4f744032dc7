"""The accuracy ladder (issue 6): honest errors against closed forms, and readable outputs.

Speed is measured, not tested: no assertion here looks at a time.
"""
import dataclasses as dc
import math
import pathlib
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe import accuracy, closed_forms
from linkpipe.__main__ import main
from linkpipe.status import OK
from linkpipe.stores import accuracy as store

CONFIGS = pathlib.Path(__file__).resolve().parent.parent / "configs"
SEEDS = ("shear_press", "basketball_goal")
KINEMATIC = ("position", "velocity", "acceleration")


def coarse(name: str, steps: int = 37) -> linkpipe.Scene:
    """A shipped scene over the same range with fewer steps (the tests' ladders stay small)."""
    return accuracy._with_steps(linkpipe.load_scene(str(CONFIGS / f"{name}.toml")), steps)


@pytest.fixture(scope="module")
def tol_ladders():
    """The tolerance ladder (and the tightest analytic setting) of the two closed-form scenes."""
    return {name: accuracy.measure(coarse(name), repeats=1, knobs=("tol", "jacobian"))
            for name in ("fourbar_crank_rocker", "slider_crank", "dump_truck")}


def rows(ladder, knob, value=None):
    return [r for r in ladder.rows if r.knob == knob and (value is None or r.value == value)]


# ------------------------------------------------------------------ the reference
@pytest.mark.parametrize("name, kind", [("fourbar_crank_rocker", "fourbar"),
                                        ("slider_crank", "slider_crank"),
                                        ("basketball_goal", "fourbar"),
                                        ("shear_press", None),
                                        ("dump_truck", "cylinder_rocker"),
                                        ("excavator_arm", None)])
def test_closed_forms_are_detected_structurally(name, kind):
    scene = linkpipe.load_scene(str(CONFIGS / f"{name}.toml"))
    form = closed_forms.detect(scene)
    assert (form.kind if form else None) == kind
    refs = accuracy.References(scene)
    assert refs.kind.startswith("closed form") == (kind is not None)
    assert "closed_form_rejected" not in refs.checks


FOURBAR_MOVED = """
[points]
P2 = { x = 1.0, y = 2.0, fixed = true }
Q  = { x = 0.5, y = 2.8660254037844386 }
R  = { x = 0.0, y = 0.0 }
P4 = { x = 3.0, y = 5.464101615137754, fixed = true }
T  = { x = 1.0, y = 1.0 }
[[links]]
name = "crank"
points = ["P2", "Q"]
[[links]]
name = "coupler"
points = ["Q", "R", "T"]
lengths = { "Q-R" = 3.5 }
local = { T = [1.5, -0.8] }
[[links]]
name = "rocker"
points = ["R", "P4"]
lengths = { "R-P4" = 3.0 }
[[drivers]]
name = "crank"
angle = ["Q", "P2"]
from = 0.0
to = 360.0
steps = 73
rate = 300.0
acceleration = 50.0
"""

SLIDER_TILTED = """
[points]
O = { x = 1.0, y = -1.0, fixed = true }
A = { x = 2.0, y = -1.0 }
B = { x = -1.5, y = -2.0 }
G = { x = 0.0, y = 0.0 }
[[links]]
name = "crank"
points = ["O", "A"]
[[links]]
name = "rod"
points = ["A", "B", "G"]
lengths = { "A-B" = 3.5 }
local = { G = [1.0, 0.3] }
[[sliders]]
name = "guide"
point = "B"
along = { through = [0.0, -1.5], direction = [2.0, 0.5] }
[[drivers]]
name = "crank"
angle = ["O", "A"]
from = 10.0
to = 370.0
steps = 73
rate = -200.0
"""


CYLINDER_OTHER_BRANCH = """
[points]
C = { x = 2.0, y = 1.0, fixed = true }
O = { x = -1.0, y = 0.5, fixed = true }
P = { x = -0.2, y = -0.9 }
E = { x = 0.5, y = -2.0 }
[[links]]
name = "arm"
points = ["O", "P", "E"]
[[drivers]]
name = "jack"
distance = ["P", "C"]
from = 2.9
to = 4.2
steps = 73
rate = -0.3
acceleration = 0.7
"""


@pytest.mark.parametrize("text", [FOURBAR_MOVED, SLIDER_TILTED, CYLINDER_OTHER_BRANCH],
                         ids=["fourbar", "slider_crank", "cylinder_rocker"])
def test_closed_forms_anywhere_in_the_plane(tmp_path, text):
    # moved pivots, a tilted ground line or guide, the other assembly branch, a reversed or
    # accelerating driver, further points on the coupler: the closed form still matches
    path = tmp_path / "moved.toml"
    path.write_text(text)
    scene = linkpipe.load_scene(str(path))
    scene = dc.replace(scene, solver=dc.replace(scene.solver, tol=1e-15), outputs=dc.replace(
        scene.outputs, kinematics=("velocity", "acceleration")))
    r = linkpipe.solve(scene)
    assert (r.status == OK).all()
    form = closed_forms.detect(scene, r.position[0])
    assert form is not None
    from linkpipe.kinematics import driver_motion

    _, s, sd, sdd = driver_motion(r.model)
    X, V, A = closed_forms.evaluate(form, scene, s[:, 0], sd[:, 0], sdd[:, 0])
    size = r.model.size
    assert np.abs(X - r.position).max() <= 1e-12 * size
    assert np.abs(V - r.velocity).max() <= 1e-12 * np.abs(V).max()
    assert np.abs(A - r.acceleration).max() <= 1e-11 * np.abs(A).max()


# ------------------------------------------------------------------ the tolerance ladder
@pytest.mark.parametrize("name", ["fourbar_crank_rocker", "slider_crank"])
def test_errors_fall_as_the_tolerance_tightens(tol_ladders, name):
    ladder = tol_ladders[name]
    assert ladder.reference.startswith("closed form")
    tol = sorted(rows(ladder, "tol"), key=lambda r: -float(r.value))  # loose -> tight
    assert [float(r.value) for r in tol] == sorted(accuracy.FULL["tol"], reverse=True)
    solved = [r for r in tol if r.steps_failed == 0]
    assert solved and solved[-1].value == "1e-14"
    floor = 1e-14  # rounding noise, relative
    for q in KINEMATIC:
        errors = [r.relative_error[q] for r in solved]
        for looser, tighter in zip(errors, errors[1:]):
            assert tighter <= 2 * looser + floor, (q, errors)
        # and every error is within what its tolerance allows: a residual of at most tol x size
        # moves the positions by up to cond x tol x size, with the Jacobian's condition below 15
        # on both scenes (14.2 and 5.7, Result.condition), and the velocities and accelerations
        # solved at those positions by as much again: 2 x 15 x tol (measured: up to 7.8 x tol)
        for r in solved:
            assert r.relative_error[q] <= max(30 * float(r.value), floor), (q, r.label)


@pytest.mark.parametrize("name", ["fourbar_crank_rocker", "slider_crank", "dump_truck"])
def test_tightest_analytic_setting_matches_the_closed_form(tol_ladders, name):
    ladder = tol_ladders[name]
    (tight,) = rows(ladder, "tol", "1e-14")
    assert tight.solver["jacobian"] == "analytic" and tight.solver["derivatives"] == "linear"
    assert tight.steps_failed == 0 and tight.branch_kept
    for q in KINEMATIC:
        assert tight.relative_error[q] <= 1e-12, (q, tight.relative_error)
    # the finite-difference Jacobian converges to the same answer
    (fd,) = rows(ladder, "jacobian", "finite_difference")
    assert fd.steps_failed == 0 and fd.relative_error["position"] <= 1e-10


# ------------------------------------------------------------------ finite differences
def test_finite_difference_velocities_converge_at_second_order():
    scene = coarse("fourbar_crank_rocker", 37)
    ladder = accuracy.measure(scene, repeats=1, knobs=("derivatives",))
    fd = sorted(rows(ladder, "derivatives", "finite_difference"), key=lambda r: r.steps)
    assert [r.steps for r in fd] == [10, 19, 37, 73, 145]
    (linear,) = rows(ladder, "derivatives", "linear")
    assert linear.relative_error["velocity"] <= 1e-12
    # the order measured from two step counts, each against the reference at its own values
    e1, e2 = fd[-2].error["velocity"], fd[-1].error["velocity"]
    h1, h2 = 1 / (fd[-2].steps - 1), 1 / (fd[-1].steps - 1)
    order = math.log(e1 / e2) / math.log(h1 / h2)
    assert 1.8 <= order <= 2.2, order
    assert fd[-1].observed_order["velocity"] == pytest.approx(order)
    # central differences: the velocity error falls ~4x per doubling on the fine end
    assert fd[-1].relative_error["velocity"] < fd[-2].relative_error["velocity"] / 3
    # and the shortcut is far from the linear solves at the scene's own resolution
    (same,) = [r for r in fd if r.steps == scene.n_steps]
    assert same.relative_error["velocity"] > 1e3 * linear.relative_error["velocity"]


# ------------------------------------------------------------------ the command and its files
def rerun_exe():
    exe = pathlib.Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


@pytest.mark.parametrize("name", SEEDS)
def test_accuracy_command_on_the_seeds(tmp_path, capsys, name):
    out = tmp_path / "out"
    assert main(["accuracy", str(CONFIGS / f"{name}.toml"), "--quick", "--repeats", "1",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "reference:" in printed and "tol" in printed and "dyads" in printed
    h5, rrd = out / f"{name}_accuracy.h5", out / f"{name}_accuracy.rrd"
    assert h5.exists() and rrd.exists()
    # errors do not depend on timing: a fresh measurement gives the same numbers
    ladder = accuracy.measure(str(CONFIGS / f"{name}.toml"), quick=True, repeats=1)
    data = store.read_h5(h5)
    assert list(data["row"]) == [r.label for r in ladder.rows]
    assert list(data["quantity"]) == list(ladder.quantities)
    want = np.array([[r.relative_error[q] for q in ladder.quantities] for r in ladder.rows])
    np.testing.assert_array_equal(data["relative_error"], want)
    np.testing.assert_array_equal(data["steps_failed"], [r.steps_failed for r in ladder.rows])
    exe = rerun_exe()
    if exe is None:
        pytest.skip("no rerun executable")
    done = subprocess.run([exe, "rrd", "verify", str(rrd)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr


def test_h5_holds_what_measure_returned(tmp_path):
    ladder = accuracy.measure(str(CONFIGS / "shear_press.toml"), quick=True, repeats=2)
    path = tmp_path / "ladder.h5"
    store.write_h5(ladder, path)
    with h5py.File(path, "r") as f:
        assert f.attrs["scene_name"] == "shear_press"
        assert f.attrs["repeats"] == 2
        labels = [x.decode() if isinstance(x, bytes) else x for x in f["row"][()]]
        assert labels == [r.label for r in ladder.rows]
        for name in ("seconds", "seconds_solve", "seconds_positions", "iterations_mean"):
            np.testing.assert_array_equal(f[name][()], [getattr(r, name) for r in ladder.rows])
            assert f[name].dims[0][0].name == "/row"
        np.testing.assert_array_equal(
            f["error"][()], [[r.error[q] for q in ladder.quantities] for r in ladder.rows])
        assert f["seconds"].attrs["units"] == "s"
        np.testing.assert_array_equal(f["branch_kept"][()], [r.branch_kept for r in ladder.rows])
    xr = pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds["relative_error"].dims == ("row", "quantity")
        sel = ds["seconds_solve"].sel(row="tol=1e-12").item()
        (row,) = [r for r in ladder.rows if r.label == "tol=1e-12"]
        assert sel == row.seconds_solve
        assert list(ds["quantity"].values) == ["position", "velocity", "acceleration",
                                               "input_force"]


def test_every_knob_has_rows_and_dyads_never_crash():
    ladder = accuracy.measure(str(CONFIGS / "shear_press.toml"), quick=True, repeats=1)
    knobs = {r.knob for r in ladder.rows}
    # every knob but the log knobs, which need a [time] scene driven by motion laws (below),
    # and friction_velocity_scale, which needs friction (tests/test_friction.py)
    assert knobs == set(accuracy.KNOBS) - {"log", "friction_velocity_scale"}
    methods = {r.value: r for r in rows(ladder, "method")}
    assert set(methods) == {"auto", "newton", "dyads"}
    assert methods["auto"].available and methods["newton"].available
    dy = methods["dyads"]
    assert dy.available and dy.path == "dyads"  # every shipped scene decomposes
    for r in rows(ladder, "predictor"):  # iterations and the branch are reported
        assert r.iterations_max >= 1 and isinstance(r.branch_kept, bool)
    text = accuracy.table(ladder)
    assert len(text.splitlines()) == len(ladder.rows) + 2
    assert any(r.base for r in ladder.rows) and any(r.front for r in ladder.rows)


def test_a_lost_branch_is_reported():
    # the crank-rocker's other assembly (B mirrored across A-O4) is a different mechanism state:
    # a row that lands there is flagged, however small its residual
    scene = coarse("fourbar_crank_rocker", 37)
    refs = accuracy.References(scene)
    ref = refs.at(scene.n_steps)
    r = linkpipe.solve(accuracy._all_orders(scene))
    row = accuracy.Row("predictor", "none", scene.n_steps, "kinematics", {})
    accuracy._measure_errors(row, r, ref, accuracy._scales(ref))
    assert row.branch_kept and row.steps_failed == 0
    other = dc.replace(refs.form, branch=-refs.form.branch)
    from linkpipe.kinematics import driver_motion

    _, s, sd, sdd = driver_motion(r.model)
    X, V, A = closed_forms.evaluate(other, r.scene, s[:, 0], sd[:, 0], sdd[:, 0])
    flipped = dc.replace(r, position=np.where(np.arange(len(X))[:, None, None] == 20, X, r.position))
    row = accuracy.Row("predictor", "none", scene.n_steps, "kinematics", {})
    accuracy._measure_errors(row, flipped, ref, accuracy._scales(ref))
    assert not row.branch_kept


def test_method_rows_say_which_path_ran():
    class Old:  # a result from a build without the fast path
        pass

    assert accuracy.method_available(Old(), "dyads") == (
        False, "not available: no dyads fast path in this build")
    assert accuracy.method_available(Old(), "newton")[0]
    ladder = accuracy.measure(coarse("fourbar_crank_rocker", 37), repeats=1, knobs=("method",))
    methods = {r.value: r for r in rows(ladder, "method")}
    assert methods["newton"].path == "newton"
    dy = methods["dyads"]
    assert dy.available and dy.path == "dyads" and dy.iterations_max == 0
    for q in KINEMATIC:  # the closed-form fast path: as exact as the closed form (rounding)
        assert dy.relative_error[q] <= 1e-14


def test_a_rung_that_crashes_is_a_row_with_its_error_and_the_command_fails(tmp_path, monkeypatch, capsys):
    """No exception is swallowed: the rung's row carries the error (table and .h5), the other
    rungs are measured, and `accuracy` exits 1."""
    import h5py

    from linkpipe.accuracy import timing

    real_solve = timing.solve

    def solve(scene):
        if scene.solver.tol == 1e-4:
            raise ZeroDivisionError("injected")
        return real_solve(scene)

    monkeypatch.setattr(timing, "solve", solve)
    path = CONFIGS / "shear_press.toml"
    assert main(["accuracy", str(path), "--quick", "--repeats", "1", "--out", str(tmp_path)]) == 1
    captured = capsys.readouterr()
    assert "FAILED: ZeroDivisionError: injected" in captured.out
    assert "1 setting(s) failed: tol=" in captured.err
    with h5py.File(tmp_path / "shear_press_accuracy.h5") as f:
        failures = [x.decode() for x in f["failure"][()]]
        labels = [x.decode() for x in f["row"][()]]
    assert failures[[i for i, x in enumerate(labels) if x.startswith("tol=") and "04" in x][0]] == "ZeroDivisionError: injected"
    assert sum(bool(x) for x in failures) == 1


@pytest.mark.parametrize("name", ["hatch_gas_spring", "dump_truck"])
def test_version_2_springs_and_cylinders_show_their_force_error_in_the_ladder(name):
    """A gas-sprung hatch and a cylinder-driven tipper on the tolerance ladder: the input force
    (a torque from gas struts and gravity; a cylinder's axial force) converges as tol tightens
    and the tightest setting agrees with the reference to rounding."""
    ladder = accuracy.measure(coarse(name, 41), repeats=1, knobs=("tol",))
    tol = sorted(rows(ladder, "tol"), key=lambda r: -float(r.value))
    forces = [r.relative_error["input_force"] for r in tol if r.steps_failed == 0]
    assert len(forces) == len(accuracy.FULL["tol"])
    for looser, tighter in zip(forces, forces[1:]):
        assert tighter <= 2 * looser + 1e-14, forces
    assert forces[0] > 1e-4  # tol 1e-2 is visibly wrong: the ladder measures something
    assert forces[-1] <= 1e-12


LAW_SCENE_TAIL = '''[time]
from = 0.0
to = 2.0
steps = 401
[[drivers]]
name = "crank"
angle = ["O2", "A"]
law = "cycloidal"
from = 0.0
to = 360.0
[analysis]
effects = ["inertia"]
[[masses]]
link = "coupler"
mass = 2.0
center = "P"
inertia = 0.5
'''


def test_log_knobs_measure_a_log_of_the_law_against_the_law_itself():
    """A cycloidal crank law, logged at every k-th instant and driven through the spline:
    against the law's exact closed form, position errors fall as h^4 (at least 8x per halving
    of the spacing, 16x in theory), accelerations as h^2 (at least 3x, 4x in theory); a log at
    every instant reproduces the positions to rounding (the spline interpolates); smoothing
    only adds error to noise-free samples, more as lam grows."""
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
    scene = linkpipe.scene.parse_scene(text[:text.index("[[drivers]]")] + LAW_SCENE_TAIL, "law.toml")
    ladder = accuracy.measure(scene, repeats=1, knobs=("log",))
    assert ladder.reference.startswith("closed form")
    every = sorted(rows(ladder, "log_every"), key=lambda r: int(r.value))
    assert [int(r.value) for r in every] == [1, 2, 4, 8, 16]
    assert every[0].relative_error["position"] <= 1e-13
    for fine, coarse in zip(every[1:], every[2:]):
        assert coarse.relative_error["position"] >= 8 * fine.relative_error["position"]
        assert coarse.relative_error["acceleration"] >= 3 * fine.relative_error["acceleration"]
        assert coarse.relative_error["input_force"] > fine.relative_error["input_force"]
    smooth = sorted(rows(ladder, "log_smoothing"), key=lambda r: float(r.value))
    errors = [r.relative_error["velocity"] for r in smooth]
    assert len(errors) == 3 and errors == sorted(errors)
    assert errors[0] > every[0].relative_error["velocity"]
    assert all(r.seconds_solve > 0 for r in every + smooth)
    assert not any(r.base or r.newton_base for r in every + smooth)  # not the scene's own run


def test_log_knobs_only_for_law_driven_time_scenes():
    assert accuracy.knobs.log_settings(coarse("fourbar_crank_rocker")) == []


def test_a_time_scene_is_resampled_keeping_its_instants():
    """The ladder's other step counts of a [time] scene: a refinement by a whole factor keeps
    every instant (uneven log time stamps too), so the drivers' values there are the scene's
    own to rounding; other counts are evenly spaced over the same span."""
    instants = np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.6, 0.8, 1.0])
    fine = accuracy.knobs.resampled_instants(instants, 3 * 7 + 1)
    np.testing.assert_array_equal(fine[::3], instants)
    np.testing.assert_allclose(np.diff(fine).reshape(7, 3), np.repeat(np.diff(instants) / 3, 3)
                               .reshape(7, 3), rtol=1e-12)
    np.testing.assert_array_equal(accuracy.knobs.resampled_instants(instants, 5),
                                  np.linspace(0.0, 1.0, 5))
    scene = linkpipe.load_scene(str(CONFIGS / "logged" / "dump_truck_logged.toml"))
    S = scene.n_steps
    finer = accuracy._with_steps(scene, 2 * (S - 1) + 1)
    assert finer.n_steps == len(finer.time.instants) == 2 * S - 1 and finer.measurements == ()
    from linkpipe.model.drive import driver_motion
    base, refined = driver_motion(scene), driver_motion(finer)
    np.testing.assert_array_equal(finer.time.instants[::2], scene.time.instants)
    np.testing.assert_allclose(refined.value[::2], base.value, rtol=0, atol=1e-12)  # m
    np.testing.assert_allclose(refined.rate[::2], base.rate, rtol=0, atol=1e-12)  # m/s


def test_the_ladder_runs_on_a_logged_time_scene():
    """configs/logged/dump_truck_logged.toml (a cylinder on a logged stroke, closed-form
    reference): the rows at other step counts solve (they crashed on the time grid once), and
    their positions meet the closed form to the solver's tolerance (1e-10 of the size)."""
    scene = linkpipe.load_scene(str(CONFIGS / "logged" / "dump_truck_logged.toml"))
    ladder = accuracy.measure(scene, quick=True, repeats=1, knobs=("derivatives", "predictor"))
    assert ladder.reference.startswith("closed form")
    assert ladder.units["input_force"] == "N"  # one cylinder: its axial force (was "mixed")
    assert all(r.failure == "" for r in ladder.rows), [r.failure for r in ladder.rows]
    other = [r for r in ladder.rows if r.steps != scene.n_steps]
    assert {r.steps for r in other} == {2 * scene.n_steps - 1, (scene.n_steps - 1) // 4 + 1}
    for r in other:
        assert r.relative_error["position"] <= 1e-10, (r.knob, r.value, r.steps)
        assert r.steps_failed == 0
    (linear,) = rows(ladder, "derivatives", "linear")
    for r in rows(ladder, "derivatives", "finite_difference"):
        assert linear.relative_error["velocity"] < r.relative_error["velocity"] < 1e-3


def test_a_single_instant_takes_only_the_rows_it_can():
    """[time] from = to, steps = 1: no finite differences, predictors or logs (no second
    instant to difference, predict from or sample); every row the ladder builds runs."""
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
    law = LAW_SCENE_TAIL.replace("to = 2.0\nsteps = 401", "to = 0.0\nsteps = 1").replace(
        'law = "cycloidal"\nfrom = 0.0\nto = 360.0', "rate = 30.0\nfrom = 10.0")
    scene = linkpipe.scene.parse_scene(text[:text.index("[[drivers]]")] + law, "one.toml")
    assert scene.n_steps == 1
    assert accuracy.knobs.log_settings(scene) == []
    ladder = accuracy.measure(scene, quick=True, repeats=1)
    assert ladder.rows and all(r.failure == "" for r in ladder.rows)
    assert {r.knob for r in ladder.rows} <= {"tol", "max_iter", "jacobian", "linear_algebra",
                                              "method"}


def test_finite_differences_on_a_logged_drive_converge_as_the_ladder_says():
    """The logged tipper (1001 log samples, 0 .. 40 s): finite differences approach the
    drive's splines at order 2 (velocity) and 1 (acceleration: a cubic spline's third
    derivative jumps at every sample, so the second difference across a sample errs by
    O(h)) once the instants are finer than the samples (2001 -> 4001 instants, each a whole
    refinement keeping the log's stamps); the printed line says so and names the log."""
    scene = linkpipe.load_scene(str(CONFIGS / "logged" / "dump_truck_logged.toml"))
    ladder = accuracy.measure(scene, repeats=1, knobs=("derivatives",))
    finest = max(rows(ladder, "derivatives", "finite_difference"), key=lambda r: r.steps)
    assert finest.steps == 4 * (scene.n_steps - 1) + 1
    assert abs(finest.observed_order["velocity"] - 2.0) < 0.2
    assert abs(finest.observed_order["acceleration"] - 1.0) < 0.2
    line = accuracy.orders_line(ladder)
    assert "1001 in log rig" in line and "order 2 (velocity) and 1" in line


#: a crank lifting 10 kg (its input a torque, N*m) beside a cylinder raising a 1 kg lever (its
#: input a force, N): two independent mechanisms, so two input-force units in one scene
MIXED_UNITS = """\
[scene]
name = "crank_and_cylinder"
units = { length = "m", mass = "kg", time = "s", force = "N" }

[points]
O = { x = 0.0, y = 0.0, fixed = true }
A = { x = 1.0, y = 0.0 }
O2 = { x = 0.0, y = -3.0, fixed = true }
C = { x = 1.5, y = -3.0, fixed = true }
P = { x = 1.0, y = -2.0 }

[[links]]
name = "crank"
points = ["O", "A"]

[[links]]
name = "lever"
points = ["O2", "P"]

[[drivers]]
name = "crank"
angle = ["O", "A"]
from = 0.0
to = 60.0
steps = 13

[[drivers]]
name = "cylinder"
distance = ["C", "P"]
from = 1.118033988749895
to = 1.3
steps = 13

[analysis]
effects = ["gravity"]

[gravity]
g = [0.0, -9.81]

[[masses]]
link = "crank"
mass = 10.0
center = "A"

[[masses]]
link = "lever"
mass = 1.0
center = "P"
"""


def test_drivers_of_different_units_are_each_scaled_by_their_own_unit(tmp_path):
    """A torque (N*m) and a force (N) share no scale: each driver's input-force error is
    divided by the largest reference magnitude among the drivers of its unit. An error of
    0.01 in both columns at one step is 0.01 / (the cylinder's largest force) relative,
    not 0.01 / (the crank's far larger torque), which one scale for both had reported."""
    scene = linkpipe.scene.parse_scene(MIXED_UNITS, str(tmp_path / "mixed.toml"))
    ref = accuracy.References(scene).at(scene.n_steps)
    scales = accuracy._scales(ref, ["N*m", "N"])
    magnitude = np.abs(ref.values["input_force"]).max(axis=0)  # (2,): torque, force
    assert magnitude[0] > 5 * magnitude[1]  # ~98 N*m against ~10 N
    np.testing.assert_array_equal(scales["input_force_per_driver"], magnitude)
    assert math.isnan(scales["input_force"])
    assert accuracy._scales(ref)["input_force"] == magnitude.max()  # one unit: one scale

    r = linkpipe.solve(accuracy._all_orders(scene))
    name, F = r.forces["input_force"][0], r.forces["input_force"][1].copy()
    F[5] = ref.values["input_force"][5] + 0.01  # N*m and N
    off = dc.replace(r, forces={**r.forces, "input_force": (name, F)})
    row = accuracy.Row("tol", "x", scene.n_steps, "positions", {})
    accuracy._measure_errors(row, off, ref, scales)
    assert row.relative_error["input_force"] == pytest.approx(0.01 / magnitude[1], rel=1e-6)
    assert math.isnan(row.error["input_force"])  # no one unit for an absolute error

    ladder = accuracy.measure(scene, repeats=1, knobs=("tol",))
    assert ladder.units["input_force"] == "mixed"
    text = accuracy.header(ladder)
    assert f"input_force by unit {magnitude[0]:.4g} N*m and {magnitude[1]:.4g} N" in text
    path = tmp_path / "mixed_accuracy.h5"
    store.write_h5(ladder, path)
    with h5py.File(path) as f:
        assert f.attrs["units_input_force_per_driver"] == "N*m,N"
        np.testing.assert_array_equal(f.attrs["scale_input_force_per_driver"], magnitude)
        tight = [i for i, v in enumerate(f["value"].asstr()[:]) if v.startswith("1e-12")]
        assert f["relative_error"][tight[0], -1] < 1e-9  # the scene's own tolerance, both units
