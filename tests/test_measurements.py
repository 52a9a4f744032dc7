"""[[measurements]]: a logged signal beside the computed variable it measures.

The shipped example (``configs/fourbar_crank_encoder.toml``) measures the rocker's angle with a
second, synthetic encoder: the geometry's exact angle plus seeded Gaussian noise of 0.05
degrees (``configs/logs/make_crank_encoder.py``). The residual computed - measured is then
minus that noise, known exactly, at every step where both exist.
"""
import importlib.util
import pathlib
import shutil

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe.__main__ import main
from linkpipe.scene import parse_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "fourbar_crank_encoder.toml"


def _make_script():
    spec = importlib.util.spec_from_file_location("make", ROOT / "configs" / "logs" / "make_crank_encoder.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_residual_is_the_logged_noise(tmp_path, capsys):
    make = _make_script()
    assert main(["run", str(SCENE), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    with h5py.File(tmp_path / "fourbar_crank_encoder.h5") as f:
        names = [n.decode() if isinstance(n, bytes) else n for n in f["measurement"][:]]
        measured = f["measured"][:, 0]
        residual = f["measured_residual"][:, 0]
        rms, max_abs = f["measured_residual"].attrs["rms"], f["measured_residual"].attrs["max_abs"]
        status = f["status"][:]
        t = f["time"][:]
    assert names == ["rocker_angle"]
    noise = np.random.default_rng(15).normal(0.0, make.ROCKER_NOISE_DEG, len(t))
    exact = np.radians(make.rocker_angle(make.angle(t)))
    ok = status == 0
    # computed - measured = (exact + solver error) - (exact + noise + 9-decimal rounding of the
    # CSV): -noise to 1e-9 degrees (the written digits) plus the positions' 1e-12
    np.testing.assert_allclose(residual[ok], -np.radians(noise[ok]), rtol=0, atol=2e-11)
    np.testing.assert_allclose(measured, exact + np.radians(noise), rtol=0, atol=2e-11)
    assert np.isnan(residual[~ok]).all() and (~ok).sum() == 1  # the no_input step
    expect_rms = np.sqrt(np.mean(np.radians(noise[ok]) ** 2))
    assert rms[0] == pytest.approx(expect_rms, rel=1e-8)
    assert max_abs[0] == pytest.approx(np.abs(np.radians(noise[ok])).max(), rel=1e-8)
    assert f"measurement rocker_angle (of link_angle.rocker): computed - measured rms {rms[0]:.4g}" in out


def test_the_recording_plots_computed_beside_measured(tmp_path):
    from rerun.chunk import RrdReader

    r = linkpipe.solve(str(SCENE))
    from linkpipe.stores import rrd
    rrd.write(r, tmp_path / "x.rrd")
    store = RrdReader(tmp_path / "x.rrd").store().stream().collect()
    entities = {c.entity_path for c in store.schema().component_columns()}
    assert {"/plots/measurements/rocker_angle/computed",
            "/plots/measurements/rocker_angle/measured"} <= entities
    frame = store.reader(index="step", contents="/plots/measurements/rocker_angle/measured").to_pandas()
    got = np.concatenate(frame["/plots/measurements/rocker_angle/measured:Scalars:scalars"].to_list())
    np.testing.assert_allclose(got, r.measurements["measured"][:, 0], rtol=0, atol=0)


def _scene_text():
    return SCENE.read_text()


BAD = [
    ('of = "link_angle.rocker"', 'of = "link_angel.rocker"', "of", 'did you mean "link_angle"'),
    ('of = "link_angle.rocker"', 'of = "link_angle.rockr"', "of", 'no link named "rockr"'),
    ('of = "link_angle.rocker"', 'of = "position.B"', "of", '"position" has x and y'),
    ('log = "encoder.rocker_deg"', 'log = "encoder.rocker"', "log", 'has no data column "rocker"'),
    ('log = "encoder.rocker_deg"', 'log = "other.rocker_deg"', "log", "no [[logs]] entry"),
    ('sigma = 0.0008726646259971648', "sigma = 0.0", "sigma", "must be positive"),
    ('of = "link_angle.rocker"', 'of = "spring_force.x"', "of", 'no spring named "x"'),
]


@pytest.mark.parametrize("old, new, key, words", BAD, ids=[b[1] for b in BAD])
def test_a_bad_measurement_is_one_message_exit_2_nothing_written(tmp_path, capsys, old, new, key, words):
    folder = tmp_path / "scene"
    shutil.copytree(SCENE.parent / "logs", folder / "logs")
    path = folder / "m.toml"
    text = _scene_text()
    assert text.count(old) == 1
    path.write_text(text.replace(old, new))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert str(path) in err and f'[measurements "rocker_angle"] {key}:' in err and words in err, err
    assert not out.exists() or not any(p for p in out.iterdir() if not p.name.startswith("."))


def test_a_measurement_needs_time_from_its_log():
    text = _scene_text().replace('[time]\nlog = "encoder"', '[time]\nfrom = 0.0\nto = 2.0\nsteps = 401')
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(text, str(SCENE))
    assert "needs [time] log" in str(err.value)


def test_measuring_what_the_scene_does_not_compute_is_its_mistake(tmp_path, capsys):
    folder = tmp_path / "scene"
    shutil.copytree(SCENE.parent / "logs", folder / "logs")
    path = folder / "m.toml"
    text = _scene_text().replace('of = "link_angle.rocker"', 'of = "input_force.crank"')
    path.write_text(text.replace('effects = ["inertia"]', "effects = []"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert '[measurements "rocker_angle"] of: "input_force" is not computed by this scene' in err
    assert not out.exists() or not any(p for p in out.iterdir() if not p.name.startswith("."))
