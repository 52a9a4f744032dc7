"""Large mechanisms on the sparse LU (issue 16): ``[solver] linear_algebra``.

A chain of four-bar loops (benchmarks/bench_threads.py's scene) solved with the one-step work
on dense Jacobians and on the sparse LU must give the same sweep to rounding; its Lagrange
multipliers and reactions must equal a dense solve of ``Phi_q^T lambda = Q`` written here;
and one step's factorisation must agree with numpy on solves, the determinant's sign and the
condition. No timings here: benchmarks/bench_scale.py measures speed and memory.
"""
import pathlib
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import linkpipe
from linkpipe.forces.lagrange import body_rows, joints
from linkpipe.kinematics.sparse_lu import SPARSE_FROM, step_lu, uses_sparse
from linkpipe.model import build_model
from linkpipe.scene import parse_scene
from linkpipe.stores import hdf5

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_threads import chain_text  # noqa: E402

G = (0.0, -9.81)
MASS, CENTER = 1.5, (0.5, 0.1)


def chain_scene(loops: int, steps: int, linear_algebra: str = "auto", gravity: bool = False):
    """The chain of ``loops`` four-bar loops; with ``gravity`` a mass on every link."""
    text = chain_text(loops, steps).replace("[solver]\n", f'[solver]\nlinear_algebra = "{linear_algebra}"\n')
    if gravity:
        text += f'[analysis]\neffects = ["gravity"]\n[gravity]\ng = [{G[0]}, {G[1]}]\n'
        names = ([f"crank{k}" for k in range(loops)] + [f"coupler{k}" for k in range(loops)]
                 + ["rocker_last"])
        for name in names:
            text += (f'[[masses]]\nlink = "{name}"\nmass = {MASS}\n'
                     f'center = [{CENTER[0]}, {CENTER[1]}]\ninertia = 0.1\n')
    return parse_scene(text, "chain.toml")


@pytest.fixture(scope="module")
def dense_and_sparse():
    """A 16-loop chain (64 unknowns: auto takes the sparse LU) with gravity on every link,
    1,200 steps (coarse continuation + batched Newton), solved both ways."""
    return {la: linkpipe.solve(chain_scene(16, 1200, la, gravity=True)) for la in ("dense", "sparse")}


def test_the_choice_is_automatic_by_size_and_said():
    small, large = (build_model(chain_scene(n, 10)) for n in (8, 16))
    assert small.n_q < SPARSE_FROM <= large.n_q
    assert not uses_sparse(small) and uses_sparse(large)
    assert uses_sparse(build_model(chain_scene(8, 10, "sparse")))
    assert not uses_sparse(build_model(chain_scene(16, 10, "dense")))
    r = linkpipe.solve(chain_scene(16, 50))
    assert r.linear_algebra_used == f"sparse LU (auto: 64 >= {SPARSE_FROM} unknowns)"
    assert hdf5.root_attributes(r)["solver_linear_algebra_used"] == r.linear_algebra_used
    from linkpipe.__main__ import summary
    assert "linear algebra sparse LU (auto: 64 >= 64 unknowns)" in summary(r)
    assert linkpipe.solve(chain_scene(8, 50)).linear_algebra_used.startswith("dense (auto: 32 < ")


def test_sparse_and_dense_sweeps_agree_to_rounding(dense_and_sparse):
    """Same statuses and iterations; positions, rates, condition and forces equal to rounding.

    Both paths run the same Newton from the same predictions, ending in a quadratic step; only
    the factorisations' rounding differs (about n eps cond = 64 x 2.2e-16 x 40 ~ 6e-13 in the
    worst case, ~1e-14 of the size measured), so 1e-12 of each quantity's scale is rounding
    with margin, and far below the solver's tolerance effects (tol = 1e-12 of the size)."""
    d, s = dense_and_sparse["dense"], dense_and_sparse["sparse"]
    assert d.linear_algebra_used.startswith("dense") and s.linear_algebra_used.startswith("sparse")
    assert d.message == s.message == "all 1200 steps ok"
    np.testing.assert_array_equal(d.status, s.status)
    np.testing.assert_array_equal(d.iterations, s.iterations)
    size = d.model.size
    np.testing.assert_allclose(s.position, d.position, rtol=0, atol=1e-12 * size)
    np.testing.assert_allclose(s.condition, d.condition, rtol=1e-12)
    for name in ("input_force", "input_force_lagrange", "link_force", "joint_force", "ground_reaction"):
        a, b = d.forces[name][1], s.forces[name][1]
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.abs(a).max(), err_msg=name)


def _weights(model, scene, masses):
    """Q (S-independent, (P, 2)): each of ``masses``' weight m g at its centre (u, v) in the link's
    frame, distributed onto the link's first two points: r_G = (1 - C) r_a + C r_b with
    C = (u I + v R90) / L, so a gets (I - C)^T m g and b gets C^T m g."""
    Q = np.zeros((model.n_points, 2))
    R90 = np.array([[0.0, -1.0], [1.0, 0.0]])
    X0 = model.start_position
    for m in masses:
        link = next(ln for ln in scene.links if ln.name == m.link)
        a, b = (model.point_names.index(p) for p in link.points[:2])
        L = np.hypot(*(X0[b] - X0[a]))
        C = (m.center[0] * np.eye(2) + m.center[1] * R90) / L
        w = m.mass * np.asarray(G)
        Q[a] += (np.eye(2) - C).T @ w
        Q[b] += C.T @ w
    return Q


def test_reactions_equal_the_dense_lagrange_solution(dense_and_sparse):
    """lambda from numpy's dense solve of Phi_q^T lambda = Q (statics: gravity only), then the
    ground reactions -Q_p + sum_r lambda_r dPhi_r/dX_p and the pin forces of every body
    -Q_k,p + sum over the body's rows, from the dense Phi_X; and each body's pin forces sum
    to minus its weight (its rows are translation invariant)."""
    r = dense_and_sparse["sparse"]
    model, scene = r.model, r.scene
    pick = np.arange(0, r.n_steps, 37)  # 33 steps over the sweep
    X, s = r.position[pick], np.deg2rad(r.driver_value[pick])
    J = model.jacobian(X, s)  # (k, m, n)
    JX = model.jacobian_points(X, s)  # (k, m, P, 2)
    Q = _weights(model, scene, scene.masses)
    rhs = np.broadcast_to(Q[model.moving].reshape(-1), (len(pick), model.n_q))
    lam = np.linalg.solve(np.swapaxes(J, 1, 2), rhs[..., None])[..., 0]
    fixed = np.flatnonzero(model.fixed)
    ground = -Q[fixed] + np.einsum("kr,krpj->kpj", lam, JX[:, :, fixed])
    scale = np.abs(ground).max()
    np.testing.assert_allclose(r.forces["ground_reaction"][1][pick], ground, rtol=0, atol=1e-11 * scale)
    rows = body_rows(model)
    masses = {m.link: m for m in scene.masses}
    pins = r.forces["joint_force"][1][pick]
    by_link = {}
    for k, (li, p) in enumerate(joints(model)):
        link = scene.links[li]
        own = rows == li
        body_q = _weights(model, scene, [masses[link.name]])[p]  # the link's own weight at p
        expected = -body_q + np.einsum("kr,krj->kj", lam[:, own], JX[:, own, p])
        np.testing.assert_allclose(pins[:, k], expected, rtol=0, atol=1e-11 * scale)
        by_link.setdefault(link.name, []).append(pins[:, k])
    for name, forces in by_link.items():
        np.testing.assert_allclose(sum(forces), np.broadcast_to(-MASS * np.asarray(G), (len(pick), 2)),
                                   rtol=0, atol=1e-11 * scale, err_msg=name)


@settings(max_examples=25, deadline=None)
@given(loops=st.integers(16, 24), seed=st.integers(0, 10_000), spread=st.floats(0.0, 0.3))
def test_one_step_factor_agrees_with_numpy(loops, seed, spread):
    """At random configurations near the drawn one (off the constraint manifold: any regular
    Jacobian of the pattern): solves, J^T solves, det sign and the condition (estimated: a
    lower bound within 3.1x, or exact) against numpy's dense LU and inverse."""
    model = build_model(chain_scene(loops, 10))
    plan = step_lu(model)
    rng = np.random.default_rng(seed)
    q = model.q_of(model.start_position[None])[0] + spread * rng.normal(size=model.n_q)
    s = np.array([rng.uniform(-np.pi, np.pi)])
    J = model.jacobian(model.positions(q[None]), s[None])[0]
    f = plan.factor(q, s)
    # the entries come from the engine's affine map (terms read off Model.jacobian_terms at
    # probe configurations): rounding of sums of coordinates up to the mechanism's extent
    np.testing.assert_allclose(f.dense(), J, rtol=0, atol=1e-13 * model.size)
    b = rng.normal(size=(model.n_q, 3))
    x = np.linalg.solve(J, b)
    np.testing.assert_allclose(f.solve(b), x, rtol=0, atol=1e-9 * np.abs(x).max())
    np.testing.assert_allclose(f.solve(b, trans=True), np.linalg.solve(J.T, b), rtol=0,
                               atol=1e-9 * np.abs(np.linalg.solve(J.T, b)).max())
    assert f.det_sign() == np.linalg.slogdet(J)[0]
    exact = np.linalg.cond(J, 1)
    cond = f.condition(1e-6, 1e-3, within=10.0)
    assert exact / 3.2 <= cond <= exact * (1 + 1e-9)
    assert f.condition(1e-6, 1e-3, within=1e6) == pytest.approx(exact, rel=1e-9)  # exact near


def test_the_accuracy_ladder_shows_the_choice_and_both_rows():
    from linkpipe import accuracy

    scene = chain_scene(16, 40)
    ladder = accuracy.measure(scene, repeats=1, knobs=("linear_algebra",))
    rows = {r.value: r for r in ladder.rows}
    assert rows["dense"].linear_algebra == "dense (forced)"
    assert rows["sparse"].linear_algebra == "sparse LU (forced)"
    # the same errors against the reference, to rounding (tol 1e-12 of the size)
    for q in ("position", "velocity", "acceleration"):
        assert abs(rows["dense"].relative_error[q] - rows["sparse"].relative_error[q]) < 1e-12
    assert "one-step solves: sparse LU (auto: 64 >= 64 unknowns)" in accuracy.header(ladder)
    assert "newton (sparse LU)" in accuracy.table(ladder)


CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("*.toml")) + sorted((CONFIGS / "hard").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_shipped_scene_on_the_sparse_lu_agrees_with_dense(path):
    """Every row kind, driver kind, gap, toggle and change point of the shipped scenes, forced
    onto the sparse LU on the general path: the same statuses, positions within 1e-12 of the
    size where the condition is below 1e6, and
    within 1e-7 of it at the near-singular steps (a double root is determined only to about
    the square root of the tolerance there: both paths stop on it at rounding's whim)."""
    import dataclasses as dc

    scene = linkpipe.load_scene(path)
    d, s = (linkpipe.solve(dc.replace(scene, solver=dc.replace(scene.solver, method="newton",
                                                                linear_algebra=la)))
            for la in ("dense", "sparse"))
    if d.model.n_rows != d.model.n_q:
        assert s.linear_algebra_used.startswith("dense (no sparse engine")
    np.testing.assert_array_equal(d.status, s.status)
    np.testing.assert_array_equal(np.isfinite(d.position), np.isfinite(s.position))
    size = d.model.size
    regular = d.condition < 1e6
    np.testing.assert_allclose(s.position[regular], d.position[regular], rtol=0, atol=1e-12 * size)
    np.testing.assert_allclose(s.position, d.position, rtol=0, atol=1e-7 * size)
