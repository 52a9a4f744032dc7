"""Stage 1 against exact answers: closed forms, the shear-press seed's table, the parallelogram."""
import pathlib

import numpy as np

import linkpipe
from linkpipe.status import NO_ASSEMBLY, OK

from linkpipe.closed_forms import fourbar, slider_crank

DATA = pathlib.Path(__file__).parent / "data"


def idx(result, name):
    return result.point_names.index(name)


def test_crank_rocker_matches_closed_form():
    r = linkpipe.solve("configs/fourbar_crank_rocker.toml")
    assert (r.status == OK).all()
    th = np.deg2rad(r.driver_value[:, 0])
    cf = fourbar(1.0, 3.5, 3.0, 4.0, th, 10.0, 0.0, branch=+1, coupler_uv=(1.5, 0.8))
    L, w = 4.0, 10.0  # length scale (ground link) and crank speed: tolerances are relative to them
    for name in ("A", "B", "P"):
        i = idx(r, name)
        np.testing.assert_allclose(r.position[:, i], cf[name], rtol=0, atol=1e-10 * L)
        np.testing.assert_allclose(r.velocity[:, i], cf["V" + name], rtol=0, atol=1e-10 * L * w)
        np.testing.assert_allclose(r.acceleration[:, i], cf["A" + name], rtol=0, atol=1e-10 * L * w**2)
    links = r.link_names
    np.testing.assert_allclose(r.link_angular_velocity[:, links.index("coupler")], cf["omega3"], atol=1e-10 * w)
    np.testing.assert_allclose(r.link_angular_velocity[:, links.index("rocker")], cf["omega4"], atol=1e-10 * w)
    np.testing.assert_allclose(r.link_angular_acceleration[:, links.index("rocker")], cf["alpha4"],
                               atol=1e-10 * w**2)
    # the crank angle is unwrapped: 0 .. 2 pi without a jump
    np.testing.assert_allclose(r.link_angle[:, links.index("crank")], th, atol=1e-12)


def test_slider_crank_matches_closed_form():
    r = linkpipe.solve("configs/slider_crank.toml")
    assert (r.status == OK).all()
    th = np.deg2rad(r.driver_value[:, 0])
    cf = slider_crank(1.0, 3.5, 0.5, th, 10.0, 0.0)
    L, w = 4.5, 10.0
    for name in ("A", "B"):
        i = idx(r, name)
        np.testing.assert_allclose(r.position[:, i], cf[name], atol=1e-10 * L)
        np.testing.assert_allclose(r.velocity[:, i], cf["V" + name], atol=1e-10 * L * w)
        np.testing.assert_allclose(r.acceleration[:, i], cf["A" + name], atol=1e-10 * L * w**2)


# The seed's printed table (003, R. Lot): xP yP | xB yB | xC yC, printed to 3 decimals.
SHEAR_TABLE = np.array([
    [+0.415, +0.500, +0.062, +0.222, +0.270, -0.120],
    [+0.444, +0.475, +0.075, +0.218, +0.270, -0.131],
    [+0.469, +0.450, +0.086, +0.213, +0.270, -0.142],
    [+0.492, +0.425, +0.097, +0.208, +0.270, -0.152],
    [+0.512, +0.400, +0.108, +0.203, +0.270, -0.162],
    [+0.531, +0.375, +0.117, +0.198, +0.270, -0.172],
    [+0.548, +0.350, +0.126, +0.192, +0.270, -0.181],
    [+0.563, +0.325, +0.135, +0.186, +0.270, -0.190],
    [+0.577, +0.300, +0.143, +0.180, +0.270, -0.199],
])


def test_shear_press_reproduces_seed_table():
    r = linkpipe.solve("configs/shear_press.toml")
    assert (r.status == OK).all()
    got = np.concatenate([r.position[:, idx(r, n)] for n in ("P", "B", "C")], axis=1)
    # the table is printed to 3 decimals: half a unit of the last digit, plus float slack
    assert np.abs(got - SHEAR_TABLE).max() <= 0.0005 + 1e-12
    # and the four constant distances of the Maple model hold exactly
    P, B, C = (r.position[:, idx(r, n)] for n in ("P", "B", "C"))
    for (u, v, L) in ((B, 0 * B, 0.230), (B, C, 0.400), (P, 0 * P, 0.650), (B, P, 0.450)):
        np.testing.assert_allclose(np.linalg.norm(u - v, axis=1), L, atol=1e-12)


def test_basketball_backboard_translates():
    r = linkpipe.solve("configs/basketball_goal.toml")
    assert (r.status == OK).all() and r.n_steps == 25
    B, C = r.position[:, idx(r, "B")], r.position[:, idx(r, "C")]
    # backboard stays vertical: B directly above C, 1 ft apart, at every step
    np.testing.assert_allclose(B[:, 0] - C[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(B[:, 1] - C[:, 1], 1.0, atol=1e-12)
    # and the lower link is at the driven angle, the handle on its extension
    th = np.deg2rad(np.arange(-60, 61, 5))
    O4 = np.array([0.0, -2.0])
    np.testing.assert_allclose(C, O4 + 2 * np.stack([np.cos(th), np.sin(th)], 1), atol=1e-12)
    np.testing.assert_allclose(r.position[:, idx(r, "H")], O4 - np.stack([np.cos(th), np.sin(th)], 1),
                               atol=1e-12)


def test_sweep_out_of_assembly_range_gives_nan_and_recovers(tmp_path):
    r = linkpipe.solve(str(DATA / "triple_rocker.toml"))
    # assembly needs |A - O4| <= 4: 4 + 12.25 - 14 cos t <= 16 -> cos t >= 0.25/14
    th = np.deg2rad(r.driver_value[:, 0])
    dist = np.hypot(2 * np.cos(th) - 3.5, 2 * np.sin(th))
    inside = dist < 4 - 1e-6
    outside = dist > 4 + 1e-6
    assert (r.status[outside] == NO_ASSEMBLY).all() and outside.sum() > 100
    assert np.isnan(r.position[outside][:, idx(r, "A")]).all()
    # fixed points keep their positions at failed steps
    np.testing.assert_array_equal(r.position[outside][:, idx(r, "O4")], [[3.5, 0.0]] * outside.sum())
    assert (r.status[inside] == OK).all()
    # recovered steps are assembled: the links keep their lengths
    A, B = r.position[inside][:, idx(r, "A")], r.position[inside][:, idx(r, "B")]
    np.testing.assert_allclose(np.linalg.norm(B - A, axis=1), 2.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(B - [3.5, 0.0], axis=1), 2.0, atol=1e-12)
    assert inside[-1] and r.status[-1] == OK  # the sweep came back and ends assembled


def test_max_iter_caps_each_newton_run():
    """max_iter caps the Newton iterations a step gets from its prediction: the contract's
    not_converged is "iteration cap hit". The crank-rocker needs 2 iterations a step from its
    predictor (1 degree steps). With max_iter = 2 every step is ok in exactly those 2 and
    equals the closed form; with max_iter = 1 every step after the start is not_converged
    after exactly 1 iteration (no damped least squares, no sub-steps finish what the cap
    stopped): NaN moving points, fixed points kept, a residual above the tolerance, and the
    sweep goes on to its last step. (Sub-steps after a capped run are kept for a predictor that
    overshot by more than the mechanism's size, next to a limit: tests/hard/test_properties.py's
    first explicit example.)"""
    import dataclasses as dc

    from linkpipe.status import NOT_CONVERGED

    scene = linkpipe.load_scene("configs/fourbar_crank_rocker.toml")

    def run(max_iter):
        return linkpipe.solve(dc.replace(scene, solver=dc.replace(
            scene.solver, method="newton", max_iter=max_iter)))

    th_cf = lambda r: fourbar(1.0, 3.5, 3.0, 4.0, np.deg2rad(r.driver_value[:, 0]), 10.0, 0.0,  # noqa: E731
                              branch=+1, coupler_uv=(1.5, 0.8))
    r2, r1 = run(2), run(1)
    assert (r2.status == OK).all() and (r2.iterations[1:] == 2).all()
    np.testing.assert_allclose(r2.position[:, idx(r2, "B")], th_cf(r2)["B"], rtol=0, atol=1e-10 * 4.0)

    capped = r1.status == NOT_CONVERGED
    assert r1.status[0] == OK and capped[1:].all() and len(r1.status) == 361
    assert (r1.iterations[1:] == 1).all()
    tol_abs = scene.solver.tol * r1.model.size
    assert (r1.residual[1:] > tol_abs).all()
    assert np.isnan(r1.position[1:, idx(r1, "B")]).all() and np.isnan(r1.position[1:, idx(r1, "A")]).all()
    np.testing.assert_array_equal(r1.position[1:, idx(r1, "O4")], np.broadcast_to([4.0, 0.0], (360, 2)))


def test_max_iter_caps_the_vectorised_path_too():
    """3001 steps take the vectorised general path: its batched Newton also stops at max_iter
    (a step that needs more goes back to the sequential path, which caps each Newton run): at
    max_iter = 2 most steps are batched, and every step is ok within 2 iterations; at max_iter
    = 1 the batched refinement (cubic Hermite guesses) gives up, and the sequential path's one
    iteration from its 0.12 degree steps' predictor reaches the tolerance: ok, in 1."""
    import dataclasses as dc

    from linkpipe import kinematics as kin
    from linkpipe.model import build_model

    scene = linkpipe.load_scene("configs/fourbar_crank_rocker.toml")
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=3001, step=None) for d in scene.drivers))
    outs = {}
    for max_iter in (1, 2):
        model = build_model(dc.replace(scene, solver=dc.replace(scene.solver, method="newton",
                                                                max_iter=max_iter)))
        _, s, _, _ = kin.driver_motion(model)
        outs[max_iter] = kin.vectorised.solve_newton(model, s)
    assert (~outs[2]["sequential"]).sum() > 2500
    for max_iter, out in outs.items():
        assert (out["status"] == OK).all() and out["iterations"].max() == max_iter


def test_a_low_cap_never_calls_an_assemblable_step_no_assembly():
    """The slider-driven slider-crank starts on its dead centre; with max_iter = 3 Newton from
    there runs out on the next steps. Those are not_converged (the mechanism assembles
    everywhere inside the stroke 2.5..4.5), not no_assembly, and the sweep goes on: the steps
    that converge equal the closed form (crank pin on the upper half-turn)."""
    import dataclasses as dc

    from linkpipe.status import NOT_CONVERGED, SINGULAR

    scene = linkpipe.load_scene("configs/hard/slider_driven_dead_centres.toml")
    r = linkpipe.solve(dc.replace(scene, solver=dc.replace(scene.solver, method="newton", max_iter=3)))
    x = r.driver_value[:, 0]
    inside = (x > 2.5 + 1e-9) & (x < 4.5 - 1e-9)
    assert set(np.unique(r.status[inside])) <= {OK, NOT_CONVERGED}
    assert (r.status[~inside] != NO_ASSEMBLY).all() and (r.status == SINGULAR).any()
    ok = r.status == OK
    assert ok.sum() >= 20
    # crank 1, rod 3.5, no offset: cos t = (1 + x^2 - 3.5^2) / (2 x), upper half-turn; 1e-9 of
    # the size: next to the dead centres the condition reaches ~1e3 (residual tolerance 1e-12)
    c = (1.0 + x**2 - 3.5**2) / (2 * x)
    A = np.stack([c, np.sqrt(np.clip(1 - c * c, 0, None))], axis=1)
    np.testing.assert_allclose(r.position[ok, idx(r, "A")], A[ok], rtol=0, atol=1e-9)


def test_link_angles_unwrap_across_gaps_as_each_link_alone():
    """The vectorised unwrap equals unwrapping each link's finite angles on their own, to the
    last bit, with NaN gaps anywhere (leading, inner, trailing, a link never assembled)."""
    from hypothesis import given, settings, strategies as st

    from linkpipe.kinematics.angles import unwrap_runs

    @settings(max_examples=60, deadline=None)
    @given(seed=st.integers(0, 10_000), S=st.integers(1, 60), L=st.integers(1, 4),
           gap=st.floats(0.0, 0.6))
    def check(seed, S, L, gap):
        rng = np.random.default_rng(seed)
        turns = np.cumsum(rng.normal(scale=1.5, size=(S, L)), axis=0)  # jumps of any size
        ang = np.angle(np.exp(1j * turns))
        ang[rng.uniform(size=(S, L)) < gap] = np.nan
        got = unwrap_runs(ang.copy())[0]
        for j in range(L):
            fin = np.isfinite(ang[:, j])
            expected = np.full(S, np.nan)
            if fin.any():
                expected[fin] = np.unwrap(ang[fin, j])
            np.testing.assert_array_equal(got[:, j], expected)

    check()


def test_a_driven_link_takes_its_turns_from_the_driver():
    """The crank-rocker swept 0 .. 905.9 deg in 5 steps (226.475 deg a step, more than half a
    turn): the crank's link angle is the driver's value in radians (2.5 turns at the end, 1e-12
    rad: the position's rounding), not the smallest jumps (which ran backwards to -9.32 rad).
    Through a gap of failed steps (configs/hard/triple_rocker_limits.toml: the crank turns on
    through steps where the rocker cannot assemble) it likewise follows the driver."""
    root = pathlib.Path(__file__).resolve().parents[1]
    text = (root / "configs" / "fourbar_crank_rocker.toml").read_text()
    text = text.replace("to = 360.0", "to = 905.9").replace("steps = 361", "steps = 5")
    r = linkpipe.solve(linkpipe.parse_scene(text, "coarse.toml"))
    assert r.message == "all 5 steps ok"
    crank = [ln.name for ln in r.scene.links].index("crank")
    np.testing.assert_allclose(r.link_angle[:, crank], np.radians(r.driver_value[:, 0]),
                               rtol=0, atol=1e-12)
    r = linkpipe.solve(str(root / "configs" / "hard" / "triple_rocker_limits.toml"))
    failed = r.status != OK
    assert failed[18:36].all() and (~failed[37:54]).all()  # solved again after a gap
    crank = [ln.name for ln in r.scene.links].index("crank")
    np.testing.assert_allclose(r.link_angle[~failed, crank],
                               np.radians(r.driver_value[~failed, 0]), rtol=0, atol=1e-12)


def test_running_sums_of_sparse_corrections_are_cumsums_bit_for_bit():
    """The unwrap's running sum over its few non-zero corrections equals np.cumsum over every
    step, to the last bit, with few turns, many turns, none, and a carried start."""
    from hypothesis import given, settings, strategies as st

    from linkpipe.kinematics.angles import _running_sums

    @settings(max_examples=80, deadline=None)
    @given(seed=st.integers(0, 10_000), S=st.integers(1, 5000), L=st.integers(1, 4),
           density=st.sampled_from([0.0, 1e-3, 0.01, 0.2]))
    def check(seed, S, L, density):
        rng = np.random.default_rng(seed)
        c = np.where(rng.uniform(size=(S + 1, L)) < density,
                     2 * np.pi * rng.integers(-3, 4, size=(S + 1, L))
                     + rng.normal(scale=1e-15, size=(S + 1, L)), 0.0)
        # a carried start: a sum of corrections, never -0.0 (x + y == 0 rounds to +0.0)
        c[0] = np.where(rng.uniform(size=L) < 0.5, rng.normal(scale=20.0, size=L), 0.0)
        # bit for bit, the sign of zero too
        np.testing.assert_array_equal(_running_sums(c).view(np.uint64),
                                      np.cumsum(c, axis=0).view(np.uint64))

    check()


def test_every_solver_method_the_scene_accepts_is_a_registered_sweep_solver():
    """``[solver] method`` choices (the scene's, no maths there) and ``kinematics.METHODS``
    (what ``solve_sweep`` looks the name up in) are the same names."""
    from linkpipe.kinematics import METHODS
    from linkpipe.scene.tables import SOLVER_CHOICES

    assert set(METHODS) == set(SOLVER_CHOICES["method"])
