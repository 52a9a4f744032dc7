"""The layouts of the one set of equations agree: what used to be checked at run time.

``linkpipe/model/equations.py`` writes every constraint row once. ``Model`` evaluates the rows
on stacked sweeps, the sequential continuation's one-step kernels (``kinematics._Step``) on
Python floats, and the sparse engine (``kin.sparse.Engine``) on per-coordinate arrays. Here, for
every shipped scene and for hypothesis-drawn four-bars, slider-cranks and six-bars:

* Φ, Φq, Φs of the float kernels equal the model's to the last bit (the continuation's branch
  choices at a double root depend on the last bit);
* the engine's Φ and Φs equal the model's to the last bit, and its affine reconstruction of
  Φq equals the model's to rounding of the affine coefficients (1e-13 of the largest entry);
* Φq is the derivative of Φ and Φs its derivative in the driver (central differences, to
  their truncation error), and γ = −d(Φq q̇)/dt · (second differences along a motion).
"""
import pathlib
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import linkpipe
from linkpipe import kinematics
from linkpipe import kinematics as kin
from linkpipe.model import build_model

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "hard"))
import hard_scenes as hs  # noqa: E402

SCENES = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "configs" / "hard").glob("*.toml"))


def _samples(model, n=4, seed=3):
    """Random shapes of the mechanism's size and driver values (not assembled: equality of
    the layouts holds everywhere, not only on the constraint manifold)."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, model.n_q)) * model.size
    s = rng.uniform(-4, 4, size=(n, model.n_drivers))
    v = rng.normal(size=(n, model.n_points, 2)) * model.size
    v[:, model.fixed] = 0.0
    return q, s, v, rng.normal(size=(n, model.n_drivers)), rng.normal(size=(n, model.n_drivers))


def _layouts_agree(model):
    q, s, V, s_dot, s_ddot = _samples(model)
    X = model.positions(q)
    step = kinematics.step._step_kernels(model)
    for i in range(len(q)):  # one step at a time: the float kernels against the model at S = 1
        np.testing.assert_array_equal(step.phi(q[i], s[i]), model.phi(X[i:i + 1], s[i:i + 1])[0])
        np.testing.assert_array_equal(step.jac(q[i], s[i]), model.jacobian(X[i:i + 1], s[i:i + 1])[0])
        np.testing.assert_array_equal(step.phi_s(q[i], s[i]), model.phi_s(X[i:i + 1], s[i:i + 1])[0])
    eng = kin.sparse.engine(model)
    if eng is None:  # non-square (redundant) scenes take the dense path, by declaration
        assert model.n_rows != model.n_q
        return
    X2 = eng.points(np.ascontiguousarray(q.T))
    np.testing.assert_array_equal(eng.phi(X2, s.T).T, model.phi(X, s))
    np.testing.assert_array_equal(eng.phi_s(X2, s.T).T, model.phi_s(X, s))
    J = model.jacobian(X, s)
    Je = eng.dense(eng.entries(q, s))
    assert np.abs(Je - J).max() <= 1e-13 * max(1.0, np.abs(J).max())


def _derivatives_agree(model):
    """Φq and Φs are the derivatives of Φ; γ closes Φq q̈ = γ along a smooth motion."""
    q, s, _, _, _ = _samples(model, n=2, seed=5)
    h = 1e-6 * model.size
    for i in range(len(q)):
        X, si = model.positions(q[i:i + 1]), s[i:i + 1]
        J = model.jacobian(X, si)[0]
        fd = np.empty_like(J)
        for k in range(model.n_q):
            dq = np.zeros(model.n_q)
            dq[k] = h
            fd[:, k] = (model.phi(model.positions(q[i:i + 1] + dq), si)[0]
                        - model.phi(model.positions(q[i:i + 1] - dq), si)[0]) / (2 * h)
        assert np.abs(fd - J).max() <= 1e-7 * max(1.0, np.abs(J).max())
    # along q(t) = q0 + q1 t + q2 t^2 / 2 and s(t) likewise: d2/dt2 Phi = Phi_q q'' - gamma = 0
    # at t = 0 means gamma = Phi_q q2 - d2Phi/dt2
    rng = np.random.default_rng(8)
    q0, q1, q2 = (rng.normal(size=model.n_q) * model.size for _ in range(3))
    s0, s1, s2 = (rng.uniform(-1, 1, size=model.n_drivers) for _ in range(3))
    dt = 1e-4

    def phi_at(t):
        return model.phi(model.positions((q0 + q1 * t + q2 * t * t / 2)[None]),
                         (s0 + s1 * t + s2 * t * t / 2)[None])[0]

    d2 = (phi_at(dt) - 2 * phi_at(0.0) + phi_at(-dt)) / dt**2
    X0 = model.positions(q0[None])
    V0 = model.velocities(q1[None])
    J = model.jacobian(X0, s0[None])[0]
    g = model.gamma(X0, V0, s0[None], s1[None], s2[None])[0]
    # d2Phi/dt2 = Phi_q q2 - gamma (gamma holds every other term, the driver's -Phi_s s'' too)
    expected = J @ q2 - g
    scale = max(1.0, np.abs(J @ q2).max(), np.abs(g).max())
    assert np.abs(d2 - expected).max() <= 1e-5 * scale


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_layouts_agree_for_every_shipped_scene(path):
    model = build_model(linkpipe.load_scene(str(path)))
    _layouts_agree(model)
    _derivatives_agree(model)


@settings(max_examples=25, deadline=None)
@given(family=st.sampled_from(["fourbar", "slider_crank", "six_bar"]),
       a=st.floats(0.3, 1.5), b=st.floats(2.0, 4.0), c=st.floats(2.0, 4.0), d=st.floats(2.5, 4.5),
       scale=st.sampled_from([1e-3, 1.0, 1e3]), start=st.floats(0.0, 360.0))
def test_layouts_agree_for_families_of_mechanisms(family, a, b, c, d, scale, start):
    if family == "fourbar":
        text = hs.fourbar_text(1.0, 3.5, 3.0, 4.0, start, start + 10, 3, scale=scale,
                               coupler_uv=(a, b - 2))
    elif family == "slider_crank":
        text = hs.slider_crank_text(a, b + 1, c - 2.5, start, start + 10, 3, scale=scale)
    else:
        text = hs.six_bar_text(1.0, 3.5, 3.0, 4.0, (1.2, 0.9), (5.5, 3.0), (4.6, 4.2), 0.0, 10.0, 3)
    model = build_model(linkpipe.parse_scene(text, f"{family}.toml"))
    _layouts_agree(model)


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_the_newton_loop_converges_quadratically_from_near_a_root(path):
    """The one Newton loop (``step._Step.newton``, which :func:`kinematics.newton` runs step by
    step): from the assembled start moved by 1e-3 of the size it returns to a root within tol
    in at most 5 iterations (quadratic convergence: 1e-3 -> 1e-6 -> 1e-12), with the analytic
    and the finite-difference Jacobian alike, and every step of a batch as alone."""
    from linkpipe.kinematics import newton, start_state

    model = build_model(linkpipe.load_scene(str(path)))
    if not model.n_q:
        return
    from linkpipe.kinematics import driver_motion

    _, s, _, _ = driver_motion(model)
    tol_abs = model.scene.solver.tol * model.size
    q0, _ = start_state(model, s[0], tol_abs, 25)
    from linkpipe.kinematics.linalg import condition

    cond = condition(model.jacobian(model.positions(q0[None]), s[:1]))[0]
    if cond * model.scene.solver.singular_rcond >= 1e-3:
        pytest.skip("the start is a singular shape (a limit, a dead centre): Newton is linear there")
    rng = np.random.default_rng(13)
    guesses = q0 + rng.normal(size=(3, q0.size)) * 1e-3 * model.size
    for jac in ("analytic", "finite_difference"):
        q, res, its, conv = newton(model, guesses, np.repeat(s[:1], 3, axis=0), tol_abs, 25, jac)
        assert conv.all() and (res <= tol_abs).all() and (its <= 5).all(), (res, its)
        for i in range(3):
            one = newton(model, guesses[i:i + 1], s[:1], tol_abs, 25, jac)
            np.testing.assert_array_equal(one[0], q[i:i + 1])


_ALL_CONFIGS = sorted((pathlib.Path(__file__).resolve().parent.parent / "configs").rglob("*.toml"))


@pytest.mark.parametrize("config", [c for c in _ALL_CONFIGS if "studies" not in c.parts],
                         ids=lambda p: p.stem)
def test_condition_without_the_inverse_is_the_inverses_bit_for_bit(config):
    """The condition from the inverse's column sums block by block (only the columns each block
    reaches) equals the one from the whole inverse, bit for bit, at every step of every shipped
    scene (singular, unassembled and missing-input steps included: inf in both); the column
    sums themselves too wherever the Jacobian's entries are finite."""
    from linkpipe.kinematics.sparse import engine

    result = linkpipe.solve(config)
    eng = engine(result.model)
    if eng is None:
        pytest.skip("redundant constraints: the dense path, no engine")
    _, s, _, _ = kin.driver_motion(result.model)
    X = np.where(np.isfinite(result.position), result.position, 0.0)
    if result.scene.dynamics is not None:  # the integrated driver values, up to the instant
        reached = np.isfinite(result.kinematics.s).all(axis=1)  # an event ended the run at
        s, X = result.kinematics.s[reached], X[reached]   # (no position of any point after it)
    E = eng.entries(result.model.q_of(X), s)
    inv = eng.inverse(E)
    np.testing.assert_array_equal(eng.condition(E), eng.condition(E, inv))
    finite = np.isfinite(E).all(axis=0)
    np.testing.assert_array_equal(eng.inverse_column_sums(E)[:, finite],
                                  np.abs(inv).sum(axis=0)[:, finite])
    assert finite.sum() >= 0.9 * len(finite)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_condition_without_the_inverse_at_random_and_singular_configurations(seed):
    """Any configuration of the six-bar and the slider-crank, exact singular ones among them (a
    block of the Jacobian with a zero determinant): the same conditions, bit for bit."""
    from linkpipe.kinematics.sparse import engine

    rng = np.random.default_rng(seed)
    for text in (hs.six_bar_text(1.0, 3.5, 3.0, 4.0, (1.2, 0.9), (5.5, 3.0), (4.6, 4.2),
                                 0.0, 20.0, 5),
                 hs.slider_crank_text(1.0, 3.0, 0.3, 0.0, 90.0, 5)):
        model = build_model(linkpipe.parse_scene(text, "m.toml"))
        eng = engine(model)
        q = rng.normal(size=(64, model.n_q)) * model.size
        q[:8] = 0.0  # every point at the origin: zero determinants
        s = rng.uniform(-4, 4, size=(64, model.n_drivers))
        E = eng.entries(q, s)
        np.testing.assert_array_equal(eng.condition(E), eng.condition(E, eng.inverse(E)))


def test_norm1_is_the_dense_largest_column_sum_bit_for_bit():
    """The engine's 1-norm, column by column in place, equals numpy's |J|_1 of the dense
    Jacobians to the last bit (the same additions in the same order), every shipped scene."""
    from linkpipe.kinematics.sparse import engine

    for config in [c for c in _ALL_CONFIGS if "studies" not in c.parts]:
        model = build_model(linkpipe.load_scene(config))
        eng = engine(model)
        if eng is None:
            continue
        q, s = _samples(model, n=16)[:2]
        E = eng.entries(q, s)
        np.testing.assert_array_equal(eng.norm1(E), np.abs(eng.dense(E)).sum(axis=1).max(axis=1))


def test_entries_of_points_are_the_entries_of_their_coordinates():
    """Engine.entries_of (one gather of the moving coordinates) gives Engine.entries of
    model.q_of, bit for bit, on every shipped scene with an engine."""
    from linkpipe.kinematics.sparse import engine

    for config in [c for c in _ALL_CONFIGS if "studies" not in c.parts]:
        model = build_model(linkpipe.load_scene(config))
        eng = engine(model)
        if eng is None:
            continue
        q, s = _samples(model, n=16)[:2]
        X = model.positions(q)
        np.testing.assert_array_equal(model.qT_of(X), model.q_of(X).T)
        np.testing.assert_array_equal(eng.entries_of(X, s), eng.entries(q, s))


def _link_rates_as_written(link_a, link_b, X, V, A):
    """The links' rates by the formula as written (one numpy expression per quantity, the
    form link_rate_rows had before it worked in scratch columns)."""
    w, al = [], []
    for a, b in zip(link_a, link_b):
        dx, dy = X[:, b, 0] - X[:, a, 0], X[:, b, 1] - X[:, a, 1]
        dvx, dvy = V[:, b, 0] - V[:, a, 0], V[:, b, 1] - V[:, a, 1]
        dax, day = A[:, b, 0] - A[:, a, 0], A[:, b, 1] - A[:, a, 1]
        n2 = dx * dx + dy * dy
        wj = (dx * dvy - dy * dvx) / n2
        w.append(wj)
        al.append((dx * day - dy * dax) / n2 - 2 * wj * (dx * dvx + dy * dvy) / n2)
    return np.stack(w, axis=1), np.stack(al, axis=1)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 300), scale=st.integers(-200, 200))
def test_link_rate_columns_are_the_written_formula_bit_for_bit(seed, n, scale):
    """The links' rates in scratch columns (link_rate_rows on whole rows, and the dyads' chunk
    columns with the fixed points read as at rest) equal the formula as written to the last
    bit, NaN, inf and zero-length links included; the fused directions equal
    model.link_angles."""
    from linkpipe.kinematics.angles import link_rate_columns, link_rate_rows

    model = build_model(linkpipe.load_scene(str(_ALL_CONFIGS[0].parent / "fourbar_crank_rocker.toml")))
    rng = np.random.default_rng(seed)
    P, L = model.n_points, len(model.link_a)
    X = rng.normal(size=(n, P, 2)) * 10.0 ** (scale / 10)
    V, A = (rng.normal(size=(n, P, 2)) * 10.0 ** (scale / 10) for _ in range(2))
    fixed = np.flatnonzero(model.fixed)
    X[:, fixed] = model.start_position[fixed]
    V[:, fixed] = A[:, fixed] = 0.0
    k = rng.integers(0, n, 3)
    X[k[0], model.link_b[0]] = model.start_position[model.link_a[0]] if not model.fixed[model.link_b[0]] else np.nan
    V[k[1], rng.integers(0, P)] = np.nan
    A[k[2], rng.integers(0, P)] = np.inf
    V[:, fixed] = A[:, fixed] = 0.0
    with np.errstate(all="ignore"):
        want_w, want_al = _link_rates_as_written(model.link_a, model.link_b, X, V, A)
        w, al = np.empty((n, L)), np.empty((n, L))
        link_rate_rows(model.link_a, model.link_b, X, V, A, w, al)
        np.testing.assert_array_equal(w, want_w)
        np.testing.assert_array_equal(al, want_al)
        cw, cal, ang = np.empty((n, L)), np.empty((n, L)), np.empty((n, L))

        def col(Y, p):  # the dyads' columns: a fixed point's position a float, its rates 0.0
            if model.fixed[p]:
                return (float(Y[0, p, 0]), float(Y[0, p, 1])) if Y is X else (0.0, 0.0)
            return np.ascontiguousarray(Y[:, p, 0]), np.ascontiguousarray(Y[:, p, 1])

        link_rate_columns(model.link_a, model.link_b, lambda p: col(X, p), lambda p: col(V, p),
                          lambda p: col(A, p), cw, cal, still={int(p) for p in fixed}, angle=ang)
    np.testing.assert_array_equal(cw, want_w)
    np.testing.assert_array_equal(cal, want_al)
    np.testing.assert_array_equal(ang, model.link_angles(X))
