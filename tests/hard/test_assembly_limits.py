"""Hard case 3: a non-Grashof four-bar driven past its assembly limits, and back into range.

Triple rocker: crank a = 2, coupler b = 2, rocker c = 2, ground d = 3.5 m. It assembles while
|A - O4| <= b + c, i.e. for crank angles within +-T_LIM. Past a limit: NaN and `no_assembly`, no
exception; on a limit (coupler and rocker in line, a double root): `singular`; back in range:
solved again, in the assembly mode the sweep left (B on the left of A->O4, the sign of
det Phi_q), which is also where the sweep started.
"""
import re

import h5py
import numpy as np
import pytest

from linkpipe.closed_forms import fourbar
from hard_scenes import HARD_DIR, fourbar_text, point, solve_config, solve_text, method  # noqa: F401 - a fixture
from linkpipe.__main__ import main
from linkpipe.status import NO_ASSEMBLY, OK, SINGULAR

A_, B_, C_, D_ = 2.0, 2.0, 2.0, 3.5
T_LIM = np.degrees(np.arccos((A_**2 + D_**2 - (B_ + C_) ** 2) / (2 * A_ * D_)))
L = D_
# Regular steps (10 deg or more from a limit here): residual tolerance 1e-12 of the size times a
# Jacobian condition below ~100: 1e-10 L leaves a margin.
POS = 1e-10 * L
# On a limit the root is double: rounding-size residuals fix B along the null direction only to
# ~sqrt(1e-16 * L) ~ 2e-8 m; allow 1e-6 L.
POS_LIMIT = 1e-6 * L
CONFIG = HARD_DIR / "triple_rocker_limits.toml"


def wrapped(t_deg):
    """Crank angle in (-180, 180]."""
    return (np.asarray(t_deg) + 180.0) % 360.0 - 180.0


def side(r):
    """Which side of A->O4 B is on: +1 left (the closed form's branch +1), -1 right."""
    A, B = point(r, "A"), point(r, "B")
    u, v = np.array([D_, 0.0]) - A, B - A
    return np.sign(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])


def check_sweep(r):
    t = wrapped(r.driver_value[:, 0])
    on_limit = np.isclose(np.abs(t), T_LIM, rtol=0, atol=1e-9)
    inside = (np.abs(t) < T_LIM) & ~on_limit
    outside = (np.abs(t) > T_LIM) & ~on_limit
    assert (r.status[inside] == OK).all()
    assert (r.status[outside] == NO_ASSEMBLY).all()
    assert (r.status[on_limit] == SINGULAR).all()
    moving = ~r.model.fixed
    assert np.isnan(r.position[outside][:, moving]).all()
    # fixed points keep their positions at failed steps
    np.testing.assert_array_equal(r.position[outside][:, r.point_names.index("O4")],
                                  [[D_, 0.0]] * outside.sum())
    # every assembled step is on branch +1, the branch the sweep started on (re-entry included)
    cf = fourbar(A_, B_, C_, D_, np.deg2rad(r.driver_value[:, 0]), 10.0, 0.0, branch=+1)
    assert (side(r)[inside] == 1).all()
    np.testing.assert_allclose(point(r, "B")[inside], cf["B"][inside], rtol=0, atol=POS)
    np.testing.assert_allclose(point(r, "B")[on_limit], cf["B"][on_limit], rtol=0, atol=POS_LIMIT)
    return inside, outside, on_limit


def test_two_turns_leave_and_reenter(method):
    r = solve_config(CONFIG, method)
    inside, outside, on_limit = check_sweep(r)
    assert on_limit.sum() == 3 and outside.sum() > 30
    # gaps followed by recovery: the sweep comes back into range twice
    entering = np.flatnonzero(outside[:-1] & ~outside[1:]) + 1
    assert len(entering) == 2 and (r.status[entering] != NO_ASSEMBLY).all()


@pytest.mark.parametrize("turns, steps", [(1, 361), (2, 73), (-2, 145), (-1, 37)])
def test_reentry_keeps_the_assembly_mode(method, turns, steps):
    """Sweeps that cross the out-of-range arc in either direction, fine and coarse."""
    r = solve_text(fourbar_text(A_, B_, C_, D_, 0.0, 360.0 * turns, steps), method)
    inside, outside, on_limit = check_sweep(r)
    assert inside.sum() > 0 and outside.sum() > 0 and inside[-1]


def test_steps_exactly_on_both_limits(method):
    """Start on the upper limit, cross the whole out-of-range arc, end on the lower limit."""
    r = solve_text(fourbar_text(A_, B_, C_, D_, T_LIM, 360.0 - T_LIM, 11, B_guess=(2.6, 1.6)), method)
    assert r.status[0] == SINGULAR and r.status[-1] == SINGULAR
    assert (r.status[1:-1] == NO_ASSEMBLY).all()
    # on a limit the coupler and the rocker are in line: B is on the segment A-O4, b from A
    for i in (0, -1):
        A, B = point(r, "A")[i], point(r, "B")[i]
        np.testing.assert_allclose(B, A + B_ * (np.array([D_, 0.0]) - A) / (B_ + C_), rtol=0,
                                   atol=POS_LIMIT)
    assert np.isnan(r.velocity[[0, -1]][:, ~r.model.fixed]).all()  # undetermined there


def test_approaching_a_limit_from_inside(method):
    r = solve_text(fourbar_text(A_, B_, C_, D_, 0.0, T_LIM, 11), method)
    assert (r.status[:-1] == OK).all() and r.status[-1] == SINGULAR
    cf = fourbar(A_, B_, C_, D_, np.deg2rad(r.driver_value[:, 0]), 10.0, 0.0)
    np.testing.assert_allclose(point(r, "B")[:-1], cf["B"][:-1], rtol=0, atol=POS)


def test_cli_exit_0_and_hdf5_written(tmp_path, capsys):
    assert main(["run", str(CONFIG), "--out", str(tmp_path), "--no-rrd", "--quiet"]) == 0
    assert "Traceback" not in capsys.readouterr().err
    with h5py.File(tmp_path / "triple_rocker_limits.h5") as f:
        status = f["status"][:]
        pos = f["position"][:]
        assert f["status"].attrs["flag_meanings"].split()[:3] == ["ok", "no_assembly", "singular"]
    assert (status == NO_ASSEMBLY).sum() > 30 and (status == SINGULAR).sum() == 3
    assert np.isnan(pos[status == NO_ASSEMBLY]).any() and np.isfinite(pos[status == OK]).all()


def _scaled(text: str, k: float, turn_deg: float = 0.0) -> str:
    """The scene scaled by ``k`` and turned by ``turn_deg`` about the origin (its drawn points,
    lengths and the crank's angles)."""
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))

    def point(m):
        x, y = float(m.group(1)) * k, float(m.group(2)) * k
        return f"x = {float(c * x - s * y)!r}, y = {float(s * x + c * y)!r}"

    text = re.sub(r"x = ([-0-9.e]+), y = ([-0-9.e]+)", point, text)
    text = re.sub(r"(from|to) = ([-0-9.e]+)", lambda m: f"{m.group(1)} = {float(m.group(2)) + turn_deg!r}", text)
    return re.sub(r"= (2\.0|3\.5) }", lambda m: f"= {float(m.group(1)) * k!r} }}", text)


def _sides(r) -> set:
    """The sides B takes of A->O4 at the ok steps (+1 left, -1 right)."""
    names = r.point_names
    A, B, O4 = (r.position[:, names.index(n)] for n in ("A", "B", "O4"))
    d, e = O4 - A, B - A
    return set(np.sign(d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0])[r.status == OK].tolist())


@pytest.mark.parametrize("steps", [73, 145, 721])
@pytest.mark.parametrize("scale, turn", [(1.0, 0.0), (1e-3, 0.0), (2e-3, 0.0), (1e3, 0.0),
                                         (1.0, 75.0), (1.0, -120.0), (1e-3, 160.0)])
def test_a_start_drawn_on_its_limit_leaves_it_the_same_way_whatever_the_steps_or_units(
        steps, scale, turn):
    """The config starts on the lower limit with B drawn on the line A-O4 (to rounding): the
    drawing does not say which side the sweep leaves to, and rounding had decided it (the
    mirrored mode at 145 and 721 steps or in km; 3.7 m off). The mode's orientation decides
    (det Phi_q > 0: B on the left of A->O4 here), the same at every step count, scale and
    rotation of the drawing (a rule on the axes had flipped with a 75 deg turn)."""
    text = re.sub(r"steps = \d+", f"steps = {steps}", _scaled(CONFIG.read_text(), scale, turn))
    assert _sides(solve_text(text, "auto")) == {1.0}


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_start_drawn_just_off_its_limit_leaves_it_to_that_side(side):
    """B drawn 1e-6 of the size off the line A-O4 (far above rounding): the sweep leaves the
    limit to the side it is drawn on, left or right, at any step count."""
    A, O4 = np.array([0.035714285714285234, -1.9996810970242027]), np.array([3.5, 0.0])
    d = (O4 - A) / np.linalg.norm(O4 - A)
    B = (A + O4) / 2 + side * 1e-6 * L * np.array([-d[1], d[0]])
    text = CONFIG.read_text().replace("B  = { x = 1.7678571428571426, y = -0.9998405485121014 }",
                                      f"B  = {{ x = {float(B[0])!r}, y = {float(B[1])!r} }}")
    for steps in (73, 145):
        r = solve_text(re.sub(r"steps = \d+", f"steps = {steps}", text), "auto")
        assert _sides(r) == {side}
