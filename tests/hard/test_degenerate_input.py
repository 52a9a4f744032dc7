"""Hard case 7: near-degenerate input either solves correctly or fails with a clear message.

* very short links next to long ones (ratio 1e-4);
* start guesses with links (nearly) in line;
* start guesses on the other branch's side, or far from any assembly;
* start positions that cannot be assembled at all.

A clear message is a SceneError that names the file, the table and the key, says what is wrong
and what to do (exit status 2 from the CLI, no traceback).
"""
import numpy as np
import pytest

from linkpipe.closed_forms import fourbar, slider_crank
from hard_scenes import (fourbar_text, point, solve_text, velocity, acceleration,
                         method)  # noqa: F401 - a fixture
import linkpipe
from linkpipe.__main__ import main
from linkpipe.status import OK

W = 10.0  # crank speed, rad/s (the builders' default rate)


def test_tiny_crank_next_to_long_links(method):
    """Crank 1e-4 m, coupler, rocker and ground 1 m (Grashof: 1e-4 + 1 < 1 + 1)."""
    a = 1e-4
    r = solve_text(fourbar_text(a, 1.0, 1.0, 1.0, 0.0, 360.0, 73), method)
    assert (r.status == OK).all()
    cf = fourbar(a, 1.0, 1.0, 1.0, np.deg2rad(r.driver_value[:, 0]), W, 0.0)
    # The solver's tolerance is relative to the mechanism's size (1.4 m), so the crank pin is
    # exact to ~1e-12 m, i.e. to 1e-8 of the crank's own length; velocities and accelerations
    # in the crank's scale a W, a W^2 (the rocker barely moves: its scale is a W too).
    for name in ("A", "B"):
        np.testing.assert_allclose(point(r, name), cf[name], rtol=0, atol=1e-11)
        np.testing.assert_allclose(velocity(r, name), cf["V" + name], rtol=0, atol=1e-6 * a * W)
        np.testing.assert_allclose(acceleration(r, name), cf["A" + name], rtol=0,
                                   atol=1e-6 * a * W**2)
    crank = np.linalg.norm(point(r, "A"), axis=1)
    np.testing.assert_allclose(crank, a, rtol=1e-8)


def test_tiny_crank_of_a_slider_crank(method):
    text = fourbar_text(1e-4, 1.0, 1.0, 1.0, 0.0, 360.0, 37)  # reuse the crank; replace the rocker
    text = text.replace('[[links]]\nname = "rocker"\npoints = ["O4", "B"]\nlengths = { "O4-B" = 1.0 }',
                        '[[sliders]]\nname = "piston"\npoint = "B"\n'
                        'along = { through = [0.0, 0.0], direction = [1.0, 0.0] }')
    text = text.replace("O4 = { x = 1.0, y = 0.0, fixed = true }", "")
    text = text.replace("B  = { x = 0.5000500000000001, y = 0.8660254037844386 }",
                        "B  = { x = 1.0001, y = 0.0 }")
    r = solve_text(text, method)
    assert (r.status == OK).all()
    cf = slider_crank(1e-4, 1.0, 0.0, np.deg2rad(r.driver_value[:, 0]), W, 0.0)
    np.testing.assert_allclose(point(r, "B"), cf["B"], rtol=0, atol=1e-11)
    np.testing.assert_allclose(velocity(r, "B"), cf["VB"], rtol=0, atol=1e-6 * 1e-4 * W)


def far_point_text(a, first_two):
    """A tiny crank O2-A (a) carrying a point P 1 m away; the link's frame is its first two points."""
    text = fourbar_text(a, 1.0, 1.0, 1.0, 0.0, 360.0, 37)
    if first_two == "O2-A":
        link = (f'points = ["O2", "A", "P"]\nlengths = {{ "O2-A" = {a!r} }}\n'
                'local = { P = [1.0, 0.2] }')
    else:  # the long pair spans the frame, A is the further point
        link = ('points = ["O2", "P", "A"]\nlengths = { "O2-P" = 1.019803902718557 }\n'
                f'local = {{ A = [{a / 1.019803902718557!r}, {-0.2 * a / 1.019803902718557!r}] }}')
    text = text.replace(f'points = ["O2", "A"]\nlengths = {{ "O2-A" = {a!r} }}', link)
    return text.replace("O4 = { x = 1.0, y = 0.0, fixed = true }",
                        "O4 = { x = 1.0, y = 0.0, fixed = true }\nP = { x = 1.0, y = 0.2 }")


def test_far_point_on_a_tiny_frame_is_refused_clearly():
    """P 1e4 times farther out than the frame is long: the Jacobian's condition is ~1e8."""
    with pytest.raises(linkpipe.SceneError) as err:
        solve_text(far_point_text(1e-4, "O2-A"), name="far_point.toml")
    e = err.value
    assert (e.path, e.table, e.key) == ("far_point.toml", 'links "crank"', "local")
    assert "1.02e+04 times farther" in str(e) and 'points = ["O2", "P", ...]' in str(e)


def test_far_point_with_the_long_pair_as_frame_solves(method):
    """The same body with the frame on O2-P, as the message says: solves, P exact."""
    r = solve_text(far_point_text(1e-4, "O2-P"), method)
    assert (r.status == OK).all()
    t = np.deg2rad(r.driver_value[:, 0])
    P = np.stack([np.cos(t) - 0.2 * np.sin(t), np.sin(t) + 0.2 * np.cos(t)], 1)
    VP = W * np.stack([-np.sin(t) - 0.2 * np.cos(t), np.cos(t) - 0.2 * np.sin(t)], 1)
    # P's position follows the 1e-4 crank's direction, known to ~1e-12 / 1e-4 rad: 1e-8 m
    np.testing.assert_allclose(point(r, "P"), P, rtol=0, atol=1e-8)
    np.testing.assert_allclose(velocity(r, "P"), VP, rtol=0, atol=1e-7 * W)


@pytest.mark.parametrize("B_guess, branch", [((2.5, 1e-9), +1), ((2.5, -1e-9), -1),
                                             ((4.0, 3.0), +1), ((4.0, -3.0), -1),
                                             ((100.0, 100.0), +1), ((3.0, -1e-3), -1)])
def test_start_guess_picks_the_branch_on_its_side(method, B_guess, branch):
    """Crank-rocker 1, 3.5, 3, 4 at crank 0 deg: A = (1, 0), O4 = (4, 0). B's guess on either side
    of the line A-O4, even 1e-9 m from it, gives the assembly on that side for the whole turn."""
    r = solve_text(fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 37, B_guess=B_guess), method)
    assert (r.status == OK).all()
    cf = fourbar(1.0, 3.5, 3.0, 4.0, np.deg2rad(r.driver_value[:, 0]), W, 0.0, branch=branch)
    np.testing.assert_allclose(point(r, "B"), cf["B"], rtol=0, atol=1e-10 * 4.0)
    np.testing.assert_allclose(velocity(r, "B"), cf["VB"], rtol=0, atol=1e-10 * 4.0 * W)


@pytest.mark.parametrize("B_guess", [(2.5, 0.0), (5.0, 0.0)])
def test_start_guess_exactly_in_line_is_refused_clearly(B_guess, tmp_path, capsys):
    """B's guess exactly on the line A-O4: it does not say which mirror image is meant."""
    text = fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 37, B_guess=B_guess)
    with pytest.raises(linkpipe.SceneError) as err:
        solve_text(text, name="in_line.toml")
    e = err.value
    assert (e.path, e.table, e.key) == ("in_line.toml", "points", "B")
    assert "in line" in e.message and "move B a little off the line" in e.hint
    # the CLI: one line, exit status 2, no traceback
    path = tmp_path / "in_line.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path), "--no-rrd"]) == 2
    err_text = capsys.readouterr().err
    assert "in_line.toml: [points] B:" in err_text and "Traceback" not in err_text


def test_start_that_cannot_be_assembled_names_the_constraint():
    """Coupler 1 + rocker 1 cannot reach across a ground of 4 from a crank of 1."""
    with pytest.raises(linkpipe.SceneError) as err:
        solve_text(fourbar_text(1.0, 1.0, 1.0, 4.0, 0.0, 360.0, 37, B_guess=(2.0, 1.0)),
                   name="too_short.toml")
    e = err.value
    assert (e.path, e.table) == ("too_short.toml", "points")
    assert "cannot be assembled" in e.message and '[links "' in e.message
    assert "check the link lengths" in e.hint


def test_start_from_a_sloppy_guess_far_from_the_sweep_start(method):
    """All moving points guessed at the origin's side, far off: still assembles (branch +1)."""
    r = solve_text(fourbar_text(1.0, 3.5, 3.0, 4.0, 30.0, 390.0, 37, B_guess=(0.5, 8.0)), method)
    assert (r.status == OK).all()
    cf = fourbar(1.0, 3.5, 3.0, 4.0, np.deg2rad(r.driver_value[:, 0]), W, 0.0, branch=+1)
    np.testing.assert_allclose(point(r, "B"), cf["B"], rtol=0, atol=1e-10 * 4.0)


CYLINDER_ARM = """
[scene]
name = "arm"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}
[points]
O  = {{ x = 0.0, y = 0.0, fixed = true }}
C0 = {{ x = 0.5, y = -0.8, fixed = true }}
C  = {{ x = 1.0, y = 0.0 }}
[[links]]
name = "arm"
points = ["O", "C"]
[[drivers]]
name = "cyl"
distance = ["C0", "C"]
from = {first!r}
to = 1.0
steps = 5
"""


@pytest.mark.parametrize("first, unreached", [(0.01, 1), (3.0, 3)])
def test_first_values_out_of_reach_are_no_assembly_and_the_note_names_the_reach(first, unreached):
    """An arm of radius 1 about O, a cylinder from C0 (|C0| = sqrt(0.89)) to its end: the
    cylinder's length lies between 1 - |C0| and 1 + |C0| (the arm along the line through O and
    C0). Steps beyond that are no_assembly (failures are data: the sweep goes on, and starts
    at the first step in reach: 0.01 -> 1.0 in 5 steps leaves out 0.01; 3.0 -> 1.0 leaves out
    3.0, 2.5, 2.0); the run's reach_note says how far the mechanism goes from the drawing
    towards the first value (the limit bisected: to 1e-6 m, the solver's tolerance near a fold,
    where the length's first order in the arm's angle vanishes). The steps in reach meet the
    constraints to Newton's tolerance: C on the unit circle at the cylinder's length from C0."""
    r = linkpipe.solve(linkpipe.parse_scene(CYLINDER_ARM.format(first=first), "arm.toml"))
    assert list(r.status) == [1] * unreached + [OK] * (5 - unreached)
    limit = 1.0 - np.sqrt(0.89) if first < 1 else 1.0 + np.sqrt(0.89)
    said = float(r.reach_note.split("as far as ")[1].split(" m")[0])
    assert said == pytest.approx(limit, abs=1e-5)  # printed to 6 significant digits
    assert f"the first driver value {first:g} m is out of reach" in r.reach_note
    C, C0 = point(r, "C")[unreached:], np.array([0.5, -0.8])
    tol = 1e-12 * r.model.size  # Newton's tolerance
    np.testing.assert_allclose(np.hypot(*C.T), 1.0, rtol=0, atol=tol)
    # the driver's row is (d^2 - s^2) / (2 L), L its largest length (1 + |C0|): d to tol L / s
    length = r.driver_value[unreached:, 0]
    assert (np.abs(np.hypot(*(C - C0).T) - length) <= tol * (1 + np.sqrt(0.89)) / length).all()
    assert np.isnan(point(r, "C")[:unreached]).all()


def test_an_angle_out_of_reach_a_turn_on_says_the_drawings_angle_and_the_limit():
    """Crank 2.5, coupler 2, rocker 3, ground 4: the crank reaches up to the angle where
    |O4 A| = coupler + rocker = 5, cos t = (2.5^2 + 4^2 - 5^2) / (2 * 2.5 * 4) = -0.1375
    (97.903 deg). Drawn at 60 deg, swept from 480 deg (a turn on, 120 deg) to 490: every step is
    no_assembly, and the run's reach_note gives the drawing's own 60 deg, the 420 deg it is on
    the sweep's turn, and 360 + 97.903 deg."""
    from test_drawing import NON_GRASHOF

    text = NON_GRASHOF.format(ax=1.25, ay=float(2.5 * np.sin(np.radians(60.0)))).replace(
        "from = 60.0\nto = 70.0", "from = 480.0\nto = 490.0")
    r = linkpipe.solve(linkpipe.parse_scene(text, "nong.toml"))
    assert (r.status == 1).all()  # every step beyond the reach: no_assembly, no error
    assert "from the drawing's 60 deg (420 deg on the sweep's turn)" in r.reach_note, r.reach_note
    said = float(r.reach_note.split("as far as ")[1].split(" deg")[0])
    assert said == pytest.approx(360.0 + np.degrees(np.arccos(-0.1375)), abs=1e-3)  # 6 digits


def test_steps_out_of_reach_in_a_sweep_streamed_in_segments(tmp_path):
    """The arm's 3.0 -> 1.0 m over 300,001 steps (segments of 65,536; the reach ends at
    1.943 m, step 158,491, inside the third): `run` streams it and stores the same statuses and positions as the
    whole sweep solved at once, and the file's reach_note attribute says why."""
    import h5py

    from linkpipe.segments import steps_per_segment

    text = CYLINDER_ARM.format(first=3.0).replace("steps = 5", "steps = 300001")
    path = tmp_path / "arm.toml"
    path.write_text(text)
    whole = linkpipe.solve(linkpipe.parse_scene(text, str(path)))
    k = int(np.argmax(whole.status == OK))
    assert k > 2 * steps_per_segment(whole.scene)  # whole segments out of reach, then one in part
    assert whole.driver_value[k - 1, 0] > 1 + np.sqrt(0.89) >= whole.driver_value[k, 0]
    assert (whole.status[:k] == 1).all() and (whole.status[k:] == OK).all()
    assert main(["run", str(path), "--out", str(tmp_path), "--no-rrd", "--quiet"]) == 0
    with h5py.File(tmp_path / "arm.h5") as f:
        np.testing.assert_array_equal(f["status"][:], whole.status)
        np.testing.assert_array_equal(f["position"][:], whole.position)
        assert f.attrs["reach_note"] == whole.reach_note != ""


def test_an_angle_sweep_that_comes_into_reach_a_turn_later():
    """The non-Grashof crank (reach -97.903 .. 97.903 deg about its drawing at 60 deg) swept
    from 120 to 480 deg: 120 .. 260 deg are out of reach, 270 .. 450 deg (-90 .. 90 deg a turn
    on) assemble, 460 .. 480 are out again; the steps in reach as the same sweep from 270 gives
    them (they had all been no_assembly: the reach was compared without the turns)."""
    from test_drawing import NON_GRASHOF

    text = NON_GRASHOF.format(ax=1.25, ay=float(2.5 * np.sin(np.radians(60.0))))
    swept = text.replace("from = 60.0\nto = 70.0", "from = 120.0\nto = 480.0").replace(
        "steps = 3", "steps = 37")
    r = linkpipe.solve(linkpipe.parse_scene(swept, "nong.toml"))
    ok = np.flatnonzero(r.status == OK)
    assert list(r.driver_value[ok, 0]) == list(np.arange(270.0, 451.0, 10.0))
    assert (r.status[:15] == 1).all() and (r.status[34:] == 1).all()
    inside = linkpipe.solve(linkpipe.parse_scene(swept.replace("from = 120.0", "from = 270.0")
                                                 .replace("to = 480.0", "to = 450.0")
                                                 .replace("steps = 37", "steps = 19"), "in.toml"))
    # each solved to Newton's tolerance (1e-12 of the size) times the Jacobian's condition
    np.testing.assert_allclose(r.position[ok], inside.position, rtol=0,
                               atol=1e-12 * r.model.size * r.condition[ok].max())


def test_a_log_jumping_past_both_limits_starts_at_its_first_value_in_reach(tmp_path):
    """The arm's cylinder (reach 0.057 .. 1.943 m) logged 3.0, 0.01, 3.0, 0.01, 3.0, 1.0, 1.1:
    each failing value bounds the reach on its side, so the start is the first value within
    both (1.0): five no_assembly steps, then two ok (it had run out of tries and raised)."""
    (tmp_path / "rig.csv").write_text("t,d\n0,3.0\n1,0.01\n2,3.0\n3,0.01\n4,3.0\n5,1.0\n6,1.1\n")
    text = CYLINDER_ARM.format(first=3.0).replace("from = 3.0\nto = 1.0\nsteps = 5",
                                                  'log = "rig.d"') + (
        '[time]\nlog = "rig"\n[[logs]]\nname = "rig"\nfile = "rig.csv"\ntime = "t"\n')
    path = tmp_path / "arm.toml"
    path.write_text(text)
    r = linkpipe.solve(linkpipe.load_scene(str(path)))
    assert list(r.status) == [1] * 5 + [OK] * 2
    assert "the first driver value 3 m is out of reach" in r.reach_note


def test_a_study_moving_pivots_of_a_scene_that_starts_out_of_reach(tmp_path):
    """The arm (3.0 -> 1.0 m, three steps out of reach) with its cylinder's base moved: the
    study runs each variant as its own scene (the vectorised pivots path starts at step 0; it
    had raised the base's out-of-reach error), and each row is that scene's own run."""
    import h5py

    (tmp_path / "arm.toml").write_text(CYLINDER_ARM.format(first=3.0))
    (tmp_path / "study.toml").write_text(
        '[scene]\nname = "st"\n[study]\nbase = "arm.toml"\nsamples = 3\nseed = 1\n'
        '[study.parameters]\n"points.C0.x" = { uniform = [0.45, 0.55] }\n'
        '[study.metrics]\nmx = "max(abs(position.C.x))"\n')
    assert main(["study", str(tmp_path / "study.toml"), "--out", str(tmp_path), "--quiet"]) == 0
    with h5py.File(tmp_path / "st_study.h5") as f:
        x0 = f["parameter_value"][:, 0]
        mx, first_failed = f["mx"][:], f["first_failed_step"][:]
    for v, x in enumerate(x0):
        own = linkpipe.solve(linkpipe.parse_scene(
            CYLINDER_ARM.format(first=3.0).replace("x = 0.5, y = -0.8", f"x = {float(x)!r}, y = -0.8"),
            "own.toml"))
        assert list(own.status[:3]) == [1, 1, 1]
        assert first_failed[v] == 0
        assert mx[v] == np.abs(point(own, "C")[own.status == OK, 0]).max()


def test_check_says_which_first_steps_are_out_of_reach(tmp_path, capsys):
    """`check` on the arm from 3.0 m: valid (exit 0), with a warning naming the 3 of 5 steps
    out of reach and how far the mechanism assembles (as `run`'s reach_note)."""
    path = tmp_path / "arm.toml"
    path.write_text(CYLINDER_ARM.format(first=3.0))
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "warning: the first 3 of 5 steps are out of the drawing's reach" in out
    assert linkpipe.solve(str(path)).reach_note in out
