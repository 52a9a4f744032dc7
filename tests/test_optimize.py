"""``linkpipe optimize``: against closed forms (a lever a spring balances exactly, with and
without a constraint that excludes the balance), tie against a hand-tied scene, the written
scene reproducing the objective, two objectives' Pareto set, metrics at a pose, and every bad
input one message with nothing written."""
import math
import pathlib

import h5py
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe.__main__ import main
from linkpipe.executors import Pool
from linkpipe.study import load_study, run_study
from linkpipe.study.optimize import optimize
from linkpipe.study.problem import load_problem
from linkpipe.study.reductions import at_value
from linkpipe.stores.study import read_arrays

ROOT = pathlib.Path(__file__).resolve().parent.parent
GOAL = ROOT / "configs" / "basketball_goal.toml"

# A lever O-A (L = 1 m) with 2 kg at A, gravity -9.81; a spring of free length 0 from the
# anchor S = (x, a = 0.4) to B on the lever at b = 0.5 m. The input torque is
#   tau(theta) = (k a b - m g L) cos(theta) - k b x sin(theta)
# (gravity's torque about O is -m g L cos(theta); the spring's, B x k (S - B) = k b (a cos(theta)
# - x sin(theta))): zero at every pose exactly when k = m g L / (a b) = 98.1 N/m and x = 0.
M, G, L, A, B = 2.0, 9.81, 1.0, 0.4, 0.5
K_STAR = M * G * L / (A * B)
LEVER = """
[scene]
name = "{name}"

[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
A = {{ x = 1.0, y = 0.0 }}
B = {{ x = 0.5, y = 0.0 }}
S = {{ x = 0.1, y = 0.4, fixed = true }}

[[links]]
name = "lever"
points = ["O", "A", "B"]
lengths = {{ "O-A" = 1.0 }}
local = {{ B = [0.5, 0.0] }}

[[drivers]]
name = "swing"
angle = ["O", "A"]
from = -60.0
to = 60.0
steps = 25

[analysis]
effects = ["springs", "gravity"]

[gravity]
g = [0.0, -9.81]

[[masses]]
link = "lever"
mass = 2.0
center = "A"

[[springs]]
name = "balancer"
between = ["S", "B"]
k = 50.0
free_length = 0.0

[study.metrics]
peak = "max(abs(input_force.swing))"
rms = "rms(input_force.swing)"
anchor_x = "max(position.S.x)"
at_47_5 = "at_driver(input_force.swing, swing, 47.5)"
at_top = "at(input_force.swing, -1)"
failed = "count_failed()"

[optimize]
minimize = {minimize}
parameters = {{ "springs.balancer.k" = [0.0, 300.0], "points.S.x" = [-0.3, 0.3] }}
seed = 3
{extra}
"""


def tau(theta_deg, k, x):
    t = np.radians(theta_deg)
    return (k * A * B - M * G * L) * np.cos(t) - k * B * x * np.sin(t)


def lever(folder, name="lever", minimize='"peak"', extra=""):
    path = pathlib.Path(folder) / f"{name}.toml"
    path.write_text(LEVER.format(name=name, minimize=minimize, extra=extra))
    return path


def solve(path):
    with Pool() as pool:
        return optimize(load_problem(path), pool)


def test_the_spring_that_balances_the_lever_is_found_to_1e_6(tmp_path):
    found = solve(lever(tmp_path))
    k, x = found.best_values
    # the optimiser's polish ends at 1e-10 of each bound's width: far inside 1e-6
    assert abs(k - K_STAR) <= 1e-6 * K_STAR
    assert abs(x) <= 1e-6  # m
    assert found.objective[found.best] <= 1e-6  # N m: the balance is exact
    assert found.on_bound == [] and found.active == []
    # the generations' best never rises (the search is elitist) and ends at the search's best
    pb = found.population_best[np.isfinite(found.population_best)]
    assert np.all(np.diff(pb) <= 0)


def test_a_constraint_that_excludes_the_balance_moves_the_answer_to_its_boundary(tmp_path):
    found = solve(lever(tmp_path, extra='constraints = ["anchor_x >= 0.05"]'))
    k, x = found.best_values
    # on the boundary x = 0.05 the peak is 0.5 |k - k*| a b + sin(60 deg) k b x (the poses at 0
    # and +-60 deg): lowest at k = k*, where it is k* b x sin(60 deg)
    assert abs(x - 0.05) <= 1e-6
    assert abs(k - K_STAR) <= 1e-5 * K_STAR
    want = K_STAR * B * 0.05 * math.sin(math.radians(60))
    assert found.objective[found.best] == pytest.approx(want, rel=1e-6)
    assert found.active == ["anchor_x >= 0.05"]
    # every variant reported feasible meets it; the unconstrained balance (x = 0) is not one
    assert np.all(found.metrics["anchor_x"][found.feasible] >= 0.05)


def test_metrics_at_a_pose_against_the_closed_form(tmp_path):
    study_file = tmp_path / "poses.toml"
    study_file.write_text(f'[study]\nbase = "{lever(tmp_path).as_posix()}"\n'
                          '[study.parameters]\n"springs.balancer.k" = { from = 60.0, to = 120.0, steps = 4 }\n'
                          '"points.S.x" = { from = -0.1, to = 0.2, steps = 3 }\n'
                          + LEVER.split("[study.metrics]")[1].split("[optimize]")[0]
                          .replace("\npeak", "[study.metrics]\npeak", 1))
    study = load_study(study_file)
    f = read_arrays(run_study(study, tmp_path / "out"))
    k, x = study.values.T
    sign = np.sign(f["at_top"][0] / tau(60.0, k[0], x[0]))  # the input torque's sign convention
    np.testing.assert_allclose(f["at_top"], sign * tau(60.0, k, x), rtol=0, atol=1e-9)
    # at 47.5 deg, halfway between the steps at 45 and 50 deg: their mean (linear interpolation)
    np.testing.assert_allclose(f["at_47_5"], sign * 0.5 * (tau(45.0, k, x) + tau(50.0, k, x)),
                               rtol=0, atol=1e-9)
    assert np.all(f["failed"] == 0)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 30), seed=st.integers(0, 10_000), where=st.floats(0.0, 1.0))
def test_at_value_is_numpys_interpolation_on_a_rising_driver(n, seed, where):
    rng = np.random.default_rng(seed)
    d = np.cumsum(rng.uniform(0.1, 2.0, size=(3, n)), axis=1)
    x = rng.normal(size=(3, n))
    value = d[0, 0] + where * (d[0, -1] - d[0, 0])
    got = at_value(x, d, value)
    for r in range(3):
        if d[r, 0] <= value <= d[r, -1]:
            assert got[r] == pytest.approx(np.interp(value, d[r], x[r]), abs=1e-12)
        else:
            assert np.isnan(got[r])


def test_count_failed_counts_the_steps_that_are_not_ok(tmp_path):
    # the crank-rocker with longer cranks: past Grashof's condition a full turn of the crank
    # cannot be reached, and the variant's own run says which steps fail
    base = ROOT / "configs" / "fourbar_crank_rocker.toml"
    result = linkpipe.solve(base)
    study_file = tmp_path / "count.toml"
    study_file.write_text(f'[study]\nbase = "{base.as_posix()}"\n[study.parameters]\n'
                          '"links.crank.lengths.O2-A" = { from = 1.0, to = 4.0, steps = 4 }\n'
                          '[study.metrics]\nfailed = "count_failed()"\n')
    study = load_study(study_file)
    f = read_arrays(run_study(study, tmp_path / "out"))
    for v in range(study.n_variants):
        from linkpipe.study.batch import solve_variant

        r = solve_variant(study, v)
        want = study.scene.n_steps if r is None else int((r.status != 0).sum())
        assert f["failed"][v] == want
    assert f["failed"][0] == 0 and 0 < f["failed"][2] < result.n_steps  # a partial failure


def test_tie_equals_a_hand_tied_scene(tmp_path):
    """Both springs of the goal tied to one rate k are one spring of 2k between the same
    points: the study of the tied pair equals the study of a hand-written scene with one."""
    tied = tmp_path / "tied.toml"
    tied.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"springs.left.k" = { from = 0.0, to = 3000.0, steps = 7 }\n'
                    '"points.S1.y" = { from = -0.9, to = -0.1, steps = 3 }\n'
                    'tie = { "springs.right.k" = "springs.left.k" }\n'
                    '[study.metrics]\npeak = "max(abs(input_force.theta3a))"\n'
                    'top = "at(input_force.theta3a, -1)"\n')
    text = GOAL.read_text()
    one = text[:text.index('[[springs]]\nname = "right"')] + text[text.index("[[masses]]"):]
    assert 'name = "right"' not in one
    (tmp_path / "one_spring.toml").write_text(one)
    hand = tmp_path / "hand.toml"
    hand.write_text('[study]\nbase = "one_spring.toml"\n[study.parameters]\n'
                    '"springs.left.k" = { from = 0.0, to = 6000.0, steps = 7 }\n'
                    '"points.S1.y" = { from = -0.9, to = -0.1, steps = 3 }\n'
                    '[study.metrics]\npeak = "max(abs(input_force.theta3a))"\n'
                    'top = "at(input_force.theta3a, -1)"\n')
    a = load_study(tied)
    assert np.array_equal(a.values[:, 2], a.values[:, 0])  # the tied column follows
    fa = read_arrays(run_study(a, tmp_path / "a"))
    fb = read_arrays(run_study(load_study(hand), tmp_path / "b"))
    for name in ("peak", "top"):  # lbf; two equal forces summed against one of their sum
        np.testing.assert_allclose(fa[name], fb[name], rtol=1e-12, atol=1e-9)


GOAL_OPT = """
[scene]
name = "{name}"

[study]
base = "{base}"

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"
rms_handle = "rms(input_force.theta3a)"

[optimize]
minimize = {minimize}
parameters = {{ "springs.left.k" = [0.0, 3000.0], "points.S1.y" = [-0.95, -0.05] }}
tie = {tie}
seed = 2
{extra}
"""


def goal_file(folder, name="goal", minimize='"peak_handle"', tie='{ "springs.right.k" = "springs.left.k" }', extra=""):
    path = pathlib.Path(folder) / f"{name}.toml"
    path.write_text(GOAL_OPT.format(name=name, base=GOAL.as_posix(), minimize=minimize,
                                    tie=tie, extra=extra))
    return path


def test_the_written_scene_runs_to_the_objective(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["optimize", str(goal_file(tmp_path)), "--out", str(out), "--no-rrd"]) == 0
    printed = capsys.readouterr().out
    assert "springs.right.k" in printed and "tied to springs.left.k" in printed
    with h5py.File(out / "goal_optimize.h5", "r") as h5:
        best = h5["best"][()]
        names = [n.decode() if isinstance(n, bytes) else n for n in h5["parameter"][()]]
        objective = float(h5.attrs["best_objective"])
        assert h5["objective"][int(h5.attrs["best_evaluation"])] == objective
        assert np.nanmin(h5["population_best"][()]) >= objective  # the polish only improves
        assert list(h5.attrs["active_constraints"]) == []
        assert "on_bound" in h5.attrs
    assert names == ["springs.left.k", "points.S1.y", "springs.right.k"]
    assert best[2] == best[0]
    scene = linkpipe.load_scene(out / "goal_optimize.toml")
    assert scene.springs[0].k == best[0] == scene.springs[1].k
    text = (out / "goal_optimize.toml").read_text()  # each changed line says what it was
    (s1,) = [line for line in text.splitlines() if line.startswith("S1 = ")]
    assert s1.endswith("# optimized: y was -0.6571")  # the basketball goal's drawn S1.y
    assert sum(line.startswith("k = ") and "# optimized: was " in line
               for line in text.splitlines()) == 2
    result = linkpipe.solve(scene)
    assert result.message.startswith("all")
    peak = np.abs(result.forces["input_force"][1][:, 0]).max()
    assert peak == pytest.approx(objective, rel=1e-12)  # the same variant solved on its own


def test_two_objectives_give_a_pareto_set(tmp_path):
    found = solve(goal_file(tmp_path, minimize='["peak_handle", "rms_handle"]'))
    a, b = found.metrics["peak_handle"], found.metrics["rms_handle"]
    front = found.pareto
    assert len(front) >= 3 and found.best == front[0]
    ok = found.feasible
    for v in front:  # no feasible evaluation beats a member in both
        assert not np.any(ok & (a <= a[v]) & (b <= b[v]) & ((a < a[v]) | (b < b[v])))
    assert np.all(np.diff(a[front]) > 0) and np.all(np.diff(b[front]) < 0)
    # the ends: the lowest peak, and the lowest rms of every feasible evaluation
    assert a[front[0]] == a[ok].min() and b[front[-1]] == b[ok].min()


def test_the_dask_path_finds_the_same_evaluations(tmp_path):
    pytest.importorskip("dask.distributed")
    path = lever(tmp_path)
    here = solve(path)
    with Pool(workers=2) as pool:
        there = optimize(load_problem(path), pool)
    np.testing.assert_array_equal(here.values, there.values)
    np.testing.assert_array_equal(here.objective, there.objective)


@pytest.mark.parametrize("extra, file_key, says", [
    ('parameters = { "springs.balancer.k" = [300.0, 0.0] }', "springs.balancer.k",
     "low 300 >= high 0"),
    ('parameters = { "springs.balancer.k" = [1.0, 1.0] }', "springs.balancer.k", "low 1 >= high 1"),
    ('tie = { "points.S.y" = "points.S.z" }', "optimize.tie", 'no parameter varies'),
    ('tie = { "points.S.y" = "springs.balancer.free_length", "springs.balancer.free_length" = '
     '"points.S.y" }', "optimize.tie", "a cycle of ties"),
    ('tie = { "springs.balancer.k" = "points.S.x" }', "optimize.tie", "is varied itself"),
    ('minimize = "peek"', "minimize", '"peek" names no metric'),
    ('constraints = ["anchr_x <= 1"]', "constraints", '"anchr_x" names no metric'),
    ('constraints = ["anchor_x <= peak"]', "constraints", "not a metric against a number"),
    ('seed = -1', "seed", "whole number"),
    ('populaton = 10', "populaton", "unknown key"),
])
def test_bad_optimize_tables_are_one_message_and_nothing_written(tmp_path, capsys, extra,
                                                                  file_key, says):
    text = LEVER.format(name="bad", minimize='"peak"', extra="")
    key = extra.split(" =")[0]
    lines = [l for l in text.splitlines() if not l.startswith(key + " =")]
    path = tmp_path / "bad.toml"
    path.write_text("\n".join(lines) + "\n" + extra + "\n")
    out = tmp_path / "out"
    assert main(["optimize", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert str(path) in err and file_key in err and says in err
    assert not out.exists() or not any(p for p in out.iterdir() if not p.name.startswith("."))


def test_an_infeasible_problem_names_the_closest_variant(tmp_path, capsys):
    path = lever(tmp_path, name="infeasible", extra='constraints = ["anchor_x >= 0.5"]')
    out = tmp_path / "out"
    assert main(["optimize", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    # the closest variant puts the anchor as far right as the bounds allow
    assert "no variant meets the constraints" in err and "points.S.x = 0.3" in err
    assert "anchor_x = 0.3" in err and "must be >= 0.5" in err
    assert not any(p for p in out.iterdir() if not p.name.startswith("."))


def test_the_recording_marks_the_best_and_shows_the_progress(tmp_path):
    """<name>_optimize.rrd: each metric against each parameter (the best ringed where it is
    drawn), the generations' best on the ``generation`` timeline, one tab per metric."""
    from test_rrd import Recording

    out = tmp_path / "out"
    assert main(["optimize", str(lever(tmp_path)), "--out", str(out), "--quiet"]) == 0
    rec = Recording(out / "lever_optimize.rrd")
    with h5py.File(out / "lever_optimize.h5", "r") as h5:
        values, objective = h5["parameter_value"][()], h5["objective"][()]
        best = int(h5.attrs["best_evaluation"])
        progress = h5["population_best"][()]
    k = values[:, 0]
    ring = np.array(rec.static("/study/vs/springs.balancer.k/peak/best", "Points2D:positions").tolist())
    # peak spans decades (1e-9 at the balance): a log scale, the best at the bottom
    assert ring[0] == pytest.approx([(k[best] - k.min()) / np.ptp(k), 1.0], abs=1e-6)
    axes = list(rec.static("/study/vs/springs.balancer.k/peak/axes", "Points2D:labels"))
    assert axes[5].endswith("(log, up)") and float(axes[3]) == pytest.approx(objective.max(), rel=1e-3)
    frame = rec.store.reader(index="generation", contents="/study/progress/**").to_pandas()
    logged = np.concatenate(frame["/study/progress/population_best:Scalars:scalars"].dropna().to_numpy())
    np.testing.assert_allclose(logged, progress[np.isfinite(progress)])
    titles = rec.view_titles()
    assert {"springs.balancer.k [force/length]", "points.S.x [length]"} <= titles
    assert "/mechanism/links/lever" in rec.entities  # the best variant's motion


@pytest.mark.parametrize("tie, says", [
    ('{ "springs.right.k" = "springs.left.kk" }', "which no parameter varies"),
    ('{ "springs.right.k" = "springs.right.free_length", "springs.right.free_length" = '
     '"springs.right.k" }', "a cycle of ties"),
    ('{ "points.S1.y" = "springs.left.k" }', "is varied itself"),
    ('"springs.left.k"', "expected a table of addresses"),
])
def test_a_bad_tie_in_a_study_is_one_message(tmp_path, capsys, tie, says):
    path = tmp_path / "tie.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"springs.left.k" = { from = 0.0, to = 3000.0, steps = 3 }\n'
                    '"points.S1.y" = { from = -0.9, to = -0.1, steps = 2 }\n'
                    f'tie = {tie}\n')
    out = tmp_path / "out"
    assert main(["study", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and "study.parameters" in err
    assert not out.exists() or not any(p for p in out.iterdir() if not p.name.startswith("."))


def test_an_optimum_on_a_bound_is_reported_there(tmp_path, capsys):
    """Rates up to 80 N/m cannot reach the balance (98.1): the best rate is the bound, and the
    peak is the torque at 0 deg, |k a b - m g L| (the sin term vanishes there)."""
    text = LEVER.format(name="capped", minimize='"peak"', extra="").replace(
        '"springs.balancer.k" = [0.0, 300.0]', '"springs.balancer.k" = [0.0, 80.0]')
    path = tmp_path / "capped.toml"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["optimize", str(path), "--out", str(out), "--no-rrd"]) == 0
    assert "springs.balancer.k = 80 force/length (on its upper bound)" in capsys.readouterr().out
    with h5py.File(out / "capped_optimize.h5", "r") as h5:
        assert [str(a) for a in h5.attrs["on_bound"]] == ["springs.balancer.k"]
        assert [str(a) for a in h5.attrs["on_bound_side"]] == ["upper"]
        assert h5["best"][0] == 80.0
        assert float(h5.attrs["best_objective"]) == pytest.approx(abs(80.0 * A * B - M * G * L),
                                                                   rel=1e-9)


def test_a_study_says_when_its_best_sits_on_the_grid_edge(tmp_path, capsys):
    """Rates up to 50 lbf/ft cannot hold the goal up (it wants about 1,400): the lowest peak
    is at the grid's highest rate, and the study says so."""
    path = tmp_path / "edge.toml"
    path.write_text(f'[study]\nbase = "{GOAL.as_posix()}"\n[study.parameters]\n'
                    '"springs.left.k" = { from = 0.0, to = 50.0, steps = 6 }\n'
                    '"points.S1.y" = { from = -0.8, to = -0.6, steps = 3 }\n'
                    '[study.metrics]\npeak = "max(abs(input_force.theta3a))"\n')
    assert main(["study", str(path), "--out", str(tmp_path / "out"), "--no-rrd"]) == 0
    out = capsys.readouterr().out
    assert "best on the edge: springs.left.k = " in out and "is the highest value" in out
