"""Geometry slips said first, and fast (issue 34): a drawing far from the assembly it solves to
is on the first line of `check` and `run`, and a sweep that mostly cannot assemble skips what
the closed-form dyads show cannot assemble.

The scene is the crank-rocker of configs/ (crank O2-A 1, rocker O4-B 3, ground O2-O4 4, B drawn
at (3.0417, 2.8428)) with a wrong coupler length. Its exact answers are closed forms: at the
drawn crank angle 0, A = (1, 0) and B is where the circles about A (radius the coupler) and
O4 (radius 3) meet, on the drawing's side; and a crank angle assembles exactly where
|A - O4| lies within [3 - coupler, 3 + coupler].
"""
import math
import pathlib

import numpy as np
import pytest

import linkpipe
from linkpipe.__main__ import main
from linkpipe.kinematics import beyond_reach, driver_motion, start_state
from linkpipe.kinematics.continuation import solve_positions
from linkpipe.model import build_model
from linkpipe.status import NO_ASSEMBLY, OK

CONFIGS = pathlib.Path(__file__).parent.parent / "configs"
CRANK_ROCKER = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
DRAWN_B = np.array([3.0417, 2.8428])


def scene_with_coupler(tmp_path, length: float, name: str) -> pathlib.Path:
    text = CRANK_ROCKER.replace('"A-B" = 3.5', f'"A-B" = {length!r}')
    text = text.replace('name = "fourbar_crank_rocker"', f'name = "{name}"')
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def assembled_b(coupler: float) -> np.ndarray:
    """B at crank angle 0: circles about A = (1, 0) (radius ``coupler``) and O4 = (4, 0)
    (radius 3), the intersection above the ground line (the drawing's side)."""
    d = 3.0
    k = (d * d + coupler ** 2 - 9.0) / (2 * d)
    return np.array([1.0 + k, math.sqrt(coupler ** 2 - k * k)])


@pytest.mark.parametrize("coupler", [0.02, 2.5])
def test_check_and_run_say_the_slip_on_their_first_line(tmp_path, capsys, coupler):
    """0.02: only 20 of 361 crank angles assemble, and Newton from the drawing cannot reach the
    assembly (damped least squares finds it); 2.5: every step assembles, far from the drawing.
    Both said on the first line, the distance to the closed form's 3 significant figures."""
    path = scene_with_coupler(tmp_path, coupler, "slip")
    distance = float(np.hypot(*(assembled_b(coupler) - DRAWN_B)))
    said = f"B assembles {distance:.3g} m from its drawing"
    assert main(["check", str(path)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == f"{path}: scene 'slip' is valid \u2014 but {said}"
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-rrd"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    ok = 20 if coupler == 0.02 else 361
    steps = f"{ok}/361 steps ok; 341 no_assembly" if ok < 361 else "all 361 steps ok"
    assert first.startswith(f"slip: {steps} \u2014 but {said} (")


def test_a_drawing_near_its_assembly_says_no_slip(capsys):
    assert main(["check", str(CONFIGS / "fourbar_crank_rocker.toml")]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith("scene 'fourbar_crank_rocker' is valid")


def test_steps_beyond_reach_are_skipped_with_the_same_answer(tmp_path):
    """The statuses are the closed form's (|A - O4| within [2.98, 3.02]); skipping the steps the
    dyads show cannot assemble gives the same statuses and, at every assembled step, the same
    positions (to the solver's tolerance) as solving every step by damped least squares."""
    scene = linkpipe.load_scene(scene_with_coupler(tmp_path, 0.02, "short"))
    model = build_model(scene)
    _, s, _, _ = driver_motion(model)
    theta = s[:, 0]
    reach = np.hypot(np.cos(theta) - 4.0, np.sin(theta))        # |A - O4|
    assembles = (reach >= 3.0 - 0.02) & (reach <= 3.0 + 0.02)
    skip = beyond_reach(model, s)
    assert skip is not None and not (skip & assembles).any()
    assert skip.sum() >= 300                       # most of the turn is skipped
    start = start_state(model, s[0], model.tolerance(), scene.solver.max_iter)
    q_all, _, _, st_all = solve_positions(model, s, *start)
    q_skip, res_skip, it_skip, st_skip = solve_positions(model, s, *start, skip=skip)
    np.testing.assert_array_equal(st_all, np.where(assembles, OK, NO_ASSEMBLY))
    np.testing.assert_array_equal(st_skip, st_all)
    ok = st_all == OK
    tol = model.tolerance()
    np.testing.assert_allclose(q_skip[ok], q_all[ok], atol=10 * tol, rtol=0)
    assert np.isnan(q_skip[~ok]).all()
    # a skipped step is not iterated (the first step of a gap and the last before the reach
    # are solved, as before); its residual is where the gap's shape stands: above tolerance
    skipped = skip & (it_skip == 0)
    assert skipped.sum() >= 300 and (res_skip[skipped] > 10 * tol).all()
    assert np.isfinite(res_skip).all()
    result = linkpipe.solve(scene)
    np.testing.assert_array_equal(result.status, st_all)
