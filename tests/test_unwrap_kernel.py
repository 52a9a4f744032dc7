"""The links' angles unwrapped by compiled loops (linkpipe.kinematics.unwrap_kernel) equal
numpy's unwrap_runs to the bit: angles that pass +-pi often and rarely, a change of exactly pi
either way, a carry with and without a last angle, and the carry handed on; a segment with a
NaN is left to numpy's path (the kernel declines it) and gives its numbers."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st_h
from hypothesis.extra import numpy as hnp

from linkpipe.kinematics import unwrap_kernel
from linkpipe.kinematics.angles import AngleCarry, unwrap_runs


def _same(ang, carry):
    """numpy's unwrap_runs and the kernel's unwrap of the same segment after ``carry``; the
    kernel declines (None) exactly where an angle is NaN."""
    a, ca = unwrap_runs(ang, carry)
    before = carry or AngleCarry(np.full(ang.shape[1], np.nan), np.zeros(ang.shape[1]))
    got = unwrap_kernel.unwrap(ang, before.last, before.correction)
    assert (got is None) == bool(np.isnan(ang).any())
    if got is not None:
        b, last, correction = got
        np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(last, ca.last)
        np.testing.assert_array_equal(correction, ca.correction)
    return a


@settings(max_examples=200, deadline=None)
@given(steps=hnp.arrays(float, st_h.tuples(st_h.integers(0, 60), st_h.integers(1, 4)),
                        elements=st_h.floats(-7.0, 7.0)),
       last=st_h.sampled_from([np.nan, 0.5, -3.1, 3.14159]), before=st_h.floats(-50.0, 50.0))
def test_random_walks_of_angles_unwrap_as_numpy_does(steps, last, before):
    """Each link's direction (wrapped into [-pi, pi)) of a random walk whose steps reach two
    turns: many jumps, both ways; the carry's last angle and its summed correction given."""
    ang = (np.cumsum(steps, axis=0) + np.pi) % (2 * np.pi) - np.pi
    L = ang.shape[1]
    _same(ang, AngleCarry(np.full(L, last), np.full(L, before)))
    _same(ang, None)


def test_a_change_of_exactly_pi_and_a_long_sweep():
    """A change of exactly +pi and -pi (numpy's copyto branch), and 360k steps of three links
    turning at 1, 3 and 7 turns per sweep, against np.unwrap itself too."""
    ang = np.array([[0.0, 0.0], [np.pi, -np.pi], [0.0, 0.0], [-np.pi, np.pi]])
    _same(ang, None)
    t = np.linspace(0.0, 2 * np.pi, 360_000)[:, None] * np.array([1.0, 3.0, 7.0])
    wrapped = np.arctan2(np.sin(t), np.cos(t))
    out = _same(wrapped, None)
    np.testing.assert_array_equal(out, np.unwrap(wrapped, axis=0))


@pytest.mark.parametrize("where", [0, 5, 9])
def test_a_nan_goes_to_numpys_path(where):
    ang = np.linspace(-3.0, 9.0, 10)[:, None] % (2 * np.pi) - np.pi
    ang[where] = np.nan
    out = _same(ang, AngleCarry(np.array([1.0]), np.array([2 * np.pi])))
    assert np.isnan(out[where]).all() and np.isfinite(np.delete(out, where, axis=0)).all()


@pytest.mark.parametrize("config", ["fourbar_crank_rocker", "jansen", "slider_crank"])
def test_a_sweep_in_segments_gives_numpys_arrays(config, monkeypatch):
    """Three turns of the crank streamed in segments of 512 steps: with the compiled loops
    (the links' whole turns and the driven links' added in the unwrapping pass from the
    second segment on) every array of every segment's Result equals numpy's to the bit."""
    import dataclasses as dc

    import linkpipe
    from linkpipe import segments
    from conftest import CONFIG_DIR

    scene = linkpipe.load_scene(CONFIG_DIR / f"{config}.toml")
    d = scene.drivers[0]
    scene = dc.replace(scene, drivers=(dc.replace(d, to_value=d.from_value + 3 * 360.0,
                                                  steps=3001, step=None),) + scene.drivers[1:])
    from linkpipe.kinematics import unwrap_kernel

    shifted = []
    real = unwrap_kernel.unwrap
    monkeypatch.setattr(unwrap_kernel, "unwrap", lambda *a, **k: shifted.append(
        len(a) > 3 and a[3] is not None) or real(*a, **k))
    got = {}
    for flag in ("0", "1"):
        monkeypatch.setenv("LINKPIPE_COMPILED", flag)
        parts = list(segments.segments(scene, 512, {}))
        assert len(parts) == 6
        got[flag] = {v.name: np.concatenate([[w for w in p.variables() if w.name == v.name][0].data
                                             for p in parts])
                     for v in parts[0].variables() if v.dims[:1] == ("step",)}
    assert sum(shifted) == 5  # the compiled pass with the turns known: segments 2 .. 6
    assert got["0"].keys() == got["1"].keys() and "link_angle" in got["0"]
    assert np.ptp(got["0"]["link_angle"]) > 4 * np.pi  # whole turns carried across segments
    for name, a in got["0"].items():
        np.testing.assert_array_equal(got["1"][name], a, err_msg=name)
