"""Forward dynamics ([dynamics]) against exact answers: IFToMM A01 against a high-accuracy
solution of its own ODE, A03 (Andrews) against the Hairer-Wanner Test Set, a spring-mass slider
against its closed form (period, amplitude, damped motion), energy balances, an event time
against the energy integral, A02's N-four-bar through its singular pose, the drivers' forces
(constant, law, log) against closed forms; bad input is one message, exit 2, nothing written."""
from __future__ import annotations

import pathlib

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st
from scipy.integrate import quad, solve_ivp

import linkpipe
from linkpipe.__main__ import main
from linkpipe.errors import SceneError
from linkpipe.scene import parse_scene
from linkpipe.status import NO_ASSEMBLY, OK

ROOT = pathlib.Path(__file__).resolve().parent.parent
DYN = ROOT / "configs" / "dynamics"
G = 9.81


def text_of(name: str) -> str:
    return (DYN / f"{name}.toml").read_text()


def solve_text(text: str, name: str = "scene") -> linkpipe.Result:
    return linkpipe.solve(parse_scene(text, f"{name}.toml"))


# -- IFToMM A01: the simple pendulum ----------------------------------------------------------

@pytest.fixture(scope="module")
def pendulum():
    return linkpipe.solve(DYN / "pendulum_a01.toml")


def test_pendulum_a01_follows_its_own_ode(pendulum):
    """theta'' = -(g / L) cos(theta) from rest at theta = 0, solved independently at rtol 1e-13:
    the angle within 1e-8 rad and P1 within 1e-8 m over 10 s (rtol 1e-11 over ~4 swings)."""
    r = pendulum
    ref = solve_ivp(lambda t, y: [y[1], -G * np.cos(y[0])], (0, 10), [0.0, 0.0],
                    method="DOP853", rtol=1e-13, atol=1e-14, dense_output=True)
    theta = ref.sol(r.time)[0]
    assert r.time[-1] == 10.0 and (r.status == OK).all()
    assert np.abs(np.deg2rad(r.driver_value[:, 0]) - theta).max() < 1e-8
    P1 = r.position[:, r.point_names.index("P1")]
    assert np.abs(P1 - np.c_[np.cos(theta), np.sin(theta)]).max() < 1e-8
    # the positions meet the rod's length to [solver] tol at every instant: no drift
    assert np.abs(np.hypot(P1[:, 0], P1[:, 1]) - 1.0).max() < 1e-12


def test_pendulum_energy_error_within_1e_8_m_g_L(pendulum):
    """The benchmark's own check: kinetic + potential stays at its start value to 1e-8 m g L
    over 10 s (the stored energy_error); by hand from the stored velocity and height too."""
    err = pendulum.forces["energy_error"][1]
    assert np.abs(err).max() <= 1e-8 * 1.0 * G * 1.0
    P1 = pendulum.point_names.index("P1")
    v = pendulum.velocity[:, P1]
    by_hand = 0.5 * (v ** 2).sum(axis=1) + G * pendulum.position[:, P1, 1]
    assert np.abs(by_hand - by_hand[0]).max() <= 1e-8 * G
    assert np.abs(err - (by_hand - by_hand[0])).max() < 1e-12  # the same energies


# -- IFToMM A03: Andrews' squeezing mechanism ---------------------------------------------------

def test_andrews_a03_matches_the_test_set():
    """Hairer-Wanner / Bari Test Set at t = 0.03 s: beta = 15.81077119629904 rad,
    beta' = 1139.920302151208 rad/s. At rtol 1e-10: beta within 1e-7 rad, beta' within 1e-5
    rad/s (rtol's relative size on 1140 rad/s, with the error grown over 16 rad of rotation)."""
    r = linkpipe.solve(DYN / "andrews_squeezer.toml")
    assert (r.status == OK).all() and r.time[-1] == pytest.approx(0.03, abs=1e-15)
    beta = np.deg2rad(r.driver_value[-1, 0])
    beta_dot = np.deg2rad(r.driver_velocity[-1, 0])
    assert abs(beta - 15.81077119629904) < 1e-7
    assert abs(beta_dot - 1139.920302151208) < 1e-5
    # the applied torque is the stored input force; the multipliers give it back from the
    # computed motion (an independent check of the equations of motion)
    assert np.all(r.forces["input_force"][1] == 0.033)
    # every output instant's positions meet the constraints to [solver] tol (no drift)
    assert np.all(r.residual <= r.model.tolerance())
    assert np.abs(r.forces["input_force_lagrange"][1] - 0.033).max() < 1e-9
    # the motor's work and the spring's energy balance the kinetic energy: energy_error ~ 0
    work = 0.033 * (np.deg2rad(r.driver_value[:, 0]) - np.deg2rad(r.driver_value[0, 0]))
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-8 * work[-1]


# -- a spring-mass slider: closed forms -------------------------------------------------------

M, K_SPRING, A0, X_EQ = 2.0, 200.0, 0.15, 0.5
W = np.sqrt(K_SPRING / M)


def test_spring_mass_period_and_amplitude():
    """x(t) = 0.5 + 0.15 cos(w t), w = sqrt(k / m): the whole motion within 1e-8 m, the
    amplitude within 1e-9 m, the period (from the velocity's upward zero crossings) within
    1e-8 s of 2 pi / w."""
    r = linkpipe.solve(DYN / "spring_mass_slider.toml")
    t, x, v = r.time, r.driver_value[:, 0], r.driver_velocity[:, 0]
    assert np.abs(x - (X_EQ + A0 * np.cos(W * t))).max() < 1e-8
    assert np.abs(v + A0 * W * np.sin(W * t)).max() < 1e-7
    assert abs(np.abs(x - X_EQ).max() - A0) < 1e-9
    up = np.flatnonzero((v[:-1] < 0) & (v[1:] >= 0))
    crossings = t[up] - v[up] * (t[up + 1] - t[up]) / (v[up + 1] - v[up])
    # linear interpolation between samples 1 ms apart: error ~ a''' dt^2 / 8 / a' ~ 1e-7 s;
    # the period as the mean spacing of four crossings cancels it to first order
    period = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert len(crossings) >= 4 and abs(period - 2 * np.pi / W) < 1e-8


def test_energy_conserved_without_damping_and_decreasing_with_it():
    """Without damping T + V stays within 1e-8 of its 2.25 J; with damping c = 4 N s/m
    (zeta = 0.1) T + V falls at every instant and energy_error (which counts the damper's
    work) stays within 1e-8 J; the motion is the damped closed form."""
    free = linkpipe.solve(DYN / "spring_mass_slider.toml")
    e0 = 0.5 * K_SPRING * A0 ** 2
    assert np.abs(free.forces["energy_error"][1]).max() < 1e-8 * e0
    c = 4.0
    text = text_of("spring_mass_slider").replace("free_length = 0.5",
                                                 f"free_length = 0.5\ndamping = {c}")
    text = text.replace('effects = ["springs", "inertia"]',
                        'effects = ["springs", "damping", "inertia"]')
    r = solve_text(text, "damped")
    v = r.driver_velocity[:, 0]
    E = 0.5 * M * v ** 2 + r.forces["spring_energy"][1][:, 0]
    assert np.all(np.diff(E) < 1e-12) and E[-1] < 0.01 * E[0]
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-8
    zeta = c / (2 * np.sqrt(K_SPRING * M))
    wd = W * np.sqrt(1 - zeta ** 2)
    t = r.time
    x = X_EQ + A0 * np.exp(-zeta * W * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta ** 2)
                                              * np.sin(wd * t))
    assert np.abs(r.driver_value[:, 0] - x).max() < 1e-8


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(k=st.floats(10.0, 5000.0), m=st.floats(0.1, 20.0), a=st.floats(-0.3, 0.3),
       v0=st.floats(-2.0, 2.0))
def test_spring_mass_family_follows_its_closed_form(k, m, a, v0):
    """Any stiffness, mass, start offset and start rate: x(t) = x_eq + a cos(w t) + (v0 / w)
    sin(w t) over 1 s at rtol 1e-10, within 1e-7 of the amplitude (the global error of an
    adaptive 8th-order method at rtol 1e-10 over up to 11 periods) plus 100 times the
    absolute tolerance rtol x the mechanism's size (0.75 m: a motion far smaller than the
    mechanism is controlled to that, not to its own amplitude)."""
    w = np.sqrt(k / m)
    amplitude = np.hypot(a, v0 / w)
    assume(amplitude < 0.45)  # the block stays right of the spring's anchor (x > 0): the
    # spring's length is x itself (past the anchor it would be |x|, another law)
    text = text_of("spring_mass_slider").replace("to = 3.0", "to = 1.0").replace(
        "output_step = 0.001", "output_step = 0.01")
    text = text.replace("k = 200.0", f"k = {k!r}").replace("mass = 2.0", f"mass = {m!r}")
    text = text.replace("from = 0.65", f"from = {0.5 + a!r}").replace(
        "start_rate = 0.0", f"start_rate = {v0!r}")
    text = text.replace("P = { x = 0.65", f"P = {{ x = {0.5 + a!r}").replace(
        "Q = { x = 0.75", f"Q = {{ x = {0.6 + a!r}")
    r = solve_text(text, "family")
    t = r.time
    x = 0.5 + a * np.cos(w * t) + v0 / w * np.sin(w * t)
    assert np.abs(r.driver_value[:, 0] - x).max() <= 1e-7 * amplitude + 100 * 1e-10 * 0.75


# -- the drivers' forces: constant, law, log ----------------------------------------------------

def pushed(force_line: str, extra: str = "") -> linkpipe.Result:
    """The slider without its spring, from rest, pushed by its driver's force."""
    text = text_of("spring_mass_slider").replace('effects = ["springs", "inertia"]',
                                                 'effects = ["inertia"]')
    text = text.replace("start_rate = 0.0", f"start_rate = 0.0\n{force_line}")
    return solve_text(extra + text, "pushed")


def test_constant_force_moves_the_block_by_f_t2_over_2m():
    r = pushed("force = 3.0")
    t = r.time
    assert np.abs(r.driver_value[:, 0] - (0.65 + 3.0 * t ** 2 / (2 * M))).max() < 1e-9
    assert np.all(r.forces["input_force"][1] == 3.0)
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-9  # the force's work counted


def test_force_law_and_force_log_ramp(tmp_path):
    """A linear ramp 0 -> 6 N over the 3 s: x = 0.65 + F1 t^3 / (6 m T), as a law and as a
    log column of the same ramp (a cubic spline through linear data is that line)."""
    expected = None
    law = pushed('force_law = { law = "linear", from = 0.0, to = 6.0 }')
    t = law.time
    expected = 0.65 + 6.0 * t ** 3 / (6 * M * 3.0)
    assert np.abs(law.driver_value[:, 0] - expected).max() < 1e-9
    log = tmp_path / "ramp.csv"
    ts = np.linspace(0, 3, 31)
    log.write_text("t,f_kN\n" + "".join(f"{float(a)!r},{float(a) * 2.0 / 1000!r}\n" for a in ts))
    logs = f'[[logs]]\nname = "rig"\nfile = "{log}"\ntime = "t"\n\n'
    logged = pushed('force_log = "rig.f_kN"\nscale = 1000.0', logs)
    assert np.abs(logged.driver_value[:, 0] - expected).max() < 1e-9
    assert np.abs(logged.forces["input_force"][1][:, 0] - 2.0 * t).max() < 1e-9


def test_force_log_with_units_offset_and_lag(tmp_path):
    """A cylinder pressure log as a rig writes it: column "p" in bar (units), acting on a
    10 mm^2 bore (scale = 1e-5 m^2), a -1 N offset (a seal's preload), stamps 0.25 s late
    (lag): the pressure p(t_true) = 2 + 4 t bar pushes with F = 2e5 x 1e-5 (1 + 2 t) - 1 = 1 + 4 t N,
    so x = 0.65 + t^2 / (2 m) + 4 t^3 / (6 m) (a cubic spline through linear samples is that
    line). Within 1e-8 m over the 9 m run (rtol 1e-10 of a motion 12x the mechanism's size);
    the stored input_force is 1 + 4 t to 1e-9 N. Read without its lag the log would start at
    0.25 s (a scene error: it must cover 0 .. to) and push 1 N less (2.25 m short at 3 s)."""
    lag = 0.25
    log = tmp_path / "rig.tsv"
    t_true = np.linspace(0.0, 3.0, 31)
    log.write_text("time\tp\n" + "".join(f"{float(a + lag)!r}\t{float(2 + 4 * a)!r}\n"
                                           for a in t_true))
    logs = (f'[[logs]]\nname = "rig"\nfile = "{log}"\ndelimiter = "\\t"\ntime = "time"\n'
            f'units = {{ p = "bar" }}\nlag = {lag}\n\n')
    r = pushed('force_log = "rig.p"\nscale = 1e-5\noffset = -1.0', logs)
    t = r.time
    assert np.abs(r.driver_value[:, 0] - (0.65 + t ** 2 / (2 * M) + 4 * t ** 3 / (6 * M))).max() < 1e-8
    assert np.abs(r.forces["input_force"][1][:, 0] - (1 + 4 * t)).max() < 1e-9
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-8 * 0.5 * M * r.driver_velocity[-1, 0] ** 2
    # a force column in kN with units: the same ramp as test_force_law_and_force_log_ramp's scale
    log2 = tmp_path / "kn.csv"
    log2.write_text("t,f\n" + "".join(f"{float(a)!r},{float(a) * 2.0 / 1000!r}\n" for a in t_true))
    logs2 = f'[[logs]]\nname = "rig"\nfile = "{log2}"\ntime = "t"\nunits = {{ f = "kN" }}\n\n'
    kn = pushed('force_log = "rig.f"', logs2)
    assert np.abs(kn.driver_value[:, 0] - (0.65 + 6.0 * t ** 3 / (6 * M * 3.0))).max() < 1e-9


@pytest.mark.parametrize("unit,key,words", [
    ("mm", "force_log", 'is in "mm", not a force or a pressure'),
    (None, "offset", "offset belongs to a force_log"),
])
def test_force_log_bad_units_and_a_stray_offset_are_scene_errors(tmp_path, unit, key, words):
    log = tmp_path / "rig.csv"
    log.write_text("t,p\n0.0,1.0\n5.0,2.0\n")
    units = f'units = {{ p = "{unit}" }}\n' if unit else ""
    logs = f'[[logs]]\nname = "rig"\nfile = "{log}"\ntime = "t"\n{units}\n'
    line = 'force_log = "rig.p"' if unit else "force = 1.0\noffset = 2.0"
    text = text_of("spring_mass_slider").replace("start_rate = 0.0", f"start_rate = 0.0\n{line}")
    with pytest.raises(SceneError) as err:
        parse_scene(logs + text, "bad.toml")
    assert err.value.key == key and words in err.value.message


# -- events -----------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_falling_lever_reaches_its_stop_at_the_energy_integrals_time(method):
    """The lever's time to the stop, t = integral dphi / sqrt((3 g / L) sin phi) over
    [0, asin 0.7] (quadrature with the 1/sqrt weight): the integration ends within 1e-9 s of it
    (it closes in on the last assembled instant to ~1e-15 s x t; the motion itself at rtol
    1e-10), every instant after it no_assembly, the summary says when and why; by either
    integrator (Radau's Jacobian columns step back from the stop where they must)."""
    text = text_of("falling_lever").replace("rtol = 1e-10", f'rtol = 1e-10\nmethod = "{method}"')
    r = solve_text(text, "falling_lever")
    assert method in r.time_note
    t_ref = quad(lambda p: np.sqrt(p / np.sin(p)) if p > 0 else 1.0, 0, np.arcsin(0.7),
                 weight="alg", wvar=(-0.5, 0), epsabs=1e-15, epsrel=1e-14)[0] / np.sqrt(3 * G)
    ended = float(r.time_note.split("ended at t = ")[1].split(" s")[0])
    assert abs(ended - t_ref) < 1e-9
    assert np.all(r.status[r.time <= t_ref] == OK) and np.all(r.status[r.time > t_ref] == NO_ASSEMBLY)
    assert "out of assembly" in r.time_note
    last = np.flatnonzero(r.status == OK)[-1]
    assert np.isnan(r.position[last + 1:, r.point_names.index("A")]).all()


def test_a02_n_fourbar_passes_its_singular_pose_at_the_closed_form_time():
    """A02 with N = 4 (the shipped scene has N = 40): started upright at 1 m/s, the rods are
    all parallel, so theta'^2 = 1 + 2 g c (1 - sin theta) / J (J = (N+1)/3 + N, c = (N+1)/2 + N)
    and the horizontal pose comes at t* = integral dtheta / theta' over [0, pi/2]. The
    integration steps over the singular pose (no stage lands within the singular test's reach
    of it; the continuation keeps the parallelogram branch): theta crosses 0 at t* to 1e-6 s
    and the energy stays within 1e-6 of its scale."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_n_fourbar", DYN / "make_n_fourbar.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    n = 4
    r = solve_text(gen.scene_text(n, to=1.0, output_step=0.001), "a02")
    J, c = (n + 1) / 3 + n, (n + 1) / 2 + n
    t_star = quad(lambda th: 1 / np.sqrt(1 + 2 * G * c * (1 - np.sin(th)) / J), 0, np.pi / 2,
                  epsabs=1e-13, epsrel=1e-13)[0]
    theta = np.deg2rad(r.driver_value[:, 0])
    i = np.flatnonzero((theta[:-1] > 0) & (theta[1:] <= 0))[0]
    crossing = r.time[i] + theta[i] / (theta[i] - theta[i + 1]) * (r.time[i + 1] - r.time[i])
    assert abs(crossing - t_star) < 1e-6
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-6 * G * c


# -- stroke-end events --------------------------------------------------------------------------

def ended_at(r) -> float:
    return float(r.time_note.split("ended at t = ")[1].split(" s")[0])


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_a_pushed_block_stops_at_its_stroke_end_at_sqrt_2_d_m_over_f(method):
    """The 2 kg block pushed by a constant 3 N from rest at 0.65 m, its driver's stroke
    [0.5, 1.0]: it reaches the longest end after d = 0.35 m at t = sqrt(2 d m / F) = 0.6831 s.
    The integration ends there to 1e-9 s (the event on the dense output at rtol 1e-10, plus the
    allowance of [solver] tol beyond the end: 1e-10 m / 2.05 m/s), said in the summary; every
    instant before is ok, every one after no_assembly (NaN), by either integrator."""
    text = text_of("spring_mass_slider").replace("rtol = 1e-10", f'rtol = 1e-10\nmethod = "{method}"')
    r = solve_text(text.replace('effects = ["springs", "inertia"]', 'effects = ["inertia"]')
                   .replace("start_rate = 0.0", "start_rate = 0.0\nforce = 3.0\nstroke = [0.5, 1.0]"),
                   "stroke")
    t_ref = np.sqrt(2 * 0.35 * M / 3.0)
    assert abs(ended_at(r) - t_ref) < 1e-9
    assert "out of stroke: driver x at the longest end of its stroke (1 m" in r.time_note
    assert method in r.time_note
    assert np.all(r.status[r.time <= t_ref] == OK) and np.all(r.status[r.time > t_ref] == NO_ASSEMBLY)
    assert np.isnan(r.driver_value[r.time > t_ref]).all()
    ok = r.status == OK
    assert np.abs(r.driver_value[ok, 0] - (0.65 + 3.0 * r.time[ok] ** 2 / (2 * M))).max() < 1e-9
    # the margin stays inside the stroke at every stored instant (the last one 0.00013 m short)
    assert np.nanmin(r.stroke_margin[ok]) > 0


def test_a_gas_springs_compressed_length_ends_the_run_like_a_drivers_stroke():
    """The block pushed left by 3 N onto a gas strut S-P (compressed_length 0.3 m, a 1e-12 N
    push: its force moves the block by < 1e-12 m) reaches 0.3 m at t = sqrt(2 x 0.35 m x 2 kg
    / 3 N): the gas spring's stroke is found from the positions at the state (not the
    driver's value), to 1e-9 s of the closed form."""
    text = text_of("spring_mass_slider").replace(
        "start_rate = 0.0", "start_rate = 0.0\nforce = -3.0")
    text = text.replace("k = 200.0\nfree_length = 0.5",
                        'kind = "gas"\nforce_extended = 1e-12\nextended_length = 1.0\n'
                        "dead_length = 0.0\ngamma = 1.0\ncompressed_length = 0.3")
    r = solve_text(text, "gas_stroke")
    t_ref = np.sqrt(2 * 0.35 * M / 3.0)
    assert abs(ended_at(r) - t_ref) < 1e-9
    assert "gas spring spring at the shortest end of its stroke (0.3 m" in r.time_note
    assert np.all(r.status[r.time <= t_ref] == OK) and np.all(r.status[r.time > t_ref] == NO_ASSEMBLY)


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_an_angle_drivers_stroke_ends_the_falling_lever_at_the_energy_integrals_time(method):
    """The falling lever with stroke = [-30, 10] deg on its angle: it reaches -30 deg (before
    its tether's -44.4 deg stop) at t = integral dphi / sqrt((3 g / L) sin phi) over
    [0, pi/6]; the stroke in degrees, the state in radians: the end within 1e-9 s."""
    text = text_of("falling_lever").replace("rtol = 1e-10", f'rtol = 1e-10\nmethod = "{method}"')
    text = text.replace("from = 0.0", "from = 0.0\nstroke = [-30.0, 10.0]")
    r = solve_text(text, "stroke_lever")
    t_ref = quad(lambda p: np.sqrt(p / np.sin(p)) if p > 0 else 1.0, 0, np.pi / 6,
                 weight="alg", wvar=(-0.5, 0), epsabs=1e-15, epsrel=1e-14)[0] / np.sqrt(3 * G)
    assert abs(ended_at(r) - t_ref) < 1e-9
    assert "driver fall at the shortest end of its stroke (-30 deg" in r.time_note
    assert np.all(r.status[r.time <= t_ref] == OK) and np.all(r.status[r.time > t_ref] == NO_ASSEMBLY)


def test_a_start_outside_the_stroke_ends_the_run_at_once():
    """Started at 0.65 m with stroke [0.7, 1.0]: the start instant is out_of_stroke (its values
    kept), the integration ends at t = 0 and every later instant is no_assembly."""
    from linkpipe.status import OUT_OF_STROKE

    text = text_of("spring_mass_slider").replace(
        "start_rate = 0.0", "start_rate = 0.0\nstroke = [0.7, 1.0]")
    r = solve_text(text, "outside")
    assert "ended at t = 0 s: out of stroke at the start: driver x at the shortest end" in r.time_note
    assert r.status[0] == OUT_OF_STROKE and r.driver_value[0, 0] == 0.65
    assert np.all(r.status[1:] == NO_ASSEMBLY)


# -- outputs ----------------------------------------------------------------------------------

def test_run_writes_the_usual_files_on_time(tmp_path):
    assert main(["run", str(DYN / "falling_lever.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    with h5py.File(tmp_path / "falling_lever.h5") as f:
        t, status = f["time"][:], f["status"][:]
        assert f["energy_error"].dims[0][0].name.endswith("step")
        assert np.allclose(np.diff(t), 0.001) and len(t) == 1001
        assert np.isfinite(f["energy_error"][:][status == OK]).all()
        assert "out of assembly" in f.attrs["time_note"]
    assert (tmp_path / "falling_lever.rrd").stat().st_size > 0


# -- bad input --------------------------------------------------------------------------------

BAD = [
    ("[time]\nfrom = 0.0\nto = 1.0\nsteps = 11\n", None, "dynamics", None),
    ("", ("start_rate = 0.0", "start_rate = 0.0\nforce = 1.0\nlaw = \"linear\""), 'drivers "x"',
     "law"),
    ("", ("output_step = 0.001", "output_step = 0.0"), "dynamics", "output_step"),
    ("", ("output_step = 0.001", "output_step = -0.01"), "dynamics", "output_step"),
    ("", ("to = 3.0", "to = 0.0"), "dynamics", "to"),
    ("", ("to = 3.0", "to = -1.0"), "dynamics", "to"),
    ("", ("start_rate = 0.0", "start_rate = 0.0\nforce = 1.0\nforce_law = { law = \"linear\", "
          "from = 0.0, to = 1.0 }"), 'drivers "x"', "force_law"),
    ("", ("rtol = 1e-10", "rtol = 0.0"), "dynamics", "rtol"),
    ("", ("start_rate = 0.0", "start_rate = 0.0\nsteps = 10"), 'drivers "x"', "steps"),
]


@pytest.mark.parametrize("prefix,swap,table,key", BAD)
def test_bad_dynamics_input_is_one_message_exit_2_nothing_written(tmp_path, prefix, swap,
                                                                   table, key, capsys):
    text = text_of("spring_mass_slider")
    if swap:
        assert swap[0] in text
        text = text.replace(swap[0], swap[1], 1)
    path = tmp_path / "bad.toml"
    path.write_text(prefix + text)
    with pytest.raises(SceneError) as err:
        linkpipe.load_scene(path)
    assert err.value.table == table and err.value.key == key
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    printed = capsys.readouterr().err
    assert str(path) in printed and "Traceback" not in printed and printed.count("error:") == 1
    assert not out.exists() or not any(out.iterdir())


def test_a_mass_free_mechanism_is_a_scene_error(tmp_path, capsys):
    """No [[masses]]: the drivers' mass matrix is singular (a force would accelerate them
    without bound): [masses] named, exit 2, nothing written."""
    text = text_of("spring_mass_slider")
    text = text[:text.index("[[masses]]")].replace('effects = ["springs", "inertia"]',
                                                    'effects = ["springs"]')
    path = tmp_path / "massless.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        linkpipe.solve(linkpipe.load_scene(path))
    assert err.value.table == "masses" and "singular" in err.value.message
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    assert main(["check", str(path)]) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


# -- friction at pins and sliders: solved with the accelerations ------------------------------

MU_R = 0.2 * 0.05  # the lever's pivot: mu 0.2 on a 50 mm pin


def lever_pin_friction_accel(theta, w):
    """The falling lever's own equation with its pivot's friction circle, written here by
    hand: (m L^2 / 3) theta'' = -m g (L / 2) cos theta - mu r |F| sign(w), F = m a_G - m g the
    pin's force on the lever, a_G = (L / 2) (theta'' e_t - w^2 e_r): theta'' by fixed point."""
    a = -1.5 * G * np.cos(theta)
    e_r, e_t = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
    for _ in range(200):
        pin = 0.5 * (a * e_t - w ** 2 * e_r) + np.array([0.0, G])  # m = 1 kg, L = 1 m
        new = (-0.5 * G * np.cos(theta) - MU_R * np.hypot(*pin) * np.sign(w)) * 3.0
        if abs(new - a) <= 1e-15 * abs(new):
            return new
        a = new
    raise AssertionError("the reference's fixed point did not converge")


@pytest.mark.parametrize("method", ["DOP853"])  # Radau's path: the seal's test (same sdd)
def test_the_falling_lever_with_pin_friction_follows_its_own_ode(method):
    """The falling lever with friction at its pivot O (mu 0.2, r 50 mm; regularised at 1e-9 x
    size per s): theta within 1e-8 rad of scipy's DOP853 (rtol 1e-12) on the lever's own
    equation with its friction circle (torque W L cos(theta) / 2 + mu r |F|, the pin force F
    depending on theta'' : :func:`lever_pin_friction_accel`) up to the tether's stop, which
    comes later than without friction; the stored friction_force is mu r |F| at the stored
    motion's pin force (joint_force at O) to 1e-9 N m; energy_error (gravity's energy, the
    pivot's work) within 1e-8 J (rtol on the 3.4 J exchanged) and T + V falls at every
    instant by friction's work (the stored friction_power by Simpson's rule, 1e-8 J)."""
    from scipy.integrate import cumulative_simpson

    text = text_of("falling_lever").replace("rtol = 1e-10", f'rtol = 1e-10\nmethod = "{method}"')
    text = text.replace('effects = ["gravity", "inertia"]',
                        'effects = ["gravity", "inertia", "friction"]')
    r = solve_text(text + '\n[[friction]]\nname = "pivot"\njoints = ["O"]\nmu = 0.2\n'
                   "pin_radius = 0.05\n[solver]\nfriction_velocity_scale = 1e-9\n", "lever_pin")
    ok = r.status == OK
    t = r.time[ok]
    assert ended_at(r) > 0.328 and "out of assembly" in r.time_note  # 0.32797 s frictionless
    ref = solve_ivp(lambda _, y: [y[1], lever_pin_friction_accel(y[0], y[1])], (0, t[-1]),
                    [0.0, 0.0], t_eval=t, rtol=1e-12, atol=1e-14, method="DOP853")
    assert np.abs(np.radians(r.driver_value[ok, 0]) - ref.y[0]).max() < 1e-8
    pin = r.forces["joint_force"][1][ok][:, r.force_coords["joint"].index("O@lever")]
    moving = t > 1e-3  # past the regularised sign's first microseconds
    assert np.abs(r.forces["friction_force"][1][ok, 0] - MU_R * np.hypot(*pin.T))[moving].max() < 1e-9
    err = r.forces["energy_error"][1][ok]
    assert np.abs(err).max() < 1e-8  # ~4e-10 of the 3.4 J gravity gives up by the stop
    w = np.radians(r.driver_velocity[ok, 0])
    E = 0.5 * w ** 2 / 3.0 + r.forces["gravity_energy"][1][ok]
    assert np.all(np.diff(E) < 0)
    by_power = cumulative_simpson(r.forces["friction_power"][1][ok, 0], x=t, initial=0.0)
    assert np.abs((E - E[0]) - by_power).max() < 1e-8


def test_a_block_pushed_along_a_rough_guide_follows_f_minus_mu_m_g():
    """The 2 kg block on its horizontal guide under gravity, friction mu 0.2 on guide_p (its
    centre of mass P's guide carries the whole weight), pushed by 5 N from rest: x = x0 + (F -
    mu m g) t^2 / 2m, the friction force mu m g = 3.924 N solved with the guide's normal force;
    the regularised sign (v_s = 1e-9 m/s) takes < c v_s ln2 / a_min = 5e-9 N s of impulse:
    within 1e-8 m over 0.5 s; energy_error within 1e-9 J while T falls short of F (x - x0) by
    exactly mu m g (x - x0) (1e-8 J)."""
    text = text_of("spring_mass_slider").replace(
        'effects = ["springs", "inertia"]',
        'effects = ["gravity", "inertia", "friction"]\n[gravity]\ng = [0.0, -9.81]')
    text = text.replace("start_rate = 0.0", "start_rate = 0.0\nforce = 5.0")
    text = text.replace("to = 3.0", "to = 0.5")
    r = solve_text(text + '\n[[friction]]\nname = "rail"\nslider = "guide_p"\nmu = 0.2\n'
                   "[solver]\nfriction_velocity_scale = 1e-9\n", "rough")
    t, c = r.time, 0.2 * M * G
    assert np.all(r.status == OK)
    dx = r.driver_value[:, 0] - 0.65
    assert np.abs(dx - (5.0 - c) * t ** 2 / (2 * M)).max() < 1e-8
    assert np.abs(r.forces["friction_force"][1][t > 1e-3, 0] - c).max() < 1e-9
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-9
    T = 0.5 * M * r.driver_velocity[:, 0] ** 2
    assert np.abs(T - 5.0 * dx + c * dx).max() < 1e-8


# -- friction: an actuator's seal ----------------------------------------------------------------

SEAL_C, SEAL_B, PUSH = 0.5, 2.0, 3.0  # N, N s/m, N


def sealed_block(v_s: float) -> linkpipe.Result:
    """The 2 kg block without its spring pushed from rest by 3 N against its driver's seal:
    Coulomb 0.5 N + viscous 2 N s/m, sign regularised at v_s (m/s), over 1 s."""
    text = text_of("spring_mass_slider").replace('effects = ["springs", "inertia"]',
                                                 'effects = ["inertia", "friction"]')
    text = text.replace("start_rate = 0.0", f"start_rate = 0.0\nforce = {PUSH}")
    text = text.replace("to = 3.0", "to = 1.0")
    text += (f'\n[[friction]]\nname = "seal"\ndriver = "x"\ncoulomb = {SEAL_C}\n'
             f"viscous = {SEAL_B}\n[solver]\nfriction_velocity_scale = {v_s}\n")
    return solve_text(text, "sealed")


def test_a_sealed_block_follows_the_coulomb_viscous_closed_form():
    """m x'' = F - c - b x' from rest (F > c): x = x0 + V (t - (1 - e^(-k t)) / k), V = (F - c)
    / b, k = b / m. The regularised sign gives the first microsecond less than c: an impulse c
    v_s ln2 m / F = 2.3e-8 N s at v_s = 1e-7 m/s, 7e-9 m of travel by 1 s; the integration
    (rtol 1e-10 on 1.9 m) 2e-10 m: within 2e-8 m. The stored friction_force is c + b v (the
    force stage's own seal law at the stored rate) to 1e-7 N, input_force the applied 3 N and
    input_force_lagrange (m a + f by the multipliers) the same to 1e-9 N."""
    r = sealed_block(1e-7)
    t, k, V = r.time, SEAL_B / M, (PUSH - SEAL_C) / SEAL_B
    x = 0.65 + V * (t - (1 - np.exp(-k * t)) / k)
    v = V * (1 - np.exp(-k * t))
    assert np.all(r.status == OK)
    assert np.abs(r.driver_value[:, 0] - x).max() < 2e-8
    assert np.abs(r.driver_velocity[:, 0] - v).max() < 3e-8
    moving = t > 1e-3  # past the regularised sign's microsecond
    assert np.abs(r.forces["friction_force"][1][moving, 0] - (SEAL_C + SEAL_B * v[moving])).max() < 1e-7
    assert np.all(r.forces["input_force"][1] == PUSH)
    # the multipliers' force for this motion, the seal's share included, is the applied push
    assert np.abs(r.forces["input_force_lagrange"][1][:, 0] - PUSH).max() < 1e-9


def test_a_sealed_block_loses_exactly_frictions_work():
    """Energy with friction: T - T0 - W_push decreases (falls at every instant), and equals
    friction's work three ways: the integrated W_friction (energy_error within 1e-9 J of 0 on
    ~1.5 J of work), the stored friction_power integrated by Simpson's rule over the 1 ms
    instants (its h^4 error: < 1e-8 J), and the closed form -(c (x - x0) + b integral v^2 dt),
    integral v^2 = V^2 (t - 2 (1 - e^(-k t)) / k + (1 - e^(-2 k t)) / (2 k)) (the regularised
    sign's 2.3e-8 N s impulse: < 1e-7 J)."""
    from scipy.integrate import cumulative_simpson

    r = sealed_block(1e-7)
    t, k, V = r.time, SEAL_B / M, (PUSH - SEAL_C) / SEAL_B
    v = r.driver_velocity[:, 0]
    T = 0.5 * M * v ** 2
    lost = T - T[0] - PUSH * (r.driver_value[:, 0] - 0.65)  # the push's work: F (x - x0)
    assert np.all(np.diff(lost) < 0) and lost[-1] < -0.5
    assert np.abs(r.forces["energy_error"][1]).max() < 1e-9
    power = r.forces["friction_power"][1][:, 0]
    assert np.all(power <= 0)
    by_power = cumulative_simpson(power, x=t, initial=0.0)
    assert np.abs(lost - by_power).max() < 1e-8
    x = 0.65 + V * (t - (1 - np.exp(-k * t)) / k)
    v2 = V ** 2 * (t - 2 * (1 - np.exp(-k * t)) / k + (1 - np.exp(-2 * k * t)) / (2 * k))
    assert np.abs(lost + SEAL_C * (x - 0.65) + SEAL_B * v2).max() < 1e-7
    # without the seal the same push conserves: energy_error as small, T - T0 = F (x - x0)
    free = pushed(f"force = {PUSH}")
    vf = free.driver_velocity[:, 0]
    assert np.abs(0.5 * M * vf ** 2 - PUSH * (free.driver_value[:, 0] - 0.65)).max() < 1e-9


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_the_falling_lever_with_a_stribeck_hinge_seal_follows_its_own_ode(method):
    """A rotary seal on the falling lever's angle driver (Coulomb 1 N m, Stribeck peak 1.5 N m
    at 0.3 rad/s, viscous 0.5 N m s/rad; regularised at 1e-9 x size per second): the motion
    against scipy's DOP853 (rtol 1e-12) on the lever's own equation (m L^2 / 3) theta'' = -m g
    (L / 2) cos theta - f(theta'), f the exact-sign law, to 1e-8 rad (rtol 1e-10 and the
    regularisation's ~1e-9 s at rest); the stop (the tether run out) comes later than without
    friction; energy_error (gravity's energy, the seal's work) within 1e-9 J of 0 and T + V
    falls by friction's work at every instant."""
    text = text_of("falling_lever").replace("rtol = 1e-10", f'rtol = 1e-10\nmethod = "{method}"')
    text = text.replace('effects = ["gravity", "inertia"]',
                        'effects = ["gravity", "inertia", "friction"]')
    text += ('\n[[friction]]\nname = "hinge_seal"\ndriver = "fall"\ncoulomb = 1.0\n'
             "viscous = 0.5\nstribeck = { peak = 1.5, velocity = 0.3 }\n[solver]\n"
             "friction_velocity_scale = 1e-9\n")
    r = solve_text(text, "lever_seal")
    ok = r.status == OK
    t = r.time[ok]
    assert ended_at(r) > 0.33  # without friction: 0.32797 s

    def law(w):
        return (1.0 + 0.5 * np.exp(-(w / 0.3) ** 2)) * np.sign(w) + 0.5 * w

    def lever(_, y):
        return [y[1], (-G * 0.5 * np.cos(y[0]) - law(y[1])) * 3.0]

    ref = solve_ivp(lever, (0, t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-12, atol=1e-14,
                    method="DOP853")
    assert np.abs(np.radians(r.driver_value[ok, 0]) - ref.y[0]).max() < 1e-8
    err = r.forces["energy_error"][1][ok]
    assert np.abs(err).max() < 1e-9
    w = np.radians(r.driver_velocity[ok, 0])
    E = 0.5 * w ** 2 / 3.0 + r.forces["gravity_energy"][1][ok]
    assert np.all(np.diff(E) < 0)
    assert np.abs(r.forces["friction_power"][1][ok, 0] + law(w) * w)[t > 1e-3].max() < 1e-8


def test_dynamics_keys_outside_dynamics_are_errors():
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    text = text.replace('steps = 361', 'steps = 361\nforce = 1.0', 1)
    with pytest.raises(SceneError) as err:
        parse_scene(text, "x.toml")
    assert err.value.key == "force" and "[dynamics]" in err.value.message


# -- study and accuracy ---------------------------------------------------------------------

def test_a_study_of_dynamics_scenes_gives_each_variants_closing_time(tmp_path):
    """configs/studies/hatch_closing.toml: each variant integrated on its own; the 300 N
    variant's closing time is the scene's own run's last ok instant, and a weaker strut closes
    the tailgate sooner (gravity's torque is the same, the strut's smaller)."""
    from linkpipe.stores.study import read_arrays

    study_file = ROOT / "configs" / "studies" / "hatch_closing.toml"
    assert main(["study", str(study_file), "--out", str(tmp_path)]) == 0
    f = read_arrays(tmp_path / "hatch_closing_study.h5")
    own = linkpipe.solve(DYN / "hatch_closing.toml")
    assert f["closing_time"][-1] == own.time[own.status == OK].max()
    assert np.all(np.diff(f["closing_time"]) > 0)
    ended = float(own.time_note.split("ended at t = ")[1].split(" s")[0])
    assert 0 <= ended - f["closing_time"][-1] < 0.001  # within one output step


def test_a_study_over_the_push_gives_each_variants_stroke_end_time(tmp_path):
    """A study of the pushed block (stroke [0.5, 1.0] m, 0.35 m to go) over its force 1, 2.5, 4 N:
    each variant's last ok instant is the output instant at or just before its own
    t = sqrt(2 d m / F) (its stroke event), within one output step."""
    from linkpipe.stores.study import read_arrays

    text = text_of("spring_mass_slider").replace('effects = ["springs", "inertia"]',
                                                 'effects = ["inertia"]')
    text = text.replace("start_rate = 0.0", "start_rate = 0.0\nforce = 1.0\nstroke = [0.5, 1.0]")
    text = text.replace("rtol = 1e-10", "rtol = 1e-9")
    (tmp_path / "pushed.toml").write_text(text)
    study = tmp_path / "push_study.toml"
    study.write_text('[scene]\nname = "push"\n[study]\nbase = "pushed.toml"\n'
                     '[study.parameters]\n"drivers.x.force" = { from = 1.0, to = 4.0, steps = 3 }\n'
                     '[study.metrics]\nend = "max(time)"\n')
    assert main(["study", str(study), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    f = read_arrays(tmp_path / "out" / "push_study.h5")
    t_ref = np.sqrt(2 * 0.35 * M / np.array([1.0, 2.5, 4.0]))
    assert np.all((t_ref - f["end"] >= 0) & (t_ref - f["end"] < 0.001 + 1e-12))


def test_accuracy_ladders_rtol_on_a_dynamics_scene(tmp_path):
    """`accuracy` on a dynamics scene: one row per integrator and rtol, each against DOP853 at
    rtol 1e-13; DOP853's position error falls as rtol does and stays within 100 x rtol of the
    mechanism's size (the global error of an adaptive method is a few times its local rtol)."""
    text = text_of("spring_mass_slider").replace("to = 3.0", "to = 0.3")
    path = tmp_path / "spring_mass_slider.toml"
    path.write_text(text)
    assert main(["accuracy", str(path), "--quick", "--repeats", "1", "--out", str(tmp_path)]) == 0
    with h5py.File(tmp_path / "spring_mass_slider_accuracy.h5") as f:
        knob = f["knob"][:].astype(str)
        value = f["value"][:].astype(float)
        path_ = f["path"][:].astype(str)
        q = list(f["quantity"][:].astype(str))
        err = f["relative_error"][:, q.index("position")]
    assert set(knob) == {"rtol"} and set(path_) == {"DOP853", "Radau"}
    dop = path_ == "DOP853"
    order = np.argsort(-value[dop])
    assert np.all(np.diff(err[dop][order]) < 0)
    assert np.all(err[dop] < 100 * value[dop])


def test_check_describes_the_dynamics(capsys):
    """`check` on a dynamics scene says its span, integrator and each driver's start and force
    (and checks its mass matrix: test_a_mass_free_mechanism_is_a_scene_error)."""
    assert main(["check", str(DYN / "andrews_squeezer.toml"), str(DYN / "falling_lever.toml")]) == 0
    out = capsys.readouterr().out
    assert "dynamics: 0 .. 0.03 s, output every 0.0001 s (301 instants), DOP853 at rtol 1e-10" in out
    assert "crank from -3.53595 degree at 0 degree/s, force 0.033 N*m" in out
    assert "fall from 0 degree at 0 degree/s, free" in out


def test_an_input_on_a_dynamics_driver_is_warned_about():
    text = text_of("spring_mass_slider").replace(
        "start_rate = 0.0", 'start_rate = 0.0\ninput = { point = "Q", direction = [1.0, 0.0] }')
    scene = parse_scene(text, "pushed.toml")
    assert any("input is not used with [dynamics]" in w for w in scene.warnings)
