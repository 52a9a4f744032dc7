"""Hard case 1: the toggle positions of a crank-rocker (crank and coupler in line).

At a toggle the rocker stops and turns back: its angular velocity passes through zero while the
constraint Jacobian stays regular (the rocker and the coupler are not in line). Every step must
be ok, and positions, velocities and accelerations must equal the closed form there too.
"""
import numpy as np

from linkpipe.closed_forms import fourbar
from hard_scenes import HARD_DIR, acceleration, fourbar_text, point, solve_config, solve_text, velocity, method  # noqa: F401 - a fixture
from linkpipe.status import OK

A_, B_, C_, D_ = 1.0, 3.5, 3.0, 4.0  # crank, coupler, rocker, ground (m)
W = 10.0  # crank speed, rad/s
L = D_  # length scale of the mechanism
# Extended toggle: |O2 B| = a + b; folded toggle: |O2 B| = b - a, B on the far side of O2.
T_EXT = np.degrees(np.arccos(((A_ + B_) ** 2 + D_**2 - C_**2) / (2 * D_ * (A_ + B_))))
T_FOLD = 180 + np.degrees(np.arccos(((B_ - A_) ** 2 + D_**2 - C_**2) / (2 * D_ * (B_ - A_))))
# Tolerances. The solver stops at a residual of 1e-12 of the mechanism's size and the Jacobian's
# condition is below 10 on this sweep, so positions are good to ~1e-11 L; velocities and
# accelerations inherit that relative accuracy (scale L*W, L*W^2). A factor 10 above that:
POS, VEL, ACC = 1e-10 * L, 1e-10 * L * W, 1e-10 * L * W**2


def test_toggle_angles_are_on_steps():
    r = solve_config(HARD_DIR / "crank_rocker_toggles.toml")
    # the step values are from + i (to - from) / (N - 1): exact to rounding of the degrees
    np.testing.assert_allclose(r.driver_value[[100, 200], 0], [T_EXT, T_FOLD], rtol=0, atol=1e-12)


def test_every_step_ok_and_equal_to_the_closed_form(method):
    r = solve_config(HARD_DIR / "crank_rocker_toggles.toml", method)
    assert (r.status == OK).all()
    assert np.isfinite(r.acceleration).all() and np.isfinite(r.link_angular_acceleration).all()
    cf = fourbar(A_, B_, C_, D_, np.deg2rad(r.driver_value[:, 0]), W, 0.0)
    for name in ("A", "B"):
        np.testing.assert_allclose(point(r, name), cf[name], rtol=0, atol=POS)
        np.testing.assert_allclose(velocity(r, name), cf["V" + name], rtol=0, atol=VEL)
        np.testing.assert_allclose(acceleration(r, name), cf["A" + name], rtol=0, atol=ACC)
    rocker = r.link_names.index("rocker")
    np.testing.assert_allclose(r.link_angular_velocity[:, rocker], cf["omega4"], rtol=0, atol=1e-10 * W)
    np.testing.assert_allclose(r.link_angular_acceleration[:, rocker], cf["alpha4"], rtol=0,
                               atol=1e-10 * W**2)


def test_rocker_stops_and_turns_back_at_the_toggles(method):
    r = solve_config(HARD_DIR / "crank_rocker_toggles.toml", method)
    rocker = r.link_names.index("rocker")
    w4 = r.link_angular_velocity[:, rocker]
    th4 = r.link_angle[:, rocker]
    # exactly zero in the closed form; what remains is rounding of 1e-12-accurate positions
    assert abs(w4[100]) <= 1e-10 * W and abs(w4[200]) <= 1e-10 * W
    assert w4[99] * w4[101] < 0  # through zero, not just touching it
    # the rocker angle is extreme there: smallest at the extended toggle, largest at the folded
    assert th4[100] <= th4[99] and th4[100] <= th4[101]
    assert th4[200] >= th4[199]
    assert np.isclose(th4[100], th4.min(), rtol=0, atol=1e-12)
    # and the angular acceleration there is finite and non-zero (it turns back, it does not stop)
    al4 = r.link_angular_acceleration[:, rocker]
    assert np.isfinite(al4[[100, 200]]).all() and (np.abs(al4[[100, 200]]) > 1.0).all()


def test_a_sweep_starting_on_a_toggle(method):
    """A sweep that starts on the extended toggle and ends on the folded one (both exact)."""
    r = solve_text(fourbar_text(A_, B_, C_, D_, T_EXT, T_FOLD, 31), method)
    assert (r.status == OK).all()
    cf = fourbar(A_, B_, C_, D_, np.deg2rad(r.driver_value[:, 0]), W, 0.0)
    np.testing.assert_allclose(point(r, "B"), cf["B"], rtol=0, atol=POS)
    np.testing.assert_allclose(velocity(r, "B"), cf["VB"], rtol=0, atol=VEL)
    np.testing.assert_allclose(acceleration(r, "B"), cf["AB"], rtol=0, atol=ACC)
