"""Hard case 9: points drawn at another driver value than the sweep's first.

A scene's point coordinates are a drawing; the sweep may start anywhere. linkpipe carries the
drawn pose to the first driver value by continuation (in steps of at most 2 deg, or 0.5 % of
the size for a coordinate driver), so the sweep starts in the assembly the drawing shows. One
Newton jump from the drawing could land in the other: the basketball goal drawn at -60 deg and
started at +40 deg came out crossed (an anti-parallelogram, the board 1.9 ft off), and the
triple rocker drawn at its lower limit could not be assembled at +31 deg at all although it
assembles there (a SceneError for a valid scene).

Exact answers: the parallelogram's closed form; the four-bar and slider-crank closed forms on
the drawn branch. Tolerances as in test_properties.py (1e-7 of the size: the margins keep the
Jacobian's condition under ~1e4 against the residual tolerance 1e-12 of the size).
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st

import linkpipe
from linkpipe.closed_forms import fourbar, slider_crank
from linkpipe.status import NO_ASSEMBLY, OK, SINGULAR
from hard_scenes import (HARD_DIR, fourbar_text, method, point, slider_crank_text,  # noqa: F401
                         slider_driven_text, solve_text, with_driver, with_solver)
from test_properties import MARGIN, full_rotation

CONFIGS = HARD_DIR.parent
SETTINGS = dict(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def started_at(text, from_deg, to_deg, steps):
    """Return the scene text with the crank's sweep replaced (the drawing unchanged)."""
    scene = linkpipe.parse_scene(text, "drawn.toml")
    return with_driver(scene, from_value=float(from_deg), to_value=float(to_deg), steps=steps,
                       step=None)


@pytest.mark.parametrize("from_deg", [-60.0, -20.0, 10.0, 40.0, 60.0, 85.0])
def test_parallelogram_drawn_at_minus_60_started_anywhere(from_deg, method):
    """The basketball goal stays a parallelogram (backboard vertical, 1 ft tall) from any start
    between its change points at +-90 deg; it is drawn at -60 deg."""
    scene = linkpipe.load_scene(str(CONFIGS / "basketball_goal.toml"))
    scene = with_solver(with_driver(scene, from_value=from_deg, to_value=from_deg + 4.0, steps=5,
                                    step=None), method=method)
    r = linkpipe.solve(scene)
    assert (r.status == OK).all()
    t = np.deg2rad(r.driver_value[:, 0])
    arm = 2.0 * np.stack([np.cos(t), np.sin(t)], axis=1)
    np.testing.assert_allclose(point(r, "C"), [0.0, -2.0] + arm, rtol=0, atol=1e-10)
    np.testing.assert_allclose(point(r, "B"), [0.0, -1.0] + arm, rtol=0, atol=1e-10)


@pytest.mark.parametrize("method_used", ["auto", "newton", "dyads"])
@pytest.mark.parametrize("steps", [7, 3001], ids=["sequential", "vectorised"])
@pytest.mark.parametrize("from_deg, to_deg", [(90.0, 120.0), (90.0, 60.0), (-90.0, -120.0),
                                               (-90.0, -60.0)])
def test_parallelogram_started_on_a_change_point(from_deg, to_deg, steps, method_used):
    """Started exactly on a change point (all links in line; two branches cross there), either
    way: the sweep leaves it on the branch the drawing's path arrived on (the parallelogram),
    not on a side chosen by rounding (two of these four came out crossed before). 3001 steps
    run the vectorised general path, which re-runs the singular first interval sequentially;
    forced closed-form dyads take the ambiguous dyad's sign a step along that path."""
    method = method_used
    scene = linkpipe.load_scene(str(CONFIGS / "basketball_goal.toml"))
    scene = with_solver(with_driver(scene, from_value=from_deg, to_value=to_deg, steps=steps,
                                    step=None), method=method)
    r = linkpipe.solve(scene)
    assert r.status[0] == SINGULAR and (r.status[1:] == OK).all()
    t = np.deg2rad(r.driver_value[:, 0])
    arm = 2.0 * np.stack([np.cos(t), np.sin(t)], axis=1)
    # on the change point the position along the null direction is known to ~sqrt(eps) size
    np.testing.assert_allclose(point(r, "C"), [0.0, -2.0] + arm, rtol=0, atol=1e-7)
    np.testing.assert_allclose(point(r, "B")[1:], ([0.0, -1.0] + arm)[1:], rtol=0, atol=1e-10)


def test_triple_rocker_drawn_on_its_limit_assembles_inside_its_range():
    """Drawn on the lower assembly limit (-88.98 deg); +31 deg is inside the range (+-88.98)
    but 120 deg away: the sweep assembles there (it used to stop with a SceneError)."""
    scene = linkpipe.load_scene(str(HARD_DIR / "triple_rocker_limits.toml"))
    r = linkpipe.solve(with_driver(scene, from_value=31.0, to_value=61.0, steps=4, step=None))
    assert (r.status == OK).all()
    A, B, O4 = point(r, "A"), point(r, "B"), point(r, "O4")
    t = np.deg2rad(r.driver_value[:, 0])
    np.testing.assert_allclose(A, 2.0 * np.stack([np.cos(t), np.sin(t)], axis=1), atol=1e-12)
    np.testing.assert_allclose(np.hypot(*(B - A).T), 2.0, atol=1e-11)
    np.testing.assert_allclose(np.hypot(*(B - O4).T), 2.0, atol=1e-11)


def test_a_sweep_starting_outside_the_assembly_range_enters_it():
    """From 180 deg (outside the range +-88.98 deg; the carrying path leaves the range, so the
    direct solve decides): no exception, NaN and no_assembly until the sweep enters the range
    at 271.02 deg (= -88.98), ok from there on with exact bar lengths."""
    scene = linkpipe.load_scene(str(HARD_DIR / "triple_rocker_limits.toml"))
    r = linkpipe.solve(with_driver(scene, from_value=180.0, to_value=420.0, steps=25, step=None))
    inside = r.driver_value[:, 0] > 271.0232
    assert (r.status[~inside] == NO_ASSEMBLY).all() and np.isnan(point(r, "B")[~inside]).all()
    assert (r.status[inside] == OK).all()
    A, B, O4 = (point(r, p)[inside] for p in ("A", "B", "O4"))
    np.testing.assert_allclose(np.hypot(*(B - A).T), 2.0, atol=1e-11)
    np.testing.assert_allclose(np.hypot(*(B - O4).T), 2.0, atol=1e-11)


@settings(**SETTINGS)
@given(a=st.floats(0.05, 0.8), sf=st.floats(0, 1), df=st.floats(0, 1),
       branch=st.sampled_from([+1, -1]), drawn=st.floats(0.0, 360.0), start=st.floats(0.0, 360.0),
       scale=st.sampled_from([1e-3, 1.0, 1e3]), method=st.sampled_from(["auto", "newton"]))
def test_grashof_fourbar_keeps_the_drawn_branch(a, sf, df, branch, drawn, start, scale, method):
    """A crank-rocker never changes assembly mode over a turn: drawn at one angle on either
    branch and started at any other, every step is on the drawn branch."""
    d = 1.0
    b, c = full_rotation(a, d, sf, df)
    text = fourbar_text(a, b, c, d, drawn, drawn + 360.0, 37, branch=branch, scale=scale)
    scene = with_solver(started_at(text, start, start + 90.0, 7), method=method)
    r = linkpipe.solve(scene)
    assert (r.status == OK).all()
    cf = fourbar(a, b, c, d, np.deg2rad(r.driver_value[:, 0]), 10.0, 0.0, branch=branch)
    L = max(a, b, c, d) * scale
    for name in ("A", "B"):
        np.testing.assert_allclose(point(r, name), scale * cf[name], rtol=0, atol=1e-7 * L)


@settings(**SETTINGS)
@given(a=st.floats(0.05, 1.0), b=st.floats(1.2, 4.0), e=st.floats(-1.0, 1.0),
       branch=st.sampled_from([+1, -1]), drawn=st.floats(0.0, 360.0), start=st.floats(0.0, 360.0))
def test_slider_crank_keeps_the_drawn_branch(a, b, e, branch, drawn, start):
    """An offset slider-crank whose crank turns fully: the slider stays on the drawn side."""
    assume(a + abs(e) <= b * (1 - MARGIN))  # the crank turns fully, the sides never meet
    text = slider_crank_text(a, b, e, drawn, drawn + 360.0, 37, branch=branch)
    r = linkpipe.solve(started_at(text, start, start + 90.0, 7))
    assert (r.status == OK).all()
    cf = slider_crank(a, b, e, np.deg2rad(r.driver_value[:, 0]), 10.0, 0.0, branch=branch)
    np.testing.assert_allclose(point(r, "B"), cf["B"], rtol=0, atol=1e-7 * b)


def test_slider_driven_drawn_elsewhere_on_the_stroke():
    """A coordinate driver: drawn with the slider at x = 2.2 (crank 60 deg up), swept from
    x = 1.6: the crank stays on the upper side (y > 0) as drawn."""
    a, b, e = 1.0, 2.0, 0.0
    t0 = np.deg2rad(60.0)
    x_drawn = a * np.cos(t0) + np.sqrt(b**2 - (a * np.sin(t0) - e) ** 2)
    text = slider_driven_text(a, b, e, x_drawn, 2.9, 5, 60.0)
    scene = linkpipe.parse_scene(text, "slider.toml")
    r = linkpipe.solve(with_driver(scene, from_value=1.6, to_value=2.8, steps=5, step=None))
    assert (r.status == OK).all()
    x = r.driver_value[:, 0]
    # crank pin A on the circle |A| = a with |B - A| = b, B = (x, e), on the upper side:
    # a cos t = (a^2 + x^2 - b^2) / (2 x) for e = 0
    c = (a * a + x * x - b * b) / (2 * x * a)
    np.testing.assert_allclose(point(r, "A"), np.stack([a * c, a * np.sqrt(1 - c * c)], axis=1),
                               rtol=0, atol=1e-10)
