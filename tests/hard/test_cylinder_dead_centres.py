"""Hard case: the dead centres of a cylinder-driven rocker (``configs/hard/cylinder_full_stroke.toml``).

The cylinder C -> B (length s) turns the rocker O-B (R = 1) about O, with C at c = 0.8 below
O. At s = R - c and s = R + c the three pins are in line: the cylinder's row and the rocker's
have parallel gradients, dB/ds is unbounded. Those steps must be ``singular`` (positions kept,
velocities, accelerations and the cylinder force NaN); every other step is ``ok`` and equals
the law of cosines, with the cylinder force from moments about O.
"""
import numpy as np

from hard_scenes import HARD_DIR, solve_config, method  # noqa: F401 - a fixture
from linkpipe.closed_forms import cylinder_rocker
from linkpipe.status import OK, SINGULAR

R, c = 1.0, 0.8
W = np.array([0.0, -100.0])


def test_cylinder_dead_centres_are_singular_and_the_rest_exact(method):
    r = solve_config(HARD_DIR / "cylinder_full_stroke.toml", method)
    s = r.driver_value[:, 0]
    dead = np.isclose(s, R - c, rtol=0, atol=1e-12) | np.isclose(s, R + c, rtol=0, atol=1e-12)
    assert dead.sum() == 2
    np.testing.assert_array_equal(r.status, np.where(dead, SINGULAR, OK))
    # B on the right of C->O: the angle from O->C (straight down) turns counter-clockwise
    beta, w, al = cylinder_rocker(R, c, s, 0.05, 0.0, branch=+1)
    theta = -np.pi / 2 + beta
    B = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    VB = w[:, None] * np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    AB = al[:, None] * np.stack([-np.sin(theta), np.cos(theta)], axis=1) - (w * w)[:, None] * B
    b = r.point_names.index("B")
    ok = ~dead
    # regular steps: tol 1e-12 times a condition that grows towards the ends (1e3 at 1 % of the
    # stroke); at a dead centre the root is double: B is fixed to ~sqrt(1e-16) ~ 1e-8 m
    np.testing.assert_allclose(r.position[ok, b], B[ok], rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.position[dead, b], B[dead], rtol=0, atol=1e-6)
    # velocities and accelerations relative to their own size, which grows without bound
    # towards the ends (|w| ~ 1/sqrt(distance to the end))
    vs = np.abs(w)[ok, None]
    acs = (w * w + np.abs(al))[ok, None]
    assert (np.abs(r.velocity[ok, b] - VB[ok]) <= 1e-8 * vs).all()
    assert (np.abs(r.acceleration[ok, b] - AB[ok]) <= 1e-8 * acs).all()
    assert np.isnan(r.velocity[dead, b]).all() and np.isnan(r.acceleration[dead, b]).all()
    # the cylinder force: moments about O, positive pushing; NaN where undetermined
    u = (r.position[:, b] - np.array([0.0, -c])) / s[:, None]
    Bp = r.position[:, b]
    expected = -(Bp[:, 0] * W[1] - Bp[:, 1] * W[0]) / (Bp[:, 0] * u[:, 1] - Bp[:, 1] * u[:, 0])
    force = r.forces["input_force"][1][:, 0]
    assert np.isnan(force[dead]).all()
    # a 100 N weight on a 1 m rocker: relative 1e-8 of the force, which grows towards the ends
    assert (np.abs(force[ok] - expected[ok]) <= 1e-8 * np.abs(expected[ok]) + 1e-9).all()
