"""Scene text for the hard cases, built from a few numbers (closed forms live in tests/closed_forms.py).

Every builder returns TOML text for ``linkpipe.parse_scene``; start positions are assembled
exactly from the closed form (or deliberately not, where a test says so).
"""
from __future__ import annotations

import dataclasses
import pathlib

import numpy as np

import linkpipe
import pytest


def f(x: float) -> str:
    """Return a float as TOML text that round-trips exactly."""
    return repr(float(x))


def crank_driver(start_deg, to_deg, steps, rate_deg) -> str:
    """Return the [[drivers]] table of a crank "crank" driven by the angle of O2 -> A."""
    return f"""[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = {f(start_deg)}
to = {f(to_deg)}
steps = {int(steps)}
rate = {f(rate_deg)}
"""


def fourbar_B(a, b, c, d, theta, branch=+1):
    """Return B of the four-bar O2=(0,0), A=a e(theta), O4=(d,0), |AB|=b, |O4B|=c (branch +1: left of A->O4)."""
    A = np.array([a * np.cos(theta), a * np.sin(theta)])
    v = np.array([d, 0.0]) - A
    dist = np.hypot(*v)
    along = (b**2 - c**2 + dist**2) / (2 * dist)
    h = np.sqrt(max(b**2 - along**2, 0.0))
    e = v / dist
    return A + along * e + branch * h * np.array([-e[1], e[0]])


def fourbar_text(a, b, c, d, start_deg, to_deg, steps, branch=+1, rate_deg=572.9577951308232,
                 B_guess=None, scale=1.0, name="fourbar", extra="", units="m", coupler_uv=None):
    """Return a crank-driven four-bar scene: crank a, coupler b, rocker c, ground d (all x scale)."""
    th = np.deg2rad(start_deg)
    A = np.array([a * np.cos(th), a * np.sin(th)])
    B = fourbar_B(a, b, c, d, th, branch) if B_guess is None else np.asarray(B_guess, float)
    a, b, c, d = (scale * x for x in (a, b, c, d))
    A, B = scale * A, scale * B
    P = ""
    coupler_pts = '["A", "B"]'
    local = ""
    if coupler_uv is not None:
        u, v = (scale * x for x in coupler_uv)
        e = (B - A) / np.hypot(*(B - A))
        Pp = A + u * e + v * np.array([-e[1], e[0]])
        P = f"P  = {{ x = {f(Pp[0])}, y = {f(Pp[1])} }}\n"
        coupler_pts = '["A", "B", "P"]'
        local = f"\nlocal = {{ P = [{f(u)}, {f(v)}] }}"
    return f"""
[scene]
name = "{name}"
units = {{ length = "{units}", mass = "kg", time = "s", force = "N" }}

[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = {f(A[0])}, y = {f(A[1])} }}
B  = {{ x = {f(B[0])}, y = {f(B[1])} }}
O4 = {{ x = {f(d)}, y = 0.0, fixed = true }}
{P}
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = {f(a)} }}

[[links]]
name = "coupler"
points = {coupler_pts}
lengths = {{ "A-B" = {f(b)} }}{local}

[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = {f(c)} }}

{crank_driver(start_deg, to_deg, steps, rate_deg)}
[outputs]
kinematics = ["velocity", "acceleration"]
{extra}
"""


def _slider_crank_body(a, b, e, theta_deg, branch, scale, name, units=True):
    """Return the [scene], [points], links and slider of an offset slider-crank (crank a, rod b,
    guide y = e) assembled at crank angle ``theta_deg``, slider ahead of A (+1) or behind (-1);
    also the slider's x there (unscaled)."""
    t = np.deg2rad(theta_deg)
    A = np.array([a * np.cos(t), a * np.sin(t)])
    x = A[0] + branch * np.sqrt(b**2 - (A[1] - e) ** 2)
    sa, sb, se, sx = (scale * v for v in (a, b, e, x))
    A = scale * A
    unit_line = '\nunits = { length = "m", mass = "kg", time = "s", force = "N" }' if units else ""
    return f"""
[scene]
name = "{name}"{unit_line}

[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = {f(A[0])}, y = {f(A[1])} }}
B  = {{ x = {f(sx)}, y = {f(se)} }}

[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = {f(sa)} }}

[[links]]
name = "rod"
points = ["A", "B"]
lengths = {{ "A-B" = {f(sb)} }}

[[sliders]]
name = "piston"
point = "B"
along = {{ through = [0.0, {f(se)}], direction = [1.0, 0.0] }}
""", x


def slider_driven_text(a, b, e, x_from, x_to, steps, theta0_deg, rate=1.0, name="slider_driven",
                       scale=1.0, extra=""):
    """Return an offset slider-crank (crank a, rod b, guide y = e) driven by the slider's x.

    The start is assembled at crank angle ``theta0_deg`` (which must give x = ``x_from``).
    """
    body, _ = _slider_crank_body(a, b, e, theta0_deg, +1, scale, name)
    x_from, x_to, rate = (scale * v for v in (x_from, x_to, rate))
    return body + f"""
[[drivers]]
name = "piston"
coordinate = "B.x"
from = {f(x_from)}
to = {f(x_to)}
steps = {int(steps)}
rate = {f(rate)}

[outputs]
kinematics = ["velocity", "acceleration"]
{extra}
"""


def double_parallelogram_text(v=0.6, start_deg=10.0, to_deg=370.0, steps=73, name="double_parallelogram",
                              effects=True, rate_deg=572.9577951308232):
    """Return a double parallelogram: crank O2-A, rocker O4-B, fifth link O6-E (all 1, parallel),
    coupler A-B-E with E at (1, v) in its frame; O2 (0,0), O4 (2,0), O6 (1, v).

    Exactly: A = e(theta), B = A + (2, 0), E = A + (1, v): the coupler translates.
    """
    t = np.deg2rad(start_deg)
    A = np.array([np.cos(t), np.sin(t)])
    B, E = A + [2.0, 0.0], A + [1.0, v]
    forces = f"""
[analysis]
effects = ["gravity", "inertia", "loads"]

[gravity]
g = [0.0, -9.81]

[[masses]]
link = "coupler"
mass = 2.0
center = [1.0, 0.3]
inertia = 0.5

[[masses]]
link = "crank"
mass = 0.5
center = [0.5, 0.0]
inertia = 0.05

[[loads]]
name = "push"
point = "E"
force = [3.0, -1.0]
""" if effects else ""
    return f"""
[scene]
name = "{name}"
description = "Double parallelogram: a fifth link parallel to crank and rocker (one redundant constraint)"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}

[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
O4 = {{ x = 2.0, y = 0.0, fixed = true }}
O6 = {{ x = 1.0, y = {f(v)}, fixed = true }}
A  = {{ x = {f(A[0])}, y = {f(A[1])} }}
B  = {{ x = {f(B[0])}, y = {f(B[1])} }}
E  = {{ x = {f(E[0])}, y = {f(E[1])} }}

[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = 1.0 }}

[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = 1.0 }}

[[links]]
name = "fifth"
points = ["O6", "E"]
lengths = {{ "O6-E" = 1.0 }}

[[links]]
name = "coupler"
points = ["A", "B", "E"]
lengths = {{ "A-B" = 2.0 }}
local = {{ E = [1.0, {f(v)}] }}

{crank_driver(start_deg, to_deg, steps, rate_deg)}{forces}
[outputs]
kinematics = ["velocity", "acceleration"]
trace = ["E"]
"""


# Theo Jansen's "holy numbers" (Strandbeest leg), crank axle O at the origin, frame pivot F at
# (-a, -l). C: upper joint (j from the crank pin A, b from F); E: third corner of the rigid
# triangle F-C-E (d from F, e from C); D: lower joint (k from A, c from F); G: knee (f from E,
# g from D); H: foot, third corner of the rigid triangle D-G-H (i from D, h from G).
JANSEN = dict(a=38.0, b=41.5, c=39.3, d=40.1, e=55.8, f=39.4, g=36.7, h=65.7, i=49.0, j=50.0,
              k=61.9, l=7.8, m=15.0)
#: every distance that must stay fixed: (point, point, holy-number letter)
JANSEN_BARS = (("O", "A", "m"), ("A", "C", "j"), ("F", "C", "b"), ("F", "E", "d"), ("C", "E", "e"),
               ("A", "D", "k"), ("F", "D", "c"), ("E", "G", "f"), ("D", "G", "g"), ("G", "H", "h"),
               ("D", "H", "i"))


def circle_circle(P, r1, Q, r2, side):
    """Return the intersection (S, 2) of circle(P, r1) and circle(Q, r2) on ``side`` of P->Q.

    Written with sqrt, not hypot, so that it takes complex input (complex-step derivatives).
    """
    P, Q = np.broadcast_arrays(np.asarray(P), np.asarray(Q))
    v = Q - P
    D = np.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2)
    along = (r1**2 - r2**2 + D**2) / (2 * D)
    hh = np.sqrt(r1**2 - along**2)
    ev = v / D[..., None]
    n = np.stack([-ev[..., 1], ev[..., 0]], -1)
    return P + along[..., None] * ev + side * hh[..., None] * n


def jansen_closed_form(theta):
    """Return the Jansen leg's points (dict of (S, 2)) at crank angles theta (rad), dyad by dyad."""
    J = JANSEN
    th = np.atleast_1d(np.asarray(theta))
    O = np.zeros((len(th), 2))
    F = np.broadcast_to([-J["a"], -J["l"]], (len(th), 2))
    A = J["m"] * np.stack([np.cos(th), np.sin(th)], -1)
    C = circle_circle(A, J["j"], F, J["b"], -1)
    D = circle_circle(A, J["k"], F, J["c"], +1)
    E = circle_circle(F, J["d"], C, J["e"], +1)
    G = circle_circle(E, J["f"], D, J["g"], -1)
    H = circle_circle(D, J["i"], G, J["h"], +1)
    return dict(O=O, F=F, A=A, C=C, D=D, E=E, G=G, H=H)


def jansen_local():
    """Return (u, v) of E in frame F->C and of H in frame D->G (sides as in the closed form)."""
    J = JANSEN
    uE = (J["b"] ** 2 + J["d"] ** 2 - J["e"] ** 2) / (2 * J["b"])
    uH = (J["g"] ** 2 + J["i"] ** 2 - J["h"] ** 2) / (2 * J["g"])
    return (uE, np.sqrt(J["d"] ** 2 - uE**2)), (uH, np.sqrt(J["i"] ** 2 - uH**2))


# --------------------------------------------------------------------------------------------
# Solving helpers

HARD_DIR = pathlib.Path(__file__).resolve().parents[2] / "configs" / "hard"
CONFIG_DIR = HARD_DIR.parent


def with_solver(scene, **changes):
    """Return ``scene`` with ``[solver]`` settings replaced (e.g. method="newton")."""
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, **changes))


def with_driver(scene, **changes):
    """Return ``scene`` with its drivers' fields replaced (from_value, to_value, steps, step...)."""
    return dataclasses.replace(scene, drivers=tuple(dataclasses.replace(d, **changes)
                                                    for d in scene.drivers))


def solve_text(text, method="auto", name="hard.toml", **solver):
    """Parse scene text and solve it with the given solver method (and other [solver] knobs)."""
    scene = linkpipe.parse_scene(text, name)
    return linkpipe.solve(with_solver(scene, method=method, **solver))


def solve_config(path, method="auto", **solver):
    """Load a scene file and solve it with the given solver method."""
    scene = linkpipe.load_scene(str(path))
    return linkpipe.solve(with_solver(scene, method=method, **solver))


def point(result, name):
    """Return a point's positions (S, 2)."""
    return result.position[:, result.point_names.index(name)]


def velocity(result, name):
    return result.velocity[:, result.point_names.index(name)]


def acceleration(result, name):
    return result.acceleration[:, result.point_names.index(name)]


@pytest.fixture(params=["auto", "newton"])
def method(request):
    """Both stage-1 paths: auto (closed-form dyads where they apply) and the general Newton path.

    Import it into a test module (``from hard_scenes import method``) to use it there; the suite
    has no conftest.py of its own, so that ``from conftest import ...`` in tests/ stays unique.
    """
    return request.param


def slider_crank_text(a, b, e, start_deg, to_deg, steps, branch=+1, scale=1.0,
                      rate_deg=572.9577951308232, name="slider_crank"):
    """Return a crank-driven offset slider-crank: crank a, rod b, guide y = e; slider B ahead of
    A along +x (branch +1) or behind it (-1), assembled at ``start_deg``."""
    body, _ = _slider_crank_body(a, b, e, start_deg, branch, scale, name, units=False)
    return body + f"""
{crank_driver(start_deg, to_deg, steps, rate_deg)}
[outputs]
kinematics = ["velocity", "acceleration"]
"""


def six_bar_text(a, b, c, d, uv, O6, Q, start_deg, to_deg, steps, rate_deg=572.9577951308232,
                 branch=+1):
    """Return a Watt six-bar: the four-bar (a, b, c, d) with coupler point P at ``uv`` in the
    coupler's frame, and a dyad P-Q, O6-Q (lengths taken from the start configuration)."""
    th = np.deg2rad(start_deg)
    A = np.array([a * np.cos(th), a * np.sin(th)])
    B = fourbar_B(a, b, c, d, th, branch)
    e = (B - A) / np.hypot(*(B - A))
    P = A + uv[0] * e + uv[1] * np.array([-e[1], e[0]])
    return f"""
[scene]
name = "six_bar"

[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
O4 = {{ x = {f(d)}, y = 0.0, fixed = true }}
O6 = {{ x = {f(O6[0])}, y = {f(O6[1])}, fixed = true }}
A  = {{ x = {f(A[0])}, y = {f(A[1])} }}
B  = {{ x = {f(B[0])}, y = {f(B[1])} }}
P  = {{ x = {f(P[0])}, y = {f(P[1])} }}
Q  = {{ x = {f(Q[0])}, y = {f(Q[1])} }}

[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = {f(a)} }}

[[links]]
name = "coupler"
points = ["A", "B", "P"]
lengths = {{ "A-B" = {f(b)} }}
local = {{ P = [{f(uv[0])}, {f(uv[1])}] }}

[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = {f(c)} }}

[[links]]
name = "link5"
points = ["P", "Q"]

[[links]]
name = "link6"
points = ["O6", "Q"]

{crank_driver(start_deg, to_deg, steps, rate_deg)}
[outputs]
kinematics = ["velocity", "acceleration"]
"""
