"""Studies that move the mechanism's fixed points (pivots) on the vectorised path: every stored
variable of every variant equals its own one-by-one run (the scene's TOML edited by hand,
parsed and solved by ``linkpipe.solve``), including variants that cannot assemble and those
that leave the base's branches (their own runs, put in place)."""
import pathlib
import tomllib

import numpy as np
import pytest
import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st_h

import linkpipe
import linkpipe.kinematics as kin
from linkpipe.errors import SceneError
from linkpipe.scene import parse_scene
from linkpipe.status import NO_ASSEMBLY, OK
from linkpipe.stores.study import read_arrays
from linkpipe.study import load_study, run_study
from linkpipe.study import paths, pivots, vector
from test_study import EVERY_EFFECT

ROOT = pathlib.Path(__file__).resolve().parents[1]
GOAL = ROOT / "configs" / "basketball_goal.toml"
ROCKER = ROOT / "configs" / "fourbar_crank_rocker.toml"

#: the README's pin tolerances, the pins on the pole only (with link lengths:
#: tests/test_study_lengths.py)
PIN_TOLERANCE = """[study]
base = "{base}"
samples = {samples}
seed = 17

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"

[study.parameters]
"springs.left.k" = {{ from = 2820.0, to = 2820.0, steps = 1 }}
"points.S1.y" = {{ from = -0.9, to = -0.9, steps = 1 }}
"points.O2.x" = {{ uniform = [-0.00164, 0.00164] }}
"points.O2.y" = {{ uniform = [-1.00164, -0.99836] }}
"points.O4.x" = {{ uniform = [-0.00164, 0.00164] }}
"points.O4.y" = {{ uniform = [-2.00164, -1.99836] }}
"""


def write(tmp_path, text: str, name="s.toml") -> pathlib.Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def study_of(tmp_path, base, parameters: str, samples=1, seed=0, extra=""):
    """The study of ``parameters`` (the [study.parameters] table's lines) over scene ``base``."""
    return load_study(write(tmp_path, f'[study]\nbase = "{pathlib.Path(base).as_posix()}"\n'
                            f'samples = {samples}\nseed = {seed}\n{extra}[study.parameters]\n'
                            f'{parameters}', "study.toml"))


def vectorised_rows_are_own_runs(base, study):
    """Assert the study takes the vectorised path and its rows of every variant are the
    variants' own runs; return the rows (status, arrays)."""
    assert study.slots is not None
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert_rows_are_own_runs(base, study, status, arrays)
    return status, arrays


def set_value(data: dict, path: tuple, value: float) -> None:
    """data at a parameter's path (tables of names, or arrays of tables by name or link)."""
    node, rest = data[path[0]], path[1:]
    if isinstance(node, list):
        node = node[rest[0]] if isinstance(rest[0], int) else next(
            e for e in node if e.get("name", e.get("link")) == rest[0])
        rest = rest[1:]
    for key in rest[:-1]:
        node = node[key]
    node[rest[-1]] = float(value)


def own_run(base: pathlib.Path, study, v: int, text: str | None = None):
    """Variant v built independently: the base scene's TOML with each value set by hand."""
    data = tomllib.loads(base.read_text() if text is None else text)
    for p, value in zip(study.parameters, study.values[v]):
        set_value(data, p.path, value)
    try:
        return linkpipe.solve(parse_scene(tomli_w.dumps(data), str(base)))
    except SceneError:
        return None


def assert_rows_are_own_runs(base, study, status, arrays, variants=None, text=None) -> None:
    for v in range(study.n_variants) if variants is None else variants:
        r = own_run(base, study, v, text)
        if r is None:
            assert (status[v] == NO_ASSEMBLY).all() and np.isnan(arrays["position"][v]).all()
            continue
        stored = {x.name: x.data for x in r.variables() if x.dims[:1] == ("step",)}
        assert stored.keys() == arrays.keys()
        for name, want in stored.items():
            np.testing.assert_allclose(arrays[name][v], want, rtol=1e-12, atol=1e-12,
                                       err_msg=f"variant {v} {name}")


def usable(study):
    """Which variants the vectorised stage 1 keeps (the others are their own runs)."""
    base = vector.base_result(study)
    S = base.n_steps
    rows = vector.per_row_constants(study, base.model, study.slots, study.values, S)
    k = base.kinematics
    return kin.solve_pivot_variants(base.model, pivots.base_chain(study),
                                    rows["start_position"][::S], rows["size"][::S], k.s,
                                    k.s_dot, k.s_ddot, 0, False)[0]


def test_pin_tolerance_study_is_vectorised_and_equals_one_by_one_runs(tmp_path):
    study = load_study(write(tmp_path, PIN_TOLERANCE.format(base=GOAL.as_posix(), samples=12)))
    assert study.path_note.startswith("vectorised: the pivots")
    assert [s[0] for s in study.slots] == ["spring_k", "point"] + ["pivot"] * 4
    assert usable(study).all()  # +-0.5 mm: every variant on the base's branches
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert (status == OK).all()
    assert_rows_are_own_runs(GOAL, study, status, arrays)
    f = read_arrays(run_study(study, tmp_path / "out"))
    np.testing.assert_array_equal(f["peak_handle"][:, 0] if f["peak_handle"].ndim > 1
                                  else f["peak_handle"],
                                  np.abs(arrays["input_force"][:, :, 0]).max(axis=1))


def test_far_moves_and_a_variant_that_cannot_assemble_are_their_own_runs(tmp_path):
    """O4 up to 3 ft down: the parallelogram cannot close (no_assembly rows); O2 0.5 ft
    aside: starts far from the drawing leave the vectorised stage 1 (their own runs)."""
    study = load_study(write(tmp_path, f'[study]\nbase = "{GOAL.as_posix()}"\n'
                             '[study.parameters]\n'
                             '"points.O4.y" = { from = -2.0, to = -5.0, steps = 4 }\n'
                             '"points.O2.x" = { from = -0.5, to = 0.0, steps = 2 }\n'))
    assert study.slots is not None
    keep = usable(study)
    assert keep.any() and not keep.all()
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert (status[-2:] == NO_ASSEMBLY).any(axis=1).all()  # 3 ft down: steps that cannot close
    assert_rows_are_own_runs(GOAL, study, status, arrays)


def test_crank_rocker_pivot_grid_equals_one_by_one_runs(tmp_path):
    study = load_study(write(tmp_path, f'[study]\nbase = "{ROCKER.as_posix()}"\nsamples = 3\n'
                             '[study.parameters]\n'
                             '"points.O4.x" = { from = 3.9, to = 4.1, steps = 3 }\n'
                             '"points.O2.y" = { uniform = [-0.01, 0.01] }\n'))
    assert study.path_note.startswith("vectorised") and usable(study).all()
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert_rows_are_own_runs(ROCKER, study, status, arrays)


def test_derived_lengths_stay_variant_by_variant(tmp_path):
    """A pivot whose link takes its length from the drawing changes the model's rows: variant
    by variant, with the reason in the path note (a link length given in the scene takes the
    vectorised path: tests/test_study_lengths.py)."""
    data = tomllib.loads(ROCKER.read_text())
    del data["links"][2]["lengths"]
    (tmp_path / "rocker.toml").write_text(tomli_w.dumps(data))
    study = load_study(write(tmp_path, '[study]\nbase = "rocker.toml"\n[study.parameters]\n'
                             '"points.O4.x" = { from = 3.9, to = 4.1, steps = 3 }\n'))
    assert study.slots is None and "rows change" in study.path_note


@settings(max_examples=8, deadline=None)
@given(st_h.lists(st_h.floats(-0.02, 0.02), min_size=3, max_size=3), st_h.integers(0, 2**16))
def test_random_small_pivot_moves_equal_one_by_one_runs(tmp_path_factory, moves, seed):
    tmp_path = tmp_path_factory.mktemp("pivots")
    ox, oy, fy = moves
    study = study_of(tmp_path, ROCKER, f'"points.O2.x" = {{ from = {ox!r}, to = {ox!r}, steps = 1 }}\n'
                     f'"points.O2.y" = {{ from = {oy!r}, to = {oy!r}, steps = 1 }}\n'
                     '"points.O4.x" = { uniform = [3.98, 4.02] }\n'
                     f'"points.O4.y" = {{ from = {fy!r}, to = {fy!r}, steps = 1 }}\n',
                     samples=3, seed=seed)
    vectorised_rows_are_own_runs(ROCKER, study)


#: 700 variants of the every-effect basketball goal in one batch (17,500 rows: two chunks of
#: the force stage, several of stage 1 and the derivative stage): the geometry parameters
#: given, with an anchor and force numbers
CHUNK_STUDY = """[study]
base = "goal_every_effect.toml"
samples = 700
seed = {seed}
batch_size = 700
[study.parameters]
{geometry}
"points.S1.x" = {{ uniform = [-0.3, 0.3] }}
"springs.right.damping" = {{ uniform = [0.1, 0.5] }}
"masses.backboard.inertia" = {{ normal = [0.375, 0.01] }}
"loads.hand.force.1" = {{ uniform = [-8.0, -2.0] }}
[study.metrics]
peak_ground = "max(abs(ground_reaction.S1.y))"
"""
#: rows at both ends of the batch and across its chunk boundaries
CHUNK_EDGES = [0, 1, 163, 327, 654, 655, 656, 699]


def chunk_study(tmp_path, seed: int, geometry: str):
    """``(study, status, arrays)`` of :data:`CHUNK_STUDY` with ``geometry`` (its parameter
    lines), its vectorised rows all ok; the study file's metric is checked to be the rows'
    own."""
    (tmp_path / "goal_every_effect.toml").write_text(EVERY_EFFECT)
    study = load_study(write(tmp_path, CHUNK_STUDY.format(seed=seed, geometry=geometry)))
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert (status == OK).all()
    f = read_arrays(run_study(study, tmp_path / "out"))
    np.testing.assert_array_equal(
        f["peak_ground"], np.abs(arrays["ground_reaction"][:, :, 2, 1]).max(axis=1))
    return study, status, arrays


def test_pivots_with_every_effect_and_force_numbers_over_chunk_boundaries(tmp_path):
    """Pivots, an anchor and force numbers at once, every effect on, 700 variants in one batch
    (17,500 rows: two chunks of the force stage, many of the derivative stage): rows at both
    ends and across the chunk boundaries equal their own runs; the study file's metric is
    the rows' own."""
    study, status, arrays = chunk_study(
        tmp_path, 4, '"points.O2.x" = { uniform = [-0.00164, 0.00164] }\n'
                     '"points.O4.y" = { uniform = [-2.00164, -1.99836] }')
    assert study.path_note.startswith("vectorised: the pivots")
    assert_rows_are_own_runs(GOAL, study, status, arrays, CHUNK_EDGES, EVERY_EFFECT)


@pytest.mark.parametrize("table", ["springs"])
def test_force_only_studies_keep_their_path(tmp_path, table):
    study = load_study(write(tmp_path, f'[study]\nbase = "{GOAL.as_posix()}"\n'
                             '[study.parameters]\n'
                             f'"{table}.left.k" = {{ from = 2.0, to = 4.0, steps = 2 }}\n'))
    assert study.path_note.startswith("vectorised: stage 1 solved once")


@pytest.mark.parametrize("config", sorted(p.name for p in (ROOT / "configs").glob("*.toml")))
def test_every_shipped_config_pivot_variants_are_their_own_runs_to_the_bit(tmp_path, config):
    """Each shipped scene's pivots moved by up to 2 mm (3 draws): where the study takes the
    vectorised path, every stored variable equals the variant's own run bit for bit (the
    engine's entries are each variant's own coefficients: linkpipe/kinematics/affine.py)."""
    base = ROOT / "configs" / config
    scene = linkpipe.scene.load_scene(str(base))
    used = {p for link in scene.links for p in link.points}
    lines = "".join(f'"points.{n}.{ax}" = {{ uniform = [{getattr(p, ax) - 0.002!r}, '
                    f'{getattr(p, ax) + 0.002!r}] }}\n'
                    for n, p in zip(scene.point_names, scene.points)
                    if p.fixed and n in used for ax in "xy")
    if scene.time is not None or scene.measurements or not lines:
        pytest.skip("a [time] table, measurements or no pivots")
    study = load_study(write(tmp_path, f'[study]\nbase = "{base.as_posix()}"\nsamples = 3\n'
                             f'seed = 1\n[study.parameters]\n{lines}'))
    if study.slots is None:
        assert "rows change" in study.path_note  # lengths taken from the drawing
        return
    assert usable(study).all()  # every variant on the vectorised rows, none its own run
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    for v in range(study.n_variants):
        r = own_run(base, study, v)
        stored = {x.name: x.data for x in r.variables() if x.dims[:1] == ("step",)}
        assert stored.keys() == arrays.keys()
        for name, want in stored.items():
            np.testing.assert_array_equal(arrays[name][v], want, err_msg=f"variant {v} {name}")


def test_a_preload_holds_at_each_variants_own_assembled_start(tmp_path):
    """The crank-rocker drawn with B a guess and a preloaded spring from the anchor K to B: a
    study moving the anchor takes the vectorised path, each variant's spring measured from the
    assembled start (its own run's, to 1e-12); one moving a pivot solves each variant by its own
    run, the reason said (a spring's start length is each variant's own assembled drawing)."""
    from test_springs import rocker_with_spring

    text = rocker_with_spring((3.0, 2.9), 'k = 2000.0\npreload = 50.0')
    base = write(tmp_path, text, "rocker.toml")
    anchor = study_of(tmp_path, base, '"points.K.x" = { from = 4.0, to = 6.0, steps = 3 }')
    assert anchor.slots is not None and anchor.path_note.startswith("vectorised")
    _, arrays = paths.variant_arrays(anchor, anchor.slots, 0, anchor.n_variants)
    for v, x in enumerate(anchor.values[:, 0]):
        own = linkpipe.solve(parse_scene(text.replace("x = 5.0", f"x = {float(x)!r}"), str(base)))
        assert own.forces["spring_force"][1][0, 0] == pytest.approx(50.0, abs=1e-6)
        np.testing.assert_allclose(arrays["spring_force"][v], own.forces["spring_force"][1],
                                   rtol=1e-12, atol=1e-12)
    pivot = study_of(tmp_path, base, '"points.O4.x" = { from = 3.9, to = 4.1, steps = 3 }')
    assert pivot.slots is None and "assembled drawing" in pivot.path_note


def test_each_variant_takes_its_link_turns_from_its_own_drawing(tmp_path):
    """The rocker drawn along -x (180 deg) with O4 moved 0.01 m up or down: the variants'
    drawn rocker directions fall either side of +-180 deg, and each variant's link angles (and
    the torsion spring on the rocker) take their whole turns from its own drawing, as its own
    run does (the vectorised path took them all from the base's: a turn apart, 2 pi k)."""
    from test_springs import ROCKER_NEAR_HALF_TURN

    text = ROCKER_NEAR_HALF_TURN.format(start=89.0, stop=91.0)
    base = write(tmp_path, text, "rocker.toml")
    study = study_of(tmp_path, base, '"points.O4.y" = { from = -0.01, to = 0.01, steps = 3 }')
    assert study.slots is not None
    _, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    for v, y in enumerate(study.values[:, 0]):
        own = linkpipe.solve(parse_scene(text.replace("O4 = { x = 4.0, y = 0.0",
                                                      f"O4 = {{ x = 4.0, y = {float(y)!r}"), str(base)))
        np.testing.assert_array_equal(arrays["link_angle"][v], own.link_angle)
        np.testing.assert_allclose(arrays["torsion_spring_torque"][v],
                                   own.forces["torsion_spring_torque"][1], rtol=1e-12, atol=1e-12)
    first = arrays["link_angle"][:, 0, 2]  # the rocker at the first step, per variant
    assert first[0] > 0 > first[2]  # the two sides of the half turn: the test can fail
