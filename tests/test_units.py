"""Rates written with a unit, gravity against the scene's length unit, and the words users
write for ``rate``: each with its exact conversion factor or message."""
import math
import re

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe.__main__ import main
from linkpipe.scene import parse_scene

import pathlib

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"
CRANK = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
DUMP = (CONFIGS / "dump_truck.toml").read_text()


def _with(text, key, value):
    new, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, count=1, flags=re.M)
    if n == 0:  # the key is not written yet: add it after the driver's steps
        new = re.sub(r"^(steps = .*)$", rf"\1\n{key} = {value}", text, count=1, flags=re.M)
    return new


@pytest.mark.parametrize("written, deg_per_s", [
    ('"120 rpm"', 720.0), ('"12.57 rad/s"', 12.57 * 180 / math.pi), ('"720 deg/s"', 720.0),
    ('"2 rev/s"', 720.0), ('"60 rev/min"', 360.0), ("572.9578", 572.9578), ('"-30deg/s"', -30.0)])
def test_angle_rates_with_units(written, deg_per_s):
    scene = parse_scene(_with(CRANK, "rate", written), "crank.toml")
    assert scene.drivers[0].rate == pytest.approx(deg_per_s, rel=1e-15)


@pytest.mark.parametrize("written, per_s2", [
    ('"30 deg/s^2"', 30.0), ('"1 rad/s^2"', 180 / math.pi), ('"0.5 rev/s^2"', 180.0),
    ('"10 deg/s²"', 10.0)])
def test_angle_accelerations_with_units(written, per_s2):
    scene = parse_scene(_with(CRANK, "acceleration", written), "crank.toml")
    assert scene.drivers[0].acceleration == pytest.approx(per_s2, rel=1e-15)


@pytest.mark.parametrize("written, m_per_s", [
    ('"100 mm/s"', 0.1), ('"0.1 m/s"', 0.1), ('"10 cm/s"', 0.1), ('"4 in/s"', 0.1016),
    ('"1 ft/s"', 0.3048)])
def test_cylinder_rates_in_the_scenes_length_unit(written, m_per_s):
    scene = parse_scene(_with(DUMP, "rate", written), "dump.toml")  # units.length = "m"
    assert scene.drivers[0].rate == pytest.approx(m_per_s, rel=1e-15)
    mm = parse_scene(_with(DUMP, "rate", written).replace('length = "m"', 'length = "mm"'), "dump.toml")
    assert mm.drivers[0].rate == pytest.approx(m_per_s * 1000, rel=1e-15)


def test_a_rate_with_a_unit_moves_the_mechanism_as_the_number_does():
    a = linkpipe.solve(parse_scene(_with(CRANK, "rate", '"10 rad/s"'), "a.toml"))
    b = linkpipe.solve(parse_scene(_with(CRANK, "rate", repr(10 * 180 / math.pi)), "b.toml"))
    np.testing.assert_array_equal(a.velocity, b.velocity)


BAD = [
    (CRANK, "rate", '"5 mm/s"', "does not fit an angle driver"),
    (CRANK, "rate", '"fast"', "is not a number with a unit"),
    (CRANK, "acceleration", '"3 rad/s"', "does not fit an angle driver"),
    (DUMP, "rate", '"3 rpm"', "does not fit a distance driver"),
    (DUMP, "rate", '"3 mm/s^2"', "does not fit a distance driver"),
    (DUMP.replace('length = "m"', 'length = "furlong"'), "rate", '"3 mm/s"', "not a length unit"),
]


@pytest.mark.parametrize("text, key, value, words", BAD, ids=[f"{b[1]}={b[2]}" for b in BAD])
def test_a_unit_that_does_not_fit_is_one_message_exit_2_nothing_written(tmp_path, capsys, text,
                                                                     key, value, words):
    path = tmp_path / "bad.toml"
    path.write_text(_with(text, key, value))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert str(path) in err and f"] {key}:" in err and words in err
    assert "write a number" in err  # the accepted forms are listed
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("word", ["rpm", "speed", "omega", "velocity", "angular_velocity"])
def test_the_words_users_write_for_rate_point_to_rate(word):
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(CRANK.replace("rate = ", f"{word} = ", 1), "crank.toml")
    assert 'did you mean "rate"?' in str(err.value)


def test_gravity_in_the_wrong_unit_is_a_warning_in_the_summary_and_the_h5(tmp_path, capsys):
    """9.81 in a millimetre scene: standard gravity in m/s^2, 1000x too weak in mm/s^2."""
    text = (CONFIGS / "basketball_goal.toml").read_text()
    assert 'length = "ft"' in text
    path = tmp_path / "goal_mm.toml"
    path.write_text(text.replace('length = "ft"', 'length = "mm"'))  # g stays 32.174 ft/s^2
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-rrd"]) == 0
    out = capsys.readouterr().out
    assert "warning:" in out and "standard gravity in ft/s^2" in out and '"mm"' in out
    with h5py.File(tmp_path / "out" / "basketball_goal.h5") as f:
        warnings = [w.decode() if isinstance(w, bytes) else w for w in f.attrs["warnings"]]
    # and slug*mm/s^2 is not lbf: the second warning, the units' own consistency
    assert len(warnings) == 2 and "9806.65" in warnings[0] and "slug*mm/s^2" in warnings[1]


@pytest.mark.parametrize("units, ratio, fix", [
    ({"length": "mm", "mass": "kg", "time": "s", "force": "N"}, 1e-3, 'force = "mN" or mass = "t"'),
    ({"length": "m", "mass": "kg", "time": "s", "force": "kN"}, 1e-3, 'force = "N" or mass = "t"'),
    # lb in/s^2 = 0.45359237 kg x 0.0254 m/s^2 = 0.0115212 N = 0.00259008 lbf; the snail
    # (lbf s^2/in) is the mass that makes inch, second and lbf one system
    ({"length": "in", "mass": "lb", "time": "s", "force": "lbf"},
     0.45359237 * 0.0254 / 4.4482216152605, 'mass = "lbf*s^2/in"'),
    ({"length": "mm", "mass": "t", "time": "s", "force": "N"}, None, ""),
    ({"length": "ft", "mass": "slug", "time": "s", "force": "lbf"}, None, ""),
    ({"length": "in", "mass": "lbf*s^2/in", "time": "s", "force": "lbf"}, None, ""),
    ({"length": "m", "mass": "kg", "time": "s", "force": "newton"}, None, ""),  # unknown: silent
])
def test_units_that_are_not_one_system_are_a_warning(units, ratio, fix):
    """force = mass x length / time^2 in the declared units, or a warning with the factor
    (kg mm/s^2 = 0.001 N: m a in mN, labelled N) and a unit that makes it one system."""
    from linkpipe.scene.units import consistency_warning

    note = consistency_warning(units)
    if ratio is None:
        assert note == ""
        return
    assert f"is {ratio:.6g} {units['force']}, not 1" in note, note
    assert (f"declare {fix} for one consistent system" in note) if fix else "declare" not in note


def test_a_scene_with_masses_in_inconsistent_units_warns_at_load():
    """The excavator in mm, kg, N with gravity in mm/s^2: the weights come out in mN."""
    text = (CONFIGS / "excavator_arm.toml").read_text()
    assert 'length = "m"' in text
    scene = parse_scene(text.replace('length = "m"', 'length = "mm"').replace(
        "-9.81", "-9806.65"), str(CONFIGS / "excavator_mm.toml"))
    assert len(scene.warnings) == 1 and "kg*mm/s^2 is 0.001 N" in scene.warnings[0]


def test_gravity_in_the_scenes_unit_gives_no_warning():
    for name in ("basketball_goal", "excavator_arm", "dump_truck", "hatch_gas_spring"):
        assert linkpipe.load_scene(str(CONFIGS / f"{name}.toml")).warnings == ()


@pytest.mark.parametrize("address, unit", [
    ("springs.left.k", "lbf/ft"), ("springs.left.free_length", "ft"),
    ("springs.right.damping", "lbf*s/ft"), ("points.S1.y", "ft"),
    ("links.backboard.lengths.B-C", "ft"), ("masses.backboard.mass", "slug"),
    ("masses.backboard.inertia", "slug*ft^2"), ("loads.hand.force.1", "lbf"),
    ("loads.twist.torque", "lbf*ft"), ("gravity.g.1", "ft/s^2"),
    ("drivers.theta3a.from", "degree"), ("drivers.theta3a.rate", "degree/s"),
    ("torsion_springs.hinge.k", "lbf*ft/rad"), ("torsion_springs.hinge.free_angle", "degree")])
def test_a_parameter_has_the_unit_of_the_number_it_addresses(address, unit):
    """What ``fit`` and ``study`` write as ``parameter_units``: the scene's units by key (the
    benchmark's basketball goal with every effect and a torsion spring: ft, lbf, slug, s)."""
    import sys
    import tomllib

    from linkpipe.fit import locate
    from linkpipe.output_units import parameter_unit

    sys.path.insert(0, str(CONFIGS.parent / "benchmarks"))
    from bench_study import goal_every_effect

    text = goal_every_effect() + ('\n[[torsion_springs]]\nname = "hinge"\nlinks = ["upper", "ground"]\n'
                                  "k = 2.5\nfree_angle = 30.0\n")
    scene = parse_scene(text, "goal.toml")
    path, _ = locate(scene, tomllib.loads(text), address)
    assert parameter_unit(scene, tuple(path)) == unit
