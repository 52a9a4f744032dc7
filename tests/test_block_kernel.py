"""The compiled exact condition (:mod:`linkpipe.kinematics.block_kernel`) is the numpy path's,
bit for bit.

``Engine.condition(E)`` without an inverse (the 1-norm's column sums and the inverse's column
sums by block solves, numpy) is the independent method; the compiled loop repeats its
arithmetic in its order, so the answer is exact equality (``assert_array_equal``: the same
finite numbers to the last bit, inf at the same steps), from the entries and from the positions
(the entries then made in the loop from the engine's affine terms), by the engine's own
(written) loop and by the general loop, with their 1-norms and column sums too, on:

* every shipped scene with an engine, at its own sweep and at random shapes;
* hypothesis-drawn four-bars and slider-cranks of any link lengths (non-Grashof ones reach
  their limits: toggle steps and steps beyond reach), with exactly singular steps (two points
  coincident, every point at the origin: a zero determinant), steps one ulp from those, and
  NaN and inf coordinates;
* a relative angle driver (its entries by numpy, then the loop);
* ``kin.derivatives(..., compiled=True)`` (and given the drivers' cos and sin, as the dyads
  have them; on four worker threads) against ``compiled=False``: every returned array.
"""
import pathlib
import sys

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

import linkpipe
from linkpipe import kinematics as kin
from linkpipe.kinematics import block_kernel
from linkpipe.kinematics.sparse import engine
from linkpipe.model import build_model

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "hard"))
import hard_scenes as hs  # noqa: E402

CONFIGS = [c for c in sorted((ROOT / "configs").rglob("*.toml")) if "studies" not in c.parts]


def _same_condition(eng, X, s):
    """Assert the compiled condition, from the entries, from the positions and given the
    drivers' cos and sin, by the engine's own loop and by the general loop, equals
    ``Engine.condition`` at positions X (S, P, 2), driver values s (S, nd), and the loops' 1-norm
    and column sums equal ``Engine.norm1`` and ``Engine.inverse_column_sums``; return it."""
    with np.errstate(all="ignore"):  # inf and NaN coordinates: numpy's entries warn
        E = eng.entries_of(X, s)
        ref = eng.condition(E)
        norm1, sums = eng.norm1(E), eng.inverse_column_sums(E)
    for loop in ("own", "general"):
        own = block_kernel._own_loop
        if loop == "general":  # as where the own loop cannot be written
            block_kernel._own_loop = lambda *args: None
        try:
            with np.errstate(all="ignore"):  # numpy's entries of a relative angle row
                from_entries = block_kernel.condition(eng, E)
                from_positions = block_kernel.parts(eng, None, X, s)
                with_trig = block_kernel.condition(eng, None, X, s, _trig(eng, s))
        finally:
            block_kernel._own_loop = own
        np.testing.assert_array_equal(from_entries, ref, err_msg=loop)
        np.testing.assert_array_equal(from_positions[0], ref, err_msg=loop)
        np.testing.assert_array_equal(with_trig, ref, err_msg=loop)  # the caller's cos, sin
        np.testing.assert_array_equal(from_positions[1], norm1, err_msg=loop)  # the parts too
        np.testing.assert_array_equal(from_positions[2], sums, err_msg=loop)   # (NaN as numpy's)
    return ref


def _trig(eng, s):
    """{angle driver: (cos, sin)} of s's columns, as a caller (the dyads) computes them."""
    return {int(j): (np.cos(s[:, j]), np.sin(s[:, j])) for j in eng.angle}


def _sweep(model):
    """The scene's own sweep: positions (NaN where it failed), driver values and rates."""
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    return kin.solve_sweep(model, s, s_dot, s_ddot, order=2), s, s_dot, s_ddot


def _degenerate(model, X, rng):
    """X with its steps changed into exactly singular ones (two moving points made
    coincident, or every point at the origin), steps one ulp from those, and NaN and inf
    coordinates, every fourth step left as it was."""
    X = X.copy()
    S = len(X)
    moving = np.flatnonzero(~model.fixed)
    for i in range(S):
        kind = i % 8
        p, q = rng.choice(model.n_points, 2, replace=False)
        if kind == 1:  # a moving point onto another point: a zero row of a distance's entries
            X[i, moving[i % len(moving)]] = X[i, q if q != moving[i % len(moving)] else p]
        elif kind == 2:  # one ulp away from it
            a = moving[i % len(moving)]
            X[i, a] = np.nextafter(X[i, q if q != a else p], np.inf)
        elif kind == 3:
            X[i] = 0.0
        elif kind == 4:
            X[i] = np.nextafter(0.0, 1.0) * (1 + np.arange(2 * model.n_points)).reshape(-1, 2)
        elif kind == 5:
            X[i, moving[i % len(moving)], i % 2] = np.nan
        elif kind == 6:
            X[i, moving[i % len(moving)], i % 2] = np.inf
    return X


def test_the_crank_rocker_takes_the_loop():
    """The shipped crank-rocker's engine has 2x2 and 1x1 blocks only (the loop's case); a
    4x4 block (the dump truck's) keeps numpy."""
    configs = ROOT / "configs"
    rocker = engine(build_model(linkpipe.load_scene(configs / "fourbar_crank_rocker.toml")))
    truck = engine(build_model(linkpipe.load_scene(configs / "dump_truck.toml")))
    assert block_kernel.supported(rocker) and block_kernel.tables(rocker).fused
    assert sorted(len(b[1]) for b in rocker.blocks) == [1, 1, 2, 2]
    assert not block_kernel.supported(truck) and max(len(b[1]) for b in truck.blocks) == 4


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: f"{p.parent.name}-{p.stem}")
def test_every_shipped_scene_bit_for_bit(config):
    model = build_model(linkpipe.load_scene(config))
    eng = engine(model)
    if eng is None or not block_kernel.supported(eng):
        pytest.skip("no engine, or a diagonal block larger than 2x2: the numpy path")
    sweep, s, _, _ = _sweep(model)
    X = sweep.position
    ref = _same_condition(eng, X, s)
    ok = np.isfinite(X).all(axis=(1, 2)) & np.isfinite(s).all(axis=1)
    assert np.isfinite(ref[ok]).mean() > 0.9  # the sweep's own steps: mostly regular
    rng = np.random.default_rng(11)
    q = rng.normal(size=(64, model.n_q)) * model.size  # any shape, not assembled
    s_any = rng.uniform(-4, 4, size=(64, model.n_drivers))
    _same_condition(eng, model.positions(q), s_any)
    bad = _same_condition(eng, _degenerate(model, np.where(np.isfinite(X), X, 0.0), rng), s)
    assert np.isinf(bad[3::8]).all()  # every point at the origin: singular


def _assembles(kind, a, b, c, d, start) -> bool:
    """The drawn lengths close at the start angle, with a margin (a four-bar: A to O4 between
    |b - c| and b + c; a slider-crank: the rod reaches the guide y = c - 2)."""
    th = np.deg2rad(start)
    A = a * np.array([np.cos(th), np.sin(th)])
    if kind == "fourbar":
        r = np.hypot(A[0] - d, A[1])
        return abs(b - c) + 1e-3 < r < b + c - 1e-3
    return abs(A[1] - (c - 2.0)) < b - 1e-3


def test_an_engines_own_loop_is_written_once_and_else_the_general_loop_serves(tmp_path,
                                                                             monkeypatch):
    """The own loop's source is written once under OWN_FOLDER (the same text keeps its file,
    so numba's cache of it stays valid) and gives Engine.condition's numbers; where it cannot
    be written, no own loop: the general loop's numbers, the same."""
    model = build_model(linkpipe.load_scene(ROOT / "configs" / "jansen.toml"))
    eng = engine(model)
    t = block_kernel.tables(eng)
    monkeypatch.setattr(block_kernel, "_OWN", {})
    monkeypatch.setattr(block_kernel, "OWN_FOLDER", tmp_path / "kernels")
    own = block_kernel._own_compiled(t, len(eng.angle), False)
    (path,) = (tmp_path / "kernels").glob("block_*.py")
    stamp = path.stat().st_mtime_ns
    monkeypatch.setattr(block_kernel, "_OWN", {})
    assert block_kernel._own_compiled(t, len(eng.angle), False) is not None
    assert path.stat().st_mtime_ns == stamp and len(list(path.parent.glob("*.py"))) == 1
    sweep, s, _, _ = _sweep(model)
    X = sweep.position
    cos, sin = np.cos(s.T[eng.angle]), np.sin(s.T[eng.angle])
    out = np.empty(len(s))
    own(X, cos, sin, t.t_c, t.c0, out)
    np.testing.assert_array_equal(out, eng.condition(eng.entries_of(X, s)))
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(block_kernel, "_OWN", {})
    monkeypatch.setattr(block_kernel, "OWN_FOLDER", tmp_path / "file" / "kernels")
    assert block_kernel._own_compiled(t, len(eng.angle), False) is None


def test_a_long_engine_takes_the_general_loop():
    """An engine past OWN_STATEMENTS (the 41 two-by-two blocks of n_fourbar_a02, 82 unknowns)
    has no own loop; the general loop's numbers are numpy's."""
    model = build_model(linkpipe.load_scene(ROOT / "configs" / "dynamics" / "n_fourbar_a02.toml"))
    eng = engine(model)
    assert block_kernel._source(block_kernel.tables(eng), len(eng.angle), False) is None
    _same_condition(eng, _sweep(model)[0].position, _sweep(model)[1])


def _family(kind, a, b, c, d, start):
    if kind == "fourbar":
        return hs.fourbar_text(a, b, c, d, start, start + 360.0, 721, coupler_uv=(0.4 * b, 0.3))
    return hs.slider_crank_text(a, b, c - 2.0, start, start + 360.0, 721)


@settings(max_examples=30, deadline=None)
@given(kind=st.sampled_from(["fourbar", "slider_crank"]), a=st.floats(0.3, 2.5),
       b=st.floats(1.0, 4.5), c=st.floats(1.0, 4.0), d=st.floats(1.5, 4.5),
       start=st.floats(0.0, 360.0), seed=st.integers(0, 10_000))
def test_families_of_four_bars_and_slider_cranks_bit_for_bit(kind, a, b, c, d, start, seed):
    """Any link lengths over a whole crank turn: a Grashof crank-rocker turns through, others
    meet their limits (toggle steps, where the condition grows without bound, then steps
    beyond reach); then exactly singular, nearly singular, NaN and inf steps."""
    assume(_assembles(kind, a, b, c, d, start))
    model = build_model(linkpipe.parse_scene(_family(kind, a, b, c, d, start), "m.toml"))
    eng = engine(model)
    assert block_kernel.supported(eng)
    sweep, s, _, _ = _sweep(model)
    _same_condition(eng, sweep.position, s)
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(64, model.n_q)) * model.size  # any shape, not assembled
    _same_condition(eng, model.positions(q), rng.uniform(-4, 4, size=(64, 1)))
    X = np.where(np.isfinite(sweep.position), sweep.position, 0.0)
    _same_condition(eng, _degenerate(model, X, rng), s)


def test_toggle_steps_of_a_triple_rocker_bit_for_bit():
    """A non-Grashof four-bar driven up to its limits (the shipped triple rocker): steps up to
    a toggle, where the coupler and the rocker come into line and the condition grows to
    1e6 and beyond, and the steps beyond reach, NaN."""
    path = ROOT / "configs" / "hard" / "triple_rocker_limits.toml"
    model = build_model(linkpipe.load_scene(path))
    eng = engine(model)
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    fine = np.linspace(s[0, 0], s[-1, 0], 20_001)[:, None]  # close to the limits
    sweep = kin.solve_sweep(model, fine, np.ones_like(fine), np.zeros_like(fine), order=0)
    cond = _same_condition(eng, sweep.position, fine)
    finite = np.isfinite(cond)
    assert (~finite).any() and finite.any() and cond[finite].max() > 1e4


def _calls(monkeypatch):
    seen = []
    real = block_kernel.condition

    def counted(*args):
        seen.append(1)
        return real(*args)

    monkeypatch.setattr(block_kernel, "condition", counted)
    return seen


def _derivatives_same(model, sweep, s, s_dot, s_ddot, given=True, **kw):
    """kin.derivatives with compiled False, True, and True given the drivers' cos and sin:
    every returned array equal to the bit (``given``: the sweep's own rates passed in, as
    stage 1 passes the dyads')."""
    out = []
    X = np.where(np.isfinite(sweep.position), sweep.position, 0.0)
    eng = engine(model)
    trig = None if eng is None else _trig(eng, s)
    for compiled, trig_ in ((False, None), (True, None), (True, trig)):
        rates = {k: None if getattr(sweep, k) is None else getattr(sweep, k).copy()
                 for k in ("velocity", "acceleration")} if given else {}
        out.append(kin.derivatives(model, X, s, s_dot, s_ddot, sweep.status, True,
                                   compiled=compiled, trig=trig_, **rates, **kw))
    numpy_ = out[0]
    for compiled_ in out[1:]:
        assert numpy_.keys() == compiled_.keys()
        for key, value in numpy_.items():
            if value is None:
                assert compiled_[key] is None, key
            else:
                np.testing.assert_array_equal(compiled_[key], value, err_msg=key)
    return numpy_


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: f"{p.parent.name}-{p.stem}")
def test_derivatives_compiled_equals_numpy_for_every_shipped_scene(config, monkeypatch):
    """Stage 1's call (the dyads' rates given, no influence coefficients: the exact condition
    without an inverse), with influence coefficients (the inverse: no loop), without given
    rates (solved), and a study's entries (``fixed_per_row``): the same arrays."""
    model = build_model(linkpipe.load_scene(config))
    sweep, s, s_dot, s_ddot = _sweep(model)
    eng = engine(model)
    seen = _calls(monkeypatch)
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=False, residuals=True)
    takes = (eng is not None and block_kernel.supported(eng) and sweep.velocity is not None
             and model.n_q <= kin.linalg.ESTIMATE_FROM)
    assert bool(seen) == takes  # the loop ran exactly where it applies
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=True)
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=False, given=False)
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=False, fixed_per_row=True)


@settings(max_examples=15, deadline=None)
@given(kind=st.sampled_from(["fourbar", "slider_crank"]), a=st.floats(0.3, 2.5),
       b=st.floats(1.0, 4.5), c=st.floats(1.0, 4.0), d=st.floats(1.5, 4.5),
       start=st.floats(0.0, 360.0))
def test_derivatives_compiled_equals_numpy_for_families(kind, a, b, c, d, start):
    """Stage 1's call on the families above (singular and unreached steps among them: their
    statuses, NaN rates and inf conditions the same)."""
    assume(_assembles(kind, a, b, c, d, start))
    model = build_model(linkpipe.parse_scene(_family(kind, a, b, c, d, start), "m.toml"))
    sweep, s, s_dot, s_ddot = _sweep(model)
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=False, residuals=True)


def test_derivatives_compiled_on_worker_threads():
    """The loop on four worker threads at once (chunks of 1024 steps of a 40,000-step
    crank-rocker, the loops released from the GIL): the same arrays as numpy's in one thread."""
    import dataclasses as dc

    from linkpipe import workers

    scene = linkpipe.load_scene(ROOT / "configs" / "fourbar_crank_rocker.toml")
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=40_000, step=None)
                                            for d in scene.drivers))
    model = build_model(scene)
    sweep, s, s_dot, s_ddot = _sweep(model)
    with workers.using(1):
        numpy_ = kin.derivatives(model, sweep.position, s, s_dot, s_ddot, sweep.status, True,
                                 velocity=sweep.velocity.copy(),
                                 acceleration=sweep.acceleration.copy(), need_influence=False)
    with workers.using(4):
        threads = kin.derivatives(model, sweep.position, s, s_dot, s_ddot, sweep.status, True,
                                  velocity=sweep.velocity.copy(),
                                  acceleration=sweep.acceleration.copy(), need_influence=False,
                                  compiled=True, chunk=1024)
    for key, value in numpy_.items():
        if value is not None:
            np.testing.assert_array_equal(threads[key], value, err_msg=key)
    assert np.isfinite(numpy_["condition"]).all()


TWO_LINK_ARM = """
[scene]
name = "two_link_arm"
[points]
O = { x = 0.0, y = 0.0, fixed = true }
A = { x = 1.0, y = 0.0 }
B = { x = 1.5, y = 0.8 }
[[links]]
name = "upper"
points = ["O", "A"]
[[links]]
name = "fore"
points = ["A", "B"]
[[drivers]]
name = "shoulder"
angle = ["O", "A"]
from = 0.0
to = 90.0
steps = 2001
rate = 10.0
[[drivers]]
name = "elbow"
angle = ["A", "B"]
relative_to = ["A", "O"]
from = 120.0
to = -30.0
steps = 2001
rate = -9.0
[outputs]
kinematics = ["velocity", "acceleration"]
"""


def test_a_relative_angle_drivers_entries_by_numpy_then_the_loop():
    """A motor between two links (a relative angle row: its entries from the equations at
    every step, by numpy), then exactly singular, NaN and inf steps: the loop from those
    entries, the same numbers; kin.derivatives the same arrays."""
    model = build_model(linkpipe.parse_scene(TWO_LINK_ARM, "arm.toml"))
    eng = engine(model)
    assert len(eng.relative) and block_kernel.supported(eng)
    assert not block_kernel.tables(eng).fused
    sweep, s, s_dot, s_ddot = _sweep(model)
    cond = _same_condition(eng, sweep.position, s)
    assert np.isfinite(cond).all()  # both motors prescribe the arm: regular throughout
    bad = _same_condition(eng, _degenerate(model, sweep.position, np.random.default_rng(5)), s)
    assert np.isinf(bad[3::8]).all()
    _derivatives_same(model, sweep, s, s_dot, s_ddot, need_influence=False, residuals=True)
