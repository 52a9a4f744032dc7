"""Tests of the scene loader (linkpipe.scene): a full valid scene, every error class, sweeps."""
from __future__ import annotations

import numpy as np
import pytest

import linkpipe
from linkpipe.errors import SceneError
from linkpipe.scene import (
    Driver, Input, Link, Load, Mass, Outputs, Point, Scene, Slider, Solver, Spring,
    load_scene, parse_scene,
)

FULL = """\
[scene]
name = "everything"
description = "Every key of the contract"
units = { length = "m", mass = "kg", time = "s", force = "N" }

[points]
O2 = { x = 0.0, y = 0.0, fixed = true }
A  = { x = 1.0, y = 0.0 }
B  = { x = 4.4, y = 2.9 }
O4 = { x = 4, y = 0, fixed = true }
P  = { x = 2.2, y = 1.6, fixed = false }
C  = { x = 0.27, y = 1.0 }
D  = { x = 5.0, y = 1.0 }
H  = { x = 0.5, y = 0.0 }

[[links]]
name = "crank"
points = ["O2", "A", "H"]

[[links]]
name = "coupler"
points = ["A", "B", "P"]
lengths = { "B-A" = 3.5 }
local = { P = [1.5, 0.8] }

[[links]]
name = "rocker"
points = ["O4", "B", "D"]

[[sliders]]
name = "blade_guide"
point = "C"
along = { through = [0.27, 0.0], direction = [0.0, 1.0] }

[[sliders]]
name = "on_rocker"
point = "P"
along = ["O4", "D"]

[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = -60
to = 60
step = 5
rate = 572.9578
acceleration = 1.5
input = { point = "H", direction = [0.0, 1.0] }

[[drivers]]
name = "lift"
coordinate = "C.y"
from = 1.0
to = 2.2
steps = 25

[solver]
tol = 1e-10
max_iter = 40

[analysis]
effects = ["springs", "gravity", "inertia", "damping", "loads"]

[gravity]
g = [0.0, -9.81]

[[springs]]
name = "left"
between = ["A", "O4"]
k = 4
free_length = 0.5833
damping = 0.25

[[springs]]
name = "right"
between = ["B", "O2"]
k = 0.0
preload = -10.0

[[masses]]
link = "coupler"
mass = 1.554
center = "P"
inertia = 0.0347

[[masses]]
link = "rocker"
mass = 2
center = [0.5, -0.1]

[[loads]]
name = "cutting_force"
point = "C"
force = [0.0, 500.0]

[[loads]]
name = "brake"
link = "rocker"
torque = -2.0

[outputs]
kinematics = ["velocity", "acceleration"]
trace = ["P"]
vectors = ["P", "B"]
"""

BASE = """\
[points]
O2 = { x = 0.0, y = 0.0, fixed = true }
A  = { x = 1.0, y = 0.0 }
B  = { x = 4.4, y = 2.9 }
O4 = { x = 4.0, y = 0.0, fixed = true }
P  = { x = 2.2, y = 1.6 }

[[links]]
name = "crank"
points = ["O2", "A"]

[[links]]
name = "coupler"
points = ["A", "B", "P"]

[[links]]
name = "rocker"
points = ["O4", "B"]

[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 0.0
to = 360.0
steps = 361
"""

# Tables that effects need, to append to BASE.
SPRING = '\n[[springs]]\nname = "s"\nbetween = ["A", "O4"]\nk = 4.0\nfree_length = 0.5\n'
MASS = '\n[[masses]]\nlink = "coupler"\nmass = 1.0\ncenter = "P"\n'
GRAVITY = "\n[gravity]\ng = [0.0, -9.81]\n"
LOAD = '\n[[loads]]\nname = "l"\npoint = "P"\nforce = [0.0, 1.0]\n'
SLIDER = '\n[[sliders]]\nname = "g"\npoint = "P"\nalong = {}\n'
CRANK_STEPS = 'from = 0.0\nto = 360.0\nsteps = 361\n'


def write(tmp_path, text, name="bad.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def variant(replace=(), add=""):
    """BASE with (old, new) replacements (each old must occur) and text appended."""
    text = BASE
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text + add


def effects(*names):
    return "\n[analysis]\neffects = [" + ", ".join(f'"{n}"' for n in names) + "]\n"


def test_full_scene_parses_to_expected_objects(tmp_path):
    path = write(tmp_path, FULL, "full.toml")
    scene = load_scene(path)
    expected = Scene(
        path=str(path),
        text=FULL,
        name="everything",
        description="Every key of the contract",
        units={"length": "m", "mass": "kg", "time": "s", "force": "N"},
        points=(
            Point("O2", 0.0, 0.0, True), Point("A", 1.0, 0.0), Point("B", 4.4, 2.9),
            Point("O4", 4.0, 0.0, True), Point("P", 2.2, 1.6, False), Point("C", 0.27, 1.0),
            Point("D", 5.0, 1.0), Point("H", 0.5, 0.0),
        ),
        links=(
            Link("crank", ("O2", "A", "H")),
            Link("coupler", ("A", "B", "P"), 3.5, {"P": (1.5, 0.8)}),
            Link("rocker", ("O4", "B", "D")),
        ),
        sliders=(
            Slider("blade_guide", "C", through=(0.27, 0.0), direction=(0.0, 1.0)),
            Slider("on_rocker", "P", line_points=("O4", "D")),
        ),
        drivers=(
            Driver("crank", "angle", ("O2", "A"), None, -60.0, 60.0, 25, 5.0,
                   rate=572.9578, acceleration=1.5, input=Input("H", (0.0, 1.0))),
            Driver("lift", "coordinate", ("C",), 1, 1.0, 2.2, 25, None),
        ),
        solver=Solver(1e-10, 40),
        effects=("springs", "gravity", "inertia", "damping", "loads"),
        gravity=(0.0, -9.81),
        springs=(
            Spring("left", ("A", "O4"), 4.0, free_length=0.5833, damping=0.25),
            Spring("right", ("B", "O2"), 0.0, preload=-10.0),
        ),
        masses=(Mass("coupler", 1.554, "P", 0.0347), Mass("rocker", 2.0, (0.5, -0.1))),
        loads=(
            Load("cutting_force", point="C", force=(0.0, 500.0)),
            Load("brake", link="rocker", torque=-2.0),
        ),
        outputs=Outputs(("velocity", "acceleration"), ("P",), ("P", "B")),
    )
    assert scene == expected
    # ints became floats, lists became tuples
    assert type(scene.points[3].x) is float and type(scene.masses[1].mass) is float
    assert isinstance(scene.links[0].points, tuple) and isinstance(scene.springs[0].between, tuple)
    assert scene.n_steps == 25 and scene.present_but_off == ()


def test_defaults_of_a_minimal_scene(tmp_path):
    scene = load_scene(write(tmp_path, BASE, "four_bar.toml"))
    assert scene.name == "four_bar"  # the file stem
    assert scene.description == "" and scene.units == {}
    assert scene.solver == Solver()
    assert scene.sliders == scene.springs == scene.masses == scene.loads == ()
    assert scene.effects == () and scene.gravity is None and scene.outputs == Outputs()
    driver = scene.drivers[0]
    assert (driver.steps, driver.step, driver.rate, driver.acceleration, driver.input) == \
        (361, None, 0.0, 0.0, None)
    assert scene.links[1] == Link("coupler", ("A", "B", "P"), None, {})


def test_tables_present_but_off(tmp_path):
    scene = load_scene(write(tmp_path, BASE + SPRING + MASS + GRAVITY, "off.toml"))
    assert scene.effects == ()
    assert scene.present_but_off == ("springs", "gravity", "inertia")


def test_parse_scene_from_text():
    scene = parse_scene(BASE)
    assert scene.path == "<string>" and scene.name == "scene" and scene.text == BASE
    with pytest.raises(SceneError, match="<string>"):
        parse_scene(BASE.replace('"A", "B", "P"', '"A", "B", "Q"'))


@pytest.mark.parametrize("start, stop, step, steps", [
    (-60, 60, 5, 25),
    (0, 1, 0.3, 4),            # 0, .3, .6, .9
    (60, -60, -5, 25),
    (1.0, 0.0, -0.3, 4),
    (0, 1, 0.1, 11),           # 10 * 0.1 lands on 1 within 1e-9 * |s|
    (0, 360, 1, 361),
    (0.5, 0.3, -0.025, 9),     # the shear press: 0.5 -> 0.3 in 9 steps
    (0, 1, 0.9, 2),            # 0, 0.9: the last value stops short of to
])
def test_step_resolution(tmp_path, start, stop, step, steps):
    text = BASE.replace(CRANK_STEPS, f"from = {start}\nto = {stop}\nstep = {step}\n")
    driver = load_scene(write(tmp_path, text, "sweep.toml")).drivers[0]
    assert (driver.steps, driver.step) == (steps, float(step))
    assert (driver.from_value, driver.to_value) == (float(start), float(stop))


def test_single_position(tmp_path):
    text = BASE.replace(CRANK_STEPS, "from = 30.0\nto = 30.0\nsteps = 1\n")
    assert load_scene(write(tmp_path, text, "still.toml")).drivers[0].steps == 1


ERRORS = [
    # (id, scene text, table, key, fragments of the message)
    ("toml-syntax", BASE + "\nbroken = \n", "", None, ["not valid TOML", "line"]),
    ("unknown-table", BASE + "\n[solvr]\ntol = 1e-9\n", "solvr", None,
     ["unknown table", 'did you mean "solver"?']),
    ("array-written-as-table", BASE.split("[[links]]")[0] + '[links]\nname = "c"\n'
     'points = ["O2", "A"]\n[[drivers]]' + BASE.split("[[drivers]]")[1], "links", None,
     ["expected an array of tables [[links]], got a table", "double brackets"]),
    ("table-written-as-array", BASE + "\n[[solver]]\ntol = 1e-9\n", "solver", None,
     ["expected a table [solver], got an array"]),
    ("unknown-key-nameless-entry", variant([('name = "rocker"', 'nmae = "rocker"')]),
     "links[3]", "nmae", ['did you mean "name"?']),
    ("unknown-key-point", variant([("A  = { x = 1.0, y = 0.0 }",
                                    "A  = { x = 1.0, y = 0.0, fixd = true }")]),
     "points.A", "fixd", ["unknown key", 'did you mean "fixed"?']),
    ("unknown-key-link", variant([('points = ["O2", "A"]',
                                   'points = ["O2", "A"]\nlenghts = { "O2-A" = 1.0 }')]),
     'links "crank"', "lenghts", ["unknown key", 'did you mean "lengths"?']),
    ("unknown-key-driver", variant([("steps = 361", "steps = 361\nrte = 1.0")]),
     'drivers "crank"', "rte", ["unknown key", 'did you mean "rate"?']),
    ("unknown-key-input", variant([("steps = 361", 'steps = 361\ninput = { point = "A", '
                                    'directon = [0.0, 1.0] }')]),
     'drivers "crank".input', "directon", ["unknown key", 'did you mean "direction"?']),
    ("unknown-key-scene", "[scene]\nnmae = \"x\"\n" + BASE, "scene", "nmae",
     ['did you mean "name"?']),
    ("string-for-number", variant([("to = 360.0", 'to = "360"')]), 'drivers "crank"', "to",
     ["expected a number, got a string", "to = 360.0"]),
    ("bool-for-number", variant([("from = 0.0", "from = true")]), 'drivers "crank"', "from",
     ["expected a number, got a boolean"]),
    ("float-for-integer", variant([("steps = 361", "steps = 361.0")]), 'drivers "crank"',
     "steps", ["expected an integer, got a float (361.0)"]),
    ("number-for-bool", variant([("fixed = true }", "fixed = 1 }")]), "points.O2", "fixed",
     ["expected true or false"]),
    ("point-not-a-table", variant([("P  = { x = 2.2, y = 1.6 }", "P  = [2.2, 1.6]")]),
     "points", "P", ["expected a table"]),
    ("missing-x", variant([("P  = { x = 2.2, y = 1.6 }", "P  = { y = 1.6 }")]), "points.P",
     "x", ["missing", "add x ="]),
    ("missing-name", variant([('name = "rocker"\n', "")]), "links[3]", "name",
     ["missing", "add name ="]),
    ("empty-name", variant([('name = "rocker"', 'name = ""')]), "links[3]", "name",
     ["is empty"]),
    ("input-on-a-fixed-point", variant([("steps = 361", 'steps = 361\ninput = { point = "O2", '
                                         'direction = [0.0, 1.0] }')]),
     'drivers "crank".input', "point", ['point "O2" is fixed', "no_leverage"]),
    ("fixed-link-length-contradicts", BASE.replace('name = "crank"', 'name = "ground"\npoints = ["O2", "O4"]\n'
                                                    'lengths = { "O2-O4" = 4.5 }\n\n[[links]]\nname = "crank"', 1),
     'links "ground".lengths', "O2-O4", ['"O2" and "O4" are both fixed, 4 apart', "the length says 4.5"]),
    ("unknown-unit-key", '[scene]\nunits = { lenght = "ft" }\n' + BASE, "scene.units", "lenght",
     ["unknown unit key", 'did you mean "length"?', "length, mass, time, force"]),
    ("units-not-strings", '[scene]\nunits = { length = 1 }\n' + BASE, "scene.units", "length",
     ["expected a string"]),
    ("unit-with-a-comma", '[scene]\nunits = { force = "kgf, cm" }\n' + BASE, "scene.units",
     "force", ["holds a comma", "driver_units", 'force = "kgf cm"']),
    ("no-points", BASE.split("[[links]]", 1)[0].replace("O2 =", "#").replace("A  =", "#")
     .replace("B  =", "#").replace("O4 =", "#").replace("P  =", "#") + "[[links]]"
     + BASE.split("[[links]]", 1)[1], "points", None, ["no points"]),
    ("no-links", BASE.split("[[links]]", 1)[0], "links", None, ["no links", "[[links]]"]),
    ("no-drivers", BASE.split("[[drivers]]", 1)[0], "drivers", None,
     ["no drivers", "[[drivers]]"]),
    # unknown names
    ("unknown-point-link", variant([('["O4", "B"]', '["O4", "Bx"]')]), 'links "rocker"',
     "points", ['unknown point "Bx"', 'did you mean "B"?']),
    ("unknown-point-slider", BASE + SLIDER.replace('point = "P"', 'point = "PP"'),
     'sliders "g"', "point", ['unknown point "PP"', 'did you mean "P"?']),
    ("unknown-point-slider-line", BASE + SLIDER.replace("{}", '["O4", "Bb"]'),
     'sliders "g"', "along", ['unknown point "Bb"', 'did you mean "B"?']),
    ("unknown-point-angle", variant([('angle = ["O2", "A"]', 'angle = ["02", "A"]')]),
     'drivers "crank"', "angle", ['unknown point "02"', 'did you mean "O2"?']),
    ("unknown-point-coordinate", variant([('angle = ["O2", "A"]', 'coordinate = "Pp.y"')]),
     'drivers "crank"', "coordinate", ['unknown point "Pp"', 'did you mean "P"?']),
    ("unknown-point-input", variant([("steps = 361", 'steps = 361\ninput = { point = "Hh", '
                                      'direction = [0.0, 1.0] }')]),
     'drivers "crank".input', "point", ['unknown point "Hh"']),
    ("unknown-point-spring", BASE + SPRING.replace('"O4"]', '"O5"]'), 'springs "s"', "between",
     ['unknown point "O5"', 'did you mean "O4"?']),
    ("unknown-point-mass-center", BASE + MASS.replace('"P"', '"Q"'), 'masses "coupler"', "center",
     ['unknown point "Q"']),
    ("mass-center-not-on-link", BASE + MASS.replace('"P"', '"O2"'), 'masses "coupler"', "center",
     ['"O2" is not a point of links "coupler"', '"A", "B", "P"']),
    ("unknown-point-load", BASE + LOAD.replace('"P"', '"Pt"'), 'loads "l"', "point",
     ['unknown point "Pt"', 'did you mean "P"?']),
    ("unknown-point-trace", BASE + '\n[outputs]\ntrace = ["p"]\n', "outputs", "trace",
     ['unknown point "p"', 'did you mean "P"?']),
    ("unknown-point-vectors", BASE + '\n[outputs]\nvectors = ["B", "C"]\n', "outputs",
     "vectors", ['unknown point "C"']),
    ("unknown-link-mass", BASE + MASS.replace('"coupler"', '"couplr"'), 'masses "couplr"', "link",
     ['unknown link "couplr"', 'did you mean "coupler"?']),
    ("unknown-link-load", BASE + '\n[[loads]]\nname = "b"\nlink = "rockr"\ntorque = 1.0\n',
     'loads "b"', "link", ['unknown link "rockr"', 'did you mean "rocker"?']),
    # links
    ("link-one-point", variant([('["O4", "B"]', '["O4"]')]), 'links "rocker"', "points",
     ["at least two points, got 1"]),
    ("link-point-twice", variant([('["A", "B", "P"]', '["A", "B", "A"]')]), 'links "coupler"',
     "points", ['"A" appears twice']),
    ("link-frame-points-same-place", variant([("B  = { x = 4.4, y = 2.9 }",
                                               "B  = { x = 1.0, y = 0.0 }")]),
     'links "coupler"', "points", ['"A" and "B" are at the same place (1, 0)',
                                   "span its frame"]),
    ("lengths-one-distance", variant([('["A", "B", "P"]',
                                       '["A", "B", "P"]\nlengths = { "A-P" = 2.0 }')]),
     'links "coupler"', "lengths", ['"P" has only one distance (A-P)', "needs two distances"]),
    ("lengths-not-positive", variant([('["A", "B", "P"]',
                                       '["A", "B", "P"]\nlengths = { "A-B" = 0 }')]),
     'links "coupler".lengths', "A-B", ["must be positive"]),
    ("local-of-frame-point", variant([('["A", "B", "P"]',
                                       '["A", "B", "P"]\nlocal = { B = [1.0, 0.0] }')]),
     'links "coupler".local', "B", ["first two points"]),
    ("local-not-on-link", variant([('["A", "B", "P"]',
                                    '["A", "B", "P"]\nlocal = { O2 = [1.0, 0.0] }')]),
     'links "coupler".local', "O2", ['not a point of links "coupler"', 'add "O2"']),
    ("local-not-a-pair", variant([('["A", "B", "P"]', '["A", "B", "P"]\nlocal = { P = [1.0] }')]),
     'links "coupler".local', "P", ["expected two numbers"]),
    # sliders
    ("slider-zero-direction", BASE + SLIDER.replace(
        "{}", "{ through = [0.0, 0.0], direction = [0.0, 0] }"), 'sliders "g".along',
     "direction", ["is zero"]),
    ("slider-missing-through", BASE + SLIDER.replace("{}", "{ direction = [0.0, 1.0] }"),
     'sliders "g".along', "through", ["missing", "add through ="]),
    ("slider-line-not-one-link", BASE + SLIDER.replace("{}", '["O2", "O4"]'), 'sliders "g"',
     "along", ['"O2" and "O4" are not on one common link ("O2" is on links "crank", "O4" on '
               'links "rocker")', "same link"]),
    ("slider-line-has-point", BASE + SLIDER.replace("{}", '["A", "P"]'), 'sliders "g"',
     "along", ['slider point "P" cannot be one of the points']),
    # drivers and sweeps
    ("steps-zero", variant([("steps = 361", "steps = 0")]), 'drivers "crank"', "steps",
     ["gives no steps", "steps >= 1"]),
    ("steps-one-with-span", variant([("steps = 361", "steps = 1")]), 'drivers "crank"',
     "steps", ["never reaches to", "steps >= 2"]),
    ("step-zero", variant([("steps = 361", "step = 0")]), 'drivers "crank"', "step",
     ["step = 0", "gives no steps", "sign of to - from"]),
    ("step-wrong-sign", variant([("steps = 361", "step = -1.0")]), 'drivers "crank"', "step",
     ["gives no steps", "step = 1"]),
    ("steps-and-step", variant([("steps = 361", "steps = 361\nstep = 1.0")]),
     'drivers "crank"', "step", ["give steps or step, not both"]),
    ("neither-steps-nor-step", variant([("steps = 361\n", "")]), 'drivers "crank"', "steps",
     ["missing: give steps or step"]),
    ("angle-and-coordinate", variant([("steps = 361", 'steps = 361\ncoordinate = "P.x"')]),
     'drivers "crank"', "coordinate", ["give one of angle, coordinate or distance, not both angle and coordinate"]),
    ("neither-angle-nor-coordinate", variant([('angle = ["O2", "A"]\n', "")]),
     'drivers "crank"', "angle", ["missing: give angle, coordinate or distance"]),
    ("bad-coordinate", variant([('angle = ["O2", "A"]', 'coordinate = "P.z"')]),
     'drivers "crank"', "coordinate", ['"P.z" is not a point coordinate', '"<point>.y"']),
    ("fixed-angle", variant([('angle = ["O2", "A"]', 'angle = ["O2", "O4"]')]),
     'drivers "crank"', "angle", ['"O2" and "O4" are both fixed']),
    ("fixed-coordinate", variant([('angle = ["O2", "A"]', 'coordinate = "O4.x"')]),
     'drivers "crank"', "coordinate", ['"O4" is fixed']),
    ("zero-input-direction", variant([("steps = 361", 'steps = 361\ninput = { point = "A", '
                                       "direction = [0, 0.0] }")]),
     'drivers "crank".input', "direction", ["is zero"]),
    ("driver-step-counts-differ", BASE + '\n[[drivers]]\nname = "lift"\ncoordinate = "B.x"\n'
     "from = 4.4\nto = 4.0\nsteps = 10\n", 'drivers "lift"', "steps",
     ["gives 10 steps", 'drivers "crank" gives 361', "make their step counts equal"]),
    # unique names
    ("duplicate-link", variant([('name = "rocker"', 'name = "crank"')]), "links[3]", "name",
     ['"crank" is used twice (links[1] and links[3])']),
    ("duplicate-slider", BASE + SLIDER.replace("{}", '["A", "B"]') * 2, "sliders[2]", "name",
     ["used twice (sliders[1] and sliders[2])"]),
    ("duplicate-driver", BASE + "\n[[drivers]]" + BASE.split("[[drivers]]")[1],
     "drivers[2]", "name", ['"crank" is used twice']),
    ("duplicate-spring", BASE + SPRING * 2, "springs[2]", "name", ["used twice"]),
    ("duplicate-load", BASE + LOAD * 2, "loads[2]", "name", ["used twice"]),
    # forces
    ("zero-mass", BASE + MASS.replace("mass = 1.0", "mass = 0"), 'masses "coupler"', "mass",
     ["must be positive"]),
    ("negative-mass", BASE + MASS.replace("mass = 1.0", "mass = -2.0"), 'masses "coupler"', "mass",
     ["must be positive, got -2"]),
    ("negative-inertia", BASE + MASS + "inertia = -1.0\n", 'masses "coupler"', "inertia",
     ["must be >= 0"]),
    ("negative-stiffness", BASE + SPRING.replace("k = 4.0", "k = -4.0"), 'springs "s"', "k",
     ["negative stiffness", "k >= 0"]),
    ("negative-damping", BASE + SPRING + "damping = -0.1\n", 'springs "s"', "damping",
     ["must be >= 0"]),
    ("negative-free-length", BASE + SPRING.replace("free_length = 0.5", "free_length = -0.5"),
     'springs "s"', "free_length", ["must be >= 0"]),
    ("free-length-and-preload", BASE + SPRING + "preload = 1.0\n", 'springs "s"', "preload",
     ["give free_length or preload, not both"]),
    ("spring-same-point", BASE + SPRING.replace('"O4"]', '"A"]'), 'springs "s"', "between",
     ['"A" appears twice']),
    ("load-force-and-torque", BASE + LOAD + "torque = 1.0\n", 'loads "l"', "torque",
     ["not both", "two [[loads]]"]),
    ("load-missing-force", BASE + LOAD.replace("force = [0.0, 1.0]\n", ""), 'loads "l"',
     "force", ["missing", "add force ="]),
    # effects
    ("unknown-effect", BASE + effects("sprngs"), "analysis", "effects",
     ['unknown effect "sprngs"', 'did you mean "springs"?']),
    ("duplicate-effect", BASE + SPRING + effects("springs", "springs"), "analysis", "effects",
     ['"springs" appears twice']),
    ("springs-without-table", BASE + effects("springs"), "analysis", "effects",
     ['"springs" is on but the scene has no [[springs]]', "add [[springs]]"]),
    ("gravity-without-table", BASE + MASS + effects("gravity"), "analysis", "effects",
     ['"gravity" is on but the scene has no [gravity]']),
    ("gravity-without-masses", BASE + GRAVITY + effects("gravity"), "analysis", "effects",
     ['"gravity" is on but the scene has no [[masses]]']),
    ("inertia-without-masses", BASE + effects("inertia"), "analysis", "effects",
     ['"inertia" is on but the scene has no [[masses]]']),
    ("loads-without-table", BASE + effects("loads"), "analysis", "effects",
     ['"loads" is on but the scene has no [[loads]]']),
    ("damping-without-springs", BASE + effects("damping"), "analysis", "effects",
     ['"damping" is on but the scene has no [[springs]]']),
    # solver and outputs
    ("tol-not-positive", BASE + "\n[solver]\ntol = 0.0\n", "solver", "tol",
     ["must be positive"]),
    ("max-iter-zero", BASE + "\n[solver]\nmax_iter = 0\n", "solver", "max_iter",
     ["at least 1"]),
    ("unknown-kinematic-order", BASE + '\n[outputs]\nkinematics = ["velocty"]\n', "outputs",
     "kinematics", ['did you mean "velocity"?']),
    ("gravity-not-a-pair", BASE + "\n[gravity]\ng = -9.81\n", "gravity", "g",
     ["expected two numbers", "g = [0.0, -9.81]"]),
]


@pytest.mark.parametrize("text, table, key, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in ERRORS])
def test_scene_errors(tmp_path, text, table, key, fragments):
    path = write(tmp_path, text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    err = info.value
    message = str(err)
    assert (err.table, err.key) == (table, key), message
    assert message.startswith(f"{path}: "), message
    assert "bad.toml" in message
    if table:
        assert f"[{table}]" in message
    if key is not None:
        assert f" {key}: " in message
    assert err.hint, message
    for fragment in fragments:
        assert fragment in message


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(SceneError, match="nowhere.toml: .*no such scene file"):
        load_scene(path)


def test_directory_and_binary(tmp_path):
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(tmp_path)
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\xff\xfe[points]")
    with pytest.raises(SceneError, match="not UTF-8"):
        load_scene(path)


@pytest.mark.parametrize("replace, steps, values, warning", [
    # from, from + i (to - from) / (steps - 1): 361 identical steps, legal, with a warning
    (("to = 360.0", "to = 0.0"), 361, [0.0] * 361, "every driver is held (from = to)"),
    # from, from + s, ... up to and including to when it lands on it: from alone
    (("to = 360.0\nsteps = 361", "to = 0.0\nstep = 1.0"), 1, [0.0], None),
    (("steps = 361", "step = 400"), 1, [0.0], "step = 400 oversteps to = 360 from from = 0"),
])
def test_sweeps_the_contract_defines_though_they_do_not_move(replace, steps, values, warning):
    """SCENE_FORMAT.md's sweep formulas give these steps (its only error is a sweep with no
    steps); what is probably not meant is a warning naming the driver and the fix."""
    scene = parse_scene(variant([replace]), "held.toml")
    assert scene.n_steps == steps
    np.testing.assert_array_equal(linkpipe.solve(scene).driver_value[:, 0], values)
    said = [w for w in scene.warnings if warning and warning in w]
    assert len(said) == (1 if warning else 0), scene.warnings
