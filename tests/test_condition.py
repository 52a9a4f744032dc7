"""The condition estimate without an inverse (large Jacobians, no force stage).

``linalg.estimate_inverse_norm1`` (Hager/Higham, LAPACK's xLACON) is checked against the exact
``|J^-1|_1`` of numpy's inverse: it is a lower bound by construction and, for these families,
within the factor of 3 the literature gives. ``derivatives`` uses it for Jacobians larger than
ESTIMATE_FROM unknowns (which it then never inverts: block solves give the velocities and the
influence coefficients), and takes the exact value wherever the estimate comes near the
singular threshold, so statuses never rest on it.
"""
import sys
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe import kinematics as kin
from linkpipe.kinematics.linalg import ESTIMATE_FROM, estimate_inverse_norm1
from linkpipe.scene import parse_scene

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_threads import chain_text  # noqa: E402


def _dense_solvers(A):
    """solve / solve_transpose on a stack A (S, n, n) in the estimator's list layout."""
    def solve(x):
        return list(np.linalg.solve(A, np.stack(x, axis=1)[..., None])[..., 0].T)

    def solve_t(x):
        return list(np.linalg.solve(np.swapaxes(A, 1, 2), np.stack(x, axis=1)[..., None])[..., 0].T)

    return solve, solve_t


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 10_000), spread=st.sampled_from([0.0, 3.0, 8.0]))
def test_estimate_is_a_lower_bound_within_a_factor_of_three(n, seed, spread):
    rng = np.random.default_rng(seed)
    S = 16
    # random matrices with singular values spread over 10^spread: from benign to ill-conditioned
    U = np.linalg.qr(rng.normal(size=(S, n, n)))[0]
    V = np.linalg.qr(rng.normal(size=(S, n, n)))[0]
    sv = 10.0 ** (-spread * rng.uniform(size=(S, n)))
    A = np.einsum("sij,sj,skj->sik", U, sv, V)
    exact = np.abs(np.linalg.inv(A)).sum(axis=1).max(axis=1)
    est = estimate_inverse_norm1(*_dense_solvers(A), n, S)
    assert (est <= exact * (1 + 1e-12)).all()  # every iterate is |J^-1 x|_1 with |x|_1 = 1
    assert (est >= exact / 3).all(), (est / exact).min()


def test_an_exactly_singular_step_is_infinite():
    A = np.stack([np.eye(3), np.diag([1.0, 1.0, 0.0])])
    est = estimate_inverse_norm1(*_dense_solvers_safe(A), 3, 2)
    assert np.isfinite(est[0]) and est[0] == 1.0 and est[1] == np.inf


def _dense_solvers_safe(A):
    """As _dense_solvers, with inf/NaN (not an exception) where a matrix is singular, as the
    sparse engine's block solves give."""
    def solve(x):
        out = []
        for a, b in zip(A, np.stack(x, axis=1)):
            try:
                out.append(np.linalg.solve(a, b))
            except np.linalg.LinAlgError:
                out.append(np.full(len(b), np.inf))
        return list(np.array(out).T)

    def solve_t(x):
        return solve(x)

    return solve, solve_t


@pytest.fixture(scope="module")
def chain_with_change_points():
    """Nine chained loops (36 unknowns > ESTIMATE_FROM), the first a parallelogram whose change
    points (crank at 0 and 180 degrees) are on steps: singular there, ill-conditioned next to it."""
    scene = parse_scene(chain_text(9, 721, first=(1.0, 4.0, 1.0, 4.0), start_deg=0.0,
                                   to_deg=360.0), "chain.toml")
    r = linkpipe.solve(scene)
    assert r.model.n_q > ESTIMATE_FROM
    return r


def test_statuses_and_conditions_near_the_threshold_are_exact(chain_with_change_points):
    r = chain_with_change_points
    m = r.model
    _, s, sd, sdd = kin.driver_motion(m)
    est = kin.derivatives(m, r.position, s, sd, sdd, r.status, True)
    exact = kin.derivatives(m, r.position, s, sd, sdd, r.status, True, dense=True)  # inverse
    np.testing.assert_array_equal(est["status"], exact["status"])
    assert (exact["status"] == 2).sum() == 3  # the two change points and the closing step
    ok = np.isfinite(exact["condition"])
    ratio = est["condition"][ok] / exact["condition"][ok]
    # a lower bound; measured down to 1/3.1 here (the statuses need it 1000x low to change)
    assert (ratio <= 1 + 1e-12).all() and (ratio >= 1 / 4).all(), ratio.min()
    near = exact["condition"] * m.scene.solver.singular_rcond >= 1e-3
    assert near.sum() >= 4  # the steps next to the change points
    # exact there: the engine's block inverse against numpy's dense one, to rounding
    np.testing.assert_allclose(est["condition"][near], exact["condition"][near], rtol=1e-9)
    # velocities, accelerations and influence coefficients by block solves equal the dense
    # inverse's to rounding amplified by the step's condition: |error| <= 1e-13 cond |x|max
    cond = exact["condition"][ok]
    for key in ("velocity", "acceleration", "influence"):
        a, b = est[key][ok], exact[key][ok]
        scale = np.abs(b).reshape(len(b), -1).max(axis=1)
        err = np.abs(a - b).reshape(len(b), -1).max(axis=1)
        assert (err <= 1e-13 * cond * scale + 1e-15).all(), (key, (err / (cond * scale)).max())
