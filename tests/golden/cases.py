"""The golden cases: every shipped config and a representative scene of each hard-case family,
on each stage-1 path that applies, plus the solver knobs that take other code paths.

``CASES`` maps a case name to a zero-argument function returning the Scene to solve. The
reference arrays are ``tests/golden/<case>.npz`` (``python tests/golden/make_goldens.py``
writes them; only a commit that says why may change them).
"""
from __future__ import annotations

import dataclasses
import pathlib
import sys

import linkpipe

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "tests" / "hard"))
import hard_scenes as hs  # noqa: E402

CONFIGS = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "configs" / "hard").glob("*.toml"))
DATA = sorted((ROOT / "tests" / "data").glob("*.toml"))


def _solver(scene, **changes):
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, **changes))


def _steps(scene, steps):
    return dataclasses.replace(scene, drivers=tuple(dataclasses.replace(d, steps=steps, step=None)
                                                    for d in scene.drivers))


def _file(path, **solver):
    return lambda: _solver(linkpipe.load_scene(str(path)), **solver)


def _text(text, name, **solver):
    return lambda: _solver(linkpipe.parse_scene(text, f"{name}.toml"), **solver)


CASES: dict = {}
for _p in CONFIGS + DATA:
    for _m in ("auto", "newton"):
        CASES[f"{_p.stem}.{_m}"] = _file(_p, method=_m)

_CR = ROOT / "configs" / "fourbar_crank_rocker.toml"
_SP = ROOT / "configs" / "shear_press.toml"
# the vectorised Newton path (sweeps of 1000 steps and more) and the dyads on a long sweep
CASES["crank_rocker_2001.newton"] = lambda: _steps(_solver(linkpipe.load_scene(str(_CR)), method="newton"), 2001)
CASES["crank_rocker_2001.dyads"] = lambda: _steps(_solver(linkpipe.load_scene(str(_CR)), method="dyads"), 2001)
CASES["basketball_goal_2001.newton"] = lambda: _steps(_solver(linkpipe.load_scene(
    str(ROOT / "configs" / "basketball_goal.toml")), method="newton"), 2001)
# solver knobs with their own code paths
for _knob, _val in (("jacobian", "finite_difference"), ("derivatives", "finite_difference"),
                    ("predictor", "none"), ("predictor", "second")):
    CASES[f"shear_press.{_knob}_{_val}"] = _file(_SP, method="newton", **{_knob: _val})
    CASES[f"crank_rocker.{_knob}_{_val}"] = _file(_CR, method="newton", **{_knob: _val})
# hard-case families (tests/hard/)
_TEXTS = {
    "toggle_fourbar": hs.fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 73, coupler_uv=(1.5, 0.8)),
    "triple_rocker_turns": hs.fourbar_text(2.0, 2.0, 2.0, 3.5, 0.0, 720.0, 145),
    "near_degenerate_crank": hs.fourbar_text(1e-4, 1.0, 1.0, 1.0, 0.0, 360.0, 37),
    "scaled_mm": hs.fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 361, scale=1000.0, units="mm"),
    "slider_crank_back": hs.slider_crank_text(1.0, 3.0, 0.4, 20.0, 380.0, 37, branch=-1),
    "slider_driven": hs.slider_driven_text(1.0, 3.5, 0.0, 2.5, 4.5, 41, 179.0, rate=0.5),
    "dead_centres": hs.slider_driven_text(1.0, 3.5, 0.0, 3.5, 4.6, 12, 81.78678929826181, rate=0.7),
    "double_parallelogram_flat": hs.double_parallelogram_text(0.0, 10.0, 370.0, 73),
    "double_parallelogram": hs.double_parallelogram_text(0.6, 0.0, 360.0, 73),
    "six_bar": hs.six_bar_text(1.0, 3.5, 3.0, 4.0, (1.2, 0.9), (5.5, 3.0), (4.6, 4.2), 0.0, 60.0, 31),
    "drawn_elsewhere": hs.fourbar_text(1.0, 3.5, 3.0, 4.0, 30.0, 390.0, 37, B_guess=(0.5, 8.0)),
}
for _name, _t in _TEXTS.items():
    for _m in ("auto", "newton"):
        CASES[f"{_name}.{_m}"] = _text(_t, _name, method=_m)

#: variables compared (relative 1e-12 of each array's largest magnitude); status exactly.
#: residual, iterations and condition are stored for reference but are the solver's own
#: diagnostics, which a refactoring of the Newton loop or the condition estimate may change.
DIAGNOSTICS = {"residual", "iterations", "condition", "velocity_residual", "acceleration_residual"}


def arrays(result) -> dict:
    """Every output array of a Result (coordinates as strings), keyed by variable name."""
    out = {}
    for v in result.coordinates() + result.variables():
        out[v.name] = v.data.astype(str) if v.data.dtype == object else v.data
    return out
