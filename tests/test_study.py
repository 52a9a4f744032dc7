"""Design studies: every row equals a one-by-one run of the same variant; bad study files are
one clear message; a killed study resumes to the same file; the Dask path gives that file too."""
import copy
import pathlib
import subprocess
import sys
import tomllib

import h5py
import numpy as np
import pytest
import tomli_w

import linkpipe
from linkpipe.__main__ import main
from linkpipe.errors import SceneError
from linkpipe.scene import parse_scene
from linkpipe.status import OK
from linkpipe.stores.study import partial_path, read_arrays
from linkpipe.study import load_study, run_study

ROOT = pathlib.Path(__file__).resolve().parent.parent
GOAL = ROOT / "configs" / "basketball_goal.toml"

STUDY = """
[scene]
name = "{name}"

[study]
base = "{base}"
samples = {samples}
seed = 3
batch_size = {batch}

[study.parameters]
"springs.left.k" = {{ from = 2.0, to = 6.0, steps = 3 }}
"points.S1.y" = {{ from = -0.75, to = -0.55, steps = 2 }}
"points.O4.y" = {{ normal = [-2.0, 0.0005] }}
"links.backboard.lengths.B-C" = {{ uniform = [0.999, 1.001] }}

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"
p95_spring = "percentile(spring_force.left, 95)"
mean_x = "mean(position.B.x) - 2 * min(spring_force.right) / 4"
"""


def write_study(folder, name="goal", samples=2, batch=4, extra=""):
    path = pathlib.Path(folder) / f"{name}.toml"
    path.write_text(STUDY.format(name=name, base=GOAL.as_posix(), samples=samples,
                                 batch=batch) + extra)
    return path


def one_by_one(study, v):
    """Variant v built independently: the base scene's TOML with the values set by hand."""
    data = tomllib.loads(GOAL.read_text())
    data = copy.deepcopy(data)
    k, s1y, o4y, bc = study.values[v]
    data["springs"][0]["k"] = k
    data["points"]["S1"]["y"] = s1y
    data["points"]["O4"]["y"] = o4y
    data["links"][2]["lengths"]["B-C"] = bc
    try:
        return linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
    except SceneError:
        return None


def expected_row(r):
    """The study's columns of one Result, by plain numpy on its ok steps."""
    ok = r.status == OK
    f = r.forces["input_force"][1][ok, 0]
    P = r.position[ok, r.point_names.index("B"), 0]
    right = r.forces["spring_force"][1][ok, 1]
    left = r.forces["spring_force"][1][ok, 0]
    return {"peak_input_force": np.abs(f).max(), "rms_input_force": np.sqrt(np.mean(f * f)),
            "input_force_range": f.max() - f.min(), "peak_handle": np.abs(f).max(),
            "p95_spring": np.percentile(left, 95), "mean_x": P.mean() - 2 * right.min() / 4,
            "worst_status": int(r.status.max()),
            "first_failed_step": int(np.flatnonzero(~ok)[0]) if (~ok).any() else -1}


def test_study_rows_equal_one_by_one_runs(tmp_path):
    study = load_study(write_study(tmp_path))
    assert study.n_variants == 3 * 2 * 2
    path = run_study(study, tmp_path / "out")
    f = read_arrays(path)
    assert f["parameter"].tolist() == ["springs.left.k", "points.S1.y", "points.O4.y",
                                       "links.backboard.lengths.B-C"]
    assert f["parameter_value"].shape == (12, 4) and f["batch_done"].tolist() == [1, 1, 1]
    with h5py.File(path, "r") as h5:  # the goal's units: a spring rate, then three lengths
        assert h5["parameter_value"].attrs["units"] == "mixed"
        assert h5["parameter_value"].attrs["parameter_units"] == "lbf/ft,ft,ft,ft"
    for v in range(study.n_variants):
        want = expected_row(one_by_one(study, v))
        for name, value in want.items():
            got = f[name][v].reshape(-1)[0]
            assert got == pytest.approx(value, rel=1e-12, abs=1e-12), (v, name)


def test_grid_product_and_seeded_draws(tmp_path):
    study = load_study(write_study(tmp_path, samples=3))
    values = study.values
    assert values.shape == (18, 4)
    grid = [(k, y) for k in (2.0, 4.0, 6.0) for y in (-0.75, -0.55) for _ in range(3)]
    assert values[:, :2].tolist() == [list(g) for g in grid]
    rng = np.random.default_rng(3)
    np.testing.assert_array_equal(values[:, 2], rng.normal(-2.0, 0.0005, 18))
    np.testing.assert_array_equal(values[:, 3], rng.uniform(0.999, 1.001, 18))


def test_distributions_alone_give_samples_variants(tmp_path):
    path = tmp_path / "tolerance.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\nsamples = 5\nseed = 9\n'
                    '[study.parameters]\n"points.O2.y" = { uniform = [-1.0016, -0.9984] }\n')
    study = load_study(path)
    np.testing.assert_array_equal(study.values[:, 0], np.random.default_rng(9).uniform(
        -1.0016, -0.9984, 5))
    f = read_arrays(run_study(study, tmp_path))
    for v in range(5):
        data = tomllib.loads(GOAL.read_text())
        data["points"]["O2"]["y"] = study.values[v, 0]
        r = linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
        assert f["peak_input_force"][v, 0] == pytest.approx(
            np.abs(r.forces["input_force"][1]).max(), rel=1e-12)
    # in the run's units: the goal's angle driver pushes at its input point H, in lbf
    assert r.forces["input_force"][2] == "lbf"
    with h5py.File(tmp_path / f"{study.name}_study.h5", "r") as h5:
        for name in ("peak_input_force", "rms_input_force", "input_force_range"):
            assert h5[name].attrs["units"] == "lbf" and h5[name].attrs["driver_units"] == "lbf"


def test_an_angle_driver_without_input_point_has_torque_units(tmp_path):
    """Without ``input`` an angle driver's input force is a torque: the study's peak, RMS and
    range are in force*length (lbf*ft here), as the run's input_force is, and equal to it."""
    base = tmp_path / "goal_torque.toml"
    base.write_text(GOAL.read_text().replace('input = { point = "H", direction = [0.0, 1.0] }\n', ""))
    assert "input =" not in base.read_text()
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{base.as_posix()}"\n[study.parameters]\n'
                    '"points.O2.y" = { from = -1.0, to = -1.001, steps = 2 }\n')
    study = load_study(path)
    f = read_arrays(run_study(study, tmp_path))
    r = linkpipe.load_scene(base)
    r = linkpipe.solve(r)
    assert r.forces["input_force"][2] == "lbf*ft"
    assert f["peak_input_force"][0, 0] == pytest.approx(np.abs(r.forces["input_force"][1]).max(),
                                                        rel=1e-12)
    with h5py.File(tmp_path / f"{study.name}_study.h5", "r") as h5:
        for name in ("peak_input_force", "rms_input_force", "input_force_range"):
            assert h5[name].attrs["units"] == "lbf*ft" and h5[name].attrs["driver_units"] == "lbf*ft"


def test_a_negative_zero_prints_as_zero(tmp_path, capsys):
    """-max(abs(spring_force.left)) at k = 0 is -0.0 (stored as such): the summary prints 0,
    not "-0", at the top of the metric's range."""
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"springs.left.k" = { from = 0.0, to = 1.0, steps = 2 }\n'
                    '[study.metrics]\nneg = "-max(abs(spring_force.left))"\n')
    assert main(["study", str(path), "--out", str(tmp_path / "out")]) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines() if x.startswith("  neg:")]
    assert " .. 0 lbf (mean " in line and "-0 " not in line, line
    with h5py.File(tmp_path / "out" / "s_study.h5") as f:
        assert np.signbit(f["neg"][0])  # the file keeps the value itself


def test_a_variant_that_cannot_assemble_is_a_row(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"points.O4.y" = { from = -2.0, to = -5.0, steps = 3 }\n')
    study = load_study(path)
    f = read_arrays(run_study(study, tmp_path))
    assert f["worst_status"].tolist()[0] == OK and f["first_failed_step"][0] == -1
    for v in (1, 2):
        r = one_by_one_o4(study.values[v, 0])
        if r is None:  # the start does not assemble: every step no_assembly
            assert f["worst_status"][v] == 1 and f["first_failed_step"][v] == 0
            assert np.isnan(f["peak_input_force"][v, 0])
        else:
            assert f["worst_status"][v] == r.status.max()
            assert f["first_failed_step"][v] == np.flatnonzero(r.status != OK)[0]
    assert f["worst_status"][2] == 1  # 3 ft below: the parallelogram cannot close


def one_by_one_o4(y):
    data = tomllib.loads(GOAL.read_text())
    data["points"]["O4"]["y"] = y
    try:
        return linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
    except SceneError:
        return None


def test_killed_study_resumes_to_the_same_file(tmp_path):
    study = load_study(write_study(tmp_path, batch=3))
    whole = read_arrays(run_study(study, tmp_path / "whole"))

    def kill(n):
        if n == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(study, tmp_path / "cut", after_batch=kill)
    path = tmp_path / "cut" / "goal_study.h5"
    assert not path.exists() and partial_path(path).exists()
    solved = []
    import linkpipe.study.run as run_module
    original = run_module.solve_batch

    def counting(st, lo, hi):
        solved.append(lo)
        return original(st, lo, hi)

    run_module.solve_batch = counting
    try:
        resumed = read_arrays(run_study(study, tmp_path / "cut"))
    finally:
        run_module.solve_batch = original
    assert sorted(solved) == [6, 9]  # only the batches not written before the kill
    assert not partial_path(path).exists()
    assert resumed.keys() == whole.keys()
    for name in whole:
        if name == "attrs":
            assert {k: str(v) for k, v in resumed[name].items()} == \
                   {k: str(v) for k, v in whole[name].items()}
        else:
            np.testing.assert_array_equal(resumed[name], whole[name])


def test_dask_local_cluster_gives_the_same_file(tmp_path):
    """--workers 2 (a LocalCluster of our own) and --scheduler (an existing cluster's address)."""
    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster

    study = load_study(write_study(tmp_path, samples=1, batch=2))
    here = read_arrays(run_study(study, tmp_path / "here"))
    there = read_arrays(run_study(study, tmp_path / "dask", "dask", workers=2))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        remote = read_arrays(run_study(study, tmp_path / "remote", "dask",
                                       scheduler=cluster.scheduler_address))
    for name in here:
        if name != "attrs":
            np.testing.assert_array_equal(there[name], here[name])
            np.testing.assert_array_equal(remote[name], here[name])


@pytest.mark.parametrize("parameters, metrics, table, key, words", [
    ('"springs.lft.k" = { from = 1.0, to = 2.0, steps = 2 }', "", "study.parameters",
     "springs.lft.k", 'did you mean "left"'),
    ('"springs.left.k" = { from = 1.0, to = 1.0, steps = 3 }', "", "study.parameters",
     "springs.left.k", "empty range"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 0 }', "", "study.parameters",
     "springs.left.k", "empty range"),
    ('"springs.left.k" = { uniform = [2.0, 1.0] }', "", "study.parameters",
     "springs.left.k", "empty range"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }', 'x = "max(3 * 2)"',
     "study.metrics", "x", "got a number"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }', 'x = "max(abs(input_forc.theta3a))"',
     "study.metrics", "x", "'input_forc' is not a variable"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }', 'x = "2 + 3"',
     "study.metrics", "x", "names no stored variable"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }', 'x = "max(velocity_residual)"',
     "study.metrics", "x", "set [solver] rate_residuals = true"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }', 'x = "__import__(\'os\')"',
     "study.metrics", "x", "unexpected"),
])
def test_bad_study_file_is_one_message(tmp_path, parameters, metrics, table, key, words):
    path = tmp_path / "bad.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n{parameters}\n'
                    f"[study.metrics]\n{metrics}\n")
    with pytest.raises(SceneError) as err:
        load_study(path)
    assert (err.value.path, err.value.table, err.value.key) == (str(path), table, key)
    assert words in str(err.value)


@pytest.mark.parametrize("text, table, key, words", [
    ('[study]\nbase = "nowhere.toml"\n[study.parameters]\n"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }\n',
     "study", "base", "no scene file"),
    ('[study]\nbase = "{goal}"\nsampels = 3\n[study.parameters]\n"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }\n',
     "study", "sampels", 'did you mean "samples"'),
    ('[study]\nbase = "{goal}"\n', "study", "parameters", "missing or empty"),
    ('[study]\nbase = "{goal}"\n[study.parameters]\n"drivers.theta3a.step" = { from = 1.0, to = 2.0, steps = 2 }\n',
     "study.parameters", "drivers.theta3a.step", "number of steps"),
    ('[study]\nbase = "{goal}"\n[points]\n', "points", None, "[study] (and [scene] name) only"),
])
def test_bad_study_tables_are_one_message(tmp_path, text, table, key, words):
    path = tmp_path / "bad.toml"
    path.write_text(text.replace("{goal}", GOAL.as_posix()))
    with pytest.raises(SceneError) as err:
        load_study(path)
    assert (err.value.path, err.value.table, err.value.key) == (str(path), table, key)
    assert words in str(err.value)


def test_cli_bad_study_exits_2_without_traceback(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"springs.left.kk" = { from = 1.0, to = 2.0, steps = 2 }\n')
    proc = subprocess.run([sys.executable, "-m", "linkpipe", "study", str(path), "--out",
                           str(tmp_path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"error: {path}: [study.parameters] springs.left.kk:")
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_study_inside_a_scene(tmp_path):
    text = GOAL.read_text() + ('\n[study]\n[study.parameters]\n'
                               '"masses.backboard.mass" = { from = 1.0, to = 2.0, steps = 2 }\n')
    path = tmp_path / "goal_in_scene.toml"
    path.write_text(text)
    assert linkpipe.load_scene(path).name == "basketball_goal"  # a scene may hold [study]
    study = load_study(path)
    f = read_arrays(run_study(study, tmp_path))
    assert study.name == "basketball_goal"
    for v, mass in enumerate((1.0, 2.0)):
        data = tomllib.loads(GOAL.read_text())
        data["masses"][0]["mass"] = mass
        r = linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
        assert f["peak_input_force"][v, 0] == pytest.approx(
            np.abs(r.forces["input_force"][1]).max(), rel=1e-12)


sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_study import goal_every_effect  # noqa: E402  (the benchmark's base scene)

EVERY_EFFECT = goal_every_effect()

FORCE_STUDY = """
[study]
base = "goal_every_effect.toml"
samples = 2
seed = 5
batch_size = 7

[study.parameters]
"springs.left.k" = { from = 2.0, to = 6.0, steps = 3 }
"points.S1.y" = { from = -0.9, to = -0.4, steps = 2 }
"springs.right.damping" = { uniform = [0.1, 0.5] }
"masses.backboard.inertia" = { normal = [0.375, 0.01] }
"loads.hand.force.1" = { uniform = [-8.0, -2.0] }
"loads.twist.torque" = { normal = [1.5, 0.2] }
"gravity.g.1" = { uniform = [-32.2, -32.1] }

[study.metrics]
peak_ground = "max(abs(ground_reaction.S1.y))"
energy = "mean(spring_energy.left) + rms(gravity_energy)"
"""


def test_force_parameters_take_the_vectorised_path_equal_to_one_by_one(tmp_path):
    """Spring rates and damping, an anchor (S1 widens the drawing: its own size), inertia,
    loads and gravity, every effect on: stage 1 once, the force stage on all variants of a
    batch at once; every stored variable of every variant equals its own run."""
    from linkpipe.study.vector import variant_arrays

    (tmp_path / "goal_every_effect.toml").write_text(EVERY_EFFECT)
    path = tmp_path / "forces.toml"
    path.write_text(FORCE_STUDY)
    study = load_study(path)
    assert study.slots is not None and study.path_note.startswith("vectorised")
    status, arrays = variant_arrays(study, study.slots, 0, study.n_variants)
    base = tomllib.loads(EVERY_EFFECT)
    for v in range(study.n_variants):
        data = copy.deepcopy(base)
        k, s1y, c, inertia, fy, torque, gy = study.values[v]
        data["springs"][0]["k"], data["points"]["S1"]["y"] = k, s1y
        data["springs"][1]["damping"], data["masses"][0]["inertia"] = c, inertia
        data["loads"][0]["force"][1], data["loads"][1]["torque"], data["gravity"]["g"][1] = fy, torque, gy
        r = linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
        stored = {x.name: x.data for x in r.variables() if x.dims[:1] == ("step",)}
        assert stored.keys() == arrays.keys()
        for name, want in stored.items():
            np.testing.assert_allclose(arrays[name][v], want, rtol=1e-12, atol=1e-12,
                                       err_msg=f"variant {v} {name}")
    f = read_arrays(run_study(study, tmp_path / "out"))
    assert study.n_variants == 12 and f["batch_done"].tolist() == [1, 1] and (f["worst_status"] == 0).all()
    ok_force = arrays["input_force"][:, :, 0]
    np.testing.assert_array_equal(f["peak_input_force"][:, 0], np.abs(ok_force).max(axis=1))
    np.testing.assert_array_equal(
        f["peak_ground"], np.abs(arrays["ground_reaction"][:, :, 2, 1]).max(axis=1))


def test_pareto_set_is_every_undominated_variant():
    from linkpipe.study.view import pareto_set

    rng = np.random.default_rng(4)
    a, b = rng.integers(0, 30, 400).astype(float), rng.integers(0, 30, 400).astype(float)
    a[::17] = np.nan
    front = set(pareto_set(a, b).tolist())
    for i in np.flatnonzero(np.isfinite(a)):
        beaten = np.isfinite(a) & (a <= a[i]) & (b <= b[i]) & ((a < a[i]) | (b < b[i]))
        same = np.isfinite(a) & (a == a[i]) & (b == b[i])
        # undominated: in the front, or an equal variant is (one of equal ones is kept)
        assert (not beaten.any()) == (i in front or bool(front & set(np.flatnonzero(same))))


def test_study_recording_draws_the_file(tmp_path):
    """The .rrd: each metric against each parameter at the file's values (unit square, y up),
    the Pareto set, and the best variant's own sweep."""
    from test_rrd import Recording

    from linkpipe.stores.rrd import study as study_rrd
    from linkpipe.study.view import pareto_set, study_view

    (tmp_path / "goal_every_effect.toml").write_text(EVERY_EFFECT)
    path = tmp_path / "forces.toml"
    path.write_text(FORCE_STUDY)
    study = load_study(path)
    f = read_arrays(run_study(study, tmp_path / "out"))
    study_rrd.write(study_view(study, f), tmp_path / "s.rrd")
    rec = Recording(tmp_path / "s.rrd")
    k, peak = study.values[:, 0], f["peak_ground"]
    entity = "/study/vs/springs.left.k/peak_ground/variants"
    xy = np.array(rec.static(entity, "Points2D:positions").tolist())
    want = np.stack([(k - k.min()) / np.ptp(k), 1 - (peak - peak.min()) / np.ptp(peak)], axis=1)
    # drawn worst first, the lowest objective on top: the same points in another order
    key = lambda a: a[np.lexsort(a.T)]
    np.testing.assert_allclose(key(xy), key(want.astype(np.float32)), rtol=1e-6)
    front = pareto_set(f["peak_input_force"][:, 0], f["input_force_range"][:, 0])
    labels = rec.static("/study/pareto/peak_input_force.theta3a/input_force_range.theta3a/"
                        "front_points", "Points2D:labels")
    assert list(labels) == [f"variant {v}" for v in front]
    # axes name their units: a spring rate (lbf/ft) against a ground force (lbf), the handle
    # force against the backboard's inertia
    axes = list(rec.static("/study/vs/springs.left.k/peak_ground/axes", "Points2D:labels"))
    assert axes[4:] == ["springs.left.k [lbf/ft]", "peak_ground [lbf] (up)"]
    axes = list(rec.static("/study/vs/masses.backboard.inertia/peak_input_force.theta3a/axes",
                           "Points2D:labels"))
    assert axes[4:] == ["masses.backboard.inertia [slug*ft^2]", "peak_input_force.theta3a [lbf] (up)"]
    table = str(rec.static("/study/best", "TextDocument:text"))
    assert "| springs.left.k [lbf/ft] | points.S1.y [ft] |" in table
    with h5py.File(tmp_path / "out" / "forces_study.h5", "r") as h5:  # a metric's own unit
        assert h5["peak_ground"].attrs["units"] == "lbf"
        assert h5["energy"].attrs["units"] == "lbf*ft"  # two energies added
    assert "/mechanism/links/upper" in rec.entities  # the best variant's motion
    assert {"/study/spread/peak_ground", "/study/spread/energy"} <= rec.entities  # histograms
    best = int(np.argmin(f["peak_input_force"][:, 0]))
    assert f"best variant {best}" in " ".join(rec.view_titles())


def test_study_killed_by_sigkill_resumes_to_the_same_file(tmp_path):
    """A real kill (SIGKILL, no clean-up) half-way: the partial file keeps the finished
    batches, the same command resumes from them, and the file equals an uninterrupted one."""
    import signal
    import time

    from linkpipe.stores.study import read_done

    path = tmp_path / "pins.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\nsamples = 160\nseed = 4\n'
                    'batch_size = 16\n[study.parameters]\n'
                    '"points.O2.y" = { uniform = [-1.0016, -0.9984] }\n')
    command = [sys.executable, "-m", "linkpipe", "study", str(path), "--no-rrd", "--quiet",
               "--out"]
    out = tmp_path / "cut"
    proc = subprocess.Popen(command + [str(out)], cwd=ROOT)
    final = out / "pins_study.h5"
    done = None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            done = read_done(final)
        except OSError:  # the writer holds it mid-write: look again
            done = None
        if done is not None and 2 <= done.sum() < len(done) - 2:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert done is not None and 0 < done.sum() < len(done), "the study was not caught half-way"
    assert not final.exists() and partial_path(final).exists()
    subprocess.run(command + [str(out)], cwd=ROOT, check=True)
    subprocess.run(command + [str(tmp_path / "whole")], cwd=ROOT, check=True)
    resumed, whole = read_arrays(final), read_arrays(tmp_path / "whole" / "pins_study.h5")
    for name in whole:
        if name != "attrs":
            np.testing.assert_array_equal(resumed[name], whole[name], err_msg=name)


def test_readme_example_best_variant_is_a_local_minimum_of_one_by_one_runs(tmp_path):
    """configs/studies/basketball_goal.toml: the variant the study ranks best has the lowest
    peak handle force among its grid neighbours, each solved on its own."""
    study = load_study(ROOT / "configs" / "studies" / "basketball_goal.toml")
    assert study.slots is not None  # spring rate and anchor: the vectorised path
    f = read_arrays(run_study(study, tmp_path))
    best = int(np.nanargmin(f["peak_handle"]))
    k, y = study.values[best]

    def peak(k, y):
        data = tomllib.loads(GOAL.read_text())
        data["springs"][0]["k"], data["points"]["S1"]["y"] = k, y
        r = linkpipe.solve(parse_scene(tomli_w.dumps(data), str(GOAL)))
        return np.abs(r.forces["input_force"][1][r.status == OK]).max()

    assert peak(k, y) == pytest.approx(f["peak_handle"][best], rel=1e-12)
    for dk, dy in ((20.0, 0.0), (-20.0, 0.0), (0.0, 0.05), (0.0, -0.05)):
        if -0.95 <= y + dy <= -0.05 and 0.0 <= k + dk <= 3000.0:
            assert peak(k + dk, y + dy) > f["peak_handle"][best]
    load_study(ROOT / "configs" / "studies" / "basketball_goal_tolerance.toml")  # loads


def test_min_transmission_angle_is_the_four_bar_closed_form(tmp_path):
    """Crank-rocker (crank a, coupler b, rocker c, ground d): at the coupler-rocker pin
    cos mu = (b^2 + c^2 - a^2 - d^2 + 2 a d cos theta) / (2 b c); the study's metric is the
    smallest min(mu, 180 - mu) over the sweep, for each rocker length."""
    base = ROOT / "configs" / "fourbar_crank_rocker.toml"
    path = tmp_path / "rocker.toml"
    path.write_text(f'[study]\nbase = "{base.as_posix()}"\n[study.parameters]\n'
                    '"links.rocker.lengths.O4-B" = { from = 3.0, to = 3.2, steps = 3 }\n')
    study = load_study(path)
    f = read_arrays(run_study(study, tmp_path))
    a, b, d = 1.0, 3.5, 4.0
    theta = np.radians(np.arange(0.0, 361.0))
    for v, c in enumerate(study.values[:, 0]):
        mu = np.degrees(np.arccos((b * b + c * c - a * a - d * d + 2 * a * d * np.cos(theta))
                                  / (2 * b * c)))
        want = np.minimum(mu, 180.0 - mu).min()
        assert f["min_transmission_angle"][v] == pytest.approx(want, abs=1e-9)


def test_a_study_without_forces_or_metrics_writes_its_recording(tmp_path, capsys):
    """No input force (kinematics only) and no [study.metrics]: nothing to draw a Pareto set
    of two metrics from; the study still writes its .h5 and .rrd and exits 0 (it crashed)."""
    from linkpipe.__main__ import main

    path = tmp_path / "nof.toml"
    path.write_text(f'[study]\nbase = "{(ROOT / "configs" / "fourbar_crank_rocker.toml").as_posix()}"\n'
                    '[study.parameters]\n'
                    '"links.coupler.lengths.A-B" = { from = 3.0, to = 4.0, steps = 4 }\n')
    assert main(["study", str(path), "--out", str(tmp_path)]) == 0
    assert (tmp_path / "nof_study.rrd").stat().st_size > 0
    assert "wrote" in capsys.readouterr().out
    assert np.isfinite(read_arrays(tmp_path / "nof_study.h5")["min_transmission_angle"]).all()


@pytest.mark.parametrize("metric, words", [
    ("max(" * 1500 + "input_force.theta3a" + ")" * 1500, "longer than 2000 characters"),
    ("(" * 600 + "max(input_force.theta3a)" + ")" * 600, "nested too deeply"),
])
def test_a_reduction_too_long_or_deep_is_one_message(tmp_path, capsys, metric, words):
    from linkpipe.__main__ import main

    path = write_study(tmp_path, extra=f'deep = "{metric}"\n')
    assert main(["study", str(path), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "[study.metrics] deep" in err and words in err and "Traceback" not in err


def test_a_metric_that_is_not_finite_is_said_in_the_summary(tmp_path, capsys):
    """x / 0 is inf for every variant: stored as it is, and the summary says so (it left the
    metric out silently, with a numpy warning on stderr)."""
    from linkpipe.__main__ import main

    path = write_study(tmp_path, extra='over_zero = "max(input_force.theta3a) / 0"\n')
    assert main(["study", str(path), "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert "over_zero: not finite at 12 variant(s) (12 infinite" in captured.out
    assert "Warning" not in captured.err
    assert np.isinf(read_arrays(tmp_path / "goal_study.h5")["over_zero"]).all()


def test_a_sweep_too_long_for_memory_stops_the_study_not_a_row(tmp_path, monkeypatch):
    """The memory refusal is the scene's error (exit 2 on the command line), never a
    variant's failed row nor a fit's failed trial."""
    import linkpipe.memory as memory
    from linkpipe.errors import MemoryRefused
    from linkpipe.study.variants import solve_variant

    study = load_study(str(write_study(tmp_path)))
    monkeypatch.setattr(memory, "available_memory", lambda: 1)
    with pytest.raises(MemoryRefused):
        solve_variant(study, 0)


def test_best_and_pareto_rank_only_variants_that_finish_the_sweep(tmp_path, capsys):
    """A variant that stops assembling partway has metrics over fewer steps: it is never listed
    as best, shown as the best motion, nor put in the Pareto set while variants that finish
    the sweep exist (it was ranked among them by its partial peaks)."""
    from linkpipe.__main__ import main
    from linkpipe.study.view import study_view

    path = tmp_path / "o4.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"points.O4.x" = { from = -0.6, to = 0.6, steps = 7 }\n'
                    '"points.O4.y" = { from = -2.3, to = -1.7, steps = 7 }\n'
                    '"springs.left.k" = { from = 0.0, to = 3000.0, steps = 4 }\n')
    assert main(["study", str(path), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    f = read_arrays(tmp_path / "o4_study.h5")
    assert (f["worst_status"] != OK).any() and (f["worst_status"] == OK).any()
    best = [int(v) for v in __import__("re").findall(r"variant (\d+):", out)]
    assert best and all(f["worst_status"][v] == OK for v in best)
    # each figure with its unit: the handle force in lbf, the anchor in ft, the rate in lbf/ft
    assert __import__("re").search(r"\n  peak_input_force\.theta3a: \S+ \.\. \S+ lbf \(mean", out)
    v = best[0]
    assert (f"variant {v}: {f['peak_input_force'][v, 0]:.6g} lbf at points.O4.x = "
            f"{f['parameter_value'][v, 0]:.6g} ft") in out
    assert "lbf/ft" in out.split(f"variant {v}:")[1].splitlines()[0]
    view = study_view(load_study(path), f)
    assert all(f["worst_status"][v] == OK for v, _ in view.best)
    assert all(f["worst_status"][v] == OK for v in view.pareto[1])


def test_a_changed_log_restarts_the_study_instead_of_resuming(tmp_path):
    """The fingerprint a resumed run must match covers the logs' data, not only the texts."""
    logged = ROOT / "configs" / "logged"
    base = tmp_path / "truck.toml"
    text = (logged / "dump_truck_logged.toml").read_text()
    log = tmp_path / "run.csv"
    log.write_text((logged / "logs" / "tipper_run.csv").read_text())
    base.write_text(text.replace("logs/tipper_run.csv", "run.csv"))
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{base.as_posix()}"\n[study.parameters]\n'
                    '"masses.body.mass" = { from = 15000.0, to = 18000.0, steps = 4 }\n')
    import pandas as pd

    first = load_study(path)
    frame = pd.read_csv(log)
    frame.to_csv(log, index=False)  # written anew: other text, the same numbers
    assert log.read_text() != (logged / "logs" / "tipper_run.csv").read_text()
    assert load_study(path).fingerprint == first.fingerprint
    frame[frame.columns[1]] *= 0.8
    frame.to_csv(log, index=False)
    assert load_study(path).fingerprint != first.fingerprint


@pytest.mark.parametrize("parameters, key, words", [
    ('"drivers.theta3a.from" = { from = -60.0, to = -40.0, steps = 3 }', "drivers.theta3a.from",
     "would change the number of steps"),
    ('"gravity.g.1" = { from = -32.0, to = -10.0, steps = 3 }\n'
     '"gravity.g.01" = { from = -1.0, to = 0.0, steps = 2 }', "gravity.g.01",
     'the same value as "gravity.g.1"'),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 1 }', "springs.left.k",
     "one step cannot cover from 1.0 to 2.0"),
    ('"springs.left.k" = { from = 1.0, to = 2.0, steps = 20000 }\n'
     '"springs.right.k" = { from = 1.0, to = 2.0, steps = 20000 }', "parameters",
     "400,000,000 variants"),
])
def test_studies_that_cannot_be_one_step_axis_or_name_a_value_twice(tmp_path, parameters, key,
                                                                    words):
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n{parameters}\n')
    with pytest.raises(SceneError) as err:
        load_study(path)
    assert key in str(err.value) and words in str(err.value)


def test_a_study_of_a_value_of_an_effect_left_off_is_one_message(tmp_path):
    """The hatch leaves inertia off (quasi-static): its tailgate's moment of inertia moves
    nothing computed, so a study of it would give identical variants; one message says why."""
    path = tmp_path / "s.toml"
    path.write_text(f'[study]\nbase = "{HATCH.as_posix()}"\n[study.parameters]\n'
                    '"masses.tailgate.inertia" = { from = 1.0, to = 2.0, steps = 3 }\n')
    with pytest.raises(SceneError) as err:
        load_study(path)
    assert err.value.key == "masses.tailgate.inertia"
    assert 'acts through the effect "inertia", which [analysis] effects leaves off' in str(err.value)
    path.write_text(path.read_text().replace("inertia\"", "mass\""))  # the mass: gravity's
    assert load_study(path).parameters[0].address == "masses.tailgate.mass"


def test_two_runs_of_one_study_into_one_folder_wait_for_each_other(tmp_path):
    """The second run waits for the first (it took the first one's unfinished file for one cut
    short by a kill and deleted it); both end with the complete file."""
    import threading
    import time

    path = write_study(tmp_path, batch=2)
    done = []

    def run(pause):
        run_study(load_study(path), tmp_path / "out",
                  after_batch=lambda n: time.sleep(pause))
        done.append(read_arrays(tmp_path / "out" / "goal_study.h5"))

    first = threading.Thread(target=run, args=(0.05,))
    first.start()
    time.sleep(0.1)
    run(0.0)
    first.join()
    assert len(done) == 2 and (done[0]["batch_done"] == 1).all()
    for name in ("peak_input_force", "worst_status"):
        np.testing.assert_array_equal(done[0][name], done[1][name])


def test_an_interrupted_study_says_it_can_be_resumed(tmp_path, capsys, monkeypatch):
    """Ctrl-C during a study: exit 130 and one line saying the finished batches are kept and
    the same command resumes (not "the one being written was not kept")."""
    import linkpipe.study
    from linkpipe.__main__ import main

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(linkpipe.study, "run_study", stop)
    assert main(["study", str(write_study(tmp_path)), "--out", str(tmp_path)]) == 130
    err = capsys.readouterr().err
    assert "the same command resumes" in err and len(err.strip().splitlines()) == 1


def test_check_validates_a_study_and_run_points_to_study(tmp_path, capsys):
    """``check`` on a study file checks it as ``study`` would (base scene, parameters, metrics)
    and describes it, exit 0; a mistake in [study] is its one message, exit 2; ``run`` on a
    study file says what it is and which command takes it; a scene holding its own [study] is
    described both as a scene and as a study."""
    path = write_study(tmp_path)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    study = load_study(path)
    assert out.startswith(f"goal: study of basketball_goal ({GOAL.as_posix()}), "
                          f"{study.n_variants} variant(s) of 25 steps")
    assert "parameter springs.left.k = 4 in the base: 2 .. 6 in 3 steps (variants 2 .. 6 lbf/ft)" in out
    assert "parameter points.O4.y = -2 in the base: normal -2, 0.0005" in out
    assert "metric p95_spring = percentile(spring_force.left, 95)" in out

    bad = write_study(tmp_path, name="bad", extra='typo = "max(abs(input_forc.theta3a))"\n')
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {bad}: [study.metrics] typo:") and len(err.splitlines()) == 1

    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "this is a study file" in err and "python -m linkpipe study" in err
    assert not (tmp_path / "out" / "goal.h5").exists()

    inside = tmp_path / "goal_in_scene.toml"
    inside.write_text(GOAL.read_text() + '\n[study]\n[study.parameters]\n'
                      '"masses.backboard.mass" = { from = 1.0, to = 2.0, steps = 2 }\n')
    assert main(["check", str(inside)]) == 0
    out = capsys.readouterr().out
    assert "basketball_goal: study of basketball_goal" in out and "is valid" in out


HATCH = ROOT / "configs" / "hatch_gas_spring.toml"

GAS_STUDY = """
[study]
base = "hatch.toml"
samples = 3
seed = 11

[study.parameters]
"springs.strut_left.force_extended" = {{ from = 200.0, to = 400.0, steps = 2 }}
"springs.strut_left.extended_length" = {{ uniform = [0.52, 0.58] }}
"springs.strut_right.dead_length" = {{ uniform = [-0.45, -0.35] }}
"springs.strut_right.gamma" = {{ from = 1.0, to = 1.4, steps = 2 }}
"torsion_springs.hinge.k" = {{ normal = [{k}, 2.0] }}
"torsion_springs.hinge.free_angle" = {{ from = {free_lo}, to = {free_hi}, steps = 2 }}

[study.metrics]
peak = "max(abs(input_force.opening))"
"""


def test_gas_and_torsion_spring_numbers_take_the_vectorised_path_equal_to_one_by_one(tmp_path):
    """The tailgate's gas struts (force at the extended length, extended and dead length, the
    exponent across the isothermal case gamma = 1) and a torsion spring's rate and free angle:
    stage 1 once, every stored variable of every variant equal to its own run (they ran variant
    by variant before, and the summary gave "changes the kinematics" as the reason). The two
    free angles lie 10 degrees either side of half a turn from the spring's first angle: the
    angle stays the links' difference for both (no whole turn taken off), in the study as in
    each variant's own run."""
    from linkpipe.study.vector import variant_arrays

    scene = HATCH.read_text() + ('\n[[torsion_springs]]\nname = "hinge"\n'
                                 'links = ["tailgate", "ground"]\nk = 20.0\nfree_angle = -30.0\n')
    (tmp_path / "hatch.toml").write_text(scene)
    path = tmp_path / "gas.toml"
    first = np.degrees(linkpipe.solve(linkpipe.load_scene(tmp_path / "hatch.toml"))
                       .forces["torsion_spring_angle"][1][0, 0])
    path.write_text(GAS_STUDY.format(k=20.0, free_lo=first + 170.0, free_hi=first + 190.0))
    study = load_study(path)
    assert study.slots is not None and study.path_note.startswith("vectorised")
    status, arrays = variant_arrays(study, study.slots, 0, study.n_variants)
    base = tomllib.loads(scene)
    for v in range(study.n_variants):
        data = copy.deepcopy(base)
        f1, l1, d, gamma, k, free = study.values[v]
        data["springs"][0]["force_extended"], data["springs"][0]["extended_length"] = f1, l1
        data["springs"][1]["dead_length"], data["springs"][1]["gamma"] = d, gamma
        data["torsion_springs"][0]["k"], data["torsion_springs"][0]["free_angle"] = k, free
        r = linkpipe.solve(parse_scene(tomli_w.dumps(data), str(tmp_path / "hatch.toml")))
        np.testing.assert_array_equal(status[v], r.status)
        stored = {x.name: x.data for x in r.variables() if x.dims[:1] == ("step",)}
        assert stored.keys() == arrays.keys()
        for name, want in stored.items():
            np.testing.assert_allclose(arrays[name][v], want, rtol=1e-12, atol=1e-12,
                                       err_msg=f"variant {v} {name}")
    assert {round(g, 6) for g in study.values[:, 3]} == {1.0, 1.4}
    assert study.n_variants == 2 * 2 * 2 * 3
    # the two free angles' runs start at the same angle, the links' difference
    start = arrays["torsion_spring_angle"][:, 0, 0]
    assert (start == start[0]).all()
    assert np.degrees(start[0]) == pytest.approx(first, abs=1e-12)
    f = read_arrays(run_study(study, tmp_path / "out"))
    np.testing.assert_array_equal(f["peak"], np.nanmax(np.abs(arrays["input_force"][:, :, 0]),
                                                       axis=1))


def test_a_study_of_a_study_or_of_the_instants_is_one_clear_message(tmp_path):
    """A base that is itself a study file names the study's own base key; a [time] value
    would move the instants (the steps' count stays), which is what the message says."""
    inner = write_study(tmp_path, name="inner")
    outer = tmp_path / "outer.toml"
    outer.write_text(f'[study]\nbase = "{inner.name}"\n[study.parameters]\n'
                     '"springs.left.k" = { from = 1.0, to = 2.0, steps = 2 }\n')
    with pytest.raises(SceneError) as err:
        load_study(outer)
    assert (err.value.path, err.value.table, err.value.key) == (str(outer), "study", "base")
    assert "is a study file, not a scene" in str(err.value)

    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    driver = text[text.index("[[drivers]]"):text.index("[outputs]")]
    timed = text.replace(driver, '[time]\nfrom = 0.0\nto = 2.0\nsteps = 41\n\n[[drivers]]\n'
                         'name = "crank"\nangle = ["O2", "A"]\nrate = 90.0\nfrom = 0.0\n\n')
    (tmp_path / "timed.toml").write_text(timed)
    for key in ("to", "from"):
        study = tmp_path / f"t_{key}.toml"
        study.write_text(f'[study]\nbase = "timed.toml"\n[study.parameters]\n'
                         f'"time.{key}" = {{ from = 1.0, to = 2.0, steps = 2 }}\n')
        with pytest.raises(SceneError) as err:
            load_study(study)
        assert err.value.key == f"time.{key}" and "would change the instants" in str(err.value)


@pytest.mark.parametrize("text, unit", [
    ("max(abs(input_force.theta3a))", "lbf"), ("percentile(spring_force.left, 95)", "lbf"),
    ("mean(position.B.x) - min(position.C.y)", "ft"),
    ("mean(position.B.x) - 2 * min(spring_force.right) / 4", ""),  # ft and lbf: no one unit
    ("max(spring_force.left) * mean(position.B.x)", "lbf*ft"),
    ("max(spring_force.left) / 2", "lbf"), ("rms(link_angle.upper)", "rad"),
    ("-min(driver_value.theta3a)", "degree"), ("max(condition)", "1")])
def test_a_metric_has_the_unit_of_what_it_reduces(tmp_path, text, unit):
    study_path = write_study(tmp_path).read_text()
    path = tmp_path / "m.toml"
    path.write_text(study_path.split("[study.metrics]")[0] + f'[study.metrics]\nm = "{text}"\n')
    assert load_study(path).metric_units() == {"m": unit}


def test_a_scene_without_study_is_told_how_to_add_its_own_and_the_advice_works(tmp_path, capsys):
    """``study`` on a plain scene: the message's advice, taken as written (a [study.parameters]
    table in the scene, no base), gives a study that runs."""
    from linkpipe.__main__ import main
    path = tmp_path / "rocker.toml"
    path.write_text((ROOT / "configs" / "fourbar_crank_rocker.toml").read_text())
    assert main(["study", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "add [study.parameters] to this scene (its own [study] has no base)" in err
    path.write_text(path.read_text() + '\n[study.parameters]\n"points.O4.x" = { from = 2.0, to = 2.2, steps = 2 }\n')
    assert main(["study", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    assert (tmp_path / "out" / "fourbar_crank_rocker_study.h5").is_file()
