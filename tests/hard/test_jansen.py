"""Hard case 9: Theo Jansen's linkage (configs/jansen.toml), a multi-loop mechanism.

Six moving joints, two rigid triangles, one crank, over two full crank turns. Every step must be
ok; every bar length recomputed from the solved points must equal Jansen's number (the loops
close); positions must equal an independent dyad-by-dyad construction (circle intersections), and
velocities and accelerations its derivatives (complex step, then central differences).
"""
import numpy as np

from hard_scenes import (CONFIG_DIR, JANSEN, JANSEN_BARS, jansen_closed_form, point, solve_config,
                         method)  # noqa: F401 - a fixture
from linkpipe.status import OK

CONFIG = CONFIG_DIR / "jansen.toml"
W = 2 * np.pi  # crank speed: one turn per second (rate = 360 deg/s)


def solved(method):
    r = solve_config(CONFIG, method)
    assert (r.status == OK).all()
    return r


def test_two_full_turns_every_step_ok_loops_closed(method):
    r = solved(method)
    th = r.driver_value[:, 0]
    assert th[0] == 0.0 and th[-1] == 720.0
    size = r.model.size  # ~152 cm
    tol_abs = r.scene.solver.tol * size
    for p, q, letter in JANSEN_BARS:
        length = np.linalg.norm(point(r, p) - point(r, q), axis=1)
        # a constraint row's residual is (|d|^2 - L^2) / (2 L) ~ |d| - L, solved to tol * size
        np.testing.assert_allclose(length, JANSEN[letter], rtol=0, atol=tol_abs,
                                   err_msg=f"bar {letter} ({p}-{q})")
    # the frame: O at the origin, F at (-a, -l)
    np.testing.assert_array_equal(point(r, "F"), [[-JANSEN["a"], -JANSEN["l"]]] * r.n_steps)
    # two turns: the second repeats the first
    half = (r.n_steps - 1) // 2
    np.testing.assert_allclose(r.position[half:], r.position[:half + 1], rtol=0, atol=10 * tol_abs)


def test_positions_equal_the_dyad_construction(method):
    r = solved(method)
    cf = jansen_closed_form(np.deg2rad(r.driver_value[:, 0]))
    # error bound: the Jacobian's condition times the residual tolerance (both measured here)
    bound = np.nanmax(r.condition) * r.scene.solver.tol * r.model.size
    for name, P in cf.items():
        np.testing.assert_allclose(point(r, name), P, rtol=0, atol=bound, err_msg=name)


def test_velocities_and_accelerations_equal_the_derivatives(method):
    r = solved(method)
    th = np.deg2rad(r.driver_value[:, 0])
    h = 1e-20  # complex step: dX/dtheta exact to rounding, no cancellation
    dX = {k: v.imag / h for k, v in jansen_closed_form(th + 1j * h).items()}
    e = 1e-5  # central differences of the exact first derivative: error ~ e^2 X''' ~ 1e-8 size
    d2X = {k: (jansen_closed_form(th + e + 1j * h)[k].imag
               - jansen_closed_form(th - e + 1j * h)[k].imag) / (2 * e * h) for k in dX}
    size = r.model.size
    bound = np.nanmax(r.condition) * r.scene.solver.tol  # relative accuracy of the solve
    for name in ("A", "C", "D", "E", "G", "H"):
        i = r.point_names.index(name)
        np.testing.assert_allclose(r.velocity[:, i], dX[name] * W, rtol=0, atol=10 * bound * size * W,
                                   err_msg=name)
        np.testing.assert_allclose(r.acceleration[:, i], d2X[name] * W**2, rtol=0,
                                   atol=1e-7 * size * W**2, err_msg=name)


def test_foot_path_is_traced_and_has_the_flat_stride():
    r = solved("auto")
    assert "H" in r.scene.outputs.trace
    H = point(r, "H")
    # the Strandbeest's foot: a stride about 1.3 crank-turn widths long, lifted ~22 units
    assert 60 < H[:, 0].max() - H[:, 0].min() < 75
    assert 20 < H[:, 1].max() - H[:, 1].min() < 25
    # the flat part: over the lowest third of the path the foot stays within ~1% of the stride
    low = H[:, 1] < np.percentile(H[:, 1], 33)
    assert H[low, 1].max() - H[low, 1].min() < 0.02 * (H[:, 0].max() - H[:, 0].min())
