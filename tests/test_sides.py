"""A plate's further points by two side lengths (``lengths = {"A-P" = .., "B-P" = ..}``),
turned into local coordinates at load: the closed form of the triangle, the drawn side or
``side``, a tracer point on a pin, and every misuse a scene error naming the key."""
import math
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe.scene import parse_scene

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"

PLATE = """
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
A = {{ x = 1.0, y = 0.0 }}
B = {{ x = 3.0417, y = 2.8428 }}
P = {{ x = {px}, y = {py} }}
Q = {{ x = 4.0, y = 0.0, fixed = true }}
[[links]]
name = "crank"
points = ["O", "A"]
[[links]]
name = "coupler"
points = ["A", "B", "P"]
{extra}
[[links]]
name = "rocker"
points = ["Q", "B"]
[[drivers]]
name = "crank"
angle = ["O", "A"]
from = 0.0
to = 360.0
steps = 73
"""


def plate(px=1.0, py=2.0, extra='lengths = { "A-P" = 2.0, "B-P" = 2.5 }'):
    return PLATE.format(px=px, py=py, extra=extra)


@settings(max_examples=60, deadline=None)
@given(d1=st.floats(0.2, 5.0), d2=st.floats(0.2, 5.0), up=st.booleans())
def test_local_coordinates_are_the_triangles_closed_form(d1, d2, up):
    base = math.hypot(2.0417, 2.8428)  # |AB| as drawn
    if not (abs(d1 - d2) < base < d1 + d2) or min(d1 + d2 - base, base - abs(d1 - d2)) < 1e-6:
        return
    px, py = (1.0, 2.0) if up else (3.0, 0.0)  # drawn left or right of A -> B
    scene = parse_scene(plate(px=px, py=py, extra=f'lengths = {{ "A-P" = {d1!r}, "B-P" = {d2!r} }}'))
    u, v = scene.links[1].local["P"]
    along = (d1 ** 2 - d2 ** 2 + base ** 2) / (2 * base)
    assert u == pytest.approx(along, rel=1e-14, abs=1e-14)
    assert v == pytest.approx((1 if up else -1) * math.sqrt(d1 ** 2 - along ** 2), rel=1e-12, abs=1e-12)
    assert math.hypot(u, v) == pytest.approx(d1, rel=1e-13)
    assert math.hypot(u - base, v) == pytest.approx(d2, rel=1e-13)


def test_side_overrides_the_drawing():
    left = parse_scene(plate(px=3.0, py=0.0, extra='lengths = { "A-P" = 2.0, "B-P" = 2.5 }\nside = { P = "left" }'))
    right = parse_scene(plate(px=3.0, py=0.0))
    assert left.links[1].local["P"][1] > 0 > right.links[1].local["P"][1]
    assert left.links[1].local["P"][0] == right.links[1].local["P"][0]


def r_ok(r):
    return bool((r.status == 0).all())


def test_a_plate_by_sides_moves_as_the_same_plate_by_local():
    sides = parse_scene(plate(), "sides.toml")
    u, v = sides.links[1].local["P"]
    local = parse_scene(plate(extra=f"local = {{ P = [{u!r}, {v!r}] }}"), "local.toml")
    a, b = linkpipe.solve(sides), linkpipe.solve(local)
    np.testing.assert_array_equal(a.position, b.position)
    P = a.position[:, a.point_names.index("P")]
    A = a.position[:, a.point_names.index("A")]
    B = a.position[:, a.point_names.index("B")]
    # the distances hold at every step (positions to 1e-12 of the size)
    assert r_ok(a)
    assert np.abs(np.linalg.norm(P - A, axis=1) - 2.0).max() < 1e-11
    assert np.abs(np.linalg.norm(P - B, axis=1) - 2.5).max() < 1e-11


def test_the_shear_press_uses_the_seeds_own_side_lengths():
    text = (CONFIGS / "shear_press.toml").read_text()
    assert '"B-P" = 0.450' in text and '"A-P" = 0.650' in text and "local" not in text
    scene = linkpipe.load_scene(str(CONFIGS / "shear_press.toml"))
    u, v = scene.links[0].local["P"]
    assert math.hypot(u, v) == pytest.approx(0.650, rel=1e-14)
    assert math.hypot(u - 0.230, v) == pytest.approx(0.450, rel=1e-14)


def test_a_tracer_point_on_a_pin_of_its_own_link():
    """P drawn at B's place on the coupler (a tracer on the pin): allowed, and it follows B."""
    r = linkpipe.solve(parse_scene(plate(px=3.0417, py=2.8428, extra="")))
    np.testing.assert_array_equal(r.status, 0)
    P, B = (r.position[:, r.point_names.index(n)] for n in "PB")
    assert np.abs(P - B).max() < 1e-12


def test_a_point_measured_from_an_earlier_further_point():
    """Q placed from A and the further point P (itself by two distances)."""
    text = plate(extra='lengths = { "A-P" = 2.0, "B-P" = 2.5, "A-R" = 1.0, "P-R" = 1.2 }')
    text = text.replace('points = ["A", "B", "P"]', 'points = ["A", "B", "P", "R"]')
    text = text.replace("Q = {", "R = { x = 1.5, y = 1.5 }\nQ = {")
    scene = parse_scene(text)
    (pu, pv), (ru, rv) = scene.links[1].local["P"], scene.links[1].local["R"]
    assert math.hypot(ru, rv) == pytest.approx(1.0, rel=1e-14)
    assert math.hypot(ru - pu, rv - pv) == pytest.approx(1.2, rel=1e-14)


BAD = [
    ("cannot-close", 'lengths = { "A-P" = 0.5, "B-P" = 0.5 }', "lengths", "cannot close"),
    ("given-twice", 'lengths = { "A-P" = 2.0, "P-A" = 2.0, "B-P" = 2.5 }', "P-A", "given twice"),
    ("local-and-distances", 'lengths = { "A-P" = 2.0, "B-P" = 2.5 }\nlocal = { P = [1.0, 1.0] }',
     "local", "by local coordinates and by the distances"),
    ("not-on-the-link", 'lengths = { "A-P" = 2.0, "Q-P" = 2.5 }', "Q-P", "not two points of this link"),
    ("one-distance", 'lengths = { "A-P" = 2.0 }', "lengths", "only one distance"),
    ("side-not-by-distances", 'side = { P = "left" }', "side", "not a point given by two distances"),
    ("side-word", 'lengths = { "A-P" = 2.0, "B-P" = 2.5 }\nside = { P = "up" }', "side",
     'must be "left" or "right"'),
]


@pytest.mark.parametrize("name, extra, key, words", BAD, ids=[b[0] for b in BAD])
def test_misuse_is_a_scene_error_naming_the_key(name, extra, key, words):
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(plate(extra=extra), "plate.toml")
    msg = str(err.value)
    assert 'plate.toml: [links "coupler"' in msg and key in msg and words in msg, msg


def test_drawn_on_the_line_needs_a_side():
    on_line = plate(px=2.02085, py=1.4214)  # on the line A -> B as drawn
    with pytest.raises(linkpipe.SceneError) as err:
        parse_scene(on_line, "plate.toml")
    assert "drawn on the line" in str(err.value) and 'side = { P = "left" }' in str(err.value)
    ok = parse_scene(on_line.replace('"B-P" = 2.5 }', '"B-P" = 2.5 }\nside = { P = "right" }'))
    assert ok.links[1].local["P"][1] < 0
