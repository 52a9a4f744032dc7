"""The closed-form dyad path and the vectorised general path against the sequential Newton path.

Every shipped config: ``method = "dyads"`` and ``method = "newton"`` give the same positions,
velocities, accelerations and statuses to 1e-12 relative (Newton run at a tight tolerance, so
that the comparison measures the fast path, not Newton's stopping point). A mechanism that does
not decompose runs Newton under ``auto`` and is a SceneError under ``dyads``.
"""
import dataclasses as dc
import pathlib
import sys

import h5py
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st_h

import linkpipe
from linkpipe import status as st
from linkpipe.kinematics import branches, dyads
from linkpipe import kinematics as kin
from linkpipe.stores import hdf5
from linkpipe.errors import SceneError
from linkpipe.model import build_model

from linkpipe.closed_forms import fourbar
from conftest import CONFIG_DIR, CONFIGS

DATA = CONFIG_DIR.parent / "tests" / "data"

REL = 1e-12


def with_solver(scene, **kw):
    return dc.replace(scene, solver=dc.replace(scene.solver, **kw))


def with_steps(scene, steps):
    return dc.replace(scene, drivers=tuple(dc.replace(d, steps=steps, step=None) for d in scene.drivers))


def rel_err(a, b):
    """Largest difference relative to the largest magnitude (NaN where both are NaN is equal)."""
    assert np.array_equal(np.isnan(a), np.isnan(b))
    scale = max(np.nanmax(np.abs(b)), 1e-300) if np.isfinite(b).any() else 1.0
    d = np.abs(a - b)
    return float(np.nanmax(d) / scale) if np.isfinite(d).any() else 0.0


@pytest.fixture(scope="module", params=[p.stem for p in CONFIGS])
def pair(request):
    scene = linkpipe.load_scene(str(CONFIG_DIR / f"{request.param}.toml"))
    scene = dc.replace(scene, outputs=dc.replace(scene.outputs, kinematics=("velocity", "acceleration")))
    fast = linkpipe.solve(with_solver(scene, method="dyads"))
    slow = linkpipe.solve(with_solver(scene, method="newton", tol=1e-14))
    return fast, slow


def test_every_shipped_config_decomposes_and_auto_takes_dyads(pair):
    fast, slow = pair
    assert fast.solver_method_used == "dyads" and slow.solver_method_used == "newton"
    assert linkpipe.solve(fast.scene.path).solver_method_used == "dyads"
    assert hdf5.root_attributes(fast)["solver_method_used"] == "dyads"


def test_dyads_agree_with_newton(pair):
    fast, slow = pair
    np.testing.assert_array_equal(fast.status, slow.status)
    assert rel_err(fast.position, slow.position) <= REL
    assert rel_err(fast.velocity, slow.velocity) <= REL
    assert rel_err(fast.acceleration, slow.acceleration) <= REL
    assert rel_err(fast.link_angle, slow.link_angle) <= REL
    np.testing.assert_allclose(fast.condition, slow.condition, rtol=1e-9)
    assert np.nanmax(fast.residual) <= 1e-14 * fast.model.size
    if fast.forces:
        for name, (_, data, _) in fast.forces.items():
            if not name.startswith("__"):
                assert rel_err(data, slow.forces[name][1]) <= 1e-10, name


def test_engine_derivatives_match_the_dense_ones(pair):
    """kin.derivatives (block-triangular sparse solves) == kinematics.derivatives (dense)."""
    _, r = pair
    model = r.model
    value, s, sd, sdd = kin.driver_motion(model)
    X = np.where(np.isfinite(r.position), r.position, 0.0)
    status = np.where(np.isfinite(r.position).all(axis=(1, 2)), st.OK, st.NO_ASSEMBLY).astype(np.int8)
    a = kin.derivatives(model, X, s, sd, sdd, status, True)
    b = kin.dense_derivatives(model, X, s, sd, sdd, status, True)
    np.testing.assert_array_equal(a["status"], b["status"])
    for key in ("velocity", "acceleration", "influence"):
        assert rel_err(a[key], b[key]) <= REL, key
    if model.n_q <= kin.linalg.ESTIMATE_FROM:
        np.testing.assert_allclose(a["condition"], b["condition"], rtol=1e-9)
    else:  # estimated without an inverse: a lower bound within 3x (tests/test_condition.py)
        ratio = a["condition"] / b["condition"]
        ok = np.isfinite(ratio)
        assert (ratio[ok] <= 1 + 1e-9).all() and (ratio[ok] >= 1 / 3).all()


@pytest.mark.parametrize("path", CONFIGS + sorted((CONFIG_DIR / "hard").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_max_abs_phi_is_the_models_residual(path):
    """The dyad path's residual (Engine.max_abs_phi: rows accumulated in place; the dense
    fallback for models without an engine, e.g. the redundant double parallelogram) equals
    max |Model.phi| at configurations off the constraints; NaN in a step stays NaN."""
    model = build_model(linkpipe.load_scene(str(path)))
    rng = np.random.default_rng(3)
    S = 50
    X = model.start_position + rng.normal(scale=0.1 * model.size, size=(S, model.n_points, 2))
    X[:, model.fixed] = model.start_position[model.fixed]
    X[7, model.moving[0], 1] = np.nan
    s = rng.uniform(-3, 3, size=(S, model.n_drivers))
    want = np.abs(model.phi(X, s)).max(axis=1)
    pts = {int(p): (X[:, p, 0].copy(), X[:, p, 1].copy()) for p in model.moving}
    got = kin.vectorised.max_abs_phi(model)(pts, np.ascontiguousarray(s.T))
    assert np.isnan(got[7]) and np.isnan(want[7])
    keep = np.arange(S) != 7
    # the same rows by the same operations up to association: a few roundings of the size
    np.testing.assert_allclose(got[keep], want[keep], rtol=0, atol=1e-14 * model.size)
    assert (want[keep] > 1e-3 * model.size).all()  # really off the constraints


def test_vectorised_general_path_on_a_long_sweep():
    """Coarse continuation + batched Newton from Hermite predictions == the closed form."""
    scene = with_steps(linkpipe.load_scene(str(CONFIG_DIR / "fourbar_crank_rocker.toml")), 3001)
    model = build_model(scene)
    value, s, sd, sdd = kin.driver_motion(model)
    out = kin.vectorised.solve_newton(model, s)
    assert (out["status"] == st.OK).all()
    der = kin.derivatives(model, model.positions(out["q"]), s, sd, sdd, out["status"], True)
    out.update(velocity=der["velocity"], acceleration=der["acceleration"])
    assert out["sequential"].sum() < 200  # the coarse nodes only: the rest went vectorised
    cf = fourbar(1.0, 3.5, 3.0, 4.0, s[:, 0], 10.0, 0.0, branch=+1, coupler_uv=(1.5, 0.8))
    X = model.positions(out["q"])
    names = model.point_names
    for p in ("A", "B", "P"):
        i = names.index(p)
        np.testing.assert_allclose(X[:, i], cf[p], atol=1e-12 * 4.0)
        np.testing.assert_allclose(out["velocity"][:, i], cf["V" + p], atol=1e-12 * 40.0)
        np.testing.assert_allclose(out["acceleration"][:, i], cf["A" + p], atol=1e-11 * 400.0)
    # and the dyads on the same sweep
    plan = kin.decompose(model)
    branches.set_branches(plan, X[0], s[0])
    sw = dyads.solve_chain(plan, s, sd, sdd)
    assert rel_err(sw.position, X) <= REL
    assert rel_err(sw.acceleration, out["acceleration"]) <= REL


STEPHENSON = """
# A crank driving a triad (a ternary link held by three binary links): an Assur group of
# class III, which closes only by solving its loops together.
[points]
O1 = { x = 0.0, y = 0.0, fixed = true }
O2 = { x = 4.0, y = 0.5, fixed = true }
O3 = { x = 0.0, y = 3.5, fixed = true }
A = { x = 1.0, y = 0.0 }
B = { x = 1.5, y = 2.0 }
C = { x = 3.0, y = 2.5 }
D = { x = 2.5, y = 1.2 }
[[links]]
name = "crank"
points = ["O1", "A"]
[[links]]
name = "ab"
points = ["A", "B"]
[[links]]
name = "o2c"
points = ["O2", "C"]
[[links]]
name = "o3d"
points = ["O3", "D"]
[[links]]
name = "triad"
points = ["B", "C", "D"]
[[drivers]]
name = "crank"
angle = ["O1", "A"]
from = 0.0
to = 20.0
steps = 21
rate = 57.29577951308232
[outputs]
kinematics = ["velocity", "acceleration"]
"""


def test_a_triad_does_not_decompose_and_auto_runs_newton():
    scene = linkpipe.parse_scene(STEPHENSON, "triad.toml")
    plan = kin.decompose(build_model(scene))
    assert not plan.ok and "B" in plan.reason
    r = linkpipe.solve(scene)
    assert r.solver_method_used == "newton" and "no closed-form dyad" in r.solver_note
    assert (r.status == st.OK).all()
    # the loops close: every link keeps its start length
    X = r.position
    for a, b in (("O1", "A"), ("A", "B"), ("O2", "C"), ("O3", "D"), ("B", "C")):
        ia, ib = r.point_names.index(a), r.point_names.index(b)
        L = np.linalg.norm(X[:, ib] - X[:, ia], axis=1)
        np.testing.assert_allclose(L, L[0], atol=1e-12)


def test_method_dyads_on_a_scene_that_does_not_decompose_is_a_scene_error():
    scene = with_solver(linkpipe.parse_scene(STEPHENSON, "triad.toml"), method="dyads")
    with pytest.raises(SceneError) as err:
        linkpipe.solve(scene)
    msg = str(err.value)
    assert "[solver] method" in msg and '"auto"' in msg and "decompose" in msg


def test_auto_leaves_dyads_that_pass_a_change_point_to_newton():
    """The basketball parallelogram swept through its change point (links collinear at 90 deg).

    The fixed-sign dyad would turn onto the anti-parallelogram there; Newton continuation goes
    on smoothly. ``auto`` must give Newton's answer.
    """
    scene = linkpipe.load_scene(str(CONFIG_DIR / "basketball_goal.toml"))
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, to_value=120.0) for d in scene.drivers),
                       effects=(), outputs=dc.replace(scene.outputs, vectors=()))
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=37) for d in scene.drivers))
    auto = linkpipe.solve(scene)
    assert auto.solver_method_used == "newton" and "singular configuration" in auto.solver_note
    # and that answer is the parallelogram through the change point (its closed form): the
    # board translates, B = O2 + 2 u(theta), C = O4 + 2 u(theta); exactly 90 deg is singular
    # (a double root: known to ~sqrt(eps) x size there, 1e-7 ft; elsewhere 1e-10 ft)
    t = np.deg2rad(auto.driver_value[:, 0])
    arm = 2.0 * np.stack([np.cos(t), np.sin(t)], axis=1)
    regular = np.abs(auto.driver_value[:, 0] - 90.0) > 1e-9
    assert (auto.status[regular] == st.OK).all() and (auto.status[~regular] == st.SINGULAR).all()
    idx = {n: auto.point_names.index(n) for n in ("B", "C")}
    np.testing.assert_allclose(auto.position[:, idx["B"]], [0.0, -1.0] + arm, rtol=0, atol=1e-7)
    np.testing.assert_allclose(auto.position[regular][:, idx["C"]], ([0.0, -2.0] + arm)[regular],
                               rtol=0, atol=1e-10)
    # forced, the fixed-sign dyads run and keep their sign on every step they assemble
    forced = linkpipe.solve(with_solver(scene, method="dyads"))
    assert forced.solver_method_used == "dyads"
    ok = forced.status == st.OK
    assert ok.sum() >= 35
    P = forced.position
    i = {n: forced.point_names.index(n) for n in ("O2", "B", "C")}
    d, r = P[ok][:, i["C"]] - P[ok][:, i["O2"]], P[ok][:, i["B"]] - P[ok][:, i["O2"]]
    side = np.sign(d[:, 0] * r[:, 1] - d[:, 1] * r[:, 0])
    assert (side == side[0]).all()


def test_dyads_without_assembly_give_nan_and_no_assembly():
    text = (DATA / "triple_rocker.toml").read_text().replace("steps = 361", "steps = 73")
    text += '\n[solver]\nmethod = "dyads"\n'
    r = linkpipe.solve(linkpipe.parse_scene(text, "triple_rocker.toml"))
    th = np.deg2rad(r.driver_value[:, 0])
    dist = np.hypot(2 * np.cos(th) - 3.5, 2 * np.sin(th))
    outside, inside = dist > 4 + 1e-6, dist < 4 - 1e-6
    assert (r.status[outside] == st.NO_ASSEMBLY).all() and outside.any()
    assert (r.status[inside] == st.OK).all()
    assert np.isnan(r.position[outside][:, r.point_names.index("B")]).all()
    np.testing.assert_array_equal(r.position[outside][:, r.point_names.index("O4")], [[3.5, 0.0]] * outside.sum())


@pytest.mark.parametrize("method", ["dyads", "newton"])
@pytest.mark.parametrize("kinematics", ['["velocity", "acceleration"]', '[]'])
def test_rates_are_zero_at_fixed_points_and_nan_at_moving_points_of_failed_steps(method, kinematics):
    """Every step's rates at a fixed point are exactly 0 (ok or not: the ground does not move),
    a failed step's rates at its moving points NaN, an ok step's finite; a scene of positions
    only stores no rates but the same rule holds for the arrays it computes (exact: a
    statement about which values are written, not about rounding)."""
    text = (DATA / "triple_rocker.toml").read_text().replace("steps = 361", "steps = 73")
    text += f'\n[solver]\nmethod = "{method}"\n[outputs]\nkinematics = {kinematics}\n'
    scene = linkpipe.parse_scene(text, "triple_rocker.toml")
    model = build_model(scene)
    rates_too = kinematics != "[]"  # as stage 1 asks: no rates for a scene of positions only
    motion = kin.driver_motion(model)[1:]
    sweep = kin.solve_sweep(model, *motion, order=2 if rates_too else 0)
    der = kin.derivatives(model, np.nan_to_num(sweep.position), *motion, sweep.status, rates_too,
                          velocity=sweep.velocity, acceleration=sweep.acceleration,
                          need_influence=False, need_velocity=rates_too)
    ok = der["status"] == st.OK
    assert ok.any() and (~ok).any()
    fixed, moving = model.fixed, ~model.fixed
    for name in ("velocity", "acceleration") if rates_too else ("velocity",):
        rates = der[name]
        assert (rates[:, fixed] == 0.0).all() and not np.signbit(rates[:, fixed]).any(), name
        assert np.isnan(rates[~ok][:, moving]).all(), name
        if rates_too:
            assert np.isfinite(rates[ok]).all(), name
        else:
            assert np.isnan(rates[:, moving]).all(), name
    assert rates_too or der["acceleration"] is None


# ------------------------------------------------------------------ the fast path shares the model
_HARD = pathlib.Path(__file__).resolve().parent / "hard"
if str(_HARD) not in sys.path:
    sys.path.insert(0, str(_HARD))


@settings(max_examples=80, deadline=None)
@given(family=st_h.sampled_from(["fourbar", "slider_crank", "six_bar"]),
       a=st_h.floats(0.5, 1.2), b=st_h.floats(3.0, 4.0), c=st_h.floats(2.5, 3.5),
       start=st_h.floats(0.0, 360.0), branch=st_h.sampled_from([1, -1]),
       scale=st_h.sampled_from([1e-3, 1.0, 1e3]))
def test_dyads_satisfy_the_models_equations_and_equal_newton(family, a, b, c, start, branch, scale):
    """The closed-form dyads solve the model's own equations (model/equations.py): Φ = 0,
    Φq v = −Φt, Φq a = γ to 1e-12 of the size (and of the velocities' and accelerations'
    scales), and equal the general Newton path, on families of four-bars (Grashof
    crank-rockers: a + 4 < b + c), offset slider-cranks and Watt six-bars: positions to 1e-12
    of the size (Newton's tolerance), derivatives step by step to (1e-11 + 1e-15 * condition)
    of their scale (Newton's positions are 1e-12 off; near a toggle the condition is 1e5+)."""
    import hard_scenes as hs

    if family == "fourbar":
        text = hs.fourbar_text(a, b, c, 4.0, start, start + 90.0, 31, branch=branch, scale=scale,
                               coupler_uv=(1.2, 0.7))
    elif family == "slider_crank":
        text = hs.slider_crank_text(a, b, 0.3 * a, start, start + 90.0, 31, branch=branch, scale=scale)
    else:
        text = hs.six_bar_text(1.0, 3.5, 3.0, 4.0, (1.2, 0.9), (5.5, 3.0), (4.6, 4.2),
                               start, start + 20.0, 21, branch=branch)
    scene = linkpipe.parse_scene(text, f"{family}.toml")
    fast = linkpipe.solve(dc.replace(scene, solver=dc.replace(scene.solver, method="dyads")))
    ok = fast.status == st.OK
    assume(ok.all())  # a six-bar drawn at random may leave its assembly range
    model = fast.model
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    X, V, A = fast.position, fast.velocity, fast.acceleration
    size = model.size
    assert np.abs(model.phi(X, s)).max() <= 1e-12 * size
    J = model.jacobian(X, s)
    v_scale = max(np.abs(V).max(), 1e-300)
    a_scale = max(np.abs(A).max(), 1e-300)
    vel_res = np.einsum("sij,sj->si", J, model.q_of(V)) + model.phi_t(X, s, s_dot)
    acc_res = np.einsum("sij,sj->si", J, model.q_of(A)) - model.gamma(X, V, s, s_dot, s_ddot)
    assert np.abs(vel_res).max() <= 1e-12 * v_scale
    assert np.abs(acc_res).max() <= 1e-11 * a_scale  # gamma's terms are products of two rates
    slow = linkpipe.solve(dc.replace(scene, solver=dc.replace(scene.solver, method="newton")))
    np.testing.assert_array_equal(slow.status, fast.status)
    assert np.abs(slow.position - X).max() <= 1e-12 * size
    # Newton's positions meet tol = 1e-12 of the size, not rounding: its derivatives, taken
    # there, carry that error times O(1) factors (1e-11), plus rounding times the condition
    allowed = 1e-11 + 1e-15 * fast.condition  # (S,)
    assert (np.abs(slow.velocity - V).max(axis=(1, 2)) <= allowed * v_scale).all()
    assert (np.abs(slow.acceleration - A).max(axis=(1, 2)) <= 10 * allowed * a_scale).all()


@pytest.mark.parametrize("method", ["auto", "newton"])
def test_rate_residuals_are_stored_only_when_asked_and_are_the_models(method, tmp_path):
    """``[solver] rate_residuals = true`` stores each step's rates put back into the model's own
    linear equations (max over rows), on the dyads and on Newton alike; by default neither the
    re-check runs nor the variables exist (the tests above prove them to rounding)."""
    from linkpipe.stores import hdf5

    text = (CONFIG_DIR / "fourbar_crank_rocker.toml").read_text()
    plain = linkpipe.parse_scene(text + f'\n[solver]\nmethod = "{method}"\n', "cr.toml")
    asked = linkpipe.parse_scene(text + f'\n[solver]\nmethod = "{method}"\nrate_residuals = true\n',
                                 "cr.toml")
    r0, r1 = linkpipe.solve(plain), linkpipe.solve(asked)
    assert r0.velocity_residual is None and r0.acceleration_residual is None
    names = {v.name for v in r0.variables()}
    assert not names & {"velocity_residual", "acceleration_residual"}
    np.testing.assert_array_equal(r1.velocity, r0.velocity)  # the re-check changes nothing
    model = r1.model
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    J = model.jacobian(r1.position, s)
    vres = np.abs(np.einsum("sij,sj->si", J, model.q_of(r1.velocity))
                  + model.phi_t(r1.position, s, s_dot)).max(axis=1)
    ares = np.abs(np.einsum("sij,sj->si", J, model.q_of(r1.acceleration))
                  - model.gamma(r1.position, r1.velocity, s, s_dot, s_ddot)).max(axis=1)
    # the same sums in another order (the engine's sparse rows against the dense product):
    # equal to rounding of the rates' scale (velocities ~10 m/s, accelerations ~100 m/s^2)
    np.testing.assert_allclose(r1.velocity_residual, vres, rtol=0, atol=1e-13)
    np.testing.assert_allclose(r1.acceleration_residual, ares, rtol=0, atol=1e-12)
    assert r1.velocity_residual.max() < 1e-13 and r1.acceleration_residual.max() < 1e-12
    hdf5.write(r1, tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5") as f:
        np.testing.assert_array_equal(f["velocity_residual"][:], r1.velocity_residual)


def _dyads_or_skip(scene):
    try:
        r = linkpipe.solve(scene)
    except SceneError:
        pytest.skip("does not decompose into closed-form dyads")
    if r.solver_method_used != "dyads":
        pytest.skip("auto takes the general path")
    return r


@pytest.mark.parametrize("config", CONFIGS + sorted((CONFIG_DIR / "hard").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_link_angles_and_rates_from_the_dyads_pass_equal_the_separate_passes_bit_for_bit(config):
    """Stage 1 takes the links' directions and rates from the dyads' own pass (the chunk's
    buffers while in cache): on every shipped scene the dyads solve (and on the hard cases with
    method = "dyads", whose failed steps are recomputed from the final arrays) they equal
    link_angles_unwrapped and link_rates run on the final positions and rates, to the bit."""
    scene = linkpipe.load_scene(config)
    if config.parent.name == "hard":
        scene = with_solver(scene, method="dyads")
    r = _dyads_or_skip(scene)
    if config.stem == "triple_rocker_limits":  # steps past its limits: recomputed, NaN
        assert (r.status == st.NO_ASSEMBLY).any()
    model, k = r.model, r.kinematics
    angles = kin.link_angles_unwrapped(model, r.position, s=k.s)
    np.testing.assert_array_equal(r.link_angle, angles)
    if r.velocity is not None:
        with np.errstate(invalid="ignore", divide="ignore"):  # NaN rows: failed steps
            w, al = kin.link_rates(model, r.position, r.velocity, r.acceleration)
        np.testing.assert_array_equal(r.link_angular_velocity, w)
        np.testing.assert_array_equal(r.link_angular_acceleration, al)
