"""Friction at pins, sliders and seals (issue 35), each against an independent answer: statics
by hand, a separately written Newton-Euler solution, the power balance and the Stribeck law.
Tolerances are in the forces' units, a few thousand times rounding of the largest force."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import fsolve

import linkpipe
from linkpipe.errors import SceneError
from linkpipe.scene.parse import parse_scene
from linkpipe.status import OK

LEVER = """
[scene]
name = "lever"
units = { length = "m", mass = "kg", time = "s", force = "N" }
[points]
O = { x = 0.0, y = 0.0, fixed = true }
A = { x = 0.8, y = 0.0 }
[[links]]
name = "arm"
points = ["O", "A"]
[[drivers]]
name = "motor"
angle = ["O", "A"]
from = -30.0
to = 60.0
steps = 91
rate = RATE
[analysis]
effects = ["loads", "friction"]
[[loads]]
name = "w"
point = "A"
force = [0.0, -500.0]
[[friction]]
name = "pivot"
joints = ["O"]
mu = 0.2
pin_radius = 0.01
"""


@pytest.mark.parametrize("rate", [20.0, -20.0])
def test_lever_with_pin_friction_is_weight_arm_plus_friction_circle(rate):
    """Torque = W L cos(theta) + mu r W sign(w): the pin carries the weight alone."""
    r = linkpipe.solve(parse_scene(LEVER.replace("RATE", str(rate))))
    assert r.message == "all 91 steps ok"
    th = np.radians(r.driver_value[:, 0])
    expected = 500 * 0.8 * np.cos(th) + math.copysign(0.2 * 0.01 * 500, rate)
    f = r.forces
    assert np.abs(f["input_force"][1][:, 0] - expected).max() < 1e-9  # N m, on 400 N m
    assert np.abs(f["input_force_lagrange"][1][:, 0] - expected).max() < 1e-9
    assert np.allclose(f["friction_force"][1][:, 0], 1.0, rtol=0, atol=1e-12)
    assert np.all(f["friction_power"][1] < 0)


SLIDER = """
[scene]
name = "slider_friction"
units = { length = "m", mass = "kg", time = "s", force = "N" }
[points]
O2 = { x = 0.0, y = 0.0, fixed = true }
A  = { x = 1.0, y = 0.0 }
B  = { x = 4.4641, y = 0.5 }
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = { "O2-A" = 1.0 }
[[links]]
name = "rod"
points = ["A", "B"]
lengths = { "A-B" = 3.5 }
[[sliders]]
name = "piston"
point = "B"
along = { through = [0.0, 0.5], direction = [1.0, 0.0] }
[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 3.0
to = 357.0
steps = 119
rate = 572.9577951308232
[analysis]
effects = ["loads", "friction"]
[[loads]]
name = "gas"
point = "B"
force = [-1000.0, 0.0]
[[friction]]
name = "guide"
slider = "piston"
mu = 0.3
"""


def test_slider_crank_guide_friction_against_statics_by_hand():
    """At the piston: P + T u + f = 0 along the guide, T u_y + N = 0 across it, with the
    friction f = -mu |N| sign(v_B): the rod force T solves T (u_x - mu |u_y| sign(T) s) = -P
    (the normal force depends on the friction force); the crank's torque is (A - O2) x (T u)."""
    r = linkpipe.solve(parse_scene(SLIDER))
    assert r.message == "all 119 steps ok"
    X, V = r.position, r.velocity
    names = r.point_names
    A, B = X[:, names.index("A")], X[:, names.index("B")]
    u = (A - B) / np.hypot(*(A - B).T)[:, None]
    s = np.sign(V[:, names.index("B"), 0])
    mu, P = 0.3, -1000.0
    T = np.where(True, -P / (u[:, 0] - mu * np.abs(u[:, 1]) * s), 0.0)  # tension first
    compressed = T < 0
    T[compressed] = (-P / (u[:, 0] + mu * np.abs(u[:, 1]) * s))[compressed]
    torque = A[:, 0] * T * u[:, 1] - A[:, 1] * T * u[:, 0]
    N = np.abs(T * u[:, 1])
    f = r.forces
    assert np.abs(f["input_force"][1][:, 0] - torque).max() < 1e-8  # N m, on ~1000 N m
    assert np.abs(f["input_force_lagrange"][1][:, 0] - torque).max() < 1e-8
    assert np.abs(f["friction_force"][1][:, 0] - mu * N).max() < 1e-8
    assert np.abs(np.abs(f["slider_force"][1][:, 0]) - N).max() < 1e-8
    # without friction the same scene's torque differs by the friction's part
    r0 = linkpipe.solve(parse_scene(SLIDER.replace('"loads", "friction"', '"loads"')))
    assert np.abs(r0.forces["input_force"][1] - f["input_force"][1]).max() > 10


FOURBAR = """
[scene]
name = "fourbar_friction"
units = { length = "m", mass = "kg", time = "s", force = "N" }
[points]
O2 = { x = 0.0, y = 0.0, fixed = true }
A  = { x = 1.0, y = 0.0 }
B  = { x = 3.0417, y = 2.8428 }
O4 = { x = 4.0, y = 0.0, fixed = true }
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = { "O2-A" = 1.0 }
[[links]]
name = "coupler"
points = ["A", "B"]
lengths = { "A-B" = 3.5 }
[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = { "O4-B" = 3.0 }
[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 1.0
to = 359.0
steps = 180
rate = 572.9577951308232
[analysis]
effects = ["gravity", "inertia", "loads", "friction"]
[gravity]
g = [0.0, -9.81]
[[masses]]
link = "crank"
mass = 2.0
center = [0.5, 0.0]
inertia = 0.2
[[masses]]
link = "coupler"
mass = 5.0
center = [1.75, 0.2]
inertia = 5.0
[[masses]]
link = "rocker"
mass = 4.0
center = [1.5, -0.1]
inertia = 3.0
[[loads]]
name = "work"
link = "rocker"
torque = -200.0
[[friction]]
name = "pins"
joints = ["O2", "A", "B", "O4"]
mu = 0.15
pin_radius = 0.04
viscous = 0.5
"""


def _newton_euler(r, mu=0.15, radius=0.04, viscous=0.5):
    """Each body's Newton-Euler equations with the pin forces F_O2 (ground on crank), F_A (crank
    on coupler), F_B (coupler on rocker), F_O4 (ground on rocker) and the motor's torque M as
    unknowns, the friction couples from their magnitudes; fsolve step by step."""
    names = r.point_names
    X, Acc = r.position, r.acceleration
    w, al = r.link_angular_velocity, r.link_angular_acceleration
    g = np.array([0.0, -9.81])
    scale = 1e-6 * r.model.size / r.model.size  # rad/s: the default friction_velocity_scale
    bodies = {"crank": ("O2", "A", 2.0, (0.5, 0.0), 0.2), "coupler": ("A", "B", 5.0, (1.75, 0.2), 5.0),
              "rocker": ("O4", "B", 4.0, (1.5, -0.1), 3.0)}
    out = []
    for k in range(r.n_steps):
        P = {n: X[k, names.index(n)] for n in names}
        Pa = {n: Acc[k, names.index(n)] for n in names}
        G, aG = {}, {}
        for b, (a_, b_, m, (u, v), inertia) in bodies.items():
            d = P[b_] - P[a_]
            L = np.hypot(*d)
            e, n_ = d / L, np.array([-d[1], d[0]]) / L
            G[b] = P[a_] + u * e + v * n_
            dd = Pa[b_] - Pa[a_]
            de, dn = dd / L, np.array([-dd[1], dd[0]]) / L
            aG[b] = Pa[a_] + u * de + v * dn
        wc, wp, wr = w[k]
        rel = {"O2": wc, "A": wp - wc, "B": wr - wp, "O4": wr}

        def cross(r_, f):
            return r_[0] * f[1] - r_[1] * f[0]

        def eqs(x):
            FO2, FA, FB, FO4, M = x[0:2], x[2:4], x[4:6], x[6:8], x[8]
            T = {p: mu * radius * np.hypot(*F) * np.tanh(rel[p] / scale) + viscous * rel[p]
                 for p, F in (("O2", FO2), ("A", FA), ("B", FB), ("O4", FO4))}
            mc, mp, mr = 2.0, 5.0, 4.0
            res = list(FO2 - FA + mc * g - mc * aG["crank"])
            res.append(cross(P["O2"] - G["crank"], FO2) + cross(P["A"] - G["crank"], -FA) + M
                       - T["O2"] + T["A"] - 0.2 * al[k, 0])
            res += list(FA - FB + mp * g - mp * aG["coupler"])
            res.append(cross(P["A"] - G["coupler"], FA) + cross(P["B"] - G["coupler"], -FB)
                       - T["A"] + T["B"] - 5.0 * al[k, 1])
            res += list(FB + FO4 + mr * g - mr * aG["rocker"])
            res.append(cross(P["B"] - G["rocker"], FB) + cross(P["O4"] - G["rocker"], FO4)
                       - 200.0 - T["B"] - T["O4"] - 3.0 * al[k, 2])
            return res

        x = fsolve(eqs, np.zeros(9), xtol=1e-13)
        assert np.abs(eqs(x)).max() < 1e-7
        out.append(x)
    return np.array(out)


def test_fourbar_with_friction_at_every_pin_against_newton_euler():
    r = linkpipe.solve(parse_scene(FOURBAR))
    assert r.message == "all 180 steps ok"
    ne = _newton_euler(r)
    f = r.forces
    torque = f["input_force"][1][:, 0]
    assert np.abs(torque - ne[:, 8]).max() < 1e-6  # N m, on up to ~400 N m
    assert np.abs(f["input_force_lagrange"][1][:, 0] - ne[:, 8]).max() < 1e-6
    joints = r.force_coords["joint"]
    jf = f["joint_force"][1]
    assert np.abs(jf[:, joints.index("O2@crank")] - ne[:, 0:2]).max() < 1e-6
    assert np.abs(jf[:, joints.index("A@coupler")] - ne[:, 2:4]).max() < 1e-6
    assert np.abs(jf[:, joints.index("B@rocker")] - ne[:, 4:6]).max() < 1e-6
    assert np.abs(jf[:, joints.index("O4@rocker")] - ne[:, 6:8]).max() < 1e-6


def test_power_balance_at_every_ok_step():
    """input + friction + every other effect's power = 0 (each effect's power stored)."""
    for text in (FOURBAR, SLIDER, LEVER.replace("RATE", "20.0")):
        r = linkpipe.solve(parse_scene(text))
        ok = r.status == OK
        f = r.forces
        effects = r.force_coords["effect"]
        assert "friction" in effects
        friction_power = f["power"][1][:, effects.index("friction")]
        assert np.allclose(friction_power, f["friction_power"][1].sum(axis=1), rtol=0, atol=1e-9)
        rate = r.kinematics.s_dot
        balance = (f["input_force"][1] * rate).sum(axis=1) + f["power"][1].sum(axis=1)
        scale = np.abs(f["input_force"][1] * rate).max()
        assert np.abs(balance[ok]).max() < 1e-10 * scale
        assert np.all(friction_power[ok] <= 1e-12)


#: the tipper's body on its cylinder, with gravity and the cylinder's seal friction (Coulomb
#: 800 N): the drivers and the rest of the seal's law are each test's own
TIPPER_BODY = """
[points]
H = { x = 0.0, y = 0.0, fixed = true }
F = { x = 5.2, y = 0.0 }
P = { x = 4.9, y = 0.4 }
C = { x = 4.6, y = -0.9, fixed = true }
G = { x = 2.6, y = 0.85 }
[[links]]
name = "body"
points = ["H", "F", "P", "G"]
"""
SEAL_FRICTION = """
[analysis]
effects = ["gravity", "friction"]
[gravity]
g = [0.0, -9.81]
[[masses]]
link = "body"
mass = 17500.0
center = "G"
[[friction]]
name = "seal"
driver = "cyl"
coulomb = 800.0
"""

SEAL = """
[scene]
name = "seal"
units = { length = "m", mass = "kg", time = "s", force = "N" }
""" + TIPPER_BODY + """[[drivers]]
name = "cyl"
distance = ["C", "P"]
from = FROM
to = TO
steps = 41
rate = RATE
""" + SEAL_FRICTION + """viscous = 2000.0
stribeck = { peak = 1200.0, velocity = 0.01 }
"""


@pytest.mark.parametrize("speed", [0.003, 0.01, 0.05])
def test_seal_raise_lower_difference_is_twice_the_stribeck_law(speed):
    up = linkpipe.solve(parse_scene(SEAL.replace("FROM", "1.4").replace("TO", "2.4")
                                    .replace("RATE", str(speed))))
    down = linkpipe.solve(parse_scene(SEAL.replace("FROM", "2.4").replace("TO", "1.4")
                                      .replace("RATE", str(-speed))))
    assert up.n_ok == down.n_ok == 41
    law = (800.0 + 400.0 * math.exp(-(speed / 0.01) ** 2)) + 2000.0 * speed
    diff = up.forces["input_force"][1][:, 0] - down.forces["input_force"][1][::-1, 0]
    assert np.abs(diff - 2 * law).max() < 1e-7  # N, on cylinder forces of ~200 kN
    assert np.allclose(up.forces["friction_force"][1][:, 0], law, rtol=1e-12)
    assert np.abs(up.forces["input_force_lagrange"][1] - up.forces["input_force"][1]).max() < 1e-7


def test_friction_at_rest_is_zero_not_nan():
    r = linkpipe.solve(parse_scene(LEVER.replace("RATE", "0.0")))
    assert r.message == "all 91 steps ok"
    assert np.all(r.forces["friction_force"][1] == 0.0)


def test_the_effects_gate_no_friction_unless_called_for():
    off = linkpipe.solve(parse_scene(FOURBAR.replace('"loads", "friction"]', '"loads"]')))
    assert "friction_force" not in off.forces and "friction_power" not in off.forces
    assert "friction" not in off.force_coords.get("effect", [])
    assert "friction" in off.scene.present_but_off
    on = linkpipe.solve(parse_scene(FOURBAR))
    assert {"friction_force", "friction_power"} <= set(on.forces)


def test_self_locking_pin_friction_is_not_converged():
    """A pin radius as large as the crank: the friction circle swallows the linkage, the
    iteration diverges and those steps are not_converged (NaN forces), never a wrong number."""
    r = linkpipe.solve(parse_scene(FOURBAR.replace("pin_radius = 0.04", "pin_radius = 3.0")
                                   .replace("mu = 0.15", "mu = 0.9")))
    bad = r.status == 3
    assert bad.any()
    assert np.isnan(r.forces["input_force"][1][bad]).all()


BAD = [
    (FOURBAR.replace("mu = 0.15", "mu = -0.1"), 'friction "pins"', "mu"),
    (FOURBAR.replace("pin_radius = 0.04", "pin_radius = 0.0"), 'friction "pins"', "pin_radius"),
    (FOURBAR.replace('joints = ["O2", "A", "B", "O4"]', 'joints = ["O2", "Z"]'),
     'friction "pins"', "joints"),
    (SLIDER.replace('slider = "piston"', 'slider = "pistn"'), 'friction "guide"', "slider"),
    (SEAL.replace('driver = "cyl"', 'driver = "boom"').replace("FROM", "1.4").replace("TO", "2.4")
     .replace("RATE", "0.1"), 'friction "seal"', "driver"),
    (SEAL.replace("FROM", "1.4").replace("TO", "2.4").replace("RATE", "0.1")
     .replace("rate = 0.1", "rate = 0.1\nstroke = [1.7, 1.2]"), 'drivers "cyl"', "stroke"),
]


@pytest.mark.parametrize("text,table,key", BAD)
def test_bad_friction_and_stroke_input_is_one_scene_error(text, table, key):
    with pytest.raises(SceneError) as err:
        parse_scene(text, "bad.toml")
    assert err.value.table == table and err.value.key == key


def test_bad_input_on_the_command_line_exit_2_nothing_written(tmp_path):
    from linkpipe.__main__ import main

    scene = tmp_path / "bad.toml"
    scene.write_text(FOURBAR.replace("mu = 0.15", "mu = -0.1"))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 2
    assert not out.exists() or not any(out.iterdir())


def test_compressed_length_not_below_extended_is_a_scene_error():
    text = open("configs/hatch_gas_spring.toml").read()
    assert "extended_length" in text
    bad = text.replace("extended_length = 0.55", "extended_length = 0.55\ncompressed_length = 0.6")
    with pytest.raises(SceneError) as err:
        parse_scene(bad, "hatch.toml")
    assert err.value.key == "compressed_length"


def test_a_study_counts_out_of_stroke_variants_as_failed_and_flags_an_edge(tmp_path, capsys):
    """The hatch's struts anchored lower or further out stretch past extended_length (0.55 m):
    those variants, and only those, are out_of_stroke (7) by the closed form |B - A| with
    A = u (cos t, sin t) on the tailgate; the best variant sits on its grid's edge, said so."""
    import pathlib

    from linkpipe.__main__ import main
    from linkpipe.stores.study import read_arrays

    root = pathlib.Path(__file__).resolve().parent.parent
    path = tmp_path / "hatch.toml"
    path.write_text(f'[study]\nbase = "{(root / "configs/hatch_gas_spring.toml").as_posix()}"\n'
                    '[study.parameters]\n"points.B.y" = { from = -0.56, to = -0.44, steps = 7 }\n'
                    '"links.tailgate.local.A.0" = { from = 0.15, to = 0.25, steps = 6 }\n')
    assert main(["study", str(path), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    f = read_arrays(tmp_path / "hatch_study.h5")
    t = np.radians(np.arange(-70.0, 15.0 + 1e-9, 0.5))
    for v, (by, u) in enumerate(f["parameter_value"]):
        A = u * np.stack([np.cos(t), np.sin(t)], axis=1)
        longest = np.hypot(A[:, 0] - 0.16, A[:, 1] - by).max()
        assert (f["worst_status"][v] == 7) == (longest > 0.55 + 1e-9), (v, longest)
    assert (f["worst_status"] == 7).any() and (f["worst_status"] == 0).any()
    assert "best on the edge: links.tailgate.local.A.0 = 0.15 is the lowest value" in out


def test_stroke_margin_of_a_cylinder_against_its_stroke():
    text = (SEAL.replace("FROM", "1.4").replace("TO", "2.4").replace("RATE", "0.1")
            .replace("rate = 0.1", "rate = 0.1\nstroke = [1.5, 2.2]"))
    r = linkpipe.solve(parse_scene(text))
    s = r.driver_value[:, 0]
    margin = np.minimum(s - 1.5, 2.2 - s)
    assert np.allclose(r.stroke_margin[:, 0], margin, rtol=0, atol=1e-12)
    outside = margin < -1e-9
    assert np.array_equal(r.status == 7, outside) and outside.any()
    assert np.isfinite(r.forces["input_force"][1][outside]).all()  # every value kept
    names = {v.name: v for v in r.variables()}
    assert names["stroke_margin"].dims == ("step", "stroke")
    assert "out_of_stroke" in names["status"].attrs["flag_meanings"].split()
    from linkpipe.report import summary

    worst = int(np.argmin(margin))  # 2.4 m against the longest 2.2 m: 0.2 m beyond
    assert (f"  out_of_stroke: cyl beyond its stroke by up to {-margin[worst]:.4g} m "
            f"(step {worst}; stroke_margin holds every step's)") in summary(r).splitlines()


def test_the_raise_lower_demo_fit_recovers_mass_and_seal_friction(tmp_path):
    """The README's demo: the fit of configs/logged/dump_truck_friction.toml lands within
    three standard errors of the generator's truth (17,500 kg, 3000 N, 20000 N s/m)."""
    import pathlib

    from linkpipe.fit import fit

    root = pathlib.Path(__file__).resolve().parent.parent
    result = fit(linkpipe.load_scene(root / "configs/logged/dump_truck_friction.toml"))
    truth = np.array([17500.0, 3000.0, 20000.0])
    assert result.names == ["masses.body.mass", "friction.seal.coulomb", "friction.seal.viscous"]
    assert np.all(np.abs(result.fitted - truth) < 3 * result.standard_error)
    assert result.stage1_solves == 1


SEAL_TIMED = """
[scene]
name = "seal_timed"
units = { length = "m", mass = "kg", time = "s", force = "N" }
""" + TIPPER_BODY + """[time]
from = 0.0
to = 20.0
steps = 401
[[drivers]]
name = "cyl"
distance = ["C", "P"]
from = 1.4
to = 2.4
law = "harmonic"
""" + SEAL_FRICTION


def test_the_accuracy_ladder_of_friction_velocity_scale_against_the_sign_law():
    """Seal friction alone: the regularised input force differs from the exact sign law's by
    coulomb (1 - tanh(|v| / scale)) at each step (v from the harmonic law, by hand); the
    ladder's away-from-rest and near-rest errors are those maxima over the largest force."""
    from linkpipe.accuracy import measure
    from linkpipe.accuracy.references import NEAR_REST

    scene = parse_scene(SEAL_TIMED, "seal_timed.toml")
    ladder = measure(scene, quick=False, repeats=1, knobs=("friction_velocity_scale",))
    rows = [r for r in ladder.rows if r.knob == "friction_velocity_scale"]
    assert [r.value for r in rows] == ["1e-01", "1e-02", "1e-03", "1e-04", "1e-06", "1e-08"]
    t = np.linspace(0.0, 20.0, 401)
    v = 0.5 * np.pi / 20.0 * np.sin(np.pi * t / 20.0)  # harmonic: (1 - cos(pi t / T)) / 2
    exact = linkpipe.solve(scene).forces["input_force"][1][:, 0]
    top = np.abs(exact).max()
    size = linkpipe.solve(scene).model.size
    rest = v <= 1e-12 * v.max()
    near = (v < NEAR_REST * v.max()) & ~rest
    away = ~near & ~rest
    for r in rows:
        scale = float(r.value) * size
        gap = 800.0 * (1.0 - np.tanh(v / scale)) / top
        assert r.relative_error_away == pytest.approx(gap[away].max(), rel=1e-6, abs=1e-13)
        assert r.relative_error_near == pytest.approx(gap[near].max(), rel=1e-6, abs=1e-13)
        assert np.isfinite(r.seconds) and r.stage == "forces"


def _with_friction_everywhere(path):
    """A shipped scene with friction at every pin, slider and driver (a rate where it has none)."""
    import pathlib
    import tomllib

    import tomli_w

    data = tomllib.loads(pathlib.Path(path).read_text())
    points, links = data["points"], data["links"]

    def moving(link):
        return not all(points[q].get("fixed", False) for q in link["points"])

    joints = [p for p in points if any(p in ln["points"] and moving(ln) for ln in links)
              and sum(p in ln["points"] and moving(ln) for ln in links)
              + points[p].get("fixed", False) >= 2]
    analysis = data.setdefault("analysis", {})
    analysis["effects"] = list(analysis.get("effects", [])) + ["friction"]
    friction = [{"name": "pins", "joints": joints, "mu": 0.2, "pin_radius": 0.02, "viscous": 0.1}]
    friction += [{"name": f"guide_{s['name']}", "slider": s["name"], "mu": 0.3, "viscous": 0.5}
                 for s in data.get("sliders", [])]
    for d in data["drivers"]:
        friction.append({"name": f"seal_{d['name']}", "driver": d["name"], "coulomb": 5.0,
                         "viscous": 1.0})
        if data.get("time") is None and "rate" not in d:
            d["rate"] = 10.0
    data["friction"] = friction
    return parse_scene(tomli_w.dumps(data), str(path))


@pytest.mark.parametrize("name", ["basketball_goal", "dump_truck", "excavator_arm", "five_bar",
                                  "fourbar_crank_encoder", "fourbar_crank_rocker",
                                  "hatch_gas_spring", "jansen", "shear_press", "slider_crank"])
def test_every_shipped_scene_with_friction_everywhere_balances(name):
    """Virtual work (friction's power included) against the Lagrange multipliers (the friction's
    loads in Q), and where no driver pushes (``input``) the power balance, at every ok step."""
    import pathlib

    path = pathlib.Path(__file__).resolve().parent.parent / "configs" / f"{name}.toml"
    r = linkpipe.solve(_with_friction_everywhere(path))
    ok = r.status == OK
    assert ok.sum() >= r.n_steps - 1
    f = r.forces
    vw, lg = f["input_force"][1][ok], f["input_force_lagrange"][1][ok]
    assert np.abs(vw - lg).max() <= 1e-12 * np.abs(vw).max()
    assert (f["friction_force"][1][ok] > 0).any(axis=0).all()  # every entry acts somewhere
    if not any(d.input is not None for d in r.scene.drivers):
        rate = r.kinematics.s_dot[ok]
        balance = (vw * rate).sum(axis=1) + f["power"][1][ok].sum(axis=1)
        assert np.abs(balance).max() <= 1e-12 * np.abs(vw * rate).max()


LOGGED_LEVER = LEVER.replace("""from = -30.0
to = 60.0
steps = 91
rate = RATE
""", 'log = "rig.angle_deg"\n') + """
[time]
log = "rig"

[[logs]]
name = "rig"
file = "rig.csv"
time = "t"

[[measurements]]
name = "pivot_torque"
log = "rig.pivot_Nmm"
scale = 0.001
of = "friction_force.pivot"

[[measurements]]
name = "pivot_power"
log = "rig.pivot_W"
of = "friction_power.pivot"
"""


def _logged_lever(tmp_path, text=LOGGED_LEVER):
    """The lever turned at a steady pi/2 rad/s (-30 to 60 degrees in 1 s) from a log that also
    holds the pin friction's closed form: torque mu r W = 0.2 x 0.01 m x 500 N = 1 N m (the pin
    carries the weight alone; logged in N mm) and its power -1 N m x pi/2 rad/s."""
    t = np.linspace(0.0, 1.0, 51)
    rows = ["t,angle_deg,pivot_Nmm,pivot_W"] + [
        f"{x!r},{-30.0 + 90.0 * x!r},1000.0,{-math.pi / 2!r}" for x in t.tolist()]
    (tmp_path / "rig.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "lever.toml").write_text(text)
    return tmp_path / "lever.toml"


def test_pin_friction_is_measurable_against_its_closed_form(tmp_path):
    """``of = "friction_force.<entry>"`` and ``"friction_power.<entry>"``: the computed
    counterpart is the stored entry, in its unit (N*m for pins); residuals against the closed
    form are rounding (1e-9 N m on 1 N m; the log's angle is read through its spline, exact on
    a straight line)."""
    from linkpipe.measure import compare
    from linkpipe.output_units import measured_units

    r = linkpipe.solve(linkpipe.load_scene(_logged_lever(tmp_path)))
    assert (r.status == OK).all()
    got = compare(r)
    assert got["names"] == ["pivot_torque", "pivot_power"]
    assert np.abs(got["residual"]).max() < 1e-9
    assert measured_units(r.scene) == ["N*m", "N*m/s"]


@pytest.mark.parametrize("old, new, words", [
    ('effects = ["loads", "friction"]', 'effects = ["loads"]',
     ['"friction_force" is computed by "friction" in [analysis] effects']),
    ('of = "friction_force.pivot"', 'of = "friction_force.pivto"',
     ["no friction entry named", "pivot"]),
])
def test_a_friction_measurement_without_its_friction_is_one_scene_error(tmp_path, old, new,
                                                                        words):
    text = LOGGED_LEVER.replace(old, new)
    with pytest.raises(SceneError) as err:
        linkpipe.load_scene(_logged_lever(tmp_path, text))
    message = str(err.value)
    assert all(w in message for w in words), message
    assert "[[measurements]]" in message or "measurements" in message


@pytest.mark.parametrize("name", ["excavator_arm", "five_bar", "jansen", "shear_press",
                                  "slider_crank"])
def test_the_stacked_unit_cases_equal_the_cases_solved_one_by_one(name, monkeypatch):
    """Friction's unit load cases solved together (``stacked_multipliers``, multipliers laid
    out row by row; ``stacked_reactions`` accumulating in its outputs' memory) against each
    case solved alone by :func:`multipliers` and :func:`reactions` (the single-case path every
    frictionless run takes): every stored force agrees to 1e-12 of its largest value (the
    block solves differ only in using inverses or factorisations: rounding)."""
    import pathlib

    import linkpipe.forces as forces
    from linkpipe.forces.lagrange import reactions

    path = pathlib.Path(__file__).resolve().parent.parent / "configs" / f"{name}.toml"
    stacked = linkpipe.solve(_with_friction_everywhere(path))

    def one_by_one(model, lam, point_forces, bodies, X, s, ok, rows=None, at_fixed=False):
        fixed = np.flatnonzero(model.fixed)
        out = []
        for k, case_bodies in enumerate(bodies):
            loads = np.zeros(X.shape)
            loads[:, fixed] = point_forces[k] if at_fixed else point_forces[k][:, fixed]
            out.append(reactions(model, np.array(lam[k]), loads, case_bodies, X, s, ok, rows))
        return np.stack([g for g, _ in out]), np.stack([p for _, p in out])

    monkeypatch.setattr(forces, "stacked_multipliers", lambda *a, **k: None)  # case by case
    monkeypatch.setattr(forces, "stacked_reactions", one_by_one)
    alone = linkpipe.solve(_with_friction_everywhere(path))
    np.testing.assert_array_equal(stacked.status, alone.status)
    assert set(stacked.forces) == set(alone.forces)
    for key, (_, values, _) in alone.forces.items():
        new = stacked.forces[key][1]
        if values.dtype.kind != "f":
            np.testing.assert_array_equal(new, values)
            continue
        np.testing.assert_array_equal(np.isnan(new), np.isnan(values))
        scale = np.nanmax(np.abs(values), initial=0.0)
        assert np.nanmax(np.abs(new - values), initial=0.0) <= 1e-12 * max(scale, 1e-300), key


@pytest.mark.parametrize("name", ["excavator_arm", "five_bar", "jansen", "shear_press",
                                  "slider_crank"])
def test_the_unit_loads_placed_at_their_few_points_equal_the_dense_loads(name, monkeypatch):
    """The stacked unit cases take each unit load at the few points it loads
    (:func:`linkpipe.forces.friction.unit_load_terms`), written into zeros; the dense loads
    (:func:`~linkpipe.forces.friction.unit_loads`, every point) give the same solve inputs, so
    every stored array is bit for bit the same when the terms list every point's dense value."""
    import pathlib

    import linkpipe.forces.friction as friction

    path = pathlib.Path(__file__).resolve().parent.parent / "configs" / f"{name}.toml"
    sparse = linkpipe.solve(_with_friction_everywhere(path))
    terms = friction.unit_load_terms

    def dense_terms(ctx, layout, influence, Xz):
        for forces, work, bodies in terms(ctx, layout, influence, Xz):
            points = ctx.zeros_points()
            for p, f in forces:
                points[:, p] += f
            yield tuple((p, points[:, p]) for p in range(points.shape[1])), work, bodies

    monkeypatch.setattr(friction, "unit_load_terms", dense_terms)
    dense = linkpipe.solve(_with_friction_everywhere(path))
    np.testing.assert_array_equal(sparse.status, dense.status)
    assert set(sparse.forces) == set(dense.forces)
    for key, (_, values, _) in dense.forces.items():
        np.testing.assert_array_equal(sparse.forces[key][1], values, err_msg=key)


def test_friction_forces_do_not_depend_on_the_chunks_of_steps():
    """Every step's friction is solved from that step alone (its unit cases, its magnitudes'
    rounds), so the force stage cut into chunks of 7 or 64 steps (as a long sweep is cut into
    FRICTION_CHUNK ones) gives the stored arrays of the whole sweep in one chunk, bit for bit."""
    import pathlib

    from linkpipe.forces import compute_forces
    from linkpipe.output_units import units_of

    path = pathlib.Path(__file__).resolve().parent.parent / "configs" / "excavator_arm.toml"
    r = linkpipe.solve(_with_friction_everywhere(path))
    motion, units = r.kinematics.motion(), units_of(r.scene)
    whole = compute_forces(r.model, motion, units, chunk=r.n_steps)
    assert (whole.status == OK).all()
    for chunk in (7, 64):
        cut = compute_forces(r.model, motion, units, chunk=chunk)
        np.testing.assert_array_equal(cut.status, whole.status)
        for name, (_, data, _) in whole.variables.items():
            np.testing.assert_array_equal(cut.variables[name][1], data, err_msg=name)


def _excavator_blocks():
    """The excavator's engine (two 4 x 4 diagonal blocks) and its Jacobian's entries (nnz, S)
    over its 201-step sweep."""
    import pathlib

    from linkpipe.kinematics.sparse import engine

    path = pathlib.Path(__file__).resolve().parent.parent / "configs" / "excavator_arm.toml"
    r = linkpipe.solve(linkpipe.load_scene(path))
    eng = engine(r.model)
    assert sorted(len(c) for _, c, _, _ in eng.blocks if len(c) > 2) == [4, 4]
    return eng, eng.entries_of(r.position, r.kinematics.s)


def test_the_force_stages_block_inverses_are_inverses():
    """Friction's kept block inverses (Gauss-Jordan with partial pivoting over all steps at
    once, :meth:`Engine.block_inverses_steps_last`) times each dense block is the identity, and
    they equal LAPACK's (:meth:`Engine.block_inverses`) to 1e-12 of their largest entry: both
    are backward stable and these blocks' condition numbers are below 1e3, so the two differ by
    at most ~cond x 1e-16."""
    from linkpipe.kinematics.sparse import _dense_block

    eng, E = _excavator_blocks()
    ours, lapack = eng.block_inverses_steps_last(E), eng.block_inverses(E)
    assert set(ours) == set(lapack)
    for i, inv in ours.items():
        M = _dense_block(E, eng.blocks[i][2])
        assert np.linalg.cond(M).max() < 1e3
        eye = np.einsum("sij,sjk->sik", M, inv)
        assert np.abs(eye - np.eye(4)).max() < 1e-12
        assert np.abs(inv - lapack[i]).max() <= 1e-12 * np.abs(lapack[i]).max()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(3, 6))
def test_gauss_jordan_pivots_where_a_diagonal_entry_is_zero(seed, k):
    """Well-conditioned matrices with a zero diagonal (a cyclic shift plus 0.1 of noise off the
    diagonal: elimination without row swaps divides by zero at once) are inverted to 1e-12
    (rounding times their condition, below 10) at every step; a singular step (all columns
    equal) is not finite, alone: its neighbours are inverted as well."""
    from linkpipe.kinematics.sparse import _gauss_jordan

    rng = np.random.default_rng(seed)
    S = 50
    M = np.roll(np.eye(k), 1, axis=1) + 0.1 * rng.uniform(-1, 1, (S, k, k)) / k
    M[:, np.arange(k), np.arange(k)] = 0.0
    M[7] = 1.0  # a singular step
    assert np.linalg.cond(np.delete(M, 7, axis=0)).max() < 10
    W = np.concatenate([np.moveaxis(M, 0, -1), np.broadcast_to(
        np.eye(k)[:, :, None], (k, k, S))], axis=1).copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.moveaxis(_gauss_jordan(W), -1, 0)
    good = np.arange(S) != 7
    assert not np.isfinite(inv[7]).all()
    assert np.isfinite(inv[good]).all()
    eye = np.einsum("sij,sjk->sik", M[good], inv[good])
    assert np.abs(eye - np.eye(k)).max() < 1e-12
