"""Nothing wrong says "ok": a step is ok only if everything stored at it is finite and its
residual met the tolerance asked for; settings that would make "ok" meaningless are refused."""
import pathlib

import numpy as np
import pytest

import linkpipe
from linkpipe import status as st
from linkpipe.errors import SceneError

ROOT = pathlib.Path(__file__).resolve().parents[2]
CRANK_ROCKER = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
GOAL = (ROOT / "configs" / "basketball_goal.toml").read_text()


def test_a_rate_whose_square_overflows_gives_non_finite_steps_not_ok():
    text = CRANK_ROCKER.replace("rate = 572.9577951308232", "rate = 1e308")
    r = linkpipe.solve(linkpipe.parse_scene(text, "fast.toml"))
    assert not np.isfinite(r.acceleration).all()  # omega^2 overflows: the physics is inf
    bad = ~np.isfinite(r.acceleration).all(axis=(1, 2))
    assert (r.status[bad] == st.NON_FINITE).all() and bad.any()
    assert (r.status[~bad] == st.OK).all()  # where nothing overflowed the step stays ok
    np.testing.assert_array_equal(r.status != st.OK, bad)


def test_huge_masses_give_non_finite_forces_not_ok():
    text = GOAL.replace("mass = 1.5540498539193137", "mass = 1e308")
    assert text != GOAL
    r = linkpipe.solve(linkpipe.parse_scene(text, "heavy.toml"))
    force = r.forces["input_force"][1]
    ok = r.status == st.OK
    assert np.isfinite(force[ok]).all()
    assert (r.status[~np.isfinite(force).all(axis=1) & (r.status != st.NO_LEVERAGE)]
            == st.NON_FINITE).all()
    assert not ok.all()


@pytest.mark.parametrize("setting, key", [("tol = 1e300", "tol"), ("tol = 0.5", "tol"),
                                          ("tol = 0.0", "tol"), ("max_iter = 1000000000", "max_iter")])
def test_solver_settings_that_make_ok_meaningless_are_scene_errors(setting, key):
    text = CRANK_ROCKER + f"\n[solver]\n{setting}\n"
    with pytest.raises(SceneError) as err:
        linkpipe.parse_scene(text, "loose.toml")
    assert err.value.table == "solver" and err.value.key == key


def test_the_loosest_tolerance_allowed_still_meets_itself():
    """tol = 1e-2 (the accuracy ladder's loosest rung) is allowed: every ok step's residual is
    within it; no step is ok with a residual above the tolerance asked for."""
    text = CRANK_ROCKER + '\n[solver]\ntol = 1e-2\nmethod = "newton"\n'
    r = linkpipe.solve(linkpipe.parse_scene(text, "loose.toml"))
    ok = r.status == st.OK
    assert ok.any() and (r.residual[ok] <= 1e-2 * r.model.size).all()


def test_assign_is_the_one_rule():
    """worst of the stages, then the tolerance, then finiteness."""
    kin = np.array([st.OK, st.OK, st.OK, st.SINGULAR, st.NO_ASSEMBLY], dtype=np.int8)
    forces = np.array([st.NO_LEVERAGE, st.OK, st.OK, st.OK, st.OK], dtype=np.int8)
    residual = np.array([0.0, 1e-9, 0.0, 0.0, np.nan])
    stored = [np.array([1.0, 1.0, np.inf, np.nan, np.nan])]
    got = st.assign([kin, forces], residual, 1e-12, stored)
    np.testing.assert_array_equal(got, [st.NO_LEVERAGE, st.NOT_CONVERGED, st.NON_FINITE,
                                        st.SINGULAR, st.NO_ASSEMBLY])
    assert st.FLAG_MEANINGS == ("ok", "no_assembly", "singular", "not_converged", "no_input",
                                "no_leverage", "non_finite", "out_of_stroke")
    # out_of_stroke (version 3) keeps its step's values: above a lack of leverage or an
    # overflow, below every verdict that leaves the step without positions or derivatives
    stroke = np.full(5, st.OUT_OF_STROKE, dtype=np.int8)
    np.testing.assert_array_equal(
        st.worst(np.array([st.OK, st.NO_LEVERAGE, st.NON_FINITE, st.SINGULAR, st.NO_ASSEMBLY]),
                 stroke),
        [st.OUT_OF_STROKE, st.OUT_OF_STROKE, st.OUT_OF_STROKE, st.SINGULAR, st.NO_ASSEMBLY])


def test_a_quantity_the_scene_does_not_define_does_not_fail_its_steps():
    """A link between two fixed points carries no computed force (NaN at every step): that is
    an undefined quantity, not a non-finite result, so the steps stay ok."""
    text = CRANK_ROCKER.replace('[[links]]\nname = "crank"',
                                '[[links]]\nname = "ground"\npoints = ["O2", "O4"]\n\n'
                                '[[links]]\nname = "crank"', 1)
    text += '\n[analysis]\neffects = ["loads"]\n\n[[loads]]\nname = "push"\npoint = "P"\nforce = [0.0, -1.0]\n'
    r = linkpipe.solve(linkpipe.parse_scene(text, "ground_link.toml"))
    link_force = r.forces["link_force"][1]
    assert np.isnan(link_force[:, r.link_names.index("ground")]).all()
    assert (r.status == st.OK).all()
