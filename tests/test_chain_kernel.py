"""The closed-form dyads' compiled loop (linkpipe.kinematics.chain_kernel) gives numpy's numbers
(linkpipe.kinematics.dyads.solve_chain) to the bit: positions, velocities, accelerations, the
assembled flags, the residual, the dyads' root gaps and branch margins, the links' directions
and rates, and the margins carried from one segment to the next. Exact equality is the test
(``assert_array_equal``: NaN in the same places; a zero's sign is not compared, as numpy skips
terms that are exactly zero where the loop adds them): both run the same IEEE operations in
the same order, with numpy's own cos, sin and arctan2.

On every shipped scene and hard case that decomposes (angle, linear, circles with fixed and
driven radii, circle and line with fixed, moving and coordinate lines), on families of
four-bars, slider-cranks, slider-driven dead centres and six-bars drawn at random (steps out of
their assembly range included), in chunks of 8,192 steps and of 7, in one call and in three
segments; and through ``linkpipe.solve``: every array a Result stores.
"""
import dataclasses as dc
import os
import pathlib
import sys
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st_h

import linkpipe
from linkpipe import kinematics as kin
from linkpipe.errors import SceneError
from linkpipe.kinematics import chain_kernel, compiled
from linkpipe.kinematics.decompose import decompose
from linkpipe.kinematics.dyads import solve_chain
from linkpipe.kinematics.plan import start_branches
from linkpipe.kinematics.vectorised import max_abs_phi
from linkpipe.model import build_model
from linkpipe.status import OK

from conftest import CONFIG_DIR, CONFIGS

_HARD = pathlib.Path(__file__).resolve().parent / "hard"
if str(_HARD) not in sys.path:
    sys.path.insert(0, str(_HARD))

import hard_scenes as hs  # noqa: E402

FIELDS = ("position", "velocity", "acceleration", "ok", "residual", "gap", "link_angle", "miss")


def _chain_of(scene):
    """The scene's dyad chain with its branches set, and its sweep in internal units."""
    model = build_model(scene)
    chain = decompose(model)
    if not chain.ok:
        return None
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    if not np.isfinite(s).all():
        return None
    try:
        start_branches(model, chain, s[:2])
    except Exception:  # noqa: BLE001 - a drawing that does not assemble: not this test's case
        return None
    return chain, s, s_dot, s_ddot


def _solved(chain, s, s_dot, s_ddot, use_compiled, chunk, segments=1):
    """solve_chain in ``segments`` calls that share one carry; the parts joined."""
    model = chain.model
    carry, parts = {}, []
    for rows in np.array_split(np.arange(len(s)), segments):
        parts.append(solve_chain(chain, s[rows], s_dot[rows], s_ddot[rows], order=2, gaps=True,
                                 max_abs_phi=max_abs_phi(model), carry=carry, links=True,
                                 compiled=use_compiled, chunk=chunk))
    joined = {f: np.concatenate([getattr(p, f) for p in parts]) for f in FIELDS}
    joined["w"] = np.concatenate([p.link_rates[0] for p in parts])
    joined["al"] = np.concatenate([p.link_rates[1] for p in parts])
    for j in parts[0].trig:  # the angle drivers' cos and sin, handed to the condition
        joined[f"cos{j}"] = np.concatenate([p.trig[j][0] for p in parts])
        joined[f"sin{j}"] = np.concatenate([p.trig[j][1] for p in parts])
    return joined, carry


def _assert_same(chain, s, s_dot, s_ddot, chunk=8192, segments=1):
    with np.errstate(invalid="ignore", divide="ignore"):
        a, carry_a = _solved(chain, s, s_dot, s_ddot, False, chunk, segments)
        b, carry_b = _solved(chain, s, s_dot, s_ddot, True, chunk, segments)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(b[name], a[name], err_msg=name)
    assert carry_b.keys() == carry_a.keys()
    for p in carry_a:
        np.testing.assert_array_equal(np.array(carry_b[p]), np.array(carry_a[p]))
    return a


SCENES = CONFIGS + sorted((CONFIG_DIR / "hard").glob("*.toml"))


@pytest.mark.parametrize("config", SCENES, ids=lambda p: p.stem)
@pytest.mark.parametrize("chunk, segments", [(8192, 1), (7, 1), (7, 3), (64, 3)])
def test_every_scene_that_decomposes_gives_numpys_numbers(config, chunk, segments):
    got = _chain_of(linkpipe.load_scene(config))
    if got is None:
        pytest.skip("no dyad chain (does not decompose, or no driver values of its own)")
    a = _assert_same(*got, chunk=chunk, segments=segments)
    assert np.isfinite(a["position"][a["ok"]]).all()


def test_the_scenes_cover_every_dyad_and_line_kind():
    """The scenes above hold every kind the loop encodes (else the equality proves less)."""
    kinds, lines, driven = set(), set(), False
    for config in SCENES:
        got = _chain_of(linkpipe.load_scene(config))
        if got is None:
            continue
        for st in got[0].steps:
            kinds.add(st.kind)
            lines |= {ln.kind for ln in (st.line1, st.line2) if ln is not None}
            driven |= st.r1_driver >= 0 or st.r2_driver >= 0
    assert kinds >= {"angle", "linear", "circles", "circle_line"}
    assert lines >= {"fixed", "coord"} and driven


@settings(max_examples=60, deadline=None)
@given(family=st_h.sampled_from(["fourbar", "slider_crank", "slider_driven", "six_bar", "lines"]),
       a=st_h.floats(0.5, 2.5), b=st_h.floats(2.5, 4.0), c=st_h.floats(2.0, 3.5),
       start=st_h.floats(0.0, 360.0), span=st_h.floats(20.0, 400.0),
       branch=st_h.sampled_from([1, -1]), scale=st_h.sampled_from([1e-3, 1.0, 1e3]),
       chunk=st_h.sampled_from([5, 64, 8192]))
def test_families_drawn_at_random_give_numpys_numbers(family, a, b, c, start, span, branch, scale,
                                                      chunk):
    """Four-bars (Grashof or not: some leave their assembly range, NaN steps), offset
    slider-cranks, slider-driven cranks past their dead centres (a coordinate line), six-bars
    and a point on two moving lines, at three scales."""
    if family == "fourbar":
        text = hs.fourbar_text(a, b, c, 4.0, start, start + span, 41, branch=branch, scale=scale,
                               coupler_uv=(1.2, 0.7))
    elif family == "slider_crank":
        text = hs.slider_crank_text(a, b, 0.3 * a, start, start + span, 41, branch=branch,
                                    scale=scale)
    elif family == "slider_driven":  # from its start at 30 deg to past its inner dead centre
        x0 = a * np.cos(np.radians(30.0)) + np.sqrt(b * b - (0.2 * a - a * np.sin(np.radians(30.0))) ** 2)
        text = hs.slider_driven_text(a, b, 0.2 * a, x0, -1.2 * (a + b), 41, 30.0)
    elif family == "six_bar":
        text = hs.six_bar_text(1.0, 3.5, 3.0, 4.0, (1.2, 0.9), (5.5, 3.0), (4.6, 4.2),
                               start, start + span / 10, 21, branch=branch)
    else:
        text = _two_lines_text(a, b, start, span)
    try:
        scene = linkpipe.parse_scene(text, f"{family}.toml")
    except SceneError:
        return  # a drawing the scene checks refuse: nothing to compare
    got = _chain_of(scene)
    if got is None:
        return
    _assert_same(*got, chunk=chunk, segments=2)


def _crank_text(name, a, start, span, steps, arm, point_p, tables):
    """A crank (O, A, B: B ``arm`` = (along, across) of OA's length from A, in its frame) and
    a point P that slides on the line through A and B, with ``tables`` of its own."""
    import math

    th = math.radians(start)
    ax, ay = a * math.cos(th), a * math.sin(th)
    bx = ax + arm[0] * a * math.cos(th) - arm[1] * a * math.sin(th)
    by = ay + arm[0] * a * math.sin(th) + arm[1] * a * math.cos(th)
    px, py = point_p(ax, ay, bx, by)
    return f"""
[scene]
name = "{name}"
[points]
O = {{ x = 0.0, y = 0.0, fixed = true }}
Q = {{ x = 3.0, y = 0.5, fixed = true }}
A = {{ x = {ax!r}, y = {ay!r} }}
B = {{ x = {bx!r}, y = {by!r} }}
P = {{ x = {px!r}, y = {py!r} }}
[[links]]
name = "crank"
points = ["O", "A", "B"]
[[sliders]]
name = "on_crank"
point = "P"
along = ["A", "B"]
{tables}
[[drivers]]
name = "crank"
angle = ["O", "A"]
from = {start!r}
to = {start + span!r}
steps = {steps}
rate = 57.3
"""


def _two_lines_text(a, b, start, span):
    """A point P on two lines: the line through the crank's A and B, and a fixed guide y = b:
    the ``lines`` dyad, with a moving and a fixed line."""
    def on_guide(ax, ay, bx, by):
        t = (b - ay) / (by - ay) if by != ay else 1.0
        return ax + t * (bx - ax), b

    return _crank_text("two_lines", a, start, span, 41, (0.0, 0.3), on_guide, f"""[[sliders]]
name = "guide"
point = "P"
along = {{{{ through = [0.0, {b!r}], direction = [1.0, 0.0] }}}}""".replace("{{", "{").replace("}}", "}"))


def test_solve_takes_the_compiled_loop_on_a_long_sweep_and_every_stored_array_is_the_same(
        monkeypatch):
    """``linkpipe.solve`` of the crank-rocker: LINKPIPE_COMPILED=1 (the loop at any length)
    and =0 (numpy) store the same numbers in every variable; the loop is taken where asked
    (counted), and not for a sweep shorter than WARM_FROM when the environment is silent."""
    scene = linkpipe.load_scene(CONFIG_DIR / "fourbar_crank_rocker.toml")
    calls = []
    real = chain_kernel.solve
    monkeypatch.setattr(chain_kernel, "solve", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setenv("LINKPIPE_COMPILED", "0")
    numpy_result = linkpipe.solve(scene)
    assert not calls
    monkeypatch.setenv("LINKPIPE_COMPILED", "1")
    compiled_result = linkpipe.solve(scene)
    assert calls
    names = [v.name for v in numpy_result.variables()]
    assert names == [v.name for v in compiled_result.variables()]
    for a, b in zip(numpy_result.variables(), compiled_result.variables()):
        np.testing.assert_array_equal(b.data, a.data, err_msg=a.name)
    monkeypatch.delenv("LINKPIPE_COMPILED")
    calls.clear()
    assert len(numpy_result.status) < compiled.WARM_FROM
    linkpipe.solve(scene)
    assert not calls


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_every_shipped_scene_stores_the_same_numbers_with_the_compiled_loops(config, monkeypatch):
    """``linkpipe.solve`` of every shipped scene (dyads, Newton, forces, friction, dynamics,
    logs) with LINKPIPE_COMPILED=1 and =0: every variable the Result stores, equal to the bit
    (where a scene's path takes no compiled loop, trivially so)."""
    scene = linkpipe.load_scene(config)
    monkeypatch.setenv("LINKPIPE_COMPILED", "0")
    a = linkpipe.solve(scene)
    monkeypatch.setenv("LINKPIPE_COMPILED", "1")
    b = linkpipe.solve(scene)
    assert [v.name for v in a.variables()] == [v.name for v in b.variables()]
    for x, y in zip(a.variables(), b.variables()):
        np.testing.assert_array_equal(y.data, x.data, err_msg=x.name)


def _inverted_slider_text(a, start):
    """A rocker (Q, P) whose end P slides on the line through the crank's A and B: the circle
    and line dyad on a moving line (an inverted slider-crank), a full turn."""
    def on_line(ax, ay, bx, by):
        return ax + 2.0 * (bx - ax), ay + 2.0 * (by - ay)

    return _crank_text("inverted_slider", a, start, 360.0, 2001, (0.5, 0.3), on_line,
                       '[[links]]\nname = "rocker"\npoints = ["Q", "P"]')


@pytest.mark.parametrize("a, start", [(0.5, 0.0), (1.0, 45.0), (1.7, 200.0)])
def test_a_moving_line_and_two_lines_give_numpys_numbers(a, start):
    """The kinds no shipped scene holds: a circle and a moving line (an inverted
    slider-crank, a full turn), and a point on two lines, one of them moving."""
    kinds = set()
    for text in (_inverted_slider_text(a, start), _two_lines_text(a, 3.0, start, 90.0)):
        got = _chain_of(linkpipe.parse_scene(text, "kinds.toml"))
        kinds |= {(st.kind, ln.kind) for st in got[0].steps for ln in (st.line1, st.line2)
                  if ln is not None}
        _assert_same(*got, chunk=7, segments=3)
        _assert_same(*got)
    assert {("circle_line", "moving"), ("lines", "moving")} <= kinds


def test_a_studys_per_row_numbers_stay_on_numpy(monkeypatch):
    """What the loop does not take (per-row constants of a study's variants) goes to numpy,
    whatever the flag: the chain with per-row radii is solved, and not by the loop."""
    scene = linkpipe.load_scene(CONFIG_DIR / "fourbar_crank_rocker.toml")
    chain, s, s_dot, s_ddot = _chain_of(scene)
    calls = []
    monkeypatch.setattr(chain_kernel, "solve", lambda *a, **k: calls.append(1))
    st = next(st for st in chain.steps if st.kind == "circles")
    st.r1 = np.full(len(s), st.r1)  # one radius per row
    sw = solve_chain(chain, s, s_dot, s_ddot, order=2, compiled=True)
    assert not calls and sw.ok.all()


def test_steps_out_of_reach_are_nan_in_the_same_places():
    """A slider-driven crank pushed past its inner dead centre: the steps beyond have no
    assembly (NaN positions, rates and residual, ok False) in both, and the rest agree."""
    a, b, e = 1.0, 3.0, 0.2
    x0 = a * np.cos(np.radians(30.0)) + np.sqrt(b * b - (e - a * np.sin(np.radians(30.0))) ** 2)
    scene = linkpipe.parse_scene(hs.slider_driven_text(a, b, e, x0, -4.8, 41, 30.0), "sd.toml")
    out = _assert_same(*_chain_of(scene), chunk=7, segments=3)
    assert 0 < (~out["ok"]).sum() < len(out["ok"])
    assert np.isnan(out["position"][~out["ok"]]).any() and np.isnan(out["residual"][~out["ok"]]).all()


def test_the_compiled_loops_are_taken_where_they_pay(monkeypatch):
    """compiled.wanted: a process that has not loaded them takes them from COLD_FROM steps
    (where their saving repays loading them), one that has from WARM_FROM;
    LINKPIPE_COMPILED=0 never, =1 at any length."""
    monkeypatch.delenv("LINKPIPE_COMPILED", raising=False)
    monkeypatch.setattr(compiled, "_loaded", False)
    assert not compiled.wanted(360_000) and compiled.wanted(compiled.COLD_FROM)
    monkeypatch.setattr(compiled, "_loaded", True)
    assert compiled.wanted(360_000) and not compiled.wanted(compiled.WARM_FROM - 1)
    monkeypatch.setenv("LINKPIPE_COMPILED", "0")
    assert not compiled.wanted(10 * compiled.COLD_FROM)
    monkeypatch.setenv("LINKPIPE_COMPILED", "1")
    assert compiled.wanted(2)


@settings(max_examples=25, deadline=None)
@given(family=st_h.sampled_from(["fourbar", "slider_crank", "lines"]),
       a=st_h.floats(0.5, 1.2), b=st_h.floats(3.0, 4.0), c=st_h.floats(2.5, 3.5),
       start=st_h.floats(0.0, 360.0), scale=st_h.sampled_from([1e-3, 1.0, 1e3]))
def test_the_compiled_stage_1_meets_the_models_own_equations(family, a, b, c, start, scale):
    """Independently of the numpy path: the compiled loops' stage 1 (LINKPIPE_COMPILED=1,
    through ``linkpipe.solve``) solves model/equations.py's rows: Phi = 0 to 1e-12 of the size,
    Phi_q v = -Phi_t and Phi_q a = gamma to 1e-12 and 1e-11 of the rates' scales, and its
    condition is numpy's dense 1-norm condition of Phi_q to rounding times the condition (Grashof crank-rockers,
    offset slider-cranks and a point on two lines, at three scales)."""
    if family == "fourbar":
        text = hs.fourbar_text(a, b, c, 4.0, start, start + 90.0, 31, scale=scale,
                               coupler_uv=(1.2, 0.7))
    elif family == "slider_crank":
        text = hs.slider_crank_text(a, b, 0.3 * a, start, start + 90.0, 31, scale=scale)
    else:
        text = _two_lines_text(a, b, start, 90.0)
    scene = linkpipe.parse_scene(text, f"{family}.toml")
    scene = dc.replace(scene, solver=dc.replace(scene.solver, method="dyads"),
                       outputs=dc.replace(scene.outputs, kinematics=("velocity", "acceleration")))
    with mock.patch.dict(os.environ, {"LINKPIPE_COMPILED": "1"}):
        r = linkpipe.solve(scene)
    assert r.solver_method_used == "dyads"
    ok = r.status == OK
    if not ok.any():
        return
    model = r.model
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    X, V, A = r.position[ok], r.velocity[ok], r.acceleration[ok]
    s, s_dot, s_ddot = s[ok], s_dot[ok], s_ddot[ok]
    assert np.abs(model.phi(X, s)).max() <= 1e-12 * model.size
    J = model.jacobian(X, s)
    v_scale, a_scale = max(np.abs(V).max(), 1e-300), max(np.abs(A).max(), 1e-300)
    vel = np.einsum("sij,sj->si", J, model.q_of(V)) + model.phi_t(X, s, s_dot)
    acc = np.einsum("sij,sj->si", J, model.q_of(A)) - model.gamma(X, V, s, s_dot, s_ddot)
    assert np.abs(vel).max() <= 1e-12 * v_scale
    assert np.abs(acc).max() <= 1e-11 * a_scale  # gamma's terms are products of two rates
    dense = np.linalg.cond(J, 1)  # LAPACK's inverse: the two inverses differ by ~eps x condition
    assert (np.abs(r.condition[ok] - dense) <= dense * (1e-14 + 1e-15 * dense)).all()


NO_CACHE_ANYWHERE = """
import numba.core.caching as caching
import numpy as np

def deny(self):  # every cache folder numba tries is unwritable (a read-only install, no home)
    raise PermissionError(13, "Permission denied", self.get_cache_path())

caching._CacheLocator.ensure_cache_path = deny
import os
import linkpipe
scene = linkpipe.load_scene(os.path.join("configs", "fourbar_crank_rocker.toml"))
os.environ["LINKPIPE_COMPILED"] = "0"
a = linkpipe.solve(scene)
os.environ["LINKPIPE_COMPILED"] = "1"
b = linkpipe.solve(scene)
from linkpipe.kinematics import compiled
assert compiled.loaded()
for x, y in zip(a.variables(), b.variables()):
    np.testing.assert_array_equal(y.data, x.data, err_msg=x.name)
print("same", len(a.variables()))
"""


def test_with_nowhere_to_write_numbas_cache_the_loops_compile_in_the_process():
    """A read-only install run by a user without a writable home: numba finds no folder for
    its cache. The compiled loops are then compiled in the process (not cached), and give
    numpy's numbers; the run does not fail (a fresh interpreter: numba's state is global)."""
    import subprocess

    done = subprocess.run([sys.executable, "-c", NO_CACHE_ANYWHERE], capture_output=True,
                          text=True, timeout=300, cwd=CONFIG_DIR.parent)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.startswith("same")
