"""Hard case 2: the change points of a parallelogram four-bar (the basketball goal past +-90 deg).

At +-90 deg the lower link points along the pole and all four links of the parallelogram are in
line: the parallelogram branch (backboard translating, B straight above C) crosses the
anti-parallelogram branch (the backboard tilts). Continuation must carry on along the
parallelogram, the crossing step itself is `singular` (the velocity there is not determined by
the constraints), and the steps next to it keep full accuracy.

Exact answer: with the lower link at angle t, C = O4 + 2 e(t), B = C + (0, 1), H = O4 - e(t).
"""
import numpy as np
import pytest

from hard_scenes import HARD_DIR, acceleration, point, solve_config, velocity, with_solver, method  # noqa: F401 - a fixture
import linkpipe
from linkpipe.status import OK, SINGULAR

W = 0.5  # driver rate, rad/s (28.6479 deg/s in the scene)
FT = 1.0  # length scale: the links are 1 and 2 ft
O4 = np.array([0.0, -2.0])
CONFIG = HARD_DIR / "basketball_goal_extended.toml"
# Regular steps: the solver's residual tolerance is 1e-12 of the size (~3.6 ft) and the Jacobian's
# condition stays below ~100 on the steps that are not singular: 1e-10 ft leaves a margin of ~3.
POS, VEL, ACC = 1e-10 * FT, 1e-10 * FT * W, 1e-10 * FT * W**2
# The crossing step is a double root: a residual of rounding size (1e-16 ft) fixes the position
# along the near-null direction only to sqrt(1e-16 * size) ~ 2e-8 ft; allow 1e-6 ft.
POS_SINGULAR = 1e-6 * FT


def exact(t_deg):
    t = np.deg2rad(t_deg)
    e = np.stack([np.cos(t), np.sin(t)], -1)
    ep = np.stack([-np.sin(t), np.cos(t)], -1)
    C = O4 + 2 * e
    return dict(C=C, B=C + [0.0, 1.0], H=O4 - e, VC=2 * W * ep, VH=-W * ep, AC=-2 * W**2 * e,
                AH=W**2 * e)


def check(r):
    t = r.driver_value[:, 0]
    crossing = np.isclose(np.abs(t), 90.0, rtol=0, atol=1e-9)
    assert crossing.sum() == 2
    # the crossing steps, and only they, are singular
    np.testing.assert_array_equal(r.status, np.where(crossing, SINGULAR, OK))
    ex = exact(t)
    ok = r.status == OK
    # on the parallelogram at every regular step: backboard vertical, B 1 ft above C
    np.testing.assert_allclose(point(r, "B")[ok] - point(r, "C")[ok], [[0.0, 1.0]] * ok.sum(),
                               rtol=0, atol=POS)
    for name in ("B", "C", "H"):
        np.testing.assert_allclose(point(r, name)[ok], ex[name][ok], rtol=0, atol=POS)
        np.testing.assert_allclose(point(r, name)[crossing], ex[name][crossing], rtol=0,
                                   atol=POS_SINGULAR)
    # velocities and accelerations: exact on every regular step (the neighbours included) ...
    for name, ref in (("B", "C"), ("C", "C"), ("H", "H")):
        np.testing.assert_allclose(velocity(r, name)[ok], ex["V" + ref][ok], rtol=0, atol=VEL)
        np.testing.assert_allclose(acceleration(r, name)[ok], ex["A" + ref][ok], rtol=0, atol=ACC)
    # ... and undetermined (NaN) at the crossings, positions kept there
    assert np.isnan(r.velocity[crossing][:, ~r.model.fixed]).all()
    assert np.isfinite(r.position[crossing]).all()
    return crossing


def test_parallelogram_crosses_both_change_points(method):
    r = solve_config(CONFIG, method)
    crossing = check(r)
    i = np.flatnonzero(crossing)
    neighbours = np.r_[i - 1, i + 1]
    # forces: undefined at the crossings, and at the neighbours the two formulations agree
    F = r.forces["input_force"][1][:, 0]
    FL = r.forces["input_force_lagrange"][1][:, 0]
    assert np.isnan(F[crossing]).all() and np.isnan(FL[crossing]).all()
    assert np.isfinite(F[neighbours]).all()
    np.testing.assert_allclose(F[neighbours], FL[neighbours], rtol=1e-9)


def extended(start_deg, stop_deg, step):
    """The extended scene's text swept from start_deg in steps of step deg, started there."""
    ex = exact(np.array([start_deg]))
    text = CONFIG.read_text()
    for name, P in (("B", ex["B"][0]), ("C", ex["C"][0]), ("G", (ex["B"][0] + ex["C"][0]) / 2)):
        old = next(line for line in text.splitlines() if line.startswith(f"{name}  = "))
        text = text.replace(old, f"{name}  = {{ x = {float(P[0])!r}, y = {float(P[1])!r} }}")
    text = (text.replace("from = -120.0", f"from = {float(start_deg)!r}")
            .replace("to = 120.0", f"to = {float(stop_deg)!r}")
            .replace("step = 2.5", f"step = {float(step)!r}"))
    return linkpipe.parse_scene(text, "basketball_goal_extended.toml")


@pytest.mark.parametrize("step", [1.0, 7.5, 15.0, 22.5, 45.0])
def test_any_step_size_through_the_crossing(method, step):
    """Fine sweeps go through the vectorised path (coarse nodes + Hermite), coarse ones not."""
    r = linkpipe.solve(with_solver(extended(-135.0, 135.0, step), method=method))
    assert r.n_steps == int(round(270 / step)) + 1
    check(r)
