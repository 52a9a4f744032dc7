"""Stage 2 against exact answers: closed forms, energy balance, Norton's Example 11-3, and
virtual work against Lagrange multipliers (two formulations, two different linear solves)."""
import pathlib
import re

import numpy as np
import pytest

import linkpipe
from linkpipe.status import OK
from linkpipe.status import NO_LEVERAGE

CONFIGS = pathlib.Path(__file__).parent.parent / "configs"
DATA = pathlib.Path(__file__).parent / "data"
BASKETBALL = (CONFIGS / "basketball_goal.toml").read_text()

# basketball goal geometry (ft): spring anchors r from O2 on the upper link, h above O2 on the pole
R_SPRING, H_SPRING, K, L_FREE, N_SPRINGS = 0.9412, 0.3429, 4.0, 0.5833, 2
M_BOARD, G = 50 / 32.174, 32.174


def scene_from(text, tmp_path, name="variant"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return linkpipe.load_scene(path)


def with_effects(text, effects):
    return re.sub(r"effects = \[[^\]]*\]", "effects = [" + ", ".join(f'"{e}"' for e in effects) + "]", text)


def basketball_closed_form(theta_deg, effects):
    """Vertical handle force (lbf, +y) holding the goal quasi-statically, by hand.

    Spring length L^2 = r^2 + h^2 - 2 r h sin(theta); dL/dtheta = -r h cos(theta) / L.
    The handle rises dH_y/dtheta = -cos(theta); the board centre rises 2 cos(theta).
    f dH_y = dV  ->  f = dV/dtheta / (-cos theta).
    """
    th = np.deg2rad(theta_deg)
    f = np.zeros_like(th)
    if "springs" in effects:
        L = np.sqrt(R_SPRING**2 + H_SPRING**2 - 2 * R_SPRING * H_SPRING * np.sin(th))
        dV = N_SPRINGS * K * (L - L_FREE) * (-R_SPRING * H_SPRING * np.cos(th) / L)
        f += dV / -np.cos(th)
    if "gravity" in effects:
        f += M_BOARD * G * 2 * np.cos(th) / -np.cos(th)
    return f


EVERY_EFFECT = (CONFIGS / "fourbar_crank_rocker.toml").read_text() + """
[analysis]
effects = ["springs", "gravity", "inertia", "damping", "loads"]

[gravity]
g = [0.0, -9.81]

[[springs]]
name = "s"
between = ["O4", "P"]
k = 120.0
free_length = 1.0
damping = 3.5

[[masses]]
link = "coupler"
mass = 2.0
center = [1.2, 0.3]
inertia = 0.4

[[masses]]
link = "rocker"
mass = 1.0
center = [1.5, 0.0]
inertia = 0.75

[[loads]]
name = "push"
point = "P"
force = [10.0, -20.0]

[[loads]]
name = "brake"
link = "rocker"
torque = -2.0
"""


@pytest.mark.parametrize("effects", [["springs"], ["gravity"], ["springs", "gravity"],
                                     ["springs", "gravity", "inertia"]])
def test_basketball_input_force_closed_form(tmp_path, effects):
    r = linkpipe.solve(scene_from(with_effects(BASKETBALL, effects), tmp_path))
    assert (r.status == OK).all()
    f = r.forces["input_force"][1][:, 0]
    # inertia does no virtual work here: the board translates on a circle at constant rate
    # (centripetal acceleration normal to its velocity), so the quasi-static answer is exact
    expect = basketball_closed_form(r.driver_value[:, 0], effects)
    np.testing.assert_allclose(f, expect, rtol=0, atol=1e-9)  # lbf; float round-off only
    np.testing.assert_allclose(r.forces["input_force_lagrange"][1][:, 0], expect, rtol=0, atol=1e-9)


def test_seed_conclusion_and_what_gravity_changes():
    r = linkpipe.solve(str(CONFIGS / "basketball_goal.toml"))
    th = r.driver_value[:, 0]
    springs_only = basketball_closed_form(th, ["springs"])
    # the seed: with springs alone the largest input force is at -60 deg
    assert th[np.argmax(np.abs(springs_only))] == -60.0
    # with the 50 lb board's weight the handle must hold ~100 lbf down, largest at +60 deg
    f = r.forces["input_force"][1][:, 0]
    assert th[np.argmax(np.abs(f))] == 60.0
    np.testing.assert_allclose(f - springs_only, -2 * 50.0, atol=1e-9)


def test_spring_outputs_closed_form():
    r = linkpipe.solve(str(CONFIGS / "basketball_goal.toml"))
    th = np.deg2rad(r.driver_value[:, 0])
    L = np.sqrt(R_SPRING**2 + H_SPRING**2 - 2 * R_SPRING * H_SPRING * np.sin(th))
    for j in range(2):
        np.testing.assert_allclose(r.forces["spring_length"][1][:, j], L, atol=1e-12)
        np.testing.assert_allclose(r.forces["spring_force"][1][:, j], K * (L - L_FREE), atol=1e-12)
        np.testing.assert_allclose(r.forces["spring_energy"][1][:, j], 0.5 * K * (L - L_FREE) ** 2, atol=1e-12)
    # the seed's span: about 0.667 ft at +60 deg to 1.25 ft at -60 deg, longest at -60
    assert abs(L[0] - 1.25) < 1e-3 and abs(L[-1] - 0.6667) < 1e-3 and np.argmax(L) == 0


def test_energy_balance_conservative_sweep(tmp_path):
    """Integral of F_in ds over a quasi-static sweep = change of spring + gravity potential."""
    text = with_effects(BASKETBALL, ["springs", "gravity"])
    text = text.replace("step = 5.0", "step = 0.25").replace("rate = 28.64788975654116", "rate = 0.0")
    text = re.sub(r"input = \{[^}]*\}\n", "", text)  # generalized force: a torque per radian
    r = linkpipe.solve(scene_from(text, tmp_path))
    assert (r.status == OK).all()
    s = np.deg2rad(r.driver_value[:, 0])
    F = r.forces["input_force"][1][:, 0]
    work = np.trapezoid(F, s)
    V = r.forces["spring_energy"][1].sum(axis=1) + r.forces["gravity_energy"][1]
    dV = V[-1] - V[0]
    # trapezoid error bound: (b - a) h^2 / 12 * max|F''|, F'' from second differences
    h = s[1] - s[0]
    f2 = np.abs(np.diff(F, 2)).max() / h**2
    bound = (s[-1] - s[0]) * h**2 / 12 * f2 * 1.5 + 1e-12 * abs(dV)
    assert abs(work - dV) <= bound
    assert bound < 1e-4 * abs(dV)  # the check is tight, not vacuous


def test_norton_example_11_3():
    r = linkpipe.solve(str(DATA / "norton_11_3.toml"))
    assert (r.status == OK).all()
    T12 = r.forces["input_force"][1][0, 0]
    # Norton rounds his intermediate kinematics to ~4 significant figures: 0.05 lb-in (0.02 %)
    assert abs(T12 - 243.24) < 0.05
    assert abs(r.forces["input_force_lagrange"][1][0, 0] - T12) < 1e-9 * abs(T12)
    # his kinematics: theta3 = 20.92 deg, theta4 = 104.41 deg
    np.testing.assert_allclose(np.rad2deg(r.link_angle[0, 1:]), [20.92, 104.41], atol=0.005)


def all_effect_scenes():
    out = [CONFIGS / "basketball_goal.toml", CONFIGS / "shear_press.toml", DATA / "norton_11_3.toml"]
    return [str(p) for p in out]


@pytest.mark.parametrize("path", all_effect_scenes())
def test_virtual_work_equals_lagrange(path):
    r = linkpipe.solve(path)
    ok = r.status == OK
    assert ok.any()
    f = r.forces["input_force"][1][ok]
    fl = r.forces["input_force_lagrange"][1][ok]
    scale = np.abs(f).max()
    assert np.abs(f - fl).max() <= 1e-9 * scale


def test_virtual_work_equals_lagrange_with_every_effect(tmp_path):
    """Springs with damping, gravity, inertia with rotation, loads: a crank-rocker at speed."""
    text = EVERY_EFFECT
    r = linkpipe.solve(scene_from(text, tmp_path))
    assert (r.status == OK).all()
    f = r.forces["input_force"][1][:, 0]
    fl = r.forces["input_force_lagrange"][1][:, 0]
    assert np.abs(f - fl).max() <= 1e-9 * np.abs(f).max()
    # power balance: the actuator's power equals minus the effects' powers
    power = r.forces["power"][1].sum(axis=1)
    np.testing.assert_allclose(f * 10.0, -power, atol=1e-9 * np.abs(power).max())


def test_shear_press_force_at_P_and_rod_force(tmp_path):
    r = linkpipe.solve(str(CONFIGS / "shear_press.toml"))
    names = r.point_names
    P, B, C = (r.position[:, names.index(n)] for n in ("P", "B", "C"))
    fP = r.forces["input_force"][1][:, 0]
    rod = r.forces["link_force"][1][:, r.link_names.index("rod")]
    # by hand: the blade C is in equilibrium under the load (0, 500), the rod force along BC and
    # the guide's horizontal reaction: rod tension T pulls C towards B -> T e_CB,y + 500 = 0
    e_cb = (B - C) / np.linalg.norm(B - C, axis=1)[:, None]
    T = -500.0 / e_cb[:, 1]
    np.testing.assert_allclose(rod, T, rtol=1e-10)
    # the lever A-B-P: moments about A of the rod's pull at B and the vertical force at P vanish
    FB = -T[:, None] * e_cb  # force of the rod on B (towards C when in tension)
    moment_B = B[:, 0] * FB[:, 1] - B[:, 1] * FB[:, 0]
    np.testing.assert_allclose(fP, -moment_B / P[:, 0], rtol=1e-10)
    assert (rod < 0).all()  # the rod is in compression while cutting


def test_no_leverage_is_flagged_not_infinite(tmp_path):
    """A centred slider-crank pushed at the slider: dead centres at 0 and 180 deg."""
    text = (CONFIGS / "slider_crank.toml").read_text()
    text = text.replace("y = 0.5 }", "y = 0.0 }").replace("through = [0.0, 0.5]", "through = [0.0, 0.0]")
    text = text.replace("x = 4.4641", "x = 4.5").replace("steps = 361", "steps = 13")
    text = text.replace('rate = 572.9577951308232     # 10 rad/s',
                        'rate = 572.9577951308232\ninput = { point = "B", direction = [1.0, 0.0] }')
    text += '\n[analysis]\neffects = ["loads"]\n\n[[loads]]\nname = "gas"\npoint = "B"\nforce = [-100.0, 0.0]\n'
    r = linkpipe.solve(scene_from(text, tmp_path))
    dead = np.isin(r.driver_value[:, 0], [0.0, 180.0, 360.0])
    assert (r.status[dead] == NO_LEVERAGE).all()
    assert np.isnan(r.forces["input_force"][1][dead]).all()
    assert (r.status[~dead] == OK).all()
    # elsewhere the actuator simply balances the gas force along x
    np.testing.assert_allclose(r.forces["input_force"][1][~dead, 0], 100.0, rtol=1e-9)


@pytest.mark.parametrize("method", ["auto", "newton"])
def test_skipped_stages_do_not_run(monkeypatch, method):
    """No effects: the force stage is never called; no inertia and no outputs: stage 1 is asked
    for positions only (order 0) and gamma, the acceleration right-hand side, is never built."""
    import dataclasses

    import linkpipe.forces
    import linkpipe.model
    from linkpipe.kinematics import plan as kin  # where the positions' paths are chosen

    def boom(*a, **k):
        raise AssertionError("this stage must not run")

    orders = []  # the kinematic order each stage-1 solve was asked for (Newton: positions)
    real_dyads, real_newton = kin.dyad_sweep, kin.solve_with_newton

    def recording_dyads(model, chain, s, s_dot, s_ddot, order, *a, **k):
        orders.append(order)
        return real_dyads(model, chain, s, s_dot, s_ddot, order, *a, **k)

    def recording_newton(*a, **k):
        orders.append(0)
        return real_newton(*a, **k)

    def recording_stage1(monkeypatch):
        monkeypatch.setattr(kin, "dyad_sweep", recording_dyads)
        monkeypatch.setattr(kin, "solve_with_newton", recording_newton)

    def solve(scene):
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method))
        return linkpipe.solve(scene)

    recording_stage1(monkeypatch)
    monkeypatch.setattr(linkpipe.forces, "compute_forces", boom)
    monkeypatch.setattr(linkpipe.model.Model, "gamma", boom)
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
    text = text.split("[outputs]")[0]  # no extra kinematic orders asked for
    r = solve(linkpipe.parse_scene(text, "crank_rocker_positions.toml"))
    assert r.forces is None and r.velocity is None and r.acceleration is None
    assert "forces" not in r.seconds and orders == [0]
    assert r.solver_method_used == ("newton" if method == "newton" else "dyads")
    # the shear press asks for loads only: forces run, velocities and accelerations still do not
    monkeypatch.undo()
    recording_stage1(monkeypatch)
    monkeypatch.setattr(linkpipe.model.Model, "gamma", boom)
    r = solve(linkpipe.load_scene(CONFIGS / "shear_press.toml"))
    assert r.forces is not None and r.acceleration is None and r.velocity is None
    assert "forces" in r.seconds and orders == [0, 0]


def test_present_but_off_is_reported_and_unused(tmp_path):
    text = with_effects(BASKETBALL, ["springs"])
    r = linkpipe.solve(scene_from(text, tmp_path))
    assert r.scene.present_but_off == ("gravity", "inertia")
    np.testing.assert_allclose(r.forces["input_force"][1][:, 0],
                               basketball_closed_form(r.driver_value[:, 0], ["springs"]), atol=1e-9)
    assert "gravity_energy" not in r.forces and "power" in r.forces
    assert r.forces["power"][1].shape[1] == 1  # springs only


def test_ground_reactions_balance_the_mechanism(tmp_path):
    """Sum of ground reactions = sum of m a_G - weights - applied loads (springs are internal)."""
    r = linkpipe.solve(scene_from(EVERY_EFFECT, tmp_path))
    R = r.forces["ground_reaction"][1]  # (S, n_fixed, 2)
    A = r.acceleration
    total = np.zeros((r.n_steps, 2))
    from linkpipe.forces.applied import body_point as _center, center_frame

    for m in r.scene.masses:
        ia, ib, u, v, L = center_frame(r.model, m.link, m.center)
        aG = _center(A, ia, ib, u, v, L)
        total += m.mass * aG - m.mass * np.array([0.0, -9.81])
    total -= np.array([10.0, -20.0])  # the point load; the couple has no net force
    scale = np.abs(total).max()
    np.testing.assert_allclose(R.sum(axis=1), total, rtol=0, atol=1e-9 * scale)


def test_shear_press_pivot_reaction_by_hand():
    r = linkpipe.solve(str(CONFIGS / "shear_press.toml"))
    names = r.point_names
    P, B, C = (r.position[:, names.index(n)] for n in ("P", "B", "C"))
    e_cb = (B - C) / np.linalg.norm(B - C, axis=1)[:, None]
    T = -500.0 / e_cb[:, 1]
    FB = -T[:, None] * e_cb  # force of the rod on the lever at B
    fP = r.forces["input_force"][1][:, 0]
    # the massless lever A-B-P: R_A + F_B + (0, f_P) = 0
    expect = -(FB + np.stack([np.zeros_like(fP), fP], axis=1))
    RA = r.forces["ground_reaction"][1][:, 0]
    np.testing.assert_allclose(RA, expect, rtol=0, atol=1e-9 * np.abs(expect).max())


def test_pin_forces_satisfy_each_body_newton_euler(tmp_path):
    """Pin forces on each body, with its weight, couples and the actuator torque, give m a_G
    and I alpha about G (Newton-Euler per body: an independent check of the multipliers)."""
    r = linkpipe.solve(scene_from(EVERY_EFFECT, tmp_path))
    from linkpipe.forces.applied import body_point as _center, center_frame

    F = r.forces["joint_force"][1]
    joints = _joint_names(r)
    X, A = r.position, r.acceleration
    names = r.point_names
    torque = r.forces["input_force"][1][:, 0]
    masses = {m.link: m for m in r.scene.masses}
    for li, link in enumerate(r.scene.links):
        cols = [k for k, j in enumerate(joints) if j.endswith("@" + link.name)]
        assert len(cols) == len(link.points)
        m = masses.get(link.name)
        if m is not None:
            ia, ib, u, v, L = center_frame(r.model, m.link, m.center)
            G = _center(X, ia, ib, u, v, L)
            aG = _center(A, ia, ib, u, v, L)
            mass, inertia = m.mass, m.inertia
        else:
            G, aG, mass, inertia = X[:, names.index(link.points[0])], 0.0, 0.0, 0.0
        net = F[:, cols].sum(axis=1) + mass * np.array([0.0, -9.81])
        scale = np.abs(F[:, cols]).max()
        np.testing.assert_allclose(net, mass * aG * np.ones_like(net), rtol=0, atol=1e-9 * scale)
        rel = X[:, [names.index(p) for p in link.points]] - G[:, None]
        moment = (rel[..., 0] * F[:, cols, 1] - rel[..., 1] * F[:, cols, 0]).sum(axis=1)
        moment += {"rocker": -2.0, "crank": torque}.get(link.name, 0.0)
        alpha = r.link_angular_acceleration[:, li]
        np.testing.assert_allclose(moment, inertia * alpha, rtol=0, atol=1e-9 * scale * r.model.size)


def _joint_names(r):
    from linkpipe.forces.lagrange import joints

    return [f"{r.point_names[p]}@{r.scene.links[li].name}" for li, p in joints(r.model)]


def test_pins_between_two_bodies_transmit_equal_and_opposite_forces():
    r = linkpipe.solve(str(DATA / "norton_11_3.toml"))
    F = r.forces["joint_force"][1][0]
    J = _joint_names(r)
    np.testing.assert_allclose(F[J.index("A@crank")], -F[J.index("A@coupler")], atol=1e-9)
    np.testing.assert_allclose(F[J.index("B@coupler")], -F[J.index("B@rocker")], atol=1e-9)
    # the ground pins carry what the ground reactions say; the coupler point carries F_P
    R = r.forces["ground_reaction"][1][0]
    np.testing.assert_allclose(F[J.index("O2@crank")], R[0], atol=1e-9)
    np.testing.assert_allclose(F[J.index("O4@rocker")], R[1], atol=1e-9)
    fp = 80 * np.array([np.cos(np.deg2rad(330)), np.sin(np.deg2rad(330))])
    np.testing.assert_allclose(F[J.index("P@coupler")], fp, atol=1e-9)


def test_a_load_at_a_shared_pin_is_what_its_pin_forces_sum_to():
    """A four-bar (crank-rocker config) with a load W at the coupler-rocker pin B and no other
    effect: coupler and rocker are massless two-force members, so by statics at the pin
    W = f_c u_AB + f_r u_O4B (two unknowns, two equations), and the pin exerts f_c u_AB on the
    coupler and f_r u_O4B on the rocker (directions: from their other end towards B). The
    forces the pin exerts on its bodies sum to the load; at A, with no load, they sum to zero."""
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
    text += '\n[analysis]\neffects = ["loads"]\n\n[[loads]]\nname = "w"\npoint = "B"\nforce = [30.0, -120.0]\n'
    scene = linkpipe.scene.parse_scene(text, "loaded.toml")
    r = linkpipe.solve(scene)
    W = np.array([30.0, -120.0])
    J = _joint_names(r)
    F = r.forces["joint_force"][1]
    X = r.position
    A, B, O4 = (X[:, r.point_names.index(n)] for n in ("A", "B", "O4"))
    u_c = (B - A) / np.linalg.norm(B - A, axis=1)[:, None]
    u_r = (B - O4) / np.linalg.norm(B - O4, axis=1)[:, None]
    M = np.stack([u_c, u_r], axis=2)  # (S, 2, 2): columns u_c, u_r
    f = np.linalg.solve(M, np.broadcast_to(W, (len(X), 2))[..., None])[..., 0]
    on_coupler, on_rocker = F[:, J.index("B@coupler")], F[:, J.index("B@rocker")]
    # ~100 N loads, positions to 1e-12 m: 1e-9 N is rounding with margin
    np.testing.assert_allclose(on_coupler, f[:, :1] * u_c, atol=1e-9)
    np.testing.assert_allclose(on_rocker, f[:, 1:] * u_r, atol=1e-9)
    np.testing.assert_allclose(on_coupler + on_rocker, np.broadcast_to(W, on_coupler.shape), atol=1e-9)
    np.testing.assert_allclose(F[:, J.index("A@crank")] + F[:, J.index("A@coupler")], 0.0, atol=1e-9)


@pytest.mark.parametrize("config", ["basketball_goal", "hard/double_parallelogram",
                                    "hard/basketball_goal_extended", "hard/cylinder_full_stroke",
                                    "dump_truck", "shear_press"])
def test_force_stage_in_chunks_equals_one_piece(config, monkeypatch):
    """Each step's forces depend on that step alone: the stage run in chunks of 7 steps (a
    prime, so chunks cut the sweep anywhere, failed steps and redundant flags included) gives
    the one-piece stage's arrays bit for bit, and the same flags and statuses."""
    import linkpipe.forces as forces

    scene = linkpipe.load_scene(CONFIGS / f"{config}.toml")
    whole = linkpipe.solve(scene)
    real = forces.compute_forces
    monkeypatch.setattr(forces, "compute_forces",
                        lambda model, motion, units, **kw: real(model, motion, units, chunk=7, **kw))
    chunked = linkpipe.solve(scene)
    assert len(whole.status) > 7 and whole.forces
    assert list(chunked.forces) == list(whole.forces)
    for name, (dims, data, unit) in whole.forces.items():
        other = chunked.forces[name]
        assert other[0] == dims and other[2] == unit, name
        np.testing.assert_array_equal(other[1], data, err_msg=name)
    np.testing.assert_array_equal(chunked.status, whole.status)


@pytest.mark.parametrize("config", ["basketball_goal", "hard/double_parallelogram",
                                    "hard/cylinder_full_stroke", "dump_truck"])
def test_a_caller_that_wants_no_lagrange_variable_skips_the_multipliers(config):
    """``wanted`` without any multiplier variable: the same input force and statuses bit for
    bit (virtual work does not use the multipliers), and none of the multipliers' variables."""
    from linkpipe.forces import LAGRANGE_VARIABLES

    scene = linkpipe.load_scene(CONFIGS / f"{config}.toml")
    whole = linkpipe.solve(scene)
    lean = linkpipe.solve(scene, wanted=frozenset({"input_force"}))
    np.testing.assert_array_equal(lean.forces["input_force"][1], whole.forces["input_force"][1])
    np.testing.assert_array_equal(lean.status, whole.status)
    assert LAGRANGE_VARIABLES & set(whole.forces) and not LAGRANGE_VARIABLES & set(lean.forces)
    both = linkpipe.solve(scene, wanted=frozenset({"input_force", "joint_force"}))
    np.testing.assert_array_equal(both.forces["joint_force"][1], whole.forces["joint_force"][1])


def test_a_reused_stage_1_recomputes_only_the_effects_whose_inputs_changed(tmp_path):
    """A fit's trials: one stage 1, force parameters changed one at a time. Each trial's input
    force equals a fresh full solve of the same scene bit for bit, and the cache kept with the
    stage 1 grows by exactly the effects that read the changed table (springs -> springs and
    damping; a mass -> gravity and inertia; back to the start -> nothing new); many values of
    one parameter keep at most CACHED_VALUES per effect (bounded memory)."""
    from linkpipe.forces import CACHED_VALUES

    base = scene_from(EVERY_EFFECT, tmp_path, "base")
    reuse = linkpipe.solve(base).kinematics
    wanted = frozenset({"input_force", "spring_force"})

    def values():
        return sum(len(v) for v in reuse.force_cache.values() if isinstance(v, dict))

    variants = [(EVERY_EFFECT, 5), (EVERY_EFFECT.replace("k = 120.0", "k = 150.0"), 2),
                (EVERY_EFFECT.replace("mass = 2.0", "mass = 2.5"), 2), (EVERY_EFFECT, 0)]
    for i, (text, new_entries) in enumerate(variants):
        scene = scene_from(text, tmp_path, f"v{i}")
        before = values()
        lean = linkpipe.solve(scene, kinematics=reuse, wanted=wanted)
        assert values() - before == new_entries, i
        full = linkpipe.solve(scene)
        for name in ("input_force", "spring_force", "power"):
            np.testing.assert_array_equal(lean.forces[name][1], full.forces[name][1], err_msg=name)
        np.testing.assert_array_equal(lean.status, full.status)
    for k in range(10):
        scene = scene_from(EVERY_EFFECT.replace("k = 120.0", f"k = {200.0 + k}"), tmp_path, f"k{k}")
        linkpipe.solve(scene, kinematics=reuse, wanted=wanted)
    assert max(len(v) for v in reuse.force_cache.values() if isinstance(v, dict)) == CACHED_VALUES


def test_per_step_constants_are_cut_into_the_same_chunks(tmp_path):
    """A study's constants with a step axis (a different mass and spring rate at every step):
    the force stage in chunks of 7 steps equals the one-piece stage bit for bit, so each chunk
    took its own rows of the constants (a chunk given the wrong rows would differ)."""
    import dataclasses

    from linkpipe.forces import compute_forces
    from linkpipe.forces.constants import ForceConstants
    from linkpipe.result import Motion

    r = linkpipe.solve(scene_from(EVERY_EFFECT, tmp_path))
    k, S = r.kinematics, r.n_steps
    base = ForceConstants.of(r.model)
    ramp = np.linspace(0.5, 2.0, S)[:, None]
    per_step = dataclasses.replace(base, mass=base.mass * ramp, spring_k=base.spring_k * ramp)
    motion = Motion(s=k.s, s_dot=k.s_dot, s_ddot=k.s_ddot, position=r.position,
                    velocity=k.velocity, acceleration=k.acceleration, status=k.der["status"],
                    influence=k.der["influence"], link_angular_acceleration=k.link_rates[1],
                    link_angle=k.link_angle)
    units = dict(force="N", length="m", time="s", mass="kg")
    whole = compute_forces(r.model, motion, units, per_step)
    chunked = compute_forces(r.model, motion, units, per_step, chunk=7)
    assert not np.allclose(whole.variables["input_force"][1], r.forces["input_force"][1])
    for name, (dims, data, unit) in whole.variables.items():
        np.testing.assert_array_equal(chunked.variables[name][1], data, err_msg=name)


def _cross(r, f):
    return r[..., 0] * f[..., 1] - r[..., 1] * f[..., 0]


def test_an_input_point_is_where_the_reactions_see_the_actuator_push():
    """With `input` the input force is a push at input.point along input.direction, and the
    reactions are those of that push (not of a torque at the driver's pivot): the crank-rocker
    pushed up at the coupler point P against a load at B is in equilibrium, force and moment
    about the origin (to rounding: 1e-12 N, N m on ~10 N); the crank, which nothing then
    turns, is a two-force member (its pins' forces cancel and lie along it); the Lagrange
    input force still equals the virtual-work one."""
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text().replace("steps = 361", "steps = 37")
    text = text.replace("rate = ", 'input = { point = "P", direction = [0.0, 1.0] }\nrate = ', 1)
    text += ('\n[analysis]\neffects = ["loads"]\n[[loads]]\nname = "w"\npoint = "B"\n'
             "force = [3.0, 4.0]\n")
    r = linkpipe.solve(linkpipe.parse_scene(text, "pushed.toml"))
    assert r.message == "all 37 steps ok"
    X, names = r.position, r.point_names
    push = r.forces["input_force"][1][:, 0, None] * np.array([0.0, 1.0])  # (S, 2) at P
    load = np.array([3.0, 4.0])
    R = r.forces["ground_reaction"][1]  # at O2, O4
    assert r.force_coords["fixed_point"] == ["O2", "O4"]
    net = R.sum(axis=1) + load + push
    moment = (_cross(X[:, names.index("O2")], R[:, 0]) + _cross(X[:, names.index("O4")], R[:, 1])
              + _cross(X[:, names.index("B")], load) + _cross(X[:, names.index("P")], push))
    assert np.abs(net).max() < 1e-12 and np.abs(moment).max() < 1e-12
    labels, F = r.force_coords["joint"], r.forces["joint_force"][1]
    at_a, at_o2 = F[:, labels.index("A@crank")], F[:, labels.index("O2@crank")]
    assert np.abs(at_a + at_o2).max() < 1e-12
    assert np.abs(_cross(X[:, names.index("A")] - X[:, names.index("O2")], at_a)).max() < 1e-12
    np.testing.assert_allclose(r.forces["input_force_lagrange"][1], r.forces["input_force"][1],
                               rtol=0, atol=1e-12)


def test_the_basketball_goals_reactions_balance_the_hand_on_its_handle():
    """configs/basketball_goal.toml (the hand pushes up at H; springs, gravity, inertia): the
    ground reactions, the push, the weight and the backboard's m a_G and I alpha balance at
    every step, force and moment (springs end on fixed points: internal to mechanism and ground); 1e-9 of
    the largest reaction (lbf, lbf ft): rounding of ~100 lbf figures."""
    r = linkpipe.solve(str(CONFIGS / "basketball_goal.toml"))
    assert r.scene.drivers[0].input.point == "H"
    X, A, names = r.position, r.acceleration, r.point_names
    push = r.forces["input_force"][1][:, 0, None] * np.array([0.0, 1.0])
    R = r.forces["ground_reaction"][1]
    fixed = [names.index(p) for p in r.force_coords["fixed_point"]]
    from linkpipe.forces.applied import body_point, center_frame

    net = R.sum(axis=1) + push
    moment = sum(_cross(X[:, p], R[:, k]) for k, p in enumerate(fixed)) + _cross(
        X[:, names.index("H")], push)
    g = np.array(r.scene.gravity)
    for m in r.scene.masses:
        ia, ib, u, v, L = center_frame(r.model, m.link, m.center)
        xg, ag = body_point(X, ia, ib, u, v, L), body_point(A, ia, ib, u, v, L)
        net += m.mass * g - m.mass * ag
        alpha = r.link_angular_acceleration[:, [ln.name for ln in r.scene.links].index(m.link)]
        moment += _cross(xg, m.mass * g - m.mass * ag) - m.inertia * alpha
    scale = np.abs(R).max()
    assert np.abs(net).max() < 1e-9 * scale and np.abs(moment).max() < 1e-9 * scale * 10
