"""[[measurements]]: a logged signal beside the computed variable it measures.

The shipped example (``configs/fourbar_crank_encoder.toml``) measures the rocker's angle with a
second, synthetic encoder: the geometry's exact angle plus seeded Gaussian noise of 0.05
degrees (``configs/logs/make_crank_encoder.py``). The residual computed - measured is then
minus that noise, known exactly, at every step where both exist.
"""
import importlib.util
import pathlib
import re
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


def test_measuring_a_force_without_the_force_stage_is_a_scene_error_check_finds(tmp_path, capsys):
    """input_force with no effects (no force stage), spring_force without "springs": one
    message at the measurement's `of` from `check` and from `run` alike, before any solve."""
    folder = tmp_path / "scene"
    shutil.copytree(SCENE.parent / "logs", folder / "logs")
    path = folder / "m.toml"
    for of, effects, words in (
            ("input_force.crank", "effects = []", '"input_force" is computed by the force stage, '
             "which runs only with [analysis] effects; this scene has none"),
            ("spring_force.s", 'effects = ["inertia"]', '"spring_force" is computed by "springs" '
             "in [analysis] effects; this scene has effects ['inertia']")):
        text = _scene_text().replace('of = "link_angle.rocker"', f'of = "{of}"')
        text = text.replace('effects = ["inertia"]', effects)
        if of.startswith("spring"):
            text = text.replace("[outputs]", '[[springs]]\nname = "s"\nbetween = ["A", "O4"]\n'
                                "k = 1.0\nfree_length = 3.0\n\n[outputs]")
        path.write_text(text)
        for command in (["check", str(path)], ["run", str(path), "--out", str(tmp_path / "out")]):
            assert main(command) == 2
            err = capsys.readouterr().err.strip()
            assert err.startswith(f'error: {path}: [measurements "rocker_angle"] of: {words}'), err
            assert len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_measured_rate_is_computed_though_no_output_asks_for_it(tmp_path):
    """A measurement of the coupler point's velocity in a scene that asks for positions only
    (no [outputs] kinematics, no vectors, no effects): the velocity is computed, stored and
    compared (the measurement calls for it); its residual is the stored velocity minus the
    measured column, exactly."""
    folder = tmp_path / "scene"
    shutil.copytree(SCENE.parent / "logs", folder / "logs")
    text = _scene_text().replace('of = "link_angle.rocker"', 'of = "velocity.P.x"')
    text = text.replace('effects = ["inertia"]', "effects = []")
    text = text.replace('kinematics = ["velocity", "acceleration"]\ntrace = ["P"]\nvectors = ["P"]',
                        'trace = ["P"]')
    assert "vectors" not in text and "kinematics =" not in text
    path = folder / "m.toml"
    path.write_text(text)
    r = linkpipe.solve(linkpipe.load_scene(str(path)))
    assert r.velocity is not None and r.acceleration is None
    p = r.point_names.index("P")
    measured = r.measurements["measured"][:, 0]
    np.testing.assert_array_equal(r.measurements["residual"][:, 0], r.velocity[:, p, 0] - measured)


# ------------------------------------------------------------------ units of mixed drivers
#: a crank on a logged angle (its input a torque, kN*mm) and a cylinder on a logged length (its
#: input a force, kN): one of each measurable variable, every unit distinct
MIXED = """\
[scene]
name = "mixed"
units = { length = "mm", mass = "kg", time = "s", force = "kN" }

[points]
O = { x = 0.0, y = 0.0, fixed = true }
A = { x = 1000.0, y = 0.0 }
O2 = { x = 0.0, y = -3000.0, fixed = true }
C = { x = 1500.0, y = -3000.0, fixed = true }
P = { x = 1000.0, y = -2000.0 }

[[links]]
name = "crank"
points = ["O", "A"]

[[links]]
name = "lever"
points = ["O2", "P"]

[time]
log = "run"

[[logs]]
name = "run"
file = "run.csv"
time = "t"

[[drivers]]
name = "crank"
angle = ["O", "A"]
log = "run.angle"

[[drivers]]
name = "cylinder"
distance = ["C", "P"]
log = "run.length"

[analysis]
effects = ["gravity", "springs"]

[gravity]
g = [0.0, -9810.0]

[[masses]]
link = "crank"
mass = 2.0
center = "A"

[[springs]]
name = "coil"
between = ["O", "P"]
k = 0.03
free_length = 1000.0

[[torsion_springs]]
name = "hinge"
links = ["crank", "ground"]
k = 5.0
free_angle = 10.0
"""

#: (of, the unit of that entry) for every measurable variable of MIXED
MEASURED = [("position.A.y", "mm"), ("velocity.A.x", "mm/s"), ("acceleration.P.y", "mm/s^2"),
            ("driver_value.crank", "degree"), ("driver_value.cylinder", "mm"),
            ("driver_velocity.crank", "degree/s"), ("driver_acceleration.cylinder", "mm/s^2"),
            ("input_force.crank", "kN*mm"), ("input_force.cylinder", "kN"),
            ("input_force_lagrange.crank", "kN*mm"), ("link_angle.lever", "rad"),
            ("link_angular_velocity.crank", "rad/s"), ("link_angular_acceleration.lever", "rad/s^2"),
            ("link_force.lever", "kN"), ("spring_force.coil", "kN"),
            ("spring_length.coil", "mm"), ("spring_extension.coil", "mm"),
            ("spring_energy.coil", "kN*mm"), ("torsion_spring_angle.hinge", "rad"),
            ("torsion_spring_torque.hinge", "kN*mm"), ("torsion_spring_energy.hinge", "kN*mm"),
            ("joint_force.A@crank.x", "kN"), ("ground_reaction.O2.y", "kN"),
            ("friction_force.pins", "kN*mm"), ("friction_power.pins", "kN*mm/s")]
#: MIXED with pin friction (version 3), for the friction's measurements
FRICTION = """
[[friction]]
name = "pins"
joints = ["O", "O2"]
mu = 0.1
pin_radius = 20.0
"""


def test_each_measurement_and_driver_carries_its_own_unit(tmp_path, capsys):
    """Drivers of two kinds: ``input_force`` is "mixed" with ``driver_units`` beside it, and each
    measurement's unit (``measurement_units``, the summary, the recording's plot names, the fit's
    and the fleet's files) is the unit of the entry it measures, read back from the run's file:
    ``driver_units`` where the variable has it, else its ``units``. The slider force is the only
    measurable variable left out (no slider): a force, as link_force. Pin friction's
    ``friction_force`` is a torque, its power a force times a speed."""
    from linkpipe.scene.timing import MEASURABLE
    assert {of.split(".")[0] for of, _ in MEASURED} == set(MEASURABLE) - {"slider_force"}
    t = np.linspace(0.0, 1.0, 21)
    import pandas as pd
    pd.DataFrame({"t": t, "angle": 10.0 + 40.0 * t, "length": 1300.0 + 200.0 * t,
                  "signal": np.sin(t)}).to_csv(tmp_path / "run.csv", index=False)
    text = MIXED.replace('effects = ["gravity", "springs"]',
                         'effects = ["gravity", "springs", "friction"]') + FRICTION + "".join(f'\n[[measurements]]\nname = "m{k}"\nlog = "run.signal"\nof = "{of}"\n'
                           for k, (of, _) in enumerate(MEASURED))
    text = text.replace('[analysis]', '[outputs]\nkinematics = ["velocity", "acceleration"]\n\n'
                        '[analysis]')
    (tmp_path / "mixed.toml").write_text(text)
    assert main(["run", str(tmp_path / "mixed.toml"), "--out", str(tmp_path / "out")]) == 0
    want = [unit for _, unit in MEASURED]
    printed = capsys.readouterr().out  # the summary: each driver's and measurement's own unit
    assert re.search(r"input force crank: \S+ \.\. \S+ kN\*mm\n", printed)
    assert re.search(r"input force cylinder: \S+ \.\. \S+ kN\n", printed)
    assert re.search(r"measurement m5 \(of driver_velocity.crank\): .* degree/s\n", printed)
    with h5py.File(tmp_path / "out" / "mixed.h5", "r") as f:
        for name in ("input_force", "input_force_lagrange"):
            assert f[name].attrs["units"] == "mixed"
            assert f[name].attrs["driver_units"] == "kN*mm,kN"
        drivers = [n.decode() for n in f["driver"][:]]
        for (of, unit), got in zip(MEASURED, f["measured"].attrs["measurement_units"].split(",")):
            variable, rest = of.split(".", 1)
            attrs = f[variable].attrs
            if "driver_units" in attrs:
                unit_in_file = attrs["driver_units"].split(",")[drivers.index(rest)]
            else:
                unit_in_file = attrs["units"]
            assert got == unit_in_file == unit, of
        assert f["measured"].attrs["units"] == "mixed"
        assert f["measured_residual"].attrs["measurement_units"] == ",".join(want)
    from linkpipe.output_units import measured_units
    assert measured_units(linkpipe.load_scene(tmp_path / "mixed.toml")) == want

    # the recording names each series' own unit; a torque and a force get a view each (each on
    # its own scale), a measurement's view its unit
    from test_rrd import Recording
    views = Recording(tmp_path / "out" / "mixed.rrd").views()
    assert views["input force [kN*mm]"] == ["/plots/input_force/crank"]
    assert views["input force [kN]"] == ["/plots/input_force/cylinder"]
    assert "input force [mixed]" not in views and views["spring force [kN]"]
    assert all(e.startswith("/plots/spring_force/") for e in views["spring force [kN]"])
    # more than four plots: a two-column grid, whose measurement titles are short (issue 34)
    assert "m7 [kN*mm]" in views
    assert "m5 [degree/s]" in views
    from linkpipe.stores.rrd.series import series_of
    r = linkpipe.solve(linkpipe.load_scene(tmp_path / "mixed.toml"))
    named = {entity: name for entity, name, _, _ in series_of(r)}
    # each series named for what it is; its unit is its view's (issue 34)
    assert named["/plots/input_force/crank"] == "torque of crank"
    assert named["/plots/input_force/cylinder"] == "cylinder axial force"
    assert named["/plots/measurements/m5/computed"] == "computed"   # its view: [degree/s]

    # a fleet of two logs: its input-force and rms columns carry the same per-entry units
    import shutil
    (tmp_path / "logs").mkdir()
    for k in range(2):
        shutil.copy(tmp_path / "run.csv", tmp_path / "logs" / f"run{k}.csv")
    assert main(["run", str(tmp_path / "mixed.toml"), "--logs", str(tmp_path / "logs" / "*.csv"),
                 "--out", str(tmp_path / "fleet"), "--quiet"]) == 0
    with h5py.File(tmp_path / "fleet" / "mixed_fleet.h5", "r") as f:
        for name in ("peak_input_force", "rms_input_force"):
            assert f[name].attrs["units"] == "mixed" and f[name].attrs["driver_units"] == "kN*mm,kN"
        assert f["measured_rms"].attrs["units"] == "mixed"
        assert f["measured_rms"].attrs["measurement_units"] == ",".join(want)
