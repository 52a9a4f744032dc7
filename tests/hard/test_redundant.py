"""Hard case 4: redundant constraints, a double parallelogram.

Crank O2-A, rocker O4-B and a fifth link O6-E, all of length 1 and parallel; the coupler A-B-E
translates: A = e(t), B = A + (2, 0), E = A + (1, v). The fifth link's constraint is implied by
the others, so the constraint Jacobian has rank 5 of 6 rows everywhere. linkpipe must find that
at load time, solve by least squares, flag `singular` only for rank loss beyond it, get the
kinematics right and say which reactions the redundancy leaves undetermined.
"""
import re

import h5py
import numpy as np

from linkpipe.kinematics import driver_motion
import pytest

from hard_scenes import (HARD_DIR, acceleration, double_parallelogram_text, point, solve_config,
                         solve_text, velocity, method)  # noqa: F401 - a fixture
import linkpipe
from linkpipe.__main__ import main
from linkpipe.status import OK, SINGULAR
from linkpipe.model import build_model, check_mobility

W = 10.0  # crank speed, rad/s
L = 2.0  # ground length O2-O4: the length scale
CONFIG = HARD_DIR / "double_parallelogram.toml"
# The Jacobian's condition stays below ~40 away from the change points and the solver's residual
# tolerance is 1e-12 of the size: 1e-10 L (L W, L W^2) leaves a margin of about 3.
POS, VEL, ACC = 1e-10 * L, 1e-10 * L * W, 1e-10 * L * W**2


def exact(t_deg, v):
    t = np.deg2rad(t_deg)
    A = np.stack([np.cos(t), np.sin(t)], -1)
    VA = W * np.stack([-np.sin(t), np.cos(t)], -1)
    return dict(A=A, B=A + [2.0, 0.0], E=A + [1.0, v], V=VA, Acc=-W**2 * A)


def check_kinematics(r, v):
    ex = exact(r.driver_value[:, 0], v)
    ok = r.status == OK
    for name in ("A", "B", "E"):
        np.testing.assert_allclose(point(r, name)[ok], ex[name][ok], rtol=0, atol=POS)
        np.testing.assert_allclose(velocity(r, name)[ok], ex["V"][ok], rtol=0, atol=VEL)
        np.testing.assert_allclose(acceleration(r, name)[ok], ex["Acc"][ok], rtol=0, atol=ACC)


def test_redundancy_found_at_load_time():
    scene = linkpipe.load_scene(str(CONFIG))
    mob = check_mobility(build_model(scene))
    assert (mob.n_q, mob.n_constraints, mob.rank, mob.dof, mob.redundant) == (6, 6, 5, 1, 1)


def test_redundancy_found_from_rounded_start_positions():
    """Written to 3 decimals the start is off the constraints and looks rigid (rank 6): the rank
    is taken at the start projected onto the constraints."""
    text = double_parallelogram_text(0.6, 30.0)
    text = re.sub(r"B  = \{.*\}", "B  = { x = 2.87, y = 0.49 }", text)  # exact: (2.866.., 0.5)
    scene = linkpipe.parse_scene(text, "rounded.toml")
    X0 = build_model(scene).start_position
    assert np.abs(X0[4] - X0[3] - [2.0, 0.0]).max() > 1e-4  # really off the constraints
    mob = check_mobility(build_model(scene))
    assert (mob.dof, mob.redundant) == (1, 1)
    assert (linkpipe.solve(scene).status == OK).all()


def test_check_and_run_report_the_redundancy(tmp_path, capsys):
    assert main(["check", str(CONFIG)]) == 0
    out = capsys.readouterr().out
    assert "rank 5, 1 redundant" in out and "redundant: 1 constraint(s)" in out
    assert main(["run", str(CONFIG), "--out", str(tmp_path), "--no-rrd"]) == 0
    out = capsys.readouterr().out
    assert "redundant constraints: 1" in out and "not unique (minimum-norm choice)" in out
    with h5py.File(tmp_path / "double_parallelogram.h5") as f:
        assert f.attrs["redundant_constraints"] == 1
        assert list(f["link_force_unique"][:]) == [0, 0, 0, 0]
        assert len(f.attrs["forces_not_unique"]) == 4


def test_kinematics_exact_and_never_singular(method):
    """E off the coupler line: the fifth link carries the mechanism through 0 and 180 deg."""
    r = solve_config(CONFIG, method)
    assert (r.status == OK).all()
    assert np.nanmax(r.condition) < 100  # full column rank beyond the one redundant row
    check_kinematics(r, 0.6)
    # the pinv solution solves J qd = -Phi_t (the model's own Jacobian, here, not the run's)
    model = r.model
    _, s, s_dot, _ = driver_motion(model)
    residual = (np.einsum("sij,sj->si", model.jacobian(r.position, s), model.q_of(r.velocity))
                + model.phi_t(r.position, s, s_dot))
    assert np.abs(residual).max() < 1e-12 * L * W


def test_singular_only_beyond_the_redundancy(method):
    """E on the coupler line (v = 0): at 0 and 180 deg every link is horizontal and the fifth link
    no longer adds a condition; that rank loss beyond the known redundancy is flagged there only."""
    r = solve_text(double_parallelogram_text(0.0, 10.0, 370.0, 73), method)
    t = r.driver_value[:, 0]
    crossing = np.isclose(t % 180.0, 0.0, atol=1e-9)
    assert crossing.sum() == 2
    np.testing.assert_array_equal(r.status, np.where(crossing, SINGULAR, OK))
    check_kinematics(r, 0.0)  # and still the parallelogram, on both sides of the crossings


def parallel_pair(drop):
    """The same mechanism without one of the three parallel links: no redundancy, unique forces."""
    text = double_parallelogram_text(0.6, 0.0, 360.0, 73)
    block = re.search(rf'\[\[links\]\]\nname = "{drop}"\n.*?\n\n', text, re.S).group(0)
    return text.replace(block, "")


def test_undetermined_reactions_are_flagged(method):
    red = solve_config(CONFIG, method)
    alt = {d: solve_text(parallel_pair(d), method) for d in ("fifth", "rocker")}
    # each plain parallelogram has change points of its own (0/180 deg without the fifth link,
    # 31/211 deg without the rocker): compare where both are regular
    ok = (alt["fifth"].status == OK) & (alt["rocker"].status == OK)
    assert ok.sum() >= 65
    for r in alt.values():
        assert r.mobility.redundant == 0 and "link_force_unique" not in r.forces
        # the same motion, so the same unique answers: kinematics and the input torque
        np.testing.assert_allclose(r.position[ok], red.position[ok], rtol=0, atol=POS)
        np.testing.assert_allclose(r.forces["input_force"][1][ok], red.forces["input_force"][1][ok],
                                   rtol=1e-9, atol=1e-9)
    names = red.link_names

    def in_red_order(r):
        """The link forces of r in the redundant scene's link order, 0 for the dropped link."""
        f = r.forces["link_force"][1][ok]
        return np.stack([f[:, r.link_names.index(n)] if n in r.link_names else np.zeros(len(f))
                         for n in names], 1)

    lf = red.forces["link_force"][1][ok]
    lf_a, lf_b = in_red_order(alt["fifth"]), in_red_order(alt["rocker"])
    # two valid distributions of the same load differ (so the reactions are not unique) ...
    assert np.abs(lf_a - lf_b).max() > 1.0
    # ... by a self-stress (their difference), and the reported one is a third valid one: it
    # differs from each of them by a multiple of the same self-stress
    n = lf_a - lf_b
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for valid in (lf_a, lf_b):
        d = lf - valid
        np.testing.assert_allclose(d - (d * n).sum(1, keepdims=True) * n, 0.0, atol=1e-8)
    # and the flags say so: every link force here shares the self-stress
    np.testing.assert_array_equal(red.forces["link_force_unique"][1], [0, 0, 0, 0])
    assert red.forces_not_unique() == [f"link {x}" for x in names]


def test_a_unique_reaction_stays_unique():
    """With E on the coupler line the self-stress does not load the coupler's A-B row."""
    r = solve_text(double_parallelogram_text(0.0, 10.0, 170.0, 33))
    flags = dict(zip(r.link_names, r.forces["link_force_unique"][1]))
    assert flags == {"crank": 0, "rocker": 0, "fifth": 0, "coupler": 1}


def test_plain_parallelogram_has_no_flags():
    r = solve_text(parallel_pair("fifth"))
    assert r.mobility.redundant == 0 and r.forces_not_unique() == []


def test_flagged_rows_are_the_left_null_space_and_lambda_is_minimum_norm():
    """Independently of force_stage: the self-stress is J's left null vector; the multipliers
    J^T lambda = Q with the least norm have no component along it."""
    from linkpipe.forces.lagrange import undetermined_rows

    scene = linkpipe.load_scene(str(CONFIG))
    model = build_model(scene)
    r = linkpipe.solve(scene)
    s = np.deg2rad(r.driver_value)
    J = model.jacobian(r.position, s)  # (S, 7, 6): 4 link rows, 2 rows for E, 1 driver row
    U, sv, _ = np.linalg.svd(J)
    assert (sv[:, -1] > 0.1).all()  # full column rank: only the one redundant row
    N = U[:, :, 6]  # the left null vector at each step
    np.testing.assert_allclose(np.einsum("sij,si->sj", J, N), 0.0, atol=1e-12)
    np.testing.assert_array_equal(undetermined_rows(J), np.abs(N).max(0) > 1e-8)
    assert list(undetermined_rows(J)) == [True] * 6 + [False]  # the driver row is unique
    # any right-hand side in the range of J^T: the least-norm solution is orthogonal to N
    rng = np.random.default_rng(5)
    Q = np.einsum("sij,si->sj", J, rng.normal(size=(len(J), 7)))
    lam = np.einsum("sij,sj->si", np.linalg.pinv(np.swapaxes(J, 1, 2), rcond=1e-12), Q)
    np.testing.assert_allclose((lam * N).sum(1), 0.0, atol=1e-10)


def test_pin_and_ground_forces_flagged_not_unique_under_redundancy():
    """A self-stress of the double parallelogram loads every pin of the loop: all flagged;
    a scene without redundancy carries no flags at all."""
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2] / "configs"
    r = linkpipe.solve(str(root / "hard" / "double_parallelogram.toml"))
    assert (r.forces["joint_force_unique"][1] == 0).all()
    assert (r.forces["ground_reaction_unique"][1] == 0).all()
    plain = linkpipe.solve(str(root / "shear_press.toml"))
    assert "joint_force_unique" not in plain.forces and "ground_reaction_unique" not in plain.forces
