"""Time-driven sweeps (issue 14, item 1): [time], motion laws, rate and acceleration as
functions of time; every answer exact (closed forms, complex-step derivatives) or bounded by
a stated finite-difference error."""
import math
import pathlib

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe import closed_forms
from linkpipe.__main__ import main
from linkpipe.errors import SceneError
from linkpipe.kinematics import driver_motion, solve_positions, start_state
from linkpipe.kinematics.vectorised import solve_newton
from linkpipe.model import build_model
from linkpipe.model.drive import LAWS, law_motion, rate_motion
from linkpipe.status import OK

CONFIGS = pathlib.Path(__file__).resolve().parent.parent / "configs"
CRANK_ROCKER = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
V1_DRIVER = """from = 0.0
to = 360.0
steps = 361
rate = 572.9577951308232     # 10 rad/s in degrees per second"""


def crank_rocker(driver: str, time: str = "from = 0.0\nto = 2.0\nsteps = 401",
                 extra: str = "") -> str:
    """The shipped crank-rocker with [time] and the crank driven by ``driver`` keys."""
    text = CRANK_ROCKER.replace(V1_DRIVER, driver)
    return text.replace("[[drivers]]", f"[time]\n{time}\n\n[[drivers]]", 1) + extra


def scene_of(text: str, name: str = "timed") -> linkpipe.Scene:
    return linkpipe.parse_scene(text, f"{name}.toml")


# ------------------------------------------------------------------ the laws themselves
@pytest.mark.parametrize("law", sorted(LAWS))
def test_each_law_has_its_exact_derivatives(law):
    """f' and f'' against the complex-step derivative of f and f' (exact to rounding: no
    subtraction), the ends f(0) = 0, f(1) = 1, and the contract's formula for f."""
    f, df, ddf = LAWS[law]
    u = np.linspace(0.0, 1.0, 101)
    h = 1e-20
    np.testing.assert_allclose(df(u), (f(u + 1j * h)).imag / h, rtol=0, atol=1e-13)
    np.testing.assert_allclose(ddf(u), (df(u + 1j * h)).imag / h, rtol=0, atol=1e-12)
    assert f(np.array(0.0)) == 0.0 and abs(f(np.array(1.0)) - 1.0) < 1e-15
    contract = {"linear": u, "harmonic": (1 - np.cos(np.pi * u)) / 2,
                "cycloidal": u - np.sin(2 * np.pi * u) / (2 * np.pi),
                "polynomial345": 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5}[law]
    np.testing.assert_allclose(f(u), contract, rtol=0, atol=1e-14)  # rounding of the two forms


@pytest.mark.parametrize("law", sorted(LAWS))
def test_law_rates_are_the_derivatives_of_its_values_in_time(law):
    """Value, rate, acceleration of a law from 20 to 110 over [1, 3] s: the rate against the
    central difference of the value, whose error is h^2/6 max|value'''| (h = 1e-4 s, value'''
    at most (to - from) (2 pi)^3 / T^3 here), and likewise the acceleration against the rate."""
    t = np.linspace(1.0, 3.0, 201)[1:-1]
    h = 1e-4
    value, rate, acc = law_motion(law, 20.0, 110.0, t, 1.0, 2.0)
    ahead, behind = law_motion(law, 20.0, 110.0, t + h, 1.0, 2.0), law_motion(law, 20.0, 110.0, t - h, 1.0, 2.0)
    third = 90.0 * (2 * np.pi) ** 3 / 2.0 ** 3 * 4  # a bound of |d3 value/dt3| (and of d4 / 2 pi)
    bound = h * h / 6 * third * 2 + 1e-9
    assert np.abs((ahead[0] - behind[0]) / (2 * h) - rate).max() <= bound
    assert np.abs((ahead[1] - behind[1]) / (2 * h) - acc).max() <= bound * 2 * np.pi
    assert value[0] > 20.0 and value[-1] < 110.0


def test_rate_and_acceleration_are_functions_of_time():
    t = np.array([0.5, 1.0, 2.5])
    value, rate, acc = rate_motion(10.0, 4.0, -2.0, t, 0.5)
    dt = t - 0.5
    np.testing.assert_array_equal(value, 10.0 + 4.0 * dt - dt * dt)
    np.testing.assert_array_equal(rate, 4.0 - 2.0 * dt)
    np.testing.assert_array_equal(acc, [-2.0, -2.0, -2.0])


# ------------------------------------------------------------------ a solved mechanism
@pytest.mark.parametrize("method", ["auto", "newton"])
@pytest.mark.parametrize("law", ["cycloidal", "harmonic", "polynomial345"])
def test_crank_rocker_driven_by_a_law_matches_the_closed_form(law, method):
    """Positions, velocities and accelerations at 2001 instants (the vectorised general path
    and the dyads) equal the four-bar's closed form with the law's per-step omega and alpha."""
    text = crank_rocker(f'law = "{law}"\nfrom = 30.0\nto = 300.0',
                        "from = 0.0\nto = 1.5\nsteps = 2001")
    text = text.replace("[outputs]", f'[solver]\nmethod = "{method}"\ntol = 1e-14\n\n[outputs]')
    r = linkpipe.solve(scene_of(text))
    assert (r.status == OK).all()
    assert r.solver_method_used == ("dyads" if method == "auto" else "newton")
    _, s, sd, sdd = driver_motion(r.model)
    assert np.ptp(sd) > 1.0 and np.ptp(sdd) > 1.0  # the rates vary from step to step
    form = closed_forms.detect(r.scene, r.position[0])
    X, V, A = closed_forms.evaluate(form, r.scene, s[:, 0], sd[:, 0], sdd[:, 0])
    assert np.abs(X - r.position).max() <= 1e-12 * r.model.size
    assert np.abs(V - r.velocity).max() <= 1e-11 * np.abs(V).max()
    assert np.abs(A - r.acceleration).max() <= 1e-10 * np.abs(A).max()
    np.testing.assert_allclose(r.time, np.linspace(0.0, 1.5, 2001), rtol=0, atol=1e-15)
    value, rate, acc = law_motion(law, 30.0, 300.0, r.time, 0.0, 1.5)
    np.testing.assert_array_equal(r.driver_value[:, 0], value)
    np.testing.assert_array_equal(r.driver_velocity[:, 0], rate)
    np.testing.assert_array_equal(r.driver_acceleration[:, 0], acc)


def test_inertia_forces_follow_the_rates_step_by_step():
    """With inertia only, the input power F * omega equals the rate of change of kinetic
    energy at every step (d/dt by central differences in time: their error, about
    h^2/6 |KE'''|, is below 1e-5 of the peak power at 4001 instants of 2 s)."""
    masses = """
[analysis]
effects = ["inertia"]

[[masses]]
link = "coupler"
mass = 2.0
center = "P"
inertia = 0.3

[[masses]]
link = "rocker"
mass = 1.5
center = [1.5, 0.0]
inertia = 0.2
"""
    r = linkpipe.solve(scene_of(crank_rocker('law = "cycloidal"\nfrom = 0.0\nto = 360.0',
                                             "from = 0.0\nto = 2.0\nsteps = 4001", masses)))
    assert (r.status == OK).all()
    V, w = r.velocity, r.link_angular_velocity
    names = r.point_names
    vP = V[:, names.index("P")]
    vG = 0.5 * (V[:, names.index("O4")] + V[:, names.index("B")])  # centre halfway O4-B
    ke = (0.5 * 2.0 * (vP ** 2).sum(1) + 0.5 * 0.3 * w[:, 1] ** 2
          + 0.5 * 1.5 * (vG ** 2).sum(1) + 0.5 * 0.2 * w[:, 2] ** 2)
    power = r.forces["input_force"][1][:, 0] * np.radians(r.driver_velocity[:, 0])
    dke = np.gradient(ke, r.time)
    assert np.abs(power).max() > 1.0
    assert np.abs(dke - power)[1:-1].max() <= 1e-5 * np.abs(power).max()
    assert np.ptp(r.forces["input_force"][1][:, 0]) > 1.0


def test_uneven_steps_and_a_reversal_stay_on_the_vectorised_path():
    """A rate law that turns back (from 10 deg, rate 300 deg/s, acceleration -400 deg/s^2 over
    1.5 s: out to 122.5 deg at 0.75 s and back to 10) at 3000 unevenly spaced values: the
    vectorised general path (Hermite in the driver value, the turn a coarse node) solves
    nearly every step without the sequential continuation and agrees with it."""
    text = crank_rocker("from = 10.0\nrate = 300.0\nacceleration = -400.0",
                        "from = 0.0\nto = 1.5\nsteps = 3000")
    model = build_model(scene_of(text))
    _, s, _, _ = driver_motion(model)
    assert np.diff(s[:, 0]).max() > 0 > np.diff(s[:, 0]).min()  # it turns back
    out = solve_newton(model, s)
    assert out["sequential"].mean() < 0.1
    q, _, _, status = solve_positions(model, s, *start_state(model, s[0], model.tolerance(),
                                                             model.scene.solver.max_iter))
    assert (out["status"] == OK).all() and (status == OK).all()
    assert np.abs(out["q"] - q).max() <= 1e-10 * model.size


# ------------------------------------------------------------------ outputs
def test_run_writes_time_and_the_driver_rates(tmp_path):
    scene = tmp_path / "timed.toml"
    scene.write_text(crank_rocker('law = "polynomial345"\nfrom = 0.0\nto = 90.0',
                                  "from = 1.0\nto = 3.0\nstep = 0.01"))
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with h5py.File(tmp_path / "out" / "fourbar_crank_rocker.h5", "r") as f:
        t = f["time"][:]
        np.testing.assert_allclose(t, 1.0 + 0.01 * np.arange(201), rtol=0, atol=1e-12)
        assert f["driver_velocity"].attrs["units"] == "degree/s"
        assert f["driver_acceleration"].attrs["units"] == "degree/s^2"
        value, rate, acc = law_motion("polynomial345", 0.0, 90.0, t, 1.0, 2.0)
        np.testing.assert_allclose(f["driver_velocity"][:, 0], rate, rtol=0, atol=1e-12)
        np.testing.assert_allclose(f["driver_acceleration"][:, 0], acc, rtol=0, atol=1e-11)
        assert f["driver_velocity"].dims[1][0].name.endswith("driver")


def test_a_version_1_sweep_writes_its_driver_rates_too(tmp_path):
    """OUTPUT_FORMAT lists driver_velocity / driver_acceleration for every sweep: a version 1
    sweep's are its drivers' constant rate and acceleration at every step (the scene's own
    numbers, exactly), per driver in its own units; the slider's driver is a length."""
    for config, rate, acc, unit in (("fourbar_crank_rocker", 572.9577951308232, 0.0, "degree"),
                                    ("hard/slider_driven_dead_centres", 0.5, 0.0, "m")):
        scene = linkpipe.load_scene(CONFIGS / f"{config}.toml")
        d = scene.drivers[0]  # the scene's numbers, as parsed
        assert (d.rate, d.acceleration) == (rate, acc)
        assert main(["run", str(CONFIGS / f"{config}.toml"), "--out", str(tmp_path), "--quiet",
                     "--no-rrd"]) == 0
        with h5py.File(tmp_path / f"{scene.name}.h5", "r") as f:
            n = f["driver_value"].shape[0]
            np.testing.assert_array_equal(f["driver_velocity"][:], np.full((n, 1), rate))
            np.testing.assert_array_equal(f["driver_acceleration"][:], np.full((n, 1), acc))
            if unit == "degree":
                assert f["driver_velocity"].attrs["units"] == "degree/s"
                assert f["driver_acceleration"].attrs["units"] == "degree/s^2"
            assert f["driver_velocity"].attrs["driver_units"] == f"{unit}/s"
            assert f["driver_velocity"].dims[1][0].name.endswith("driver")


@pytest.mark.parametrize("method", ["auto", "newton"])
def test_a_single_instant_is_a_sweep_of_one_step(method, tmp_path):
    """[time] from = to = 2 s with steps = 1: the crank at 30 + 40 t + 25 t^2 / 2 degrees, t
    counted from [time]'s from (30 degrees, 40 deg/s, 25 deg/s^2 there); positions, velocities
    and accelerations are the four-bar's closed form, and the file holds that one instant."""
    text = crank_rocker("from = 30.0\nrate = 40.0\nacceleration = 25.0",
                        "from = 2.0\nto = 2.0\nsteps = 1")
    text = text.replace("[outputs]", f'[solver]\nmethod = "{method}"\n\n[outputs]')
    r = linkpipe.solve(scene_of(text))
    assert r.n_steps == 1 and (r.status == OK).all()
    np.testing.assert_array_equal(r.time, [2.0])
    assert (r.driver_value[0, 0], r.driver_velocity[0, 0], r.driver_acceleration[0, 0]) == (
        30.0, 40.0, 25.0)
    form = closed_forms.detect(r.scene, r.position[0])
    X, V, A = closed_forms.evaluate(form, r.scene, np.radians([30.0]), np.radians([40.0]),
                                    np.radians([25.0]))
    assert np.abs(X - r.position).max() <= 1e-12 * r.model.size
    assert np.abs(V - r.velocity).max() <= 1e-11 * np.abs(V).max()
    assert np.abs(A - r.acceleration).max() <= 1e-10 * np.abs(A).max()
    path = tmp_path / "one.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path), "--quiet"]) == 0
    with h5py.File(tmp_path / f"{r.scene.name}.h5", "r") as f:
        assert f["time"][:].tolist() == [2.0] and f["status"][:].tolist() == [OK]


@pytest.mark.parametrize("time, key, hint", [
    ("from = 1.0\nto = 3.0\nsteps = 1", "steps", "to = from for a single instant"),
    ("from = 1.0\nto = 1.0\nsteps = 5", "steps", "steps = 1 for a single instant"),
    ("from = 1.0\nto = 3.0\nsteps = 0", "steps", "steps >= 1"),
    ("from = 3.0\nto = 1.0\nsteps = 5", "to", "give to > from")])
def test_time_step_mistakes_point_to_a_fix_that_parses(time, key, hint):
    """Each message's advice, taken, gives a scene that parses (they once sent a user round in
    a loop between to = from and "time runs forward")."""
    with pytest.raises(SceneError) as err:
        scene_of(crank_rocker("from = 30.0\nrate = 40.0", time))
    assert err.value.key == key and hint in str(err.value), str(err.value)
    fixed = {"to = from for a single instant": "from = 1.0\nto = 1.0\nsteps = 1",
             "steps = 1 for a single instant": "from = 1.0\nto = 1.0\nsteps = 1",
             "steps >= 1": "from = 1.0\nto = 3.0\nsteps = 2",
             "give to > from": "from = 1.0\nto = 3.0\nsteps = 5"}[hint]
    assert scene_of(crank_rocker("from = 30.0\nrate = 40.0", fixed)).n_steps >= 1


@pytest.mark.parametrize("time, warned", [
    ("from = 1.0\nto = 1.0\nstep = 0.1", False),  # from, from + s, ... up to to: from alone
    ("from = 0.0\nto = 1.0\nstep = 2.0", True),   # the step passes to: from alone, warned
])
def test_a_time_step_that_leaves_a_single_instant(time, warned):
    """[time] follows the drivers' step formula: one instant at from; a step past to says so."""
    scene = scene_of(crank_rocker("from = 30.0\nrate = 40.0", time))
    assert scene.n_steps == 1 and list(scene.time.instants) == [scene.time.from_value]
    said = [w for w in scene.warnings if "[time] step = 2 oversteps to = 1" in w]
    assert len(said) == warned


def test_a_law_needs_time_to_move_in():
    with pytest.raises(SceneError) as err:
        scene_of(crank_rocker('law = "cycloidal"\nfrom = 30.0\nto = 90.0',
                              "from = 1.0\nto = 1.0\nsteps = 1"))
    assert err.value.key == "law" and "single instant" in str(err.value)


# ------------------------------------------------------------------ scene errors
BAD = [
    ("steps", crank_rocker('law = "linear"\nfrom = 0.0\nto = 90.0\nsteps = 10'), "steps"),
    ("none", crank_rocker("from = 0.0\nto = 90.0"), "log"),
    ("two", crank_rocker('law = "linear"\nfrom = 0.0\nto = 90.0\nrate = 2.0'), "rate"),
    ("unknown law", crank_rocker('law = "cycloid"\nfrom = 0.0\nto = 90.0'), "law"),
    ("rate to", crank_rocker("from = 0.0\nto = 90.0\nrate = 10.0"), "to"),
    ("backwards", crank_rocker('law = "linear"\nfrom = 0.0\nto = 90.0',
                               "from = 2.0\nto = 1.0\nsteps = 5"), "to"),
    ("no time", CRANK_ROCKER.replace(V1_DRIVER, 'law = "linear"\nfrom = 0.0\nto = 90.0'), "law"),
    ("scale", crank_rocker('law = "linear"\nfrom = 0.0\nto = 90.0\nscale = 2.0'), "scale"),
]


@pytest.mark.parametrize("case, text, key", BAD, ids=[b[0] for b in BAD])
def test_bad_time_scenes_name_the_key(case, text, key):
    with pytest.raises(SceneError) as err:
        scene_of(text)
    assert err.value.key == key, str(err.value)


def test_a_rate_driver_may_state_its_end_value():
    scene = scene_of(crank_rocker("from = 0.0\nto = 40.0\nrate = 10.0\nacceleration = 10.0"))
    assert math.isclose(scene.drivers[0].to_value, 40.0)


def test_keys_given_together_are_quoted_as_written():
    """Two exclusive keys: the message quotes the file's own values, so either half of the
    advice can be kept as it stands."""
    with pytest.raises(SceneError) as err:
        scene_of(crank_rocker('law = "polynomial345"\nfrom = 30.0\nto = 90.0\nrate = 12.5'))
    assert err.value.key == "rate"
    assert 'keep one of law = "polynomial345" or rate = 12.5' in str(err.value)
    text = CRANK_ROCKER.replace("steps = 361", "steps = 361\nstep = 2.0")
    with pytest.raises(SceneError) as err:
        scene_of(text)
    assert "keep one of steps = 361 or step = 2.0" in str(err.value)
