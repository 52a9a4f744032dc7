"""Two degrees of freedom, two drivers: the five-bar of ``configs/five_bar.toml``.

Exact answers: the tool point P as the intersection of the arms' circles (closed form); its
partial derivatives dP/dtheta_j by complex step of that closed form (exact to rounding, an
independent method from linkpipe's linear solves); velocities from the loop equations solved
by Cramer's rule, and accelerations by complex step of those velocities; each crank's torque
by virtual work summed by hand over the load, the weights and the inertia terms of the four
bodies with those derivatives.
"""
import dataclasses as dc

import h5py
import numpy as np
import pytest

import linkpipe
from linkpipe.__main__ import main
from conftest import CONFIG_DIR

CONFIG = CONFIG_DIR / "five_bar.toml"
GROUND, CRANK, ARM = 2.0, 1.0, 2.5
H = 1e-30  # complex step


def cs(z):
    return z.real, z.imag


def closed_form(t1, t2):
    """Return A1, A2, P (..., 2) at crank angles t1, t2 (real or complex arrays)."""
    A1 = np.stack([CRANK * np.cos(t1), CRANK * np.sin(t1)], -1)
    A2 = np.stack([GROUND + CRANK * np.cos(t2), CRANK * np.sin(t2)], -1)
    d = A2 - A1
    D2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]  # no conjugate: complex-step safe
    h = np.sqrt(ARM * ARM / D2 - 0.25)  # equal arms: P above the midpoint of A1-A2
    P = A1 + 0.5 * d + h[..., None] * np.stack([-d[..., 1], d[..., 0]], -1)
    return A1, A2, P


def velocities(t1, t2, w1, w2):
    """Return V_A1, V_A2, V_P: (P - A_j) . (V_P - V_Aj) = 0 solved by Cramer's rule."""
    A1, A2, P = closed_form(t1, t2)
    VA1 = w1 * np.stack([-A1[..., 1], A1[..., 0]], -1)
    VA2 = w2 * np.stack([-(A2[..., 1]), A2[..., 0] - GROUND], -1)
    g1, g2 = P - A1, P - A2
    b1 = (g1 * VA1).sum(-1)
    b2 = (g2 * VA2).sum(-1)
    det = g1[..., 0] * g2[..., 1] - g1[..., 1] * g2[..., 0]
    VP = np.stack([(b1 * g2[..., 1] - b2 * g1[..., 1]) / det,
                   (g1[..., 0] * b2 - g2[..., 0] * b1) / det], -1)
    return VA1, VA2, VP


def partials(f, t1, t2):
    """Return d f / d t1, d f / d t2 by complex step (f of real arrays, complex-step safe)."""
    return f(t1 + 1j * H, t2).imag / H, f(t1, t2 + 1j * H).imag / H


@pytest.fixture(scope="module")
def scene():
    return linkpipe.load_scene(str(CONFIG))


@pytest.fixture(scope="module", params=["auto", "newton"])
def result(request, scene):
    return linkpipe.solve(dc.replace(scene, solver=dc.replace(scene.solver, method=request.param)))


def motion(r):
    t = np.deg2rad(r.driver_value)
    w = np.deg2rad([d.rate for d in r.scene.drivers])
    return t[:, 0], t[:, 1], w[0], w[1]


def point(r, name):
    return r.position[:, r.point_names.index(name)]


def test_kinematics_equal_the_closed_form(result):
    r = result
    t1, t2, w1, w2 = motion(r)
    assert r.mobility.dof == 2 and (r.status == 0).all()
    A1, A2, P = closed_form(t1, t2)
    for name, want in (("A1", A1), ("A2", A2), ("P", P)):
        np.testing.assert_allclose(point(r, name), want, rtol=0, atol=1e-12 * 3.5)
    VA1, VA2, VP = velocities(t1, t2, w1, w2)
    dP1, dP2 = partials(lambda a, b: closed_form(a, b)[2], t1, t2)
    np.testing.assert_allclose(VP, dP1 * w1 + dP2 * w2, rtol=0, atol=1e-13)  # the two methods
    i = r.point_names.index("P")
    vscale = np.abs(VP).max()
    np.testing.assert_allclose(r.velocity[:, i], VP, rtol=0, atol=1e-12 * vscale)
    # constant rates: a_P = sum_j dV_P/dtheta_j w_j
    d1, d2 = partials(lambda a, b: velocities(a, b, w1, w2)[2], t1, t2)
    AP = d1 * w1 + d2 * w2
    np.testing.assert_allclose(r.acceleration[:, i], AP, rtol=0, atol=1e-11 * np.abs(AP).max())


def test_time_axis_is_shared(result):
    np.testing.assert_allclose(result.time, np.linspace(0.0, 2.0, 61), rtol=0, atol=1e-12)
    assert result.time_note == ""


BODIES = {"crank1": ("O1", "A1"), "crank2": ("O2", "A2"), "arm1": ("A1", "P"), "arm2": ("A2", "P")}


def points(t1, t2, w1, w2):
    """Return {point: (position, velocity)} (..., 2) of the closed form (complex-step safe)."""
    A1, A2, P = closed_form(t1, t2)
    VA1, VA2, VP = velocities(t1, t2, w1, w2)
    zero = 0.0 * A1
    return {"O1": (zero, zero), "O2": (zero + [GROUND, 0.0], zero), "A1": (A1, VA1),
            "A2": (A2, VA2), "P": (P, VP)}


def torques_by_virtual_work(scene, t1, t2, w1, w2):
    """Return each crank's torque (S, 2) with every effect of the scene, summed by hand:
    tau_j = -[F . dP/dt_j + sum over bodies ((m g - m a_G) . dG/dt_j - I alpha dphi/dt_j)]."""
    masses = {m.link: m for m in scene.masses}
    g = np.array(scene.gravity)
    F = np.array(scene.loads[0].force)
    ws = (w1, w2)

    def rate(f):  # d f / dt at constant crank rates, by complex step
        return sum(p * w for p, w in zip(partials(f, t1, t2), ws))

    dP = partials(lambda a, b: closed_form(a, b)[2], t1, t2)
    tau = -np.stack([dP[j] @ F for j in range(2)], axis=1)
    for link, (na, nb) in BODIES.items():
        m = masses[link]
        u = m.center[0] / (CRANK if link.startswith("crank") else ARM)  # centres on the axis

        def G(a, b, na=na, nb=nb, u=u):
            pts = points(a, b, w1, w2)
            return pts[na][0] + u * (pts[nb][0] - pts[na][0])

        def vG(a, b, na=na, nb=nb, u=u):
            pts = points(a, b, w1, w2)
            return pts[na][1] + u * (pts[nb][1] - pts[na][1])

        def d(a, b, na=na, nb=nb):
            pts = points(a, b, w1, w2)
            return pts[nb][0] - pts[na][0]

        def omega(a, b, na=na, nb=nb):
            pts = points(a, b, w1, w2)
            r, v = pts[nb][0] - pts[na][0], pts[nb][1] - pts[na][1]
            return (r[..., 0] * v[..., 1] - r[..., 1] * v[..., 0]) / (r * r).sum(-1)

        dG = partials(G, t1, t2)
        dd = partials(d, t1, t2)
        r = d(t1, t2)
        dphi = [(r[..., 0] * x[..., 1] - r[..., 1] * x[..., 0]) / (r * r).sum(-1) for x in dd]
        aG, alpha = rate(vG), rate(omega)
        force = m.mass * (g - aG)
        for j in range(2):
            tau[:, j] -= (force * dG[j]).sum(-1) - m.inertia * alpha * dphi[j]
    return tau


def test_crank_torques_by_virtual_work_with_loads_only(scene):
    """Loads only: tau_j = -F . dP/dtheta_j (dP/dtheta_j by complex step)."""
    r = linkpipe.solve(dc.replace(scene, effects=("loads",)))
    t1, t2, _, _ = motion(r)
    dP1, dP2 = partials(lambda a, b: closed_form(a, b)[2], t1, t2)
    F = np.array(scene.loads[0].force)
    want = -np.stack([dP1 @ F, dP2 @ F], axis=1)
    _, tau, unit = r.forces["input_force"]
    assert unit == "N*m" and tau.shape == (61, 2)
    np.testing.assert_allclose(tau, want, rtol=0, atol=1e-10 * np.abs(want).max())


def test_crank_torques_by_virtual_work_with_every_effect(result):
    """Gravity, inertia of all four bodies and the payload, on both stage-1 paths."""
    r = result
    t1, t2, w1, w2 = motion(r)
    want = torques_by_virtual_work(r.scene, t1, t2, w1, w2)
    _, tau, _ = r.forces["input_force"]
    np.testing.assert_allclose(tau, want, rtol=0, atol=1e-10 * np.abs(want).max())
    assert np.abs(want).max() > 5.0  # N m: the check has something to check


def test_rates_that_disagree_give_no_time_axis_and_say_so(scene, tmp_path, capsys):
    """theta2 at twice the rate: its sweep takes 1 s while theta1's takes 2 s, so no single time
    axis fits both; the run has none, and says why (summary and HDF5 attribute)."""
    text = CONFIG.read_text().replace("rate = -20.0", "rate = -40.0")
    path = tmp_path / "five_bar_rates.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path), "--no-rrd"]) == 0
    out = capsys.readouterr().out
    assert "no time axis: the drivers' rates give different times" in out
    assert "theta1 2 s, theta2 1 s" in out
    with h5py.File(tmp_path / "five_bar.h5") as f:
        assert "time" not in f
        assert "theta1 2 s, theta2 1 s" in f.attrs["time_note"]
    r = linkpipe.load_scene(str(path))
    assert linkpipe.solve(r).time is None
