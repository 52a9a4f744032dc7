"""Version 2 drivers: ``distance`` (a linear actuator), ``angle`` with ``relative_to`` (a motor
between two links) and ``input.link`` (a push that turns with a link).

Every answer here is independent of linkpipe's equations: closed-form positions and their
time derivatives (law of cosines; a two-link arm's forward kinematics), statics by hand
(moments about a pivot), and the layout / derivative checks of ``test_kernels`` on scenes that
use the new rows.
"""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe.model import build_model
from linkpipe.scene import parse_scene
from linkpipe.status import NO_LEVERAGE, OK

from test_kernels import _derivatives_agree, _layouts_agree

# positions are solved to tol 1e-12 of the size (about 1 m): 1e-9 m leaves room for the
# condition of the steps near the ends of the stroke
POS_TOL = 1e-9


def cylinder_rocker(s_from=0.9, s_to=1.6, steps=71, rate=0.1, acceleration=0.0, R=1.0,
                    C=(0.5, -0.8), load=(0.0, -100.0), method="auto", extra=""):
    """A rocker O-B (length R) pushed by a cylinder from the fixed pin C to B."""
    return parse_scene(f"""
[scene]
name = "cylinder_rocker"
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
B = {{ x = {R}, y = 0.0 }}
C = {{ x = {C[0]}, y = {C[1]}, fixed = true }}
[[links]]
name = "rocker"
points = ["O", "B"]
[[drivers]]
name = "cylinder"
distance = ["C", "B"]
from = {s_from}
to = {s_to}
steps = {steps}
rate = {rate}
acceleration = {acceleration}
[solver]
method = "{method}"
[analysis]
effects = ["loads"]
[[loads]]
name = "weight"
point = "B"
force = [{load[0]}, {load[1]}]
[outputs]
kinematics = ["velocity", "acceleration"]
{extra}
""", "cylinder_rocker.toml")


def _rocker_closed_form(s, sd, sdd, R, C):
    """B on the circle |B| = R at distance s from C, on the side the scene draws it (the
    rocker turned clockwise of C's direction at the start... solved by the law of cosines),
    with its velocity and acceleration by differentiating s^2 = R^2 + c^2 - 2 R c cos(t - tc)."""
    c = math.hypot(*C)
    tc = math.atan2(C[1], C[0])
    cos_rel = (R * R + c * c - s * s) / (2 * R * c)
    rel = np.arccos(cos_rel)  # theta - tc in (0, pi): B counter-clockwise of C seen from O
    theta = tc + rel
    sin_rel = np.sin(rel)
    w = s * sd / (R * c * sin_rel)
    al = (s * sdd + sd * sd - R * c * np.cos(rel) * w * w) / (R * c * sin_rel)
    e = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    n = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    return R * e, R * w[:, None] * n, R * al[:, None] * n - R * (w * w)[:, None] * e


@pytest.mark.parametrize("method", ["dyads", "newton"])
def test_cylinder_rocker_motion_is_the_closed_form(method):
    scene = cylinder_rocker(rate=0.1, acceleration=0.05, method=method)
    r = linkpipe.solve(scene)
    assert r.message == "all 71 steps ok"
    s = np.linspace(0.9, 1.6, 71)
    B, V, A = _rocker_closed_form(s, np.full(71, 0.1), np.full(71, 0.05), 1.0, (0.5, -0.8))
    b = r.point_names.index("B")
    assert np.abs(r.position[:, b] - B).max() < POS_TOL
    # velocities and accelerations are linear solves at those positions: the same order
    assert np.abs(r.velocity[:, b] - V).max() < POS_TOL
    assert np.abs(r.acceleration[:, b] - A).max() < POS_TOL
    if method == "dyads":
        assert "r=driver 0" in r.solver_note  # the cylinder closed as a circle of the fast path


def test_cylinder_force_is_statics_by_hand():
    """Moments about O: r_OB x (F_c u_CB + W) = 0, F_c positive pushing the pins apart."""
    scene = cylinder_rocker(load=(30.0, -100.0))
    r = linkpipe.solve(scene)
    B = r.position[:, r.point_names.index("B")]
    u = B - np.array([0.5, -0.8])
    u /= np.hypot(u[:, 0], u[:, 1])[:, None]
    W = np.array([30.0, -100.0])
    moment_load = B[:, 0] * W[1] - B[:, 1] * W[0]
    moment_unit = B[:, 0] * u[:, 1] - B[:, 1] * u[:, 0]
    expected = -moment_load / moment_unit
    f = r.forces["input_force"][1][:, 0]
    fl = r.forces["input_force_lagrange"][1][:, 0]
    # 100 N loads on a 1 m rocker: rounding of the solves is ~1e-13 N; 1e-8 N leaves room for
    # the 1e-12 position tolerance times the lever arm's sensitivity
    assert np.abs(f - expected).max() < 1e-8
    assert np.abs(fl - expected).max() < 1e-8
    assert (expected > 0).all()  # lifting the weight: the cylinder pushes
    # a cylinder acts on its pins like a load: the pin at B exerts on the rocker the cylinder's
    # push plus the weight, and the ground at C pushes the cylinder's base towards B
    labels = r.force_coords["joint"]
    fb = r.forces["joint_force"][1][:, labels.index("B@rocker")]
    assert np.abs(fb - (expected[:, None] * u + W)).max() < 1e-8
    ground = r.forces["ground_reaction"][1][:, r.force_coords["fixed_point"].index("C")]
    assert np.abs(ground - expected[:, None] * u).max() < 1e-8


def test_cylinder_at_full_stroke_in_line_with_the_pivot_is_singular():
    """At s = R + |OC| the cylinder and the rocker are in line: the two rows' gradients are
    parallel; that step is singular, never a wrong ok; beyond it there is no assembly."""
    R, C = 1.0, (0.0, -0.8)
    top = R + 0.8
    scene = cylinder_rocker(s_from=1.0, s_to=2.0, steps=21, C=C, R=R)
    r = linkpipe.solve(scene)
    s = np.linspace(1.0, 2.0, 21)
    at_top = np.isclose(s, top, rtol=0, atol=1e-12)
    assert at_top.sum() == 1
    status = r.status
    assert status[at_top].tolist() == [linkpipe.status.SINGULAR]
    assert (status[s > top + 1e-9] == linkpipe.status.NO_ASSEMBLY).all()
    assert (status[s < top - 0.05] == linkpipe.status.OK).all()


def two_link_arm(load=(0.0, -50.0), rates=(10.0, -9.0), method="auto", elbow_ref='["A", "O"]',
                 extra=""):
    return parse_scene(f"""
[scene]
name = "two_link_arm"
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
A = {{ x = 1.0, y = 0.0 }}
B = {{ x = 1.5, y = 0.8 }}
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
steps = 91
rate = {rates[0]}
[[drivers]]
name = "elbow"
angle = ["A", "B"]
relative_to = {elbow_ref}
from = 120.0
to = 30.0
steps = 91
rate = {rates[1]}
[solver]
method = "{method}"
[analysis]
effects = ["loads"]
[[loads]]
name = "payload"
point = "B"
force = [{load[0]}, {load[1]}]
[outputs]
kinematics = ["velocity", "acceleration"]
{extra}
""", "two_link_arm.toml")


def test_motor_between_links_is_forward_kinematics_and_statics():
    r = linkpipe.solve(two_link_arm(load=(20.0, -50.0)))
    assert r.message == "all 91 steps ok"
    # an open chain: the note says why the dyads leave it (the motor), not "a loop"
    assert r.solver_note == ("auto: no closed-form dyad places point(s) B (the dyads do not "
                             "take a motor between links (relative_to: elbow)); general Newton "
                             "path")
    s1 = np.radians(np.linspace(0.0, 90.0, 91))
    s2 = np.radians(np.linspace(120.0, 30.0, 91))
    w1, w2 = np.radians(10.0), np.radians(-9.0)
    L1, L2 = 1.0, math.hypot(0.5, 0.8)
    phi = s1 + np.pi + s2  # the forearm's direction: the elbow angle from A->O
    A = L1 * np.stack([np.cos(s1), np.sin(s1)], axis=1)
    B = A + L2 * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    VB = (L1 * w1 * np.stack([-np.sin(s1), np.cos(s1)], axis=1)
          + L2 * (w1 + w2) * np.stack([-np.sin(phi), np.cos(phi)], axis=1))
    AB = (-L1 * w1 ** 2 * np.stack([np.cos(s1), np.sin(s1)], axis=1)
          - L2 * (w1 + w2) ** 2 * np.stack([np.cos(phi), np.sin(phi)], axis=1))
    b = r.point_names.index("B")
    assert np.abs(r.position[:, b] - B).max() < POS_TOL
    assert np.abs(r.velocity[:, b] - VB).max() < POS_TOL
    assert np.abs(r.acceleration[:, b] - AB).max() < POS_TOL
    # statics: the elbow holds the payload's moment about A, the shoulder about O (the elbow
    # angle held, the whole arm turns about O); torque per radian, CCW positive
    W = np.array([20.0, -50.0])
    rab, rob = B - A, B
    elbow = -(rab[:, 0] * W[1] - rab[:, 1] * W[0])
    shoulder = -(rob[:, 0] * W[1] - rob[:, 1] * W[0])
    torque = r.forces["input_force"][1]
    torque_l = r.forces["input_force_lagrange"][1]
    # 50 N at about 1 m: 1e-8 N m is far above rounding, far below any error of the formulas
    for T in (torque, torque_l):
        assert np.abs(T[:, 0] - shoulder).max() < 1e-8
        assert np.abs(T[:, 1] - elbow).max() < 1e-8


def test_motor_couple_lands_on_the_two_links_it_turns():
    """Each link's pin forces balance what acts on it: the forearm carries the payload and the
    motor's couple (its pins at A and B), so the pin forces on it sum to minus the payload and
    their moment about A is the motor torque (the pin at B exerts the payload on the forearm)."""
    r = linkpipe.solve(two_link_arm(load=(20.0, -50.0)))
    labels = r.force_coords["joint"]
    F = r.forces["joint_force"][1]
    O, A, B = (r.position[:, r.point_names.index(n)] for n in ("O", "A", "B"))
    W = np.array([20.0, -50.0])
    T1, T2 = r.forces["input_force"][1].T  # shoulder, elbow: torques on the driven links

    def moment(r_, f):
        return r_[:, 0] * f[:, 1] - r_[:, 1] * f[:, 0]

    # forearm: the pin at B (which carries the payload) pushes W on it; the pin at A takes the
    # rest; the elbow's couple T2 closes its moments about A
    fa, fb = F[:, labels.index("A@fore")], F[:, labels.index("B@fore")]
    assert np.abs(fb - W).max() < 1e-8
    assert np.abs(fa + fb).max() < 1e-8
    assert np.abs(moment(B - A, fb) + T2).max() < 1e-8
    # upper arm: the shoulder's couple T1 on it, the elbow's reaction -T2, pins at O and A
    ua, uo = F[:, labels.index("A@upper")], F[:, labels.index("O@upper")]
    assert np.abs(ua + uo).max() < 1e-8
    assert np.abs(moment(A - O, ua) + T1 - T2).max() < 1e-8
    # the pin at A exerts equal and opposite forces on the two links it joins
    assert np.abs(ua + fa).max() < 1e-8


@pytest.mark.parametrize("make", [cylinder_rocker, two_link_arm])
def test_new_rows_agree_across_layouts_and_with_their_derivatives(make):
    model = build_model(make())
    _layouts_agree(model)
    _derivatives_agree(model)


def test_relative_to_a_vector_that_shares_no_point():
    """Reference vector on another link with no shared pin (a motor reading two links'
    directions), and ground as the reference: still the forward kinematics."""
    scene = two_link_arm(elbow_ref='["O", "A"]')  # measured from O->A (the upper arm's u axis)
    r = linkpipe.solve(scene)
    s1 = np.radians(np.linspace(0.0, 90.0, 91))
    s2 = np.radians(np.linspace(120.0, 30.0, 91))
    phi = s1 + s2
    A = np.stack([np.cos(s1), np.sin(s1)], axis=1)
    B = A + math.hypot(0.5, 0.8) * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    # the drawing (B at 58 deg from O->A) is the other branch's 120 - 180: carried to the sweep
    assert r.message == "all 91 steps ok"
    assert np.abs(r.position[:, r.point_names.index("B")] - B).max() < POS_TOL
    _derivatives_agree(build_model(scene))


@settings(max_examples=25, deadline=None)
@given(R=st.floats(0.3, 2.0), cx=st.floats(-1.5, 1.5), cy=st.floats(-1.5, -0.3),
       scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_cylinder_rockers_fast_path_equals_newton(R, cx, cy, scale):
    c = math.hypot(cx, cy)
    lo, hi = abs(R - c), R + c
    if hi - lo < 0.2 * scale / scale:
        return
    s0, s1 = lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)
    args = dict(s_from=s0 * scale, s_to=s1 * scale, steps=41, R=R * scale,
                C=(cx * scale, cy * scale), rate=0.3 * scale, acceleration=0.1 * scale)
    fast = linkpipe.solve(cylinder_rocker(method="dyads", **args))
    slow = linkpipe.solve(cylinder_rocker(method="newton", **args))
    assert fast.message == slow.message == "all 41 steps ok"
    # Newton stops at tol 1e-12 of the size; the conditioning near the stroke ends (10 % in)
    # multiplies that by at most ~1e3
    for k in ("position", "velocity", "acceleration"):
        a, b = getattr(fast, k), getattr(slow, k)
        assert np.abs(a - b).max() <= 1e-9 * scale, k


def test_input_direction_turning_with_a_link():
    """A push at B along the rocker's own normal (v axis): the force needed is the load's
    moment about O over R, at every angle."""
    scene = cylinder_rocker(load=(30.0, -100.0))
    text = scene.text.replace('rate = 0.1', 'rate = 0.1\ninput = { point = "B", direction = [0.0, 1.0], link = "rocker" }')
    r = linkpipe.solve(parse_scene(text, "x.toml"))
    B = r.position[:, r.point_names.index("B")]
    W = np.array([30.0, -100.0])
    moment = B[:, 0] * W[1] - B[:, 1] * W[0]
    # the push P along the rocker's normal at B balances the load: P R + moment = 0
    assert np.abs(r.forces["input_force"][1][:, 0] - (-moment / 1.0)).max() < 1e-8


BAD = [
    ("cylinder-on-one-link", lambda t: t.replace('distance = ["C", "B"]', 'distance = ["O", "B"]'),
     "distance", "both points of link"),
    ("cylinder-zero-length", lambda t: t.replace("from = 0.9", "from = 0.0"), "from",
     "must be positive"),
    ("cylinder-negative-length", lambda t: t.replace("to = 1.6", "to = -1.6"), "to",
     "must be positive"),
    ("cylinder-between-fixed-points", lambda t: t.replace('distance = ["C", "B"]', 'distance = ["C", "O"]'),
     "distance", "both fixed"),
    ("relative-on-distance", lambda t: t.replace('distance = ["C", "B"]', 'distance = ["C", "B"]\nrelative_to = ["O", "B"]'),
     "relative_to", "belongs to an angle driver"),
    ("distance-and-angle", lambda t: t.replace('distance = ["C", "B"]', 'distance = ["C", "B"]\nangle = ["O", "B"]'),
     "distance", "not both angle and distance"),
    ("cylinder-without-steps", lambda t: t.replace("steps = 71\n", ""), "steps",
     "add steps = 46 or step = 0.01"),  # a length's example, not an angle's 361 steps
]


@pytest.mark.parametrize("name,edit,key,words", BAD, ids=[b[0] for b in BAD])
def test_bad_cylinder_scenes_name_the_key(name, edit, key, words):
    text = edit(cylinder_rocker().text)
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(text, "bad.toml")
    msg = str(err.value)
    assert "bad.toml" in msg and key in msg and words in msg, msg


BAD_RELATIVE = [
    ("link-against-itself", '["B", "A"]', "relative_to", "against itself"),
    ("no-link-carries", '["O", "B"]', "relative_to", "no link carries both"),
]


@pytest.mark.parametrize("name,ref,key,words", BAD_RELATIVE, ids=[b[0] for b in BAD_RELATIVE])
def test_bad_relative_angles_name_the_key(name, ref, key, words):
    text = two_link_arm().text.replace('relative_to = ["A", "O"]', f"relative_to = {ref}")
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(text, "bad.toml")
    msg = str(err.value)
    assert "bad.toml" in msg and key in msg and words in msg, msg


@pytest.mark.parametrize("name,edit,key,words", BAD[:4], ids=[b[0] for b in BAD[:4]])
def test_bad_cylinder_on_the_command_line_is_one_message_exit_2_nothing_written(
        tmp_path, capsys, name, edit, key, words):
    from linkpipe.__main__ import main

    path = tmp_path / "bad.toml"
    path.write_text(edit(cylinder_rocker().text))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert str(path) in err and key in err and words in err
    assert not out.exists() or not any(out.iterdir())


def test_relative_angle_of_a_link_against_itself_on_the_command_line(tmp_path, capsys):
    from linkpipe.__main__ import main

    path = tmp_path / "arm.toml"
    path.write_text(two_link_arm().text.replace('relative_to = ["A", "O"]', 'relative_to = ["B", "A"]'))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert str(path) in err and "relative_to" in err and "against itself" in err
    assert not out.exists() or not any(out.iterdir())


def test_a_rate_that_shortens_a_cylinder_past_zero_blames_the_rate_and_names_the_instant():
    """length = 0.9 - 0.13 t over [time] 0 .. 16 s (0.1 s apart): first not positive at 7 s
    (0.9 - 0.91 = -0.01 m), lowest -1.18 m at 16 s. The driver writes no `to`: the message is
    about its `rate`."""
    text = cylinder_rocker().text.replace(
        "from = 0.9\nto = 1.6\nsteps = 71\nrate = 0.1", "from = 0.9\nrate = -0.13") + (
        "[time]\nfrom = 0.0\nto = 16.0\nsteps = 161\n")
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(text, "bad.toml")
    assert (err.value.table, err.value.key) == ('drivers "cylinder"', "rate")
    assert "falls to -1.18 within [time] (first not positive at the instant 7)" in str(err.value)


def test_a_logged_first_value_out_of_reach_names_the_log_column(tmp_path):
    """The rocker (R 1, C 0.943 from O) reaches cylinder lengths 0.057 .. 1.943: a log whose
    first sample is 3000 mm cannot assemble: that step is no_assembly, and the run's note
    names the log column (with its scale), not a `from` the driver cannot have."""
    (tmp_path / "run.csv").write_text("t,len_mm\n0.0,3000.0\n1.0,1200.0\n2.0,1300.0\n")
    text = cylinder_rocker().text.replace(
        "from = 0.9\nto = 1.6\nsteps = 71\nrate = 0.1\nacceleration = 0.0",
        'log = "run.len_mm"\nscale = 0.001') + (
        '[time]\nlog = "run"\n[[logs]]\nname = "run"\nfile = "run.csv"\ntime = "t"\n')
    path = tmp_path / "logged.toml"
    path.write_text(text)
    r = linkpipe.solve(linkpipe.load_scene(str(path)))
    assert list(r.status) == [1, 0, 0]  # the first sample no_assembly; the sweep goes on
    msg = r.reach_note
    assert "the first driver value 3 length units is out of reach" in msg  # no [scene].units
    said = float(msg.split("as far as ")[1].split(" ")[0])  # the rocker's reach: 1 + |C|
    assert said == pytest.approx(1.0 + np.hypot(0.5, 0.8), abs=1e-5), msg
    assert 'the first value of log column "run.len_mm" (times scale = 0.001)' in msg
    assert "`from`" not in msg


def _cross2(r, f):
    return r[..., 0] * f[..., 1] - r[..., 1] * f[..., 0]


def test_a_push_does_work_on_the_other_drivers_too():
    """The shoulder pushed at B along O->B as it lies at the first step, the elbow a motor:
    the push P balances the payload W about O (the elbow's motor is internal to the arm),
    P = -(B x W) / (B x n); the elbow's torque is then what holds the forearm against W and P
    together, -(B - A) x (W + P n), not W's moment alone (1e-8 N m, as above). At the first
    step the push has no leverage: no_leverage, and both the push and the elbow's torque,
    which the push's work enters, are NaN."""
    base = two_link_arm(load=(20.0, -50.0))
    first = linkpipe.solve(base).position[0, base.point_names.index("B")]
    n = first / np.hypot(*first)
    text = base.text.replace("rate = 10.0", f'rate = 10.0\ninput = {{ point = "B", direction = '
                                            f"[{float(n[0])!r}, {float(n[1])!r}] }}")
    r = linkpipe.solve(parse_scene(text, "arm.toml"))
    assert r.status[0] == NO_LEVERAGE and (r.status[1:] == OK).all()
    force = r.forces["input_force"][1]
    assert np.isnan(force[0]).all() and np.isfinite(force[1:]).all()
    A, B = (r.position[1:, r.point_names.index(p)] for p in ("A", "B"))
    W = np.array([20.0, -50.0])
    push = -_cross2(B, W) / _cross2(B, n)
    assert np.abs(force[1:, 0] - push).max() < 1e-8 * np.abs(push).max()
    elbow = -_cross2(B - A, W + push[:, None] * n)
    assert np.abs(force[1:, 1] - elbow).max() < 1e-8 * np.abs(elbow).max()
    np.testing.assert_allclose(r.forces["input_force_lagrange"][1][1:], force[1:], rtol=1e-9)


def test_two_pushes_balance_the_arm():
    """Both drivers pushed (shoulder at A upwards, elbow at B to the right): the pushes solve
    the two drivers' virtual work together, and the arm is in equilibrium, force and moment
    about O, with the ground reaction at O (1e-9 of the ~50 N load)."""
    text = two_link_arm(load=(20.0, -50.0)).text
    text = text.replace("rate = 10.0", 'rate = 10.0\ninput = { point = "A", direction = [0.0, 1.0] }')
    text = text.replace("rate = -9.0", 'rate = -9.0\ninput = { point = "B", direction = [1.0, 0.0] }')
    r = linkpipe.solve(parse_scene(text, "arm2.toml"))
    ok = r.status == OK
    assert ok.sum() > 80
    A, B = (r.position[:, r.point_names.index(p)] for p in ("A", "B"))
    F = r.forces["input_force"][1]
    W = np.array([20.0, -50.0])
    pa, pb = F[:, 0, None] * np.array([0.0, 1.0]), F[:, 1, None] * np.array([1.0, 0.0])
    R = r.forces["ground_reaction"][1][:, 0]  # at O
    assert np.abs((R + pa + pb + W)[ok]).max() < 1e-9 * 50
    assert np.abs((_cross2(A, pa) + _cross2(B, pb + W))[ok]).max() < 1e-9 * 50
    np.testing.assert_allclose(r.forces["input_force_lagrange"][1][ok], F[ok], rtol=1e-9)


def test_two_pushes_of_different_units_do_not_depend_on_the_length_unit():
    """A crank (angle, pushed at A across it) and a slider (coordinate C.x, pushed along x):
    their pushes solve a system whose rows carry length per radian and length per length, so
    its condition is taken in the drivers' own scales. The same mechanism in a unit 2e9 times
    smaller gives the same forces (N: only lengths scale; 1e-9 relative), not no_leverage."""
    def scene(k):
        return parse_scene(f"""
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
A = {{ x = {k}, y = 0.0 }}
B = {{ x = {1.5 * k}, y = {1.0 * k} }}
C = {{ x = {3 * k}, y = 0.0 }}
[[links]]
name = "crank"
points = ["O", "A"]
[[links]]
name = "l1"
points = ["A", "B"]
[[links]]
name = "l2"
points = ["B", "C"]
[[sliders]]
name = "g"
point = "C"
along = {{ through = [0.0, 0.0], direction = [1.0, 0.0] }}
[[drivers]]
name = "th"
angle = ["O", "A"]
from = 10.0
to = 20.0
steps = 3
input = {{ point = "A", direction = [0.0, 1.0], link = "crank" }}
[[drivers]]
name = "cx"
coordinate = "C.x"
from = {3 * k}
to = {3.1 * k}
steps = 3
input = {{ point = "C", direction = [1.0, 0.0] }}
[analysis]
effects = ["loads"]
[[loads]]
name = "w"
point = "B"
force = [1.0, -2.0]
""", f"scaled_{k:g}.toml")
    one, big = (linkpipe.solve(scene(k)) for k in (1.0, 2e9))
    assert (one.status == OK).all() and (big.status == OK).all()
    np.testing.assert_allclose(big.forces["input_force"][1], one.forces["input_force"][1],
                               rtol=1e-9)


def test_a_driver_held_while_another_moves_is_a_sweep():
    """The contract's step rule with from = to: the shoulder held at 0 deg (rate 0: statics)
    while the elbow turns 120 -> 30 deg relative to the upper arm (A -> O) at 9 deg/s: forward
    kinematics at every step, the time axis from the elbow alone (|value - from| / |rate|),
    and the elbow motor's torque the payload's moment about A (statics by hand)."""
    text = two_link_arm(rates=(0.0, -9.0)).text.replace(
        "from = 0.0\nto = 90.0", "from = 0.0\nto = 0.0")
    r = linkpipe.solve(parse_scene(text, "held.toml"))
    assert r.n_ok == r.n_steps == 91
    assert (r.driver_value[:, 0] == 0.0).all()
    elbow = np.deg2rad(r.driver_value[:, 1])  # from A->O (pointing at 180 deg) to A->B
    fore = np.hypot(0.5, 0.8)  # |AB| as drawn
    B = np.stack([1.0 + fore * np.cos(np.pi + elbow), fore * np.sin(np.pi + elbow)], axis=1)
    np.testing.assert_allclose(r.position[:, r.point_names.index("B")], B, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.time, (120.0 - r.driver_value[:, 1]) / 9.0, rtol=0,
                               atol=1e-12)
    moment = (B[:, 0] - 1.0) * -50.0  # the payload (0, -50) N at B about A
    np.testing.assert_allclose(r.forces["input_force"][1][:, 1], -moment, rtol=0, atol=1e-9)


def test_every_driver_held_over_several_steps_is_that_many_identical_steps():
    """All drivers held over 91 steps: the contract's formula gives 91 identical steps (legal:
    its only error is a sweep with no steps), with a warning that says so and how to sweep."""
    text = two_link_arm().text.replace("from = 0.0\nto = 90.0", "from = 0.0\nto = 0.0").replace(
        "from = 120.0\nto = 30.0", "from = 120.0\nto = 120.0")
    scene = parse_scene(text, "held.toml")
    assert scene.n_steps == 91
    assert any("every driver is held (from = to): the sweep is 91 identical steps" in w
               for w in scene.warnings)
    result = linkpipe.solve(scene)
    assert (result.status == 0).all()
    np.testing.assert_array_equal(result.position, np.broadcast_to(result.position[0],
                                                                   result.position.shape))
    # the contract's time, |value - from| / |rate| where every rate is set: 0 s at every step
    np.testing.assert_array_equal(result.time, np.zeros(91))
