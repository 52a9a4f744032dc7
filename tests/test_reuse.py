"""What a model's solves reuse across models (issue 30's fit trials, issue 32's follow blocks)
gives the results of building everything afresh, to the last bit.

Two reuses (docs/performance.md, "Solving a small scene many times"):

* objects derived from a model alone (the sparse engine, the one-step kernels and LU, the
  assembled drawing, the mobility) are shared between models equal in
  :func:`linkpipe.model.content_key` (follow's blocks of one scene; a fit's trials that move
  only a driver's offset);
* an engine on the same rows with other numbers (a fit's geometry trials) takes its
  block-triangular order and its checked affine form from the first engine of those rows,
  reading its own coefficients.

The reference ("cold") is each solve with nothing kept between models
(``SHARED_KEEP = STRUCTURES_KEPT = 0``: every model builds its own, as before the reuse).
An independent method: the same pipeline with the reuse switched off.
"""
from __future__ import annotations

import dataclasses
import pathlib
import tomllib

import numpy as np
import pytest

import linkpipe
from linkpipe import cache
from linkpipe.fit import fit_parameters, scene_with
from linkpipe.kinematics import sparse

ROOT = pathlib.Path(__file__).resolve().parent.parent


@pytest.fixture
def cold(monkeypatch):
    """Switch the reuse off (nothing kept between models) for the block it is used in."""
    def off():
        cache._SHARED.clear()
        sparse._STRUCTURES.clear()
        monkeypatch.setattr(cache, "SHARED_KEEP", 0)
        monkeypatch.setattr(sparse, "STRUCTURES_KEPT", 0)

    def on():
        monkeypatch.setattr(cache, "SHARED_KEEP", 32)
        monkeypatch.setattr(sparse, "STRUCTURES_KEPT", 16)

    return off, on


def _same(a, b, where: str) -> None:
    """Every number of two results (arrays, dicts and tuples of them) equal to the last bit
    (NaN where NaN)."""
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape, where
        if a.dtype.kind in "fc":
            np.testing.assert_array_equal(a, b, err_msg=where, strict=True)
        else:
            assert np.array_equal(a, b), where
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (tuple, list)) and a and any(isinstance(x, np.ndarray) for x in a):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")


def _same_results(r1, r2) -> None:
    skip = {"scene", "model", "kinematics", "seconds", "mobility"}
    for f in dataclasses.fields(r1):
        if f.name not in skip:
            _same(getattr(r1, f.name), getattr(r2, f.name), f.name)
    assert r1.message == r2.message and r1.solver_note == r2.solver_note
    assert r1.mobility == r2.mobility


def _trial(scene, scale: float):
    """``scene`` with every ``[fit]`` parameter times ``scale``: a fit's trial (other
    numbers on the same rows)."""
    data = tomllib.loads(scene.text)
    params = fit_parameters(scene, data)
    return scene_with(scene, data, params, [p.initial * scale if p.initial else 0.3
                                            for p in params])


@pytest.mark.parametrize("config", ["logged/slider_crank_rig.toml", "logged/dump_truck_logged.toml",
                                    "logged/dump_truck_friction.toml"])
def test_a_fit_trial_after_others_equals_it_solved_alone(config, cold):
    """A trial solved after trials on other numbers (engine order and checked form reused)
    and again after itself (everything derived from its model shared) equals the same trial
    solved with nothing kept between models."""
    off, on = cold
    scene = linkpipe.load_scene(str(ROOT / "configs" / config))
    trial = _trial(scene, 1.01)
    off()
    alone = linkpipe.solve(trial)
    on()
    linkpipe.solve(_trial(scene, 0.99))  # another trial first: the rows' structure kept
    structures = len(sparse._STRUCTURES)
    after_other = linkpipe.solve(trial)
    assert len(sparse._STRUCTURES) == structures  # ...and reused, not built again
    again = linkpipe.solve(_trial(scene, 1.01))  # the same numbers: the objects shared
    assert cache._SHARED, "nothing was shared"
    _same_results(alone, after_other)
    _same_results(alone, again)


def test_follow_blocks_with_the_model_shared_equal_blocks_built_afresh(tmp_path, cold):
    """follow's blocks (a model per block, equal in content: its engine, kernels and mobility
    shared) equal the blocks with every model built afresh, row for row, to the last bit."""
    import shutil
    import subprocess
    import sys

    from linkpipe.follow.blocks import Window

    (tmp_path / "logs").mkdir()
    scene_path = tmp_path / "fourbar_live.toml"
    shutil.copy(ROOT / "configs" / "logged" / "fourbar_live.toml", scene_path)
    log = tmp_path / "logs" / "live_rig.csv"
    subprocess.run([sys.executable, str(ROOT / "configs" / "logged" / "rig_logger.py"), str(log),
                    "--rate", "1000", "--seconds", "0.4", "--fast"], check=True, timeout=60)
    scene = linkpipe.load_scene(str(scene_path))
    data = scene.logs[0]

    def blocks():
        window, parts = Window(scene), []
        for lo in range(0, len(data.t), 7):
            window.add(data.t[lo:lo + 7], {c: data.columns[c][lo:lo + 7] for c in window.columns})
            while (part := window.block()) is not None:
                parts.append(part)
        while (part := window.block(final=True)) is not None:
            parts.append(part)
        return parts

    off, on = cold
    off()
    fresh = blocks()
    on()
    shared = blocks()
    assert len(fresh) == len(shared) > 10
    for a, b in zip(fresh, shared):
        _same_results(a, b)
