"""Hard case 5: the dead centres of a slider-crank driven from the slider.

A coordinate driver moves the slider B along x; the crank A follows. At the dead centres (crank
and rod in line) dx/dtheta = 0: the crank's angular velocity v / (dx/dtheta) is undefined. Those
steps must be `singular` (positions kept, derivatives NaN); the steps next to them, where the crank
turns fast, keep full accuracy.

Exact answer: the crank angle t from x by the triangle O2-A-B (upper branch), then the
crank-driven closed form (tests/closed_forms.py) with the crank speed w = v / (dx/dt)(t) and the
crank acceleration alpha that makes the slider's acceleration zero.
"""
import numpy as np
import pytest

from linkpipe.closed_forms import slider_crank
from hard_scenes import (HARD_DIR, acceleration, point, slider_driven_text, solve_config,
                         solve_text, velocity, method)  # noqa: F401 - a fixture
from linkpipe.status import OK, SINGULAR

A_, B_ = 1.0, 3.5
V = 0.5  # slider speed, m/s (the scene's rate)
L = A_ + B_


def exact(x, e, v=V):
    """Crank-pin A, its velocity and acceleration for slider positions x (upper branch)."""
    # triangle O2-A-B with B = (x, e): |A - B| = b  ->  a cos(t - phi) = (a^2 + |B|^2 - b^2) / (2 |B|)
    rB = np.hypot(x, e)
    phi = np.arctan2(e, x)
    t = phi + np.arccos(np.clip((A_**2 + rB**2 - B_**2) / (2 * A_ * rB), -1, 1))
    with np.errstate(all="ignore"):  # infinite crank speed on the dead centres
        dxdt = slider_crank(A_, B_, e, t, 1.0, 0.0)["VB"][:, 0]  # dx/dtheta
        w = v / dxdt
        al = -slider_crank(A_, B_, e, t, w, 0.0)["AB"][:, 0] / dxdt  # makes the slider's xdd 0
        cf = slider_crank(A_, B_, e, t, w, al)
    return cf["A"], cf["VA"], cf["AA"], w, al


def check(r, e, dead):
    np.testing.assert_array_equal(r.status, np.where(dead, SINGULAR, OK))
    A, VA, AA, w, al = exact(r.driver_value[:, 0], e, r.scene.drivers[0].rate)
    ok = ~dead
    # positions: residual tolerance 1e-12 of the size times a condition below ~1e3 at the regular
    # steps; on a dead centre the root is double, fixing A to ~sqrt(1e-16 * L) ~ 2e-8 m
    np.testing.assert_allclose(point(r, "A")[ok], A[ok], rtol=0, atol=1e-10 * L)
    np.testing.assert_allclose(point(r, "A")[dead], A[dead], rtol=0, atol=1e-6 * L)
    # velocities and accelerations in the local physical scale: the crank pin's speed a |w| and
    # acceleration a (w^2 + |alpha|), which grow without bound towards a dead centre; relative 1e-9
    # (observed 4e-12 next to a dead centre)
    vs = (A_ * np.abs(w))[ok, None]
    acs = (A_ * (w**2 + np.abs(al)))[ok, None]
    assert (np.abs(velocity(r, "A")[ok] - VA[ok]) <= 1e-9 * vs).all()
    assert (np.abs(acceleration(r, "A")[ok] - AA[ok]) <= 1e-9 * acs).all()
    # at the dead centres: undetermined, and said so
    assert np.isnan(velocity(r, "A")[dead]).all() and np.isnan(acceleration(r, "A")[dead]).all()
    assert np.isnan(r.link_angular_velocity[dead]).all()
    # the crank stays on the upper half-turn the start guess chose (A above the axis)
    assert (point(r, "A")[ok][:, 1] > 0).all()


def test_from_dead_centre_to_dead_centre(method):
    """The config: x from b - a = 2.5 to a + b = 4.5 (both exact in binary), no offset."""
    r = solve_config(HARD_DIR / "slider_driven_dead_centres.toml", method)
    dead = np.zeros(r.n_steps, dtype=bool)
    dead[[0, -1]] = True
    check(r, 0.0, dead)
    # next to the dead centres the crank turns fast: the neighbours really are hard steps
    _, _, _, w, _ = exact(r.driver_value[:, 0], 0.0)
    assert min(abs(w[1]), abs(w[-2])) > 2.5 * np.abs(w[1:-1]).min()


@pytest.mark.parametrize("e", [0.0, 0.5])
def test_dead_centres_inside_and_at_the_ends(method, e):
    """With an offset the dead centres sqrt((b -+ a)^2 - e^2) are rounded: still flagged."""
    x_in, x_out = np.sqrt((B_ - A_) ** 2 - e**2), np.sqrt((B_ + A_) ** 2 - e**2)
    t0 = np.degrees(np.arctan2(e, x_out))  # the outer dead centre's crank angle
    # from the outer dead centre back to the inner one, through the upper half-turn
    r = solve_text(slider_driven_text(A_, B_, e, x_out, x_in, 21, t0 + 1.0, rate=-V), method)
    dead = np.zeros(r.n_steps, dtype=bool)
    dead[[0, -1]] = True
    check(r, e, dead)


def test_past_the_dead_centre_no_assembly(method):
    """Driven on past the outer dead centre: singular on it, no_assembly beyond, no exception."""
    r = solve_text(slider_driven_text(A_, B_, 0.0, 3.5, 4.6, 12, 81.78678929826181, rate=V), method)
    assert (r.status[:10] == OK).all()
    assert r.status[10] == SINGULAR  # x = 4.5 (3.5 + 10 * 0.1 rounds to 4.5 exactly)
    assert r.status[11] == 1  # no_assembly at x = 4.6
