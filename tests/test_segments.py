"""A sweep solved in segments (linkpipe.segments) writes the file the whole sweep solved at once
writes, to the last bit: every shipped scene cut into segments of a prime number of steps (so
segment edges fall anywhere: in failed runs of steps, across the dyads' chunks and the force
stage's), auto's switch from the dyads to Newton in a later segment, missing log values, torsion
springs wound over several turns. The exact answer is the whole sweep's own file."""
from __future__ import annotations

import dataclasses
import pathlib
import re
import subprocess
import sys

import h5py
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe.kinematics.angles import AngleCarry, unwrap_runs
from linkpipe.memory import memory_needed
from linkpipe.result import Totals, stride_of
from linkpipe.segments import RESTART, segment_steps, segments, steps_per_segment, stream
from linkpipe.stores import hdf5

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "benchmarks"))
from bench_sweep import EFFECTS  # noqa: E402  (every effect on the crank-rocker)

ROOT = pathlib.Path(__file__).resolve().parent.parent
CONFIGS = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "configs" / "hard").glob("*.toml")) \
    + sorted((ROOT / "configs" / "logged").glob("*.toml"))
#: attributes that differ between two runs of one scene by nature (the clock)
CLOCK = re.compile(r"^(created|seconds_.*)$")


def _without_measurements(scene):
    """The scene as streamed: measurements (compared over the whole sweep) dropped."""
    return dataclasses.replace(scene, measurements=())


def _files_equal(a: pathlib.Path, b: pathlib.Path, exact: bool = True) -> None:
    """Every dataset of two files equal bit for bit (NaN where NaN), the same dimension
    scales, and the same root attributes but for the clock's. ``exact=False``: floating-point
    data to rounding instead, 1e-13 of each variable's largest magnitude (a batched solve's
    last few steps take another SIMD path, with other rounding, than the steps before them:
    a step's last bit depends on where a batch cuts the sweep)."""
    with h5py.File(a) as fa, h5py.File(b) as fb:
        assert sorted(fa) == sorted(fb)
        for name in fa:
            da, db = fa[name], fb[name]
            assert da.shape == db.shape and da.dtype == db.dtype, name
            x, y = da[()], db[()]
            if exact or x.dtype.kind != "f":
                np.testing.assert_array_equal(x, y, err_msg=name)
            else:
                # the shipped scenes are metre-sized: a variable that is rounding noise of
                # zero (a residual, a link at rest) compares at 1e-13 of 1 unit
                scale = max(np.abs(x[np.isfinite(x)]).max(initial=0.0), 1.0)
                np.testing.assert_allclose(y, x, rtol=0, atol=1e-13 * scale, err_msg=name)
            assert hdf5.dimensions(da) == hdf5.dimensions(db), name
            assert dict(da.attrs).keys() == dict(db.attrs).keys(), name
        keys = {k for k in fa.attrs if not CLOCK.match(k)}
        assert keys == {k for k in fb.attrs if not CLOCK.match(k)}
        for k in keys:
            if exact or not isinstance(fa.attrs[k], float):
                np.testing.assert_array_equal(fa.attrs[k], fb.attrs[k], err_msg=k)
            else:
                np.testing.assert_allclose(fb.attrs[k], fa.attrs[k], rtol=0, atol=1e-13,
                                           err_msg=k)


def _streamed(scene, path, segment, max_steps=None):
    with hdf5.SweepWriter(path, scene.n_steps) as writer:
        plan = None if max_steps is None else (
            lambda part, n_steps: (stride_of(n_steps, max_steps), f"--rrd-max-steps {max_steps:,}"))
        return stream(scene, [writer], recording=plan, segment=segment)


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_segments_write_the_whole_sweeps_file(config, tmp_path):
    """Segments of 7 steps (a prime: they cut the sweep anywhere) write the file of the sweep
    solved at once: bit for bit on the closed-form dyads (every step on its own), to rounding
    on the general path (its batched solves: :func:`_files_equal`)."""
    scene = _without_measurements(linkpipe.load_scene(config))
    whole = linkpipe.solve(scene)
    hdf5.write(whole, tmp_path / "whole.h5")
    kept = _streamed(scene, tmp_path / "segments.h5", segment=7, max_steps=10)
    exact = whole.solver_method_used == "dyads"
    _files_equal(tmp_path / "whole.h5", tmp_path / "segments.h5", exact)
    if exact:
        assert _totals_equal(kept.totals, Totals.of(whole))
    assert kept.totals.status_counts == Totals.of(whole).status_counts
    # the rows the recording keeps: every stride-th step of the whole sweep, as they are there
    stride = -(-scene.n_steps // 10)
    rows = np.arange(0, scene.n_steps, stride)
    np.testing.assert_array_equal(kept.step_numbers, rows)
    np.testing.assert_array_equal(kept.position, whole.position[rows])
    np.testing.assert_array_equal(kept.status, whole.status[rows])
    for name, (dims, data, _) in (whole.forces or {}).items():
        expected = data[rows] if dims[:1] == ("step",) else data
        if exact:
            np.testing.assert_array_equal(kept.forces[name][1], expected, err_msg=name)
        else:
            np.testing.assert_allclose(kept.forces[name][1], expected, rtol=1e-12,
                                       atol=1e-13 * np.abs(expected[np.isfinite(expected)]).max(initial=1.0),
                                       err_msg=name)
    assert kept.sampled == ((stride, "--rrd-max-steps 10") if stride > 1 else None)
    assert kept.solver_method_used == whole.solver_method_used
    assert kept.solver_note == whole.solver_note


def _totals_equal(a: Totals, b: Totals) -> bool:
    for f in dataclasses.fields(Totals):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if x is None or y is None:
            assert x is y, f.name
        else:
            np.testing.assert_array_equal(x, y, err_msg=f.name)
    return True


def test_auto_leaves_the_dyads_in_a_later_segment_and_starts_again(tmp_path):
    """The extended basketball goal passes a dyad's singular shape late in its sweep: solved at
    once, auto takes Newton for the whole sweep. In segments, the first ones pass the dyads'
    branch check, a later one fails it: the sweep starts again on Newton and the file is the
    whole sweep's."""
    scene = linkpipe.load_scene(ROOT / "configs" / "hard" / "basketball_goal_extended.toml")
    parts = list(segments(scene, 7, {}))
    restart = next(i for i, p in enumerate(parts) if p is RESTART)
    assert restart >= 1 and all(p.solver_method_used == "dyads" for p in parts[:restart])
    assert all(p.solver_method_used == "newton" for p in parts[restart + 1:])
    assert sum(p.n_steps for p in parts[restart + 1:]) == scene.n_steps
    hdf5.write(linkpipe.solve(scene), tmp_path / "whole.h5")
    _streamed(scene, tmp_path / "segments.h5", segment=7)
    _files_equal(tmp_path / "whole.h5", tmp_path / "segments.h5", exact=False)


def test_segments_of_run_size_are_bit_for_bit_on_the_general_path(tmp_path):
    """Segments as ``run`` makes them (a power of two, holding whole chunks of every stage)
    agree with the whole sweep to the last bit on the general path too: the crank-rocker with
    every effect, solved by Newton, 40,001 steps in segments of 16,384."""
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    text = re.sub(r"steps = \d+", "steps = 40001", text)
    text = text.replace("[solver]", '[solver]\nmethod = "newton"') if "[solver]" in text else (
        text + '\n[solver]\nmethod = "newton"\n')
    scene = linkpipe.parse_scene(text + EFFECTS, "newton.toml")
    assert segment_steps(scene) % 16384 == 0
    whole = linkpipe.solve(scene)
    assert whole.solver_method_used == "newton" and whole.forces
    hdf5.write(whole, tmp_path / "whole.h5")
    _streamed(scene, tmp_path / "segments.h5", segment=16384)
    _files_equal(tmp_path / "whole.h5", tmp_path / "segments.h5")



TORSION = """
[analysis]
effects = ["springs"]

[[torsion_springs]]
name = "wind"
links = ["crank", "ground"]
k = 2.5
free_angle = 0.0
"""


def _crank_turns(steps: int, turns: int):
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    text = re.sub(r"steps = \d+", f"steps = {steps}", text.split("[outputs]")[0])
    text = text.replace("to = 360.0", f"to = {360.0 * turns}")
    return linkpipe.parse_scene(text + TORSION, "wound.toml")


def test_torsion_spring_winds_continuously_over_chunks_and_segments(tmp_path):
    """Three crank turns against a torsion spring to ground: its angle is the crank's angle,
    continuous (it once jumped by 2 pi at every 16,384-step chunk of the force stage); the
    torque k * angle; energy's derivative the input torque. Solved in segments, the same file."""
    scene = _crank_turns(40_001, 3)
    r = linkpipe.solve(scene)
    angle = r.forces["torsion_spring_angle"][1][:, 0]
    crank = np.deg2rad(r.driver_value[:, 0])
    # the crank's direction from its positions: to rounding of atan2 and the unwrap (1e-14 rad
    # per step over 3 turns: 1e-12)
    np.testing.assert_allclose(angle, crank, rtol=0, atol=1e-12)
    assert angle[-1] == pytest.approx(6 * np.pi, abs=1e-12)
    np.testing.assert_allclose(r.forces["torsion_spring_torque"][1][:, 0], 2.5 * angle,
                               rtol=0, atol=1e-12)
    hdf5.write(r, tmp_path / "whole.h5")
    _streamed(scene, tmp_path / "segments.h5", segment=8192)
    _files_equal(tmp_path / "whole.h5", tmp_path / "segments.h5")


def test_missing_log_values_in_segments(tmp_path):
    """The crank-encoder log with a missing sample: the no_input step and its neighbours are
    the whole sweep's (the dyads' branch margins carried over the gap and over the segment
    edges)."""
    scene = _without_measurements(linkpipe.load_scene(ROOT / "configs" / "fourbar_crank_encoder.toml"))
    whole = linkpipe.solve(scene)
    assert "no_input" in whole.status_counts()
    hdf5.write(whole, tmp_path / "whole.h5")
    for segment in (1, 2, 13, 200):
        _streamed(scene, tmp_path / f"s{segment}.h5", segment=segment)
        _files_equal(tmp_path / "whole.h5", tmp_path / f"s{segment}.h5")


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), S=st.integers(1, 80), L=st.integers(1, 3),
       gap=st.floats(0.0, 0.7), cut=st.integers(1, 30))
def test_unwrap_in_segments_equals_numpy_unwrap_of_the_whole(seed, S, L, gap, cut):
    """``unwrap_runs`` equals ``np.unwrap`` of the whole (gaps filled as the pipeline fills them)
    to the last bit, whole or in segments of ``cut`` steps carried one to the next."""
    rng = np.random.default_rng(seed)
    ang = np.angle(np.exp(1j * np.cumsum(rng.normal(scale=1.5, size=(S, L)), axis=0)))
    whole, _ = unwrap_runs(ang)
    np.testing.assert_array_equal(whole, np.unwrap(ang, axis=0))
    ang[rng.uniform(size=(S, L)) < gap] = np.nan
    whole, _ = unwrap_runs(ang)
    carry, parts = AngleCarry.start(L), []
    for lo in range(0, S, cut):
        part, carry = unwrap_runs(ang[lo:lo + cut], carry)
        parts.append(part)
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    for j in range(L):  # each link's finite angles: numpy's unwrap of them alone
        fin = np.isfinite(ang[:, j])
        np.testing.assert_array_equal(whole[fin, j], np.unwrap(ang[fin, j]))
        assert np.isnan(whole[~fin, j]).all()


def test_segment_size_and_memory_estimate():
    """Segments are powers of two from 16,384 to 131,072 steps; the memory estimate of a
    segmented run grows with the sweep only by what stays whole (driver motion, Newton's
    positions), a whole run's by every stored array."""
    small, large = _crank_turns(200_001, 1), _crank_turns(2_000_001, 1)
    seg = steps_per_segment(large)
    assert seg & (seg - 1) == 0 and 2**14 <= seg <= 2**17
    per_step_whole = (memory_needed(large) - memory_needed(small)) / 1_800_000
    per_step_segmented = (memory_needed(large, seg) - memory_needed(small, seg)) / 1_800_000
    assert per_step_segmented < 0.5 * per_step_whole
    short = _crank_turns(1001, 1)
    assert steps_per_segment(short) == short.n_steps


def test_run_streams_a_long_sweep_to_the_whole_sweeps_file_and_a_strided_recording(tmp_path, capsys):
    """``python -m linkpipe run`` on a sweep of several segments (the crank-rocker with every
    effect, 100,001 steps, segments of 32,768): the .h5 is the whole sweep's, bit for bit; the
    recording keeps every 51st step (--rrd-max-steps 2,000) on the sweep's own step numbers,
    verifies, and the summary says so; the summary's totals are the whole sweep's."""
    from rerun.chunk import RrdReader

    from linkpipe.__main__ import main

    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    path = tmp_path / "long.toml"
    path.write_text(re.sub(r"steps = \d+", "steps = 100001", text).replace(
        'name = "fourbar_crank_rocker"', 'name = "long"') + EFFECTS)
    scene = linkpipe.load_scene(path)
    assert 100_001 > steps_per_segment(scene) >= 16384
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--rrd-max-steps", "2000"]) == 0
    printed = capsys.readouterr().out
    whole = linkpipe.solve(scene)
    hdf5.write(whole, tmp_path / "whole.h5")
    _files_equal(tmp_path / "whole.h5", tmp_path / "out" / "long.h5")
    assert f"long: {whole.message} (100001 steps, 100001 ok, 0 failed)" in printed
    assert "recording: every 51st step (1,961 of 100,001; --rrd-max-steps 2,000)" in printed
    lo, hi = np.nanmin(whole.forces["input_force"][1]), np.nanmax(whole.forces["input_force"][1])
    assert f"input force crank: {lo:.6g} .. {hi:.6g}" in printed
    rrd = tmp_path / "out" / "long.rrd"
    verify = subprocess.run([str(pathlib.Path(sys.executable).with_name("rerun")), "rrd", "verify",
                             str(rrd)], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    store = RrdReader(rrd).stream().collect()
    df = store.reader(index="step", contents="/solver/residual").to_pandas()
    steps = df["step"].to_numpy()[df["/solver/residual:Scalars:scalars"].notna().to_numpy()]
    np.testing.assert_array_equal(np.sort(steps.astype(np.int64)), np.arange(0, 100_001, 51))


def _double_parallelogram_logged() -> str:
    """configs/hard/double_parallelogram.toml (one redundant constraint, every force effect)
    driven by the log dp.csv (column ang, degrees) instead of its sweep."""
    text = (ROOT / "configs" / "hard" / "double_parallelogram.toml").read_text()
    head, rest = text.split("[[drivers]]", 1)
    tail = rest[rest.index("[analysis]"):]
    return (head + '[time]\nlog = "rig"\n\n[[logs]]\nname = "rig"\nfile = "dp.csv"\n'
            'time = "t"\n\n[[drivers]]\nname = "crank"\nangle = ["O2", "A"]\n'
            'log = "rig.ang"\n\n' + tail)


def test_flags_that_only_later_segments_give(tmp_path):
    """A redundant double parallelogram driven by a log whose first 40 samples are missing:
    segments of 16 steps without an ok step give no ``*_unique`` flags; the later ones do.
    The file holds them as the whole sweep's (the minimum over the segments that give them),
    and the kept rows' forces list them for the summary."""
    t = np.arange(100) * 0.01
    angle = np.where(np.arange(100) < 40, np.nan, 30.0 * np.sin(2 * np.pi * t))
    (tmp_path / "dp.csv").write_text("t,ang\n" + "".join(
        f"{ti:.6f},{'' if np.isnan(a) else repr(float(a))}\n" for ti, a in zip(t, angle)))
    (tmp_path / "dpl.toml").write_text(_double_parallelogram_logged())
    scene = linkpipe.load_scene(tmp_path / "dpl.toml")
    whole = linkpipe.solve(scene)
    assert whole.status_counts() == {"ok": 60, "no_input": 40}
    assert "link_force_unique" in whole.forces and whole.forces_not_unique()
    parts = list(segments(scene, 16, {}))
    assert "link_force_unique" not in parts[0].forces and "link_force_unique" in parts[-1].forces
    hdf5.write(whole, tmp_path / "whole.h5")
    kept = _streamed(scene, tmp_path / "segments.h5", segment=16, max_steps=10)
    _files_equal(tmp_path / "whole.h5", tmp_path / "segments.h5", exact=False)
    assert kept.forces_not_unique() == whole.forces_not_unique()


def test_the_writer_takes_consecutive_steps_only_and_every_one(tmp_path):
    """A part that skips steps, or a finish before the last step, is refused and no file is
    published (a half-written file would read as ok steps of zeros)."""
    r = linkpipe.solve(str(ROOT / "configs" / "fourbar_crank_rocker.toml"))
    first = dataclasses.replace(r.strided(np.arange(100)), sweep_totals=None)
    gap = dataclasses.replace(r.strided(np.arange(150, 160)), sweep_totals=None)
    with pytest.raises(ValueError, match="next consecutive steps from 100"):
        with hdf5.SweepWriter(tmp_path / "x.h5", r.n_steps) as writer:
            writer.add(first)
            writer.add(gap)
    with pytest.raises(ValueError, match="steps 0 .. 99 of 361"):
        with hdf5.SweepWriter(tmp_path / "x.h5", r.n_steps) as writer:
            writer.add(first)
            writer.finish(r)
    assert list(tmp_path.iterdir()) == []


def test_totals_keep_the_first_non_finite_step_counted_over_the_whole_sweep():
    """Segments merged in step order: the first non_finite step is the earliest segment's,
    numbered from the sweep's first step (a later segment's own index + the steps before it),
    with what that segment found there."""
    from linkpipe.result import Totals

    def part(n, first=-1, causes=(), there=()):
        return Totals(n, (n, 0, 0, 0, 0, 0, 0), 0.0, 0.0, 0, 0, first_non_finite=first,
                      non_finite_causes=causes, non_finite_there=there)

    clean, late = part(100), part(50, 7, ("cause b",), ("spring_force[b]",))
    early = part(80, 3, ("cause a",), ("spring_force[a]",))
    merged = clean.merged(late)
    assert (merged.first_non_finite, merged.non_finite_causes, merged.non_finite_there) == (
        107, ("cause b",), ("spring_force[b]",))
    merged = clean.merged(early).merged(late)
    assert (merged.first_non_finite, merged.non_finite_there) == (103, ("spring_force[a]",))
    assert clean.merged(clean).first_non_finite == -1
