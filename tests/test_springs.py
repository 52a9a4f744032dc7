"""Spring kinds (linear, tension_only, compression_only, gas) and torsion springs, each against
an exact answer: closed forms at given lengths, the input force as the derivative of the
potential energy, Lagrange multipliers, each body's balance, the HDF5 file read back, the
recording, and the shipped tailgate (configs/hatch_gas_spring.toml)."""
from __future__ import annotations

import pathlib

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import linkpipe
from linkpipe.__main__ import main
from linkpipe.status import NON_FINITE, OK

ROOT = pathlib.Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"

# -- closed forms, written here independently of linkpipe/forces/springs.py --------------------


def linear(L, k, free):
    return k * (L - free), 0.5 * k * (L - free) ** 2


def tension_only(L, k, free):
    stretch = np.maximum(L - free, 0.0)
    return k * stretch, 0.5 * k * stretch ** 2


def compression_only(L, k, free):
    squeeze = np.minimum(L - free, 0.0)
    return k * squeeze, 0.5 * k * squeeze ** 2


def gas(L, f1, l1, d, gamma):
    """Tension -F1 ((L1 - d)/(L - d))^gamma and the potential whose derivative it is (zero at
    L1): F1 (L1 - d) ln((L1 - d)/(L - d)) for gamma = 1, else
    F1 (L1 - d) (((L1 - d)/(L - d))^(gamma - 1) - 1) / (gamma - 1)."""
    ratio = (l1 - d) / (L - d)
    if gamma == 1.0:
        return -f1 * ratio, f1 * (l1 - d) * np.log(ratio)
    return -f1 * ratio ** gamma, f1 * (l1 - d) * (ratio ** (gamma - 1) - 1) / (gamma - 1)


# -- scenes --------------------------------------------------------------------------------------

#: a block P-Q on a horizontal guide through O, driven by P.x: a spring O-P has length P.x
SLIDE = """\
[scene]
name = "slide"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}

[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
P = {{ x = {x0}, y = 0.0 }}
Q = {{ x = {x1}, y = 0.0 }}

[[links]]
name = "block"
points = ["P", "Q"]

[[sliders]]
name = "guide_p"
point = "P"
along = {{ through = [0.0, 0.0], direction = [1.0, 0.0] }}

[[sliders]]
name = "guide_q"
point = "Q"
along = {{ through = [0.0, 0.0], direction = [1.0, 0.0] }}

[[drivers]]
name = "x"
coordinate = "P.x"
from = {x0}
to = {x_end}
steps = {steps}

[analysis]
effects = ["springs"]
"""


def slide(x0, x_end, steps, springs_text):
    return linkpipe.parse_scene(SLIDE.format(x0=x0, x1=x0 + 0.1, x_end=x_end, steps=steps)
                                + springs_text, "slide.toml")


def spring(name, body, between='["O", "P"]'):
    return f'\n[[springs]]\nname = "{name}"\nbetween = {between}\n{body}'


GAS_BODY = ('kind = "gas"\nforce_extended = 450.0\nextended_length = 0.5\ndead_length = 0.2\n'
            'gamma = {gamma}\n')
KINDS = {
    "linear": "k = 100.0\nfree_length = 0.5\n",
    "tension_only": 'kind = "tension_only"\nk = 100.0\nfree_length = 0.5\n',
    "compression_only": 'kind = "compression_only"\nk = 100.0\nfree_length = 0.5\n',
    "gas": GAS_BODY.format(gamma=1.0),
    "gas_adiabatic": GAS_BODY.format(gamma=1.4),
}
FORMS = {"linear": lambda L: linear(L, 100.0, 0.5),
         "tension_only": lambda L: tension_only(L, 100.0, 0.5),
         "compression_only": lambda L: compression_only(L, 100.0, 0.5),
         "gas": lambda L: gas(L, 450.0, 0.5, 0.2, 1.0),
         "gas_adiabatic": lambda L: gas(L, 450.0, 0.5, 0.2, 1.4)}

FOURBAR = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
FOURBAR = FOURBAR[:FOURBAR.index("[outputs]")].replace(
    'O4 = { x = 4.0, y = 0.0, fixed = true }',
    'O4 = { x = 4.0, y = 0.0, fixed = true }\nS  = { x = 2.0, y = -1.0, fixed = true }')
#: over the crank's turn |S - P| runs from 2.397 to 3.681 m: free length 2.6 m makes the
#: one-sided springs switch between slack and loaded; the gas spring stays above dead length
FOURBAR_SPRINGS = {
    "linear": spring("s", "k = 50.0\nfree_length = 2.6\n", '["S", "P"]'),
    "tension_only": spring("s", 'kind = "tension_only"\nk = 50.0\nfree_length = 2.6\n', '["S", "P"]'),
    "compression_only": spring("s", 'kind = "compression_only"\nk = 50.0\nfree_length = 2.6\n',
                               '["S", "P"]'),
    "gas": spring("s", 'kind = "gas"\nforce_extended = 450.0\nextended_length = 3.0\n'
                  'dead_length = 1.5\ngamma = 1.4\n', '["S", "P"]'),
    "torsion": '\n[[torsion_springs]]\nname = "t"\nlinks = ["coupler", "rocker"]\nk = 2.5\n'
               'free_angle = -60.0\n',
}


def fourbar(steps, extra, effects='["springs"]'):
    text = FOURBAR.replace("steps = 361", f"steps = {steps}")
    return linkpipe.parse_scene(text + f"\n[analysis]\neffects = {effects}\n" + extra, "fourbar.toml")


def u_angle(r, link):
    """The direction of a link's u axis (first point -> second), from the positions."""
    names = r.point_names
    pts = next(l.points for l in r.scene.links if l.name == link)
    d = r.position[:, names.index(pts[1])] - r.position[:, names.index(pts[0])]
    return np.arctan2(d[:, 1], d[:, 0])


def assert_ok_but_out_of_stroke(r):
    """Every step ok but those where a gas spring is longer than its extended_length (version
    3: also its longest length), which are out_of_stroke (7) with every value kept."""
    if "spring_length" not in r.forces:  # no two-point spring: nothing has a stroke
        assert r.message == f"all {r.n_steps} steps ok"
        return np.zeros(r.n_steps, dtype=bool)
    length = r.forces["spring_length"][1]
    longest = np.array([sp.extended_length if sp.kind == "gas" else np.inf
                        for sp in r.scene.springs])
    outside = (length > longest + r.model.tolerance()).any(axis=1)
    np.testing.assert_array_equal(r.status, np.where(outside, 7, OK))
    return outside


# -- closed forms at given lengths --------------------------------------------------------------


def test_each_kind_at_given_lengths():
    """Lengths 0.25, 0.30, ..., 0.90 m: each kind's force and energy equal their closed forms,
    and the actuator holding the block carries their sum (dE/dx, by both solves)."""
    text = "".join(spring(kind, body) for kind, body in KINDS.items())
    r = linkpipe.solve(slide(0.25, 0.9, 14, text))
    assert assert_ok_but_out_of_stroke(r).sum() == 8  # the gas springs past 0.5 m
    L = r.driver_value[:, 0]
    np.testing.assert_allclose(r.forces["spring_length"][1], L[:, None] * np.ones(5), atol=1e-15)
    total = np.zeros_like(L)
    for j, kind in enumerate(KINDS):
        tension, energy = FORMS[kind](L)
        np.testing.assert_allclose(r.forces["spring_force"][1][:, j], tension, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(r.forces["spring_energy"][1][:, j], energy, rtol=1e-13, atol=1e-12)
        total += tension
    for name in ("input_force", "input_force_lagrange"):
        np.testing.assert_allclose(r.forces[name][1][:, 0], total, rtol=1e-12, atol=1e-10)
    # by hand, at 0.35 m and 0.70 m: the cable is slack / pulls 20 N, the stop pushes 15 N / 0,
    # the strut's gas volume is half / 5/3 of its extended one: -900 N and -450 (0.3/0.5) N
    force = dict(zip(KINDS, r.forces["spring_force"][1][2]))
    assert force["tension_only"] == 0.0 and force["compression_only"] == pytest.approx(-15.0)
    assert force["gas"] == pytest.approx(-900.0, rel=1e-14)
    assert force["gas_adiabatic"] == pytest.approx(-450.0 * 2.0 ** 1.4, rel=1e-14)
    force = dict(zip(KINDS, r.forces["spring_force"][1][9]))
    assert force["tension_only"] == pytest.approx(20.0) and force["compression_only"] == 0.0
    assert force["gas"] == pytest.approx(-450.0 * 0.3 / 0.5, rel=1e-14)
    # a gas strut's extension is its length minus its extended length
    np.testing.assert_allclose(r.forces["spring_extension"][1][:, 3], L - 0.5, atol=1e-15)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["linear", "tension_only", "compression_only"]),
       k=st.just(0.0) | st.floats(1e-3, 1e3), free=st.floats(0.05, 2.0), preload=st.floats(-50.0, 50.0),
       with_preload=st.booleans(), x0=st.floats(0.05, 1.0), span=st.floats(0.1, 1.0))
def test_elastic_kinds_family(kind, k, free, preload, with_preload, x0, span):
    """Any stiffness, free length or preload (the tension at the start, here the first step):
    tension and energy are the closed form clipped to the kind's sign, the energy zero where
    slack (and, with k = 0, the constant force's work from the start)."""
    body = f'kind = "{kind}"\nk = {k!r}\n' + (f"preload = {preload!r}\n" if with_preload
                                               else f"free_length = {free!r}\n")
    r = linkpipe.solve(slide(x0, x0 + span, 7, spring("s", body)))
    L = r.driver_value[:, 0]
    linear_tension = (preload + k * (L - x0)) if with_preload else k * (L - free)
    active = {"linear": np.ones(len(L), bool), "tension_only": linear_tension > 0,
              "compression_only": linear_tension < 0}[kind]
    tension = np.where(active, linear_tension, 0.0)
    if kind == "linear":
        energy = (preload * (L - x0) + 0.5 * k * (L - x0) ** 2) if with_preload else 0.5 * k * (L - free) ** 2
    elif k > 0:  # zero where slack: k/2 times the square of the length past the slack length
        slack_length = (x0 - preload / k) if with_preload else free
        energy = np.where(active, 0.5 * k * (L - slack_length) ** 2, 0.0)
    else:
        energy = np.where(active, linear_tension * (L - (x0 if with_preload else free)), 0.0)
    scale = 1.0 + abs(preload) + k * (3.0 + free)
    np.testing.assert_allclose(r.forces["spring_force"][1][:, 0], tension, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(r.forces["spring_energy"][1][:, 0], energy, rtol=1e-12,
                               atol=1e-12 * scale * 3)
    np.testing.assert_allclose(r.forces["input_force"][1][:, 0], tension, rtol=0, atol=1e-12 * scale)


@settings(max_examples=40, deadline=None)
@given(f1=st.floats(1.0, 5e3), l1=st.floats(0.3, 2.0), gap=st.floats(0.05, 1.0),
       gamma=st.sampled_from([1.0, 1.4]) | st.floats(0.2, 2.0), stroke=st.floats(0.05, 0.9))
def test_gas_family(f1, l1, gap, gamma, stroke):
    """Any gas strut over any stroke above its dead length: force and energy are the closed
    form and the input force their sum (the energy's derivative)."""
    d = l1 - gap
    lo = l1 - stroke * min(gap, l1 - 0.1)  # towards the dead length (and 0.1 m or longer)
    body = (f'kind = "gas"\nforce_extended = {f1!r}\nextended_length = {l1!r}\n'
            f"dead_length = {d!r}\ngamma = {gamma!r}\n")
    r = linkpipe.solve(slide(lo, l1, 6, spring("g", body)))
    assert r.n_ok == 6
    L = r.driver_value[:, 0]
    tension, energy = gas(L, f1, l1, d, gamma)
    np.testing.assert_allclose(r.forces["spring_force"][1][:, 0], tension, rtol=1e-11)
    # the closed form above, (r^(gamma-1) - 1)/(gamma - 1), loses digits to cancellation as gamma
    # nears 1 (about eps/|gamma - 1| of F1 (L1 - d)); linkpipe's expm1 form does not
    cancellation = 0.0 if gamma == 1.0 else 1e-15 / abs(gamma - 1.0)
    np.testing.assert_allclose(r.forces["spring_energy"][1][:, 0], energy, rtol=1e-10,
                               atol=(1e-12 + cancellation) * f1 * gap)
    np.testing.assert_allclose(r.forces["input_force"][1][:, 0], tension, rtol=1e-11)


# -- the input force is the derivative of the potential energy ---------------------------------


@pytest.mark.parametrize("kind", list(FOURBAR_SPRINGS))
def test_input_force_is_the_derivative_of_potential_energy(kind):
    """A crank-rocker with one spring and nothing else (no inertia): the crank torque by virtual
    work is dE/dtheta of the stored energy, by 5-point central differences on a 0.01 deg sweep,
    and equals the Lagrange multipliers' to rounding.

    Tolerance 2e-7 N*m: with h = 1.75e-4 rad the stencil's truncation h^4/30 |E^(5)| is far
    below its rounding, ~eps |E| / h: |E| reaches 385 J (gas) -> ~5e-10 N*m, measured 5e-9 N*m
    (gas; 3e-10 linear, 8e-12 torsion) for torques up to 426 N*m (gas); a one-sided spring's energy has a jump of E'' where
    it goes slack, so at each such kink the 4 stencils that straddle it are left out (it makes them
    wrong by up to about k (dL/dtheta)^2 h / 4)."""
    steps = 36001
    r = linkpipe.solve(fourbar(steps, FOURBAR_SPRINGS[kind]))
    assert_ok_but_out_of_stroke(r)
    energy_name = "torsion_spring_energy" if kind == "torsion" else "spring_energy"
    E = r.forces[energy_name][1].sum(axis=1)
    F = r.forces["input_force"][1][:, 0]
    h = np.deg2rad(360.0 / (steps - 1))
    dE = (E[:-4] - 8 * E[1:-3] + 8 * E[3:-1] - E[4:]) / (12 * h)
    keep = np.ones(steps - 4, dtype=bool)
    if kind in ("tension_only", "compression_only"):
        taut = r.forces["spring_force"][1][:, 0] != 0
        switches = np.flatnonzero(np.diff(taut))
        assert len(switches) == 2  # it goes slack and taut again over the turn
        for i in switches:
            keep[max(i - 3, 0):i + 1] = False  # the stencils holding steps i and i + 1
        assert (~keep).sum() == 8
    np.testing.assert_allclose(F[2:-2][keep], dE[keep], rtol=0, atol=2e-7)
    FL = r.forces["input_force_lagrange"][1][:, 0]
    np.testing.assert_allclose(FL, F, rtol=0, atol=1e-12 * np.abs(F).max())


def test_torsion_spring_between_two_moving_links_closed_form():
    """Coupler against rocker: the angle is the coupler's u direction minus the rocker's (from
    the positions, unwrapped), the torque k (angle - free); its energy, computed here, has the
    input torque as its derivative."""
    r = linkpipe.solve(fourbar(3601, FOURBAR_SPRINGS["torsion"]))
    angle = np.unwrap(u_angle(r, "coupler") - u_angle(r, "rocker"))
    free = np.deg2rad(-60.0)
    angle -= 2 * np.pi * np.round((angle[0] - free) / (2 * np.pi))
    got = r.forces["torsion_spring_angle"][1][:, 0]
    np.testing.assert_allclose(got, angle, rtol=0, atol=1e-13)
    np.testing.assert_allclose(r.forces["torsion_spring_torque"][1][:, 0], 2.5 * (angle - free),
                               rtol=0, atol=1e-12)
    E = 0.5 * 2.5 * (angle - free) ** 2
    h = np.deg2rad(0.1)
    dE = (E[:-4] - 8 * E[1:-3] + 8 * E[3:-1] - E[4:]) / (12 * h)
    # h = 1.75e-3 rad: truncation h^4/30 |E^(5)| < 1e-9 N*m here
    np.testing.assert_allclose(r.forces["input_force"][1][2:-2, 0], dE, rtol=0, atol=1e-8)


@settings(max_examples=30, deadline=None)
@given(k=st.floats(0.0, 100.0), start=st.floats(-720.0, 720.0), span=st.floats(1.0, 800.0), backwards=st.booleans(),
       free=st.floats(-1080.0, 1080.0))
def test_torsion_spring_on_a_crank_against_ground_is_exact(k, start, span, backwards, free):
    """Crank against ground: the angle is the crank's, the driver's value as written (winding
    on past a full turn, whole turns included), the input torque k (theta - free_angle) exactly
    for any free angle (no turns taken off: the contract's angle), by virtual work and by the
    multipliers."""
    text = CRANK.format(start=start, stop=start - span if backwards else start + span, k=k,
                        free=free)
    r = linkpipe.solve(linkpipe.parse_scene(text, "crank.toml"))
    assert r.n_ok == r.n_steps
    theta = np.deg2rad(r.driver_value[:, 0])
    np.testing.assert_allclose(r.forces["torsion_spring_angle"][1][:, 0], theta, rtol=0,
                               atol=1e-13 * (1 + np.abs(theta).max()))
    expect = k * (theta - np.deg2rad(free))
    scale = 1e-13 * (1 + k) * (1 + np.abs(theta).max())
    for name in ("torsion_spring_torque", "input_force", "input_force_lagrange"):
        np.testing.assert_allclose(r.forces[name][1][:, 0], expect, rtol=0, atol=scale)


CRANK = """\
[scene]
name = "crank"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
A = {{ x = 0.2, y = 0.0 }}
[[links]]
name = "crank"
points = ["O", "A"]
[[drivers]]
name = "theta"
angle = ["O", "A"]
from = {start!r}
to = {stop!r}
steps = 97
[analysis]
effects = ["springs"]
[[torsion_springs]]
name = "hinge"
links = ["crank", "ground"]
k = {k!r}
free_angle = {free!r}
"""


@pytest.mark.parametrize("start, stop, free, torque_deg", [
    (300.0, 1020.0, -90.0, (1020.0 + 90.0)),  # two turns wound on from 300 deg
    (0.0, 10.0, 200.0, 10.0 - 200.0),         # free past half a turn: not taken as -160
    (0.0, 10.0, -720.0, 10.0 + 720.0),        # a spring wound two turns at the start
    (360.0, 450.0, 0.0, 450.0),               # the driver's whole turn winds the spring
])
def test_torsion_spring_angle_is_the_links_difference_as_written(start, stop, free, torque_deg):
    """The contract's angle: the first link's direction minus the second's (ground 0), with the
    crank's link angle the driver's value as the scene writes it (no wrapping), and the torque
    k (angle - free_angle) for the free angle as written: the torque at the last step."""
    text = CRANK.format(start=start, stop=stop, k=3.0, free=free)
    r = linkpipe.solve(linkpipe.parse_scene(text, "crank.toml"))
    angle = np.rad2deg(r.forces["torsion_spring_angle"][1][:, 0])
    np.testing.assert_allclose(angle, r.driver_value[:, 0], rtol=0, atol=1e-11)
    np.testing.assert_allclose(r.link_angle[:, 0], np.deg2rad(r.driver_value[:, 0]), rtol=0,
                               atol=1e-13)
    assert r.forces["torsion_spring_torque"][1][-1, 0] == pytest.approx(
        3.0 * np.deg2rad(torque_deg), rel=1e-13)


# -- each body's balance ------------------------------------------------------------------------


def test_joint_forces_balance_each_body_with_every_kind():
    """Every spring kind at once, torsion springs on moving links and against ground, with
    gravity and inertia at 10 rad/s: the pin forces on each body, its weight, the torsion
    couples on it (-torque on the first link, +torque on the second) and the crank torque give
    m a_G and I alpha (Newton-Euler per body); a spring's pin carries its force."""
    extra = "".join(FOURBAR_SPRINGS[k].replace('name = "s"', f'name = "{k}"')
                    for k in ("linear", "tension_only", "compression_only", "gas"))
    extra += FOURBAR_SPRINGS["torsion"] + ('\n[[torsion_springs]]\nname = "t0"\n'
                                           'links = ["crank", "ground"]\nk = 4.0\nfree_angle = 0.0\n')
    extra += ('\n[gravity]\ng = [0.0, -9.81]\n'
              '\n[[masses]]\nlink = "coupler"\nmass = 2.0\ncenter = "P"\ninertia = 0.4\n'
              '\n[[masses]]\nlink = "rocker"\nmass = 1.5\ncenter = [1.5, 0.0]\ninertia = 1.1\n')
    r = linkpipe.solve(fourbar(361, extra, '["springs", "gravity", "inertia"]'))
    assert assert_ok_but_out_of_stroke(r).any()
    from linkpipe.forces.applied import body_point, center_frame
    from linkpipe.forces.lagrange import joints

    joint_names = [f"{r.point_names[p]}@{r.scene.links[li].name}" for li, p in joints(r.model)]
    F = r.forces["joint_force"][1]
    X, A, names = r.position, r.acceleration, r.point_names
    torque = r.forces["torsion_spring_torque"][1]
    couple = {"crank": -torque[:, 1] + r.forces["input_force"][1][:, 0],
              "coupler": -torque[:, 0], "rocker": torque[:, 0]}
    masses = {m.link: m for m in r.scene.masses}
    for li, link in enumerate(r.scene.links):
        cols = [k for k, j in enumerate(joint_names) if j.endswith("@" + link.name)]
        m = masses.get(link.name)
        if m is not None:
            frame = center_frame(r.model, m.link, m.center)
            G, aG, mass, inertia = body_point(X, *frame), body_point(A, *frame), m.mass, m.inertia
        else:
            G, aG, mass, inertia = X[:, names.index(link.points[0])], 0.0, 0.0, 0.0
        scale = np.abs(F[:, cols]).max()
        net = F[:, cols].sum(axis=1) + mass * np.array([0.0, -9.81])
        np.testing.assert_allclose(net, mass * aG * np.ones_like(net), rtol=0, atol=1e-9 * scale)
        rel = X[:, [names.index(p) for p in link.points]] - G[:, None]
        moment = (rel[..., 0] * F[:, cols, 1] - rel[..., 1] * F[:, cols, 0]).sum(axis=1)
        np.testing.assert_allclose(moment + couple[link.name],
                                   inertia * r.link_angular_acceleration[:, li], rtol=0,
                                   atol=1e-9 * scale * r.model.size)
    # the coupler point P carries the four springs' pull towards S (tension positive)
    unit = X[:, names.index("P")] - X[:, names.index("S")]
    unit /= np.linalg.norm(unit, axis=1)[:, None]
    pull = -r.forces["spring_force"][1].sum(axis=1)[:, None] * unit
    np.testing.assert_allclose(F[:, joint_names.index("P@coupler")], pull, rtol=0,
                               atol=1e-9 * np.abs(pull).max())


# -- a gas strut pushed to its dead length ------------------------------------------------------


def test_gas_spring_at_its_dead_length_is_non_finite_never_ok(tmp_path, capsys):
    """Lengths 0.10 ... 0.90 m against a dead length of 0.2 m: at 0.1 and 0.2 the gas volume is
    gone, the force infinite: those steps are non_finite (the file says so); the others ok. The
    summary says why, at the first such step: the spring's length against its dead length, and
    what is not finite there."""
    path = tmp_path / "dead.toml"
    path.write_text(SLIDE.format(x0=0.1, x1=0.2, x_end=0.9, steps=9)
                    + spring("g", GAS_BODY.format(gamma=1.0)))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-rrd"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if "non_finite:" in ln)
    assert line == ("  non_finite: first at step 0; gas spring g: length 0.1 m at or below its "
                    "dead_length 0.2 m; not finite there: spring_energy[g], spring_force[g], "
                    "power[springs], input_force[x], input_force_lagrange[x], "
                    "slider_force[guide_p], ground_reaction[O]")
    with h5py.File(out / "slide.h5", "r") as f:
        status = f["status"][:]
        force = f["spring_force"][:, 0]
    assert list(status) == [NON_FINITE] * 2 + [OK] * 3 + [7] * 4  # past 0.5 m: out of stroke
    assert list(force[:2]) == [-np.inf, -np.inf]
    np.testing.assert_allclose(force[2:], gas(np.arange(3, 10) / 10, 450.0, 0.5, 0.2, 1.0)[0],
                               rtol=1e-14)


# -- the files ----------------------------------------------------------------------------------


def test_hdf5_holds_the_torsion_spring_variables(tmp_path):
    """Read the real .h5 back: dimension torsion_spring with its labels, three variables on
    (step, torsion_spring) with units, values from the closed form."""
    extra = FOURBAR_SPRINGS["torsion"] + ('\n[[torsion_springs]]\nname = "t0"\n'
                                          'links = ["crank", "ground"]\nk = 4.0\nfree_angle = 0.0\n')
    path = tmp_path / "fourbar.toml"
    path.write_text(FOURBAR.replace("steps = 361", "steps = 73")
                    + '\n[analysis]\neffects = ["springs"]\n' + extra)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    r = linkpipe.solve(str(path))
    theta = np.deg2rad(r.driver_value[:, 0])
    with h5py.File(out / "fourbar_crank_rocker.h5", "r") as f:
        assert [s.decode() if isinstance(s, bytes) else s for s in f["torsion_spring"][:]] == ["t", "t0"]
        for name, unit in (("torsion_spring_angle", "rad"), ("torsion_spring_torque", "N*m"),
                           ("torsion_spring_energy", "N*m")):
            ds = f[name]
            assert ds.shape == (73, 2) and ds.attrs["units"] == unit
            dims = [f[ref[0]].name for ref in ds.attrs["DIMENSION_LIST"]]
            assert dims == ["/step", "/torsion_spring"]
        np.testing.assert_allclose(f["torsion_spring_angle"][:, 1], theta, atol=1e-13)
        np.testing.assert_allclose(f["torsion_spring_torque"][:, 1], 4.0 * theta, atol=1e-12)
        np.testing.assert_allclose(f["torsion_spring_energy"][:, 1], 2.0 * theta ** 2, atol=1e-12)
        np.testing.assert_array_equal(f["torsion_spring_torque"][:, 0],
                                      r.forces["torsion_spring_torque"][1][:, 0])
        assert list(f["effect"].asstr()[:]) == ["springs"]
        assert "spring" not in f  # no two-point springs in this scene


def test_recording_plots_torsion_spring_torque(tmp_path):
    from rerun.chunk import RrdReader
    from linkpipe.stores import rrd

    r = linkpipe.solve(linkpipe.parse_scene(CRANK.format(start=0.0, stop=90.0, k=2.0, free=30.0),
                                            "crank.toml"))
    path = tmp_path / "crank.rrd"
    rrd.write(r, path)
    store = RrdReader(path).store().stream().collect()
    entity = "/plots/torsion_spring_torque/hinge"
    frame = store.reader(index="step", contents=entity).to_pandas()
    values = np.array([v[0] for v in frame[f"{entity}:Scalars:scalars"]])
    np.testing.assert_allclose(values, 2.0 * np.deg2rad(r.driver_value[:, 0] - 30.0), atol=1e-12)


# -- the shipped tailgate -----------------------------------------------------------------------


def test_hatch_input_torque_is_the_derivative_of_its_energy():
    """configs/hatch_gas_spring.toml: the hinge torque is dV/dtheta of gravity + two gas struts,
    V computed here from the config's numbers (centre of mass 0.45 m and strut end 0.19 m out
    along the tailgate, body end (0.16, -0.50)), differentiated by central differences with
    h = 1e-6 rad on the closed form (truncation ~h^2 |V'''| < 1e-9, rounding ~eps |V| / h
    ~ 1e-8 N*m: tolerance 1e-6 N*m). The numbers its comments quote are checked too."""
    r = linkpipe.solve(str(CONFIGS / "hatch_gas_spring.toml"))
    assert r.message == "all 171 steps ok"
    m, g, f1, l1, d = 20.0, 9.81, 300.0, 0.55, -0.4033

    def V(theta):
        A = 0.19 * np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        L = np.hypot(*(A - [0.16, -0.50]).T)
        return m * g * 0.45 * np.sin(theta) + 2 * f1 * (l1 - d) * np.log((l1 - d) / (L - d))

    theta = np.deg2rad(r.driver_value[:, 0])
    h = 1e-6
    expect = (V(theta + h) - V(theta - h)) / (2 * h)
    F = r.forces["input_force"][1][:, 0]
    np.testing.assert_allclose(F, expect, rtol=0, atol=1e-6)
    np.testing.assert_allclose(r.forces["input_force_lagrange"][1][:, 0], F, rtol=0, atol=1e-10)
    # the comments' figures
    assert F[0] == pytest.approx(21.13, abs=0.01) and F[-1] == pytest.approx(-23.51, abs=0.01)
    i = np.flatnonzero(np.diff(np.sign(F)))
    assert len(i) == 1 and r.driver_value[i[0], 0] == -61.5
    assert F.min() == pytest.approx(-41.21, abs=0.01) and r.driver_value[F.argmin(), 0] == -25.5
    strut = r.forces["spring_force"][1]
    assert strut[0, 0] == pytest.approx(-387.3, abs=0.1) and strut[-1, 1] == pytest.approx(-300.1, abs=0.1)
    length = r.forces["spring_length"][1][:, 0]
    assert 0.33 < length.min() and length.max() < 0.55  # within the strut's stroke


# -- bad input: one message naming file, table and key; exit 2; nothing written --------------

BAD_BASE = (SLIDE.format(x0=0.3, x1=0.4, x_end=0.9, steps=7)
            + spring("s", "k = 100.0\nfree_length = 0.5\n")
            + spring("g", GAS_BODY.format(gamma=1.0))
            + '\n[[torsion_springs]]\nname = "t"\nlinks = ["block", "ground"]\nk = 1.0\nfree_angle = 0.0\n')
GAS_SPRING = 'name = "g"\nbetween = ["O", "P"]\n'
TORSION = '[[torsion_springs]]\nname = "t"\n'
SPRING_ERRORS = [
    ("dead-not-below-extended", ("dead_length = 0.2", "dead_length = 0.5"), 'springs "g"',
     "dead_length", ["dead_length = 0.5 is not below extended_length = 0.5"]),
    ("gas-missing-force", ("force_extended = 450.0\n", ""), 'springs "g"', "force_extended",
     ["missing: a gas spring needs force_extended, extended_length and dead_length",
      "add force_extended = 450.0"]),
    ("gas-missing-extended", ("extended_length = 0.5\n", ""), 'springs "g"', "extended_length",
     ["missing"]),
    ("gas-missing-dead", ("dead_length = 0.2\n", ""), 'springs "g"', "dead_length", ["missing"]),
    ("gas-key-on-linear", ("free_length = 0.5\n", "free_length = 0.5\ndead_length = 0.1\n"),
     'springs "s"', "dead_length", ['only a gas spring has dead_length (this one is kind = "linear")',
                                    'write kind = "gas"']),
    ("gamma-on-cable", ("k = 100.0\nfree_length", 'kind = "tension_only"\ngamma = 1.4\nk = 100.0\nfree_length'),
     'springs "s"', "gamma", ['only a gas spring has gamma (this one is kind = "tension_only")']),
    ("k-on-gas", (GAS_SPRING, GAS_SPRING + "k = 5.0\n"), 'springs "g"', "k",
     ["a gas spring has no k", "remove k"]),
    ("free-length-on-gas", (GAS_SPRING, GAS_SPRING + "free_length = 0.4\n"), 'springs "g"',
     "free_length", ["a gas spring has no free_length"]),
    ("unknown-kind", ('kind = "gas"', 'kind = "gass"'), 'springs "g"', "kind",
     ['unknown spring kind "gass"', 'did you mean "gas"?']),
    ("unknown-kind-cable", ("k = 100.0\nfree_length", 'kind = "tension"\nk = 100.0\nfree_length'),
     'springs "s"', "kind", ['unknown spring kind "tension"', 'did you mean "tension_only"?']),
    ("gamma-zero", ("gamma = 1.0", "gamma = 0.0"), 'springs "g"', "gamma", ["must be positive, got 0"]),
    ("force-extended-negative", ("force_extended = 450.0", "force_extended = -450.0"),
     'springs "g"', "force_extended", ["must be positive"]),
    ("torsion-self", ('links = ["block", "ground"]', 'links = ["block", "block"]'),
     'torsion_springs "t"', "links", ['between link "block" and itself', "two different links"]),
    ("torsion-unknown-link", ('links = ["block", "ground"]', 'links = ["blok", "ground"]'),
     'torsion_springs "t"', "links", ['unknown link "blok"', 'did you mean "block"?']),
    ("torsion-ground-first", ('links = ["block", "ground"]', 'links = ["ground", "block"]'),
     'torsion_springs "t"', "links", ['"ground" may only be the second link']),
    ("torsion-one-link", ('links = ["block", "ground"]', 'links = ["block"]'),
     'torsion_springs "t"', "links", ["expected two links, got 1"]),
    ("torsion-negative-k", (TORSION + 'links = ["block", "ground"]\nk = 1.0',
                            TORSION + 'links = ["block", "ground"]\nk = -1.0'),
     'torsion_springs "t"', "k", ["negative stiffness"]),
    ("torsion-missing-free-angle", ("free_angle = 0.0\n", ""), 'torsion_springs "t"',
     "free_angle", ["missing", "add free_angle = 30.0"]),
    ("torsion-unknown-key", ("free_angle = 0.0", "free_angel = 0.0"), 'torsion_springs "t"',
     "free_angel", ['did you mean "free_angle"?']),
]


@pytest.mark.parametrize("change, table, key, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in SPRING_ERRORS])
def test_bad_springs_are_one_clear_message(tmp_path, capsys, change, table, key, fragments):
    old, new = change
    assert BAD_BASE.count(old) == 1, old
    path = tmp_path / "bad.toml"
    path.write_text(BAD_BASE.replace(old, new))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count(f"{path}: [{table}] {key}: ") == 1, err
    for fragment in fragments:
        assert fragment in err, err
    assert "Traceback" not in err
    assert not out.exists() or not any(out.iterdir())


def test_the_unbroken_base_of_those_runs(tmp_path):
    """The scene the bad cases break runs (so each message above is that one change's)."""
    path = tmp_path / "good.toml"
    path.write_text(BAD_BASE)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    written = sorted(p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith("."))
    assert written == ["slide.h5", "slide.rrd"]  # (beside the advisory lock file)


# -- a preload holds at the start configuration, not at a guessed drawing ------------------------
def rocker_with_spring(B: tuple[float, float], body: str) -> str:
    """The crank-rocker (crank 1, coupler 3.5, rocker 3, ground 4; lengths given, so B may be a
    guess) at its drawn crank angle 0 deg, a spring from the fixed anchor K to B."""
    return f"""
[scene]
name = "preload_on_guess"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}
[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = 1.0, y = 0.0 }}
B  = {{ x = {B[0]!r}, y = {B[1]!r} }}
O4 = {{ x = 4.0, y = 0.0, fixed = true }}
K  = {{ x = 5.0, y = 4.0, fixed = true }}
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = 1.0 }}
[[links]]
name = "coupler"
points = ["A", "B"]
lengths = {{ "A-B" = 3.5 }}
[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = 3.0 }}
[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 0.0
to = 90.0
steps = 7
[[springs]]
name = "s"
between = ["K", "B"]
{body}
[analysis]
effects = ["springs"]
"""


#: B assembled at crank angle 0: |B - A| = 3.5 and |B - O4| = 3 (x from the difference of the
#: two circles, 6 x - 15 = 3.25; y above the ground line, as drawn)
B_EXACT = (73.0 / 24.0, float(np.sqrt(9.0 - (73.0 / 24.0 - 4.0) ** 2)))


@pytest.mark.parametrize("kind, k, preload", [("linear", 2000.0, 50.0), ("linear", 2000.0, 0.0),
                                              ("tension_only", 500.0, 5.0)])
def test_preload_holds_at_the_assembled_start_not_at_a_guessed_drawing(kind, k, preload):
    """A drawing whose B is a guess 0.07 m off (the lengths are given) starts from the pose
    it assembles to; a spring's preload (or, without one, zero tension) holds there: the first
    step's tension is the preload, and every step equals the exactly drawn scene's (before:
    the start length was the guess's, 2000 N/m x ~0.05 m = ~100 N off)."""
    body = f'kind = "{kind}"\nk = {k!r}\npreload = {preload!r}'
    guessed = linkpipe.solve(linkpipe.parse_scene(rocker_with_spring((3.0, 2.9), body), "g.toml"))
    exact = linkpipe.solve(linkpipe.parse_scene(rocker_with_spring(B_EXACT, body), "e.toml"))
    assert guessed.n_ok == exact.n_ok == 7
    tension = guessed.forces["spring_force"][1][:, 0]
    # the assembly and the exact drawing agree to the solver's tolerance (1e-10 of the size,
    # ~5e-10 m): times k = 2000 N/m, 1e-6 N
    assert abs(tension[0] - preload) < 1e-6
    np.testing.assert_allclose(tension, exact.forces["spring_force"][1][:, 0], rtol=0, atol=1e-6)
    assert abs(tension[-1] - tension[0]) > 10.0  # the spring does work: the test can fail


ROCKER_NEAR_HALF_TURN = """
[scene]
name = "rocker_half_turn"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}
[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = 0.0, y = 1.0 }}
B  = {{ x = 1.0, y = 0.0 }}
O4 = {{ x = 4.0, y = 0.0, fixed = true }}
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = 1.0 }}
[[links]]
name = "coupler"
points = ["A", "B"]
lengths = {{ "A-B" = 1.4142135623730951 }}
[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = 3.0 }}
[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = {start!r}
to = {stop!r}
steps = 3
rate = 1.0
[analysis]
effects = ["springs"]
[[torsion_springs]]
name = "hinge"
links = ["rocker", "ground"]
k = 1.0
free_angle = 180.0
"""


def test_the_same_pose_reads_the_same_angle_whichever_way_the_sweep_runs():
    """A rocker drawn pointing along -x (180 deg) reads -179.7 or +179.7 deg as the principal
    direction just either side of it. Its whole turns come from the drawing, so the crank at
    90 deg (the middle step, swept 89 -> 91 or 91 -> 89) gives the rocker the same angle
    and the torsion spring free at 180 deg the same (small) torque both ways; before, the
    sweep up read -180.3 deg and a torque of -2 pi k."""
    up = linkpipe.solve(linkpipe.parse_scene(ROCKER_NEAR_HALF_TURN.format(start=89.0, stop=91.0), "u.toml"))
    down = linkpipe.solve(linkpipe.parse_scene(ROCKER_NEAR_HALF_TURN.format(start=91.0, stop=89.0), "d.toml"))
    assert up.n_ok == down.n_ok == 3
    rocker = up.link_names.index("rocker")
    np.testing.assert_allclose(up.link_angle[1, rocker], down.link_angle[1, rocker], rtol=0, atol=1e-12)
    assert abs(up.link_angle[1, rocker] - np.pi) < 0.01  # the drawing's 180 deg, not -180
    torque_up, torque_down = (r.forces["torsion_spring_torque"][1][1, 0] for r in (up, down))
    assert torque_up == pytest.approx(torque_down, abs=1e-12) and abs(torque_up) < 0.01


@pytest.mark.parametrize("order", [["O2", "A", "C"], ["O2", "C", "A"], ["C", "A", "O2"]])
def test_a_plate_an_angle_driver_turns_takes_the_drivers_turns_whatever_its_point_order(order):
    """A crank plate O2, A, C (C at 45 deg from A about O2, |O2C| = |O2A|) driven 360 -> 370
    deg against a torsion spring free at 0: the plate's link angle is the driver's value plus
    the plate's own offset to its first two points' direction (0, 45 or 135 + 180 deg: C A O2
    points from C to A), whatever the order the points are listed in, and the spring winds a
    whole turn with it (before, only a plate listing the driver's pair first kept the turn)."""
    points = ", ".join(f'"{p}"' for p in order)
    text = f"""
[scene]
name = "plate"
[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = 1.0, y = 0.0 }}
C  = {{ x = {float(np.sqrt(0.5))!r}, y = {float(np.sqrt(0.5))!r} }}
[[links]]
name = "crank"
points = [{points}]
[[drivers]]
name = "theta"
angle = ["O2", "A"]
from = 360.0
to = 370.0
steps = 3
[analysis]
effects = ["springs"]
[[torsion_springs]]
name = "hinge"
links = ["crank", "ground"]
k = 2.0
free_angle = 0.0
"""
    r = linkpipe.solve(linkpipe.parse_scene(text, "plate.toml"))
    C = np.array([np.sqrt(0.5), np.sqrt(0.5)])
    first = {"O2": np.zeros(2), "A": np.array([1.0, 0.0]), "C": C}
    d = first[order[1]] - first[order[0]]
    offset = np.degrees(np.arctan2(d[1], d[0]))  # the plate's direction at theta = 0
    want = r.driver_value[:, 0] + offset
    np.testing.assert_allclose(np.degrees(r.link_angle[:, 0]), want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.forces["torsion_spring_torque"][1][:, 0], 2.0 * np.radians(want),
                               rtol=1e-12)
