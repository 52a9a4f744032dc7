"""Studies that change link lengths (``links.<name>.lengths.<first>-<second>``) on the vectorised
path: each batch's model constants built at once (linkpipe/model/rows.py: variant_rows), the
dyads' constants from them (linkpipe/kinematics/decompose.py: chain_at), stage 1, the
derivative stage and the force stage on V x S rows. Every stored variable of every variant
equals its own one-by-one run (the scene's TOML edited by hand, parsed and solved by
``linkpipe.solve``), bit for bit where the vectorised rows hold it; variants that cannot
assemble or leave the base's branches are their own runs, put in place."""
import pathlib
import tomllib

import numpy as np
import pytest
import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st_h

import linkpipe
import linkpipe.kinematics as kin
from linkpipe.kinematics.decompose import bodies_of, chain_at
from linkpipe.model import build_model
from linkpipe.model.rows import variant_rows
from linkpipe.status import NO_ASSEMBLY, OK
from linkpipe.stores.study import read_arrays
from linkpipe.study import load_study, run_study
from linkpipe.study import paths, pivots, vector
from test_study import EVERY_EFFECT
from test_study_pivots import (CHUNK_EDGES, assert_rows_are_own_runs, chunk_study, own_run, study_of,
                               vectorised_rows_are_own_runs, write)

ROOT = pathlib.Path(__file__).resolve().parents[1]
GOAL = ROOT / "configs" / "basketball_goal.toml"
ROCKER = ROOT / "configs" / "fourbar_crank_rocker.toml"
TOLERANCE = ROOT / "configs" / "studies" / "basketball_goal_tolerance.toml"


def usable(study, values=None):
    """Which variants the vectorised stage 1 keeps (the others are their own runs)."""
    values = study.values if values is None else values
    base = vector.base_result(study)
    S = base.n_steps
    rows = vector.per_row_constants(study, base.model, study.slots, values, S)
    chain, model_rows, alike = pivots.variant_model(study, study.slots, values)
    k = base.kinematics
    return alike & kin.solve_pivot_variants(base.model, chain, rows["start_position"][::S],
                                            rows["size"][::S], k.s, k.s_dot, k.s_ddot, 0, False,
                                            model_rows)[0]


def assert_bitwise_own_runs(base, study, arrays, variants, text=None) -> None:
    """Every stored variable of the variants equals its own run's to the last bit."""
    for v in variants:
        r = own_run(base, study, v, text)
        stored = {x.name: x.data for x in r.variables() if x.dims[:1] == ("step",)}
        assert stored.keys() == arrays.keys()
        for name, want in stored.items():
            np.testing.assert_array_equal(arrays[name][v], want, err_msg=f"variant {v} {name}")


def tolerance_study(tmp_path, samples: int):
    """The shipped tolerance study (pins and link lengths within +-0.5 mm), fewer samples."""
    text = TOLERANCE.read_text().replace("samples = 1000", f"samples = {samples}")
    return load_study(write(tmp_path, text.replace('base = "../basketball_goal.toml"',
                                                   f'base = "{GOAL.as_posix()}"')))


def test_the_shipped_tolerance_study_is_vectorised_and_equals_one_by_one_runs_to_the_bit(tmp_path):
    study = tolerance_study(tmp_path, 16)
    assert study.path_note.startswith("vectorised: the link lengths as per-row constants and "
                                      "the pivots")
    assert [s[0] for s in study.slots] == (["spring_k", "point"] + ["pivot"] * 4
                                           + ["length"] * 3)
    assert usable(study).all()  # +-0.5 mm: every variant on the vectorised rows
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert (status == OK).all()
    assert_bitwise_own_runs(GOAL, study, arrays, range(study.n_variants))
    f = read_arrays(run_study(study, tmp_path / "out"))
    np.testing.assert_array_equal(f["peak_handle"],
                                  np.abs(arrays["input_force"][:, :, 0]).max(axis=1))


def test_the_shipped_tolerance_study_file_takes_the_vectorised_path():
    study = load_study(TOLERANCE)
    assert study.n_variants == 1000 and study.slots is not None
    assert "link lengths as per-row constants" in study.path_note


def test_lengths_that_cannot_close_or_leave_the_branches_are_their_own_runs(tmp_path):
    """The lower link from 1 to 3 ft against a 2 ft upper link: the parallelogram cannot close
    over the whole travel at the ends (no_assembly steps), and variants far from the drawing
    start elsewhere: their own runs, put in place; the rest vectorised."""
    study = load_study(write(tmp_path, f'[study]\nbase = "{GOAL.as_posix()}"\n'
                             '[study.parameters]\n'
                             '"links.lower.lengths.O4-C" = { from = 1.0, to = 3.0, steps = 9 }\n'
                             '"links.backboard.lengths.B-C" = { from = 0.5, to = 1.0, steps = 3 }\n'))
    assert study.slots is not None
    keep = usable(study)
    assert keep.any() and not keep.all()
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert (status == NO_ASSEMBLY).any()
    assert_rows_are_own_runs(GOAL, study, status, arrays)
    assert_bitwise_own_runs(GOAL, study, arrays, np.flatnonzero(keep))


def test_crank_rocker_link_length_grid_equals_one_by_one_runs_to_the_bit(tmp_path):
    """Every link of the crank-rocker (crank, coupler with its coupler point, rocker), 361
    steps: velocities and accelerations of the dyads, no forces."""
    study = load_study(write(tmp_path, f'[study]\nbase = "{ROCKER.as_posix()}"\nsamples = 2\n'
                             '[study.parameters]\n'
                             '"links.coupler.lengths.A-B" = { from = 3.45, to = 3.55, steps = 3 }\n'
                             '"links.rocker.lengths.O4-B" = { from = 2.98, to = 3.02, steps = 2 }\n'
                             '"links.crank.lengths.O2-A" = { uniform = [0.99, 1.01] }\n'
                             '"points.O4.x" = { uniform = [3.99, 4.01] }\n'))
    assert study.path_note.startswith("vectorised: the link lengths")
    assert usable(study).all()
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    assert_bitwise_own_runs(ROCKER, study, arrays, range(study.n_variants))


def test_lengths_taken_from_the_drawing_stay_variant_by_variant(tmp_path):
    """A pivot whose link takes its length from the drawing changes the model's rows: variant
    by variant, with the reason in the path note (a moving point's drawn coordinate, which
    changes them too, takes the vectorised path: tests/test_study_plates.py)."""
    data = tomllib.loads(ROCKER.read_text())
    del data["links"][2]["lengths"]
    (tmp_path / "rocker.toml").write_text(tomli_w.dumps(data))
    study = load_study(write(tmp_path, '[study]\nbase = "rocker.toml"\n[study.parameters]\n'
                             '"points.O4.x" = { from = 3.9, to = 4.1, steps = 3 }\n'))
    assert study.slots is None and "rows change" in study.path_note
    study = load_study(write(tmp_path, '[study]\nbase = "rocker.toml"\n[study.parameters]\n'
                             '"points.B.x" = { from = 3.0, to = 3.1, steps = 3 }\n'))
    assert study.slots is not None and "drawn coordinates" in study.path_note


def test_lengths_with_every_effect_over_chunk_boundaries(tmp_path):
    """Link lengths, pivots, an anchor and force numbers at once, every effect on (the mass
    centre's frame on a link whose length varies), 700 variants in one batch (17,500 rows:
    two chunks of the force stage, several of stage 1): rows at both ends and across the
    chunk boundaries equal their own runs to the bit."""
    study, status, arrays = chunk_study(
        tmp_path, 5, '"links.backboard.lengths.B-C" = { uniform = [0.99, 1.01] }\n'
                     '"links.upper.lengths.O2-B" = { uniform = [1.998, 2.002] }\n'
                     '"points.O4.y" = { uniform = [-2.00164, -1.99836] }')
    assert study.path_note.startswith("vectorised: the link lengths")
    assert_bitwise_own_runs(GOAL, study, arrays, CHUNK_EDGES, EVERY_EFFECT)


def test_variant_rows_and_dyads_are_each_variants_own_model():
    """The model's rows and dyad constants built for V variants at once equal those each
    variant's own scene builds (build_model, decompose), number for number."""
    base = build_model(linkpipe.load_scene(str(ROCKER)))
    lengths = {"coupler": np.array([3.4, 3.5, 3.61]), "crank": np.array([0.9, 1.0, 1.1])}
    rows, ok = variant_rows(base, lengths)
    assert ok.all()
    chain = kin.decompose(base)
    chain_v, same = chain_at(chain, bodies_of(base, rows))
    assert same.all()
    data = tomllib.loads(ROCKER.read_text())
    for v in range(3):
        data["links"][0]["lengths"]["O2-A"] = float(lengths["crank"][v])
        data["links"][1]["lengths"]["A-B"] = float(lengths["coupler"][v])
        assert_variant_is_own_model(rows, chain_v, v, build_model(
            linkpipe.scene.parse_scene(tomli_w.dumps(data), str(ROCKER))))


@pytest.mark.parametrize("config", sorted(p.name for p in (ROOT / "configs").glob("*.toml")))
def test_every_shipped_config_link_length_variants_are_their_own_runs_to_the_bit(tmp_path, config):
    """Each shipped scene with every link's frame length given (as drawn where the scene does
    not give it) and varied by up to 0.1 % (3 draws): where the study takes the vectorised
    path, every stored variable equals the variant's own run bit for bit."""
    scene = linkpipe.scene.load_scene(str(ROOT / "configs" / config))
    if scene.time is not None or scene.measurements:
        pytest.skip("a [time] table or measurements")
    data = tomllib.loads(scene.text)
    model = build_model(scene)
    fixed = dict(zip(scene.point_names, (p.fixed for p in scene.points)))
    lines = ""
    for entry, link in zip(data["links"], scene.links):
        a, b = link.points[:2]
        if fixed[a] and fixed[b]:
            continue
        pair = next((key for key in entry.get("lengths", {}) if key in (f"{a}-{b}", f"{b}-{a}")),
                    f"{a}-{b}")
        ia, ib = scene.point_names.index(a), scene.point_names.index(b)
        length = link.length if link.length is not None else float(
            np.hypot(*(model.start_position[ib] - model.start_position[ia])))
        entry.setdefault("lengths", {})[pair] = length
        lines += (f'"links.{link.name}.lengths.{pair}" = {{ uniform = [{length * 0.999!r}, '
                  f'{length * 1.001!r}] }}\n')
    base = tmp_path / config
    base.write_text(tomli_w.dumps(data))
    study = load_study(write(tmp_path, f'[study]\nbase = "{base.as_posix()}"\nsamples = 3\n'
                             f'seed = 2\n[study.parameters]\n{lines}', "study.toml"))
    if study.slots is None:
        assert study.path_note.startswith("variant by variant: ")
        pytest.skip(study.path_note)
    status, arrays = paths.variant_arrays(study, study.slots, 0, study.n_variants)
    keep = usable(study)
    assert_rows_are_own_runs(base, study, status, arrays)
    assert_bitwise_own_runs(base, study, arrays, np.flatnonzero(keep))


def assert_variant_is_own_model(rows, chain, v: int, own) -> None:
    """Variant ``v`` of the model's rows and dyads built for V variants at once (``rows``,
    ``chain``) equals the model its own scene builds (``own``) and its dyads, number for
    number."""
    assert rows.take(v) == own.rows
    for mine, theirs in zip(chain.take(v).steps, kin.decompose(own).steps):
        assert (mine.kind, mine.targets, mine.w, mine.ab, mine.r1, mine.r2) == (
            theirs.kind, theirs.targets, theirs.w, theirs.ab, theirs.r1, theirs.r2)


@settings(max_examples=8, deadline=None)
@given(st_h.lists(st_h.floats(-0.05, 0.05), min_size=3, max_size=3), st_h.integers(0, 2**16))
def test_random_link_lengths_equal_one_by_one_runs(tmp_path_factory, moves, seed):
    tmp_path = tmp_path_factory.mktemp("lengths")
    crank, coupler, rocker = moves
    study = study_of(tmp_path, ROCKER,
                     f'"links.crank.lengths.O2-A" = {{ from = {1 + crank!r}, to = '
                     f'{1 + crank!r}, steps = 1 }}\n'
                     f'"links.coupler.lengths.A-B" = {{ uniform = [{3.5 + coupler!r}, '
                     f'{3.55 + coupler!r}] }}\n'
                     f'"links.rocker.lengths.O4-B" = {{ from = {3 + rocker!r}, to = '
                     f'{3 + rocker!r}, steps = 1 }}\n', samples=3, seed=seed)
    _, arrays = vectorised_rows_are_own_runs(ROCKER, study)
    assert_bitwise_own_runs(ROCKER, study, arrays, np.flatnonzero(usable(study)))


def test_the_batch_rows_equal_the_variant_by_variant_paths(tmp_path):
    """The study file's rows of a batch (every metric) on the vectorised path and on the same
    study forced variant by variant (each variant's scene parsed and solved): equal."""
    import dataclasses

    from linkpipe.study.batch import solve_batch

    study = tolerance_study(tmp_path, 6)
    fast = solve_batch(study, 0, 6)
    slow = solve_batch(dataclasses.replace(study, slots=None), 0, 6)
    assert fast.keys() == slow.keys()
    for name in fast:
        np.testing.assert_array_equal(fast[name], slow[name], err_msg=name)
