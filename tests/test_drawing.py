"""A drawn pose far from an assembled one (a `local` coordinate or length that does not match
the drawing) is legal, since the points' x, y are a guess, but it is probably not what was meant:
``check``, the run's summary and the .h5's ``warnings`` say which point moves and how far."""
from __future__ import annotations

import pathlib

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe.__main__ import main
from linkpipe.kinematics.start import DRAWING_MOVED_FRACTION, drawing_offset, drawing_warnings
from linkpipe.model import build_model
from linkpipe.study.spec import study_kind

ROOT = pathlib.Path(__file__).resolve().parents[1]
CRANK_ROCKER = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
DRAWN_P = "P  = { x = 1.2252, y = 1.6850 }"


def test_a_point_drawn_away_from_its_local_place_is_named_with_its_distance(tmp_path, capsys):
    """The crank-rocker's coupler point P drawn 1.5 m to the right of where its `local`
    coordinates put it: assembled at the drawing's own crank angle (0 deg, the sweep's first
    step) P lands at the first step's solved place, so the warning's distance is the distance
    from the shifted drawing to that place (to the solver's tolerance, 1e-12 m)."""
    assert DRAWN_P in CRANK_ROCKER
    first_p = linkpipe.solve(linkpipe.parse_scene(CRANK_ROCKER, "cr.toml")).position[0, 4]
    shifted = CRANK_ROCKER.replace(DRAWN_P, "P  = { x = 2.7252, y = 1.6850 }")
    path = tmp_path / "shifted.toml"
    path.write_text(shifted)
    scene = linkpipe.load_scene(str(path))
    name, distance = drawing_offset(build_model(scene))
    assert name == "P"
    assert distance == pytest.approx(float(np.hypot(*(np.array([2.7252, 1.6850]) - first_p))),
                                     abs=1e-12)
    (warning,) = drawing_warnings(build_model(scene))
    assert warning.startswith(f"{path}: [points] P: the drawing is not an assembled pose")
    assert f"P lands {distance:.3g} m from where it is drawn" in warning

    assert main(["check", str(path)]) == 0
    assert f"  warning: {warning}" in capsys.readouterr().out
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-rrd"]) == 0
    assert f"  warning: {warning}" in capsys.readouterr().out
    with h5py.File(out / "fourbar_crank_rocker.h5") as f:
        assert list(f.attrs["warnings"]) == [warning]


def test_a_guess_near_its_assembly_is_not_warned_about():
    """Within DRAWING_MOVED_FRACTION of the size (the shipped crank-rocker draws B "a guess" to
    four decimals) no warning; every shipped scene's drawing is within it."""
    scenes = [p for p in sorted(ROOT.glob("configs/**/*.toml")) if not study_kind(str(p))]
    assert len(scenes) >= 15
    for p in scenes:
        model = build_model(linkpipe.load_scene(str(p)))
        found = drawing_offset(model)
        assert found is None or found[1] < DRAWING_MOVED_FRACTION * model.size / 10, (p, found)
        assert drawing_warnings(model) == ()


NON_GRASHOF = """
[scene]
name = "nong"
units = {{ length = "m", mass = "kg", time = "s", force = "N" }}
[points]
O2 = {{ x = 0.0, y = 0.0, fixed = true }}
A  = {{ x = {ax!r}, y = {ay!r} }}
B  = {{ x = 3.0, y = 2.5 }}
O4 = {{ x = 4.0, y = 0.0, fixed = true }}
K  = {{ x = 5.0, y = 4.0, fixed = true }}
[[links]]
name = "crank"
points = ["O2", "A"]
lengths = {{ "O2-A" = 2.5 }}
[[links]]
name = "coupler"
points = ["A", "B"]
lengths = {{ "A-B" = 2.0 }}
[[links]]
name = "rocker"
points = ["O4", "B"]
lengths = {{ "O4-B" = 3.0 }}
[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 60.0
to = 70.0
steps = 3
[[springs]]
name = "s"
between = ["K", "B"]
k = 100.0
preload = 5.0
[analysis]
effects = ["springs"]
"""


def test_a_drawing_that_does_not_assemble_warns_that_springs_measure_on_it():
    """Crank 2.5, coupler 2, rocker 3, ground 4 reaches crank angles within +-97.9 deg: drawn at
    120 deg the drawing has no assembly at its own driver value (the sweep from 60 deg starts
    there directly), so the spring's start length, where its preload holds, comes from the
    drawing as written: a warning names the spring. Drawn at 60 deg: no warning."""
    far = linkpipe.parse_scene(NON_GRASHOF.format(ax=float(2.5 * np.cos(np.radians(120.0))),
                                                  ay=float(2.5 * np.sin(np.radians(120.0)))),
                               "far.toml")
    near = linkpipe.parse_scene(NON_GRASHOF.format(ax=1.25, ay=float(2.5 * np.sin(np.radians(60.0)))),
                                "near.toml")
    (warning,) = drawing_warnings(build_model(far))
    assert 'springs "s" measure their start length' in warning and "free_length" in warning
    assert drawing_warnings(build_model(near)) == ()
    assert linkpipe.solve(far).n_ok == 3  # the sweep itself runs


def test_a_held_driver_with_a_rate_is_a_warning():
    """from = to over 61 steps while the other crank moves, and a rate of 30 deg/s: the value
    stays while the velocity is 30 deg/s at every step (the contract's instantaneous state):
    legal, probably not meant. With rate = 0 (statics) no warning."""
    text = (ROOT / "configs" / "five_bar.toml").read_text()
    assert "from = 60.0\nto = 120.0" in text and "rate = 30.0 " in text
    held = text.replace("from = 60.0\nto = 120.0", "from = 60.0\nto = 60.0")
    scene = linkpipe.parse_scene(held, "held.toml")
    assert any('[drivers "theta1"] is held' in w and "give rate = 0" in w for w in scene.warnings)
    statics = held.replace("rate = 30.0 ", "rate = 0.0 ")
    assert not any("is held" in w for w in linkpipe.parse_scene(statics, "s.toml").warnings)
