"""Real-machine configs checked against answers that do not use linkpipe's equations.

* ``configs/dump_truck.toml``: statics by hand (moments about the rear hinge) and the energy
  balance F ṡ = d(KE + PE)/dt from the body's closed-form rotation (law of cosines).
* ``configs/excavator_arm.toml``: the derivative of the loads' potential by central finite
  differences, each cylinder in turn, from a position solution written here (circle
  intersections in the order a draughtsman would construct the arm).
"""
import math
import pathlib

import numpy as np
import pytest

import linkpipe

ROOT = pathlib.Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


def _load(name):
    return linkpipe.load_scene(str(CONFIGS / name))


def _point(scene, name):
    p = next(p for p in scene.points if p.name == name)
    return np.array([p.x, p.y])


def _rotate(v, angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


# ------------------------------------------------------------------------------ dump truck
def _tipper(scene, s):
    """The body's rotation about the hinge theta(s) (rad, 0 as drawn) for cylinder length s,
    from the law of cosines in triangle H, C, P."""
    H, C, P = (_point(scene, n) for n in "HCP")
    rp, rc = np.hypot(*(P - H)), np.hypot(*(C - H))
    angle_p0, angle_c = math.atan2(*(P - H)[::-1]), math.atan2(*(C - H)[::-1])
    cos_between = (rp * rp + rc * rc - s * s) / (2 * rp * rc)
    return angle_c + np.arccos(cos_between) - angle_p0  # P counter-clockwise of C about H


def test_dump_truck_cylinder_force_is_statics_by_hand():
    scene = _load("dump_truck.toml")
    import dataclasses as dc
    static = dc.replace(scene, effects=("gravity",))
    r = linkpipe.solve(static)
    assert r.message == f"all {r.n_steps} steps ok"
    s = np.linspace(1.35, 5.2, r.n_steps)
    theta = _tipper(scene, s)
    H, C, P, G = (_point(scene, n) for n in "HCPG")
    m, g = 19000.0, 9.81
    force = np.empty_like(s)
    for i, t in enumerate(theta):
        p, gp = _rotate(P - H, t), _rotate(G - H, t)
        u = (p - (C - H)) / np.hypot(*(p - (C - H)))
        weight_moment = gp[0] * (-m * g)  # r x (0, -m g)
        arm = p[0] * u[1] - p[1] * u[0]
        force[i] = -weight_moment / arm
    got = r.forces["input_force"][1][:, 0]
    # forces of ~1e5 N from positions solved to 1e-12 m: 1e-6 N is rounding with margin
    assert np.abs(got - force).max() < 1e-6
    assert np.abs(r.forces["input_force_lagrange"][1][:, 0] - force).max() < 1e-6
    theta_end = np.degrees(theta[-1])
    assert 45 < theta_end < 55  # the sheet's tipping angle


def test_dump_truck_cylinder_power_is_the_energy_rate():
    """With inertia: F ṡ = d/dt (½ I_H ω² + m g y_G), ω = θ'(s) ṡ at constant ṡ, so
    F = dE/ds with E(s) evaluated from the closed-form θ(s) (central differences)."""
    scene = _load("dump_truck.toml")
    r = linkpipe.solve(scene)
    s = np.linspace(1.35, 5.2, r.n_steps)[1:-1]
    sd, m, I_g, g = 0.1, 19000.0, 52000.0, 9.81
    H, G = _point(scene, "H"), _point(scene, "G")
    I_h = I_g + m * float((G - H) @ (G - H))
    gx, gy = G - H

    Hp, Cp, Pp = (_point(scene, n) for n in "HCP")
    rp, rc = np.hypot(*(Pp - Hp)), np.hypot(*(Cp - Hp))

    def energy(x):
        cos_between = (rp * rp + rc * rc - x * x) / (2 * rp * rc)
        w = x / (rp * rc * np.sqrt(1 - cos_between ** 2)) * sd  # d theta/ds, exactly, times ṡ
        t = _tipper(scene, x)
        y = gx * np.sin(t) + gy * np.cos(t)
        return 0.5 * I_h * w * w + m * g * y

    # E ~ 5e5 J varies over ~1 m: truncation (third derivative x h^2 / 6) ~ 1e-5 N and
    # rounding (1e-16 E / h) ~ 1e-5 N
    h = 1e-5
    expected = (energy(s + h) - energy(s - h)) / (2 * h)
    got = r.forces["input_force"][1][1:-1, 0]
    assert np.abs(got - expected).max() < 1e-3
    assert (got > 0).all()  # a tipper cylinder only pushes


# ------------------------------------------------------------------------------ excavator
def _circle_meet(c1, r1, c2, r2, near):
    """The intersection of two circles nearer to ``near``."""
    d = c2 - c1
    L = np.hypot(*d)
    a = (r1 * r1 - r2 * r2 + L * L) / (2 * L)
    h = math.sqrt(max(r1 * r1 - a * a, 0.0))
    base = c1 + a * d / L
    perp = np.array([-d[1], d[0]]) / L
    roots = (base + h * perp, base - h * perp)
    return min(roots, key=lambda x: np.hypot(*(x - near)))


def _carry(drawn_a, drawn_b, drawn_p, a, b):
    """A third point of a rigid body placed from two of its points' new positions."""
    za, zb, zp = (complex(*x) for x in (drawn_a, drawn_b, drawn_p))
    ra, rb = complex(*a), complex(*b)
    z = ra + (zp - za) / (zb - za) * (rb - ra)
    return np.array([z.real, z.imag])


def _excavator(scene, s, near):
    """Every point's position for cylinder lengths s = (boom, stick, bucket), built as a
    draughtsman would: boom by its cylinder, then the stick, then the bucket four-bar."""
    X0 = {p.name: np.array([p.x, p.y]) for p in scene.points}
    d = {k: np.hypot(*(X0[a] - X0[b])) for k, (a, b) in
         {"O-BR": ("O", "BR"), "T-SR": ("T", "SR"), "N-M": ("N", "M"), "M-L": ("M", "L"),
          "K-L": ("K", "L")}.items()}
    X = {"O": X0["O"], "BC": X0["BC"]}
    X["BR"] = _circle_meet(X["O"], d["O-BR"], X["BC"], s[0], near["BR"])
    for p in ("T", "SC"):
        X[p] = _carry(X0["O"], X0["BR"], X0[p], X["O"], X["BR"])
    X["SR"] = _circle_meet(X["T"], d["T-SR"], X["SC"], s[1], near["SR"])
    for p in ("K", "BB", "N"):
        X[p] = _carry(X0["T"], X0["SR"], X0[p], X["T"], X["SR"])
    X["M"] = _circle_meet(X["N"], d["N-M"], X["BB"], s[2], near["M"])
    X["L"] = _circle_meet(X["M"], d["M-L"], X["K"], d["K-L"], near["L"])
    for p in ("G", "Q"):
        X[p] = _carry(X0["K"], X0["L"], X0[p], X["K"], X["L"])
    return X


def test_excavator_cylinder_forces_are_the_derivative_of_the_loads_potential():
    scene = _load("excavator_arm.toml")
    r = linkpipe.solve(scene)
    assert r.message == f"all {r.n_steps} steps ok"
    assert r.solver_method_used == "dyads"  # three cylinders, each a circle of the fast path
    names = r.point_names
    W_soil = np.array([0.0, -1500.0 * 9.81])
    W_dig = np.array([-20000.0, 8000.0])
    s_all = np.stack([np.linspace(d.from_value, d.to_value, d.steps) for d in scene.drivers], axis=1)
    h = 1e-6
    for i in range(0, r.n_steps, 20):
        near = {p: r.position[i, names.index(p)] for p in names}
        X = _excavator(scene, s_all[i], near)
        for p in names:  # the independent construction lands on the solved positions
            assert np.hypot(*(X[p] - near[p])) < 1e-9
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            Xp, Xm = _excavator(scene, s_all[i] + e, near), _excavator(scene, s_all[i] - e, near)

            def potential(Y):
                return -(W_soil @ Y["G"] + W_dig @ Y["Q"])

            expected = (potential(Xp) - potential(Xm)) / (2 * h)
            got = r.forces["input_force"][1][i, j]
            # central differences with h = 1e-6 m: truncation ~h² x curvature (~1e-8 relative)
            # and rounding ~1e-16 x 1e5 N / 1e-6 m ~ 1e-5 N: 1e-3 N of forces ~1e5 N
            assert abs(got - expected) < 1e-3, (i, j, got, expected)
            assert abs(r.forces["input_force_lagrange"][1][i, j] - got) < 1e-6


@pytest.mark.parametrize("name", ["excavator_arm.toml", "dump_truck.toml"])
def test_machine_configs_say_where_their_dimensions_come_from(name):
    text = (CONFIGS / name).read_text()
    assert "Where the dimensions come from" in text
