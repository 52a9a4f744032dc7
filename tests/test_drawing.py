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
