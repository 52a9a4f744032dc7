"""Hard case 6: the same mechanism in metres and in millimetres gives the same results.

Every tolerance inside linkpipe is relative to the mechanism's size (the Newton tolerance, the
singular test, the leverage test), so scaling all lengths by 1000 must scale positions,
velocities and accelerations by 1000 to relative 1e-12, leave statuses, iteration counts and
condition numbers alone, keep forces and scale torques by 1000.
"""
import numpy as np

from hard_scenes import (fourbar_text, slider_driven_text, solve_text,
                         method)  # noqa: F401 - a fixture

K = 1000.0  # mm per m
REL = 1e-12  # the bound, relative to the mechanism's size (or speed, acceleration scale)

LOADS = """
[analysis]
effects = ["loads"]

[[loads]]
name = "weight"
point = "P"
force = [0.0, -100.0]

[[loads]]
name = "brake"
link = "rocker"
torque = {torque}
"""


def pair(build, **kw):
    """Solve a scene built in m and in mm; return both results."""
    return build(1.0, "m", **kw), build(K, "mm", **kw)


def compare(m, mm, size, speed, accel):
    np.testing.assert_array_equal(m.status, mm.status)
    np.testing.assert_array_equal(m.iterations, mm.iterations)
    np.testing.assert_allclose(mm.position / K, m.position, rtol=0, atol=REL * size, equal_nan=True)
    if m.velocity is not None:
        np.testing.assert_allclose(mm.velocity / K, m.velocity, rtol=0, atol=REL * speed,
                                   equal_nan=True)
        np.testing.assert_allclose(mm.acceleration / K, m.acceleration, rtol=0, atol=REL * accel,
                                   equal_nan=True)
    # the condition number is dimensionless: the same in both units
    np.testing.assert_allclose(mm.condition, m.condition, rtol=1e-9, equal_nan=True)


def test_crank_rocker_with_loads(method):
    def build(scale, unit):
        extra = LOADS.format(torque=-2.0 * scale)  # N*m -> N*mm
        return solve_text(fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 361, scale=scale, units=unit,
                                       coupler_uv=(1.5, 0.8), extra=extra), method)

    m, mm = pair(build)
    size, w = 4.0, 10.0
    compare(m, mm, size, size * w, size * w**2)
    # forces are forces in both (N); the input torque is N*m vs N*mm
    fm, fmm = m.forces, mm.forces
    scale_f = 100.0  # the load's size
    np.testing.assert_allclose(fmm["link_force"][1], fm["link_force"][1], rtol=0, atol=REL * scale_f * 10)
    np.testing.assert_allclose(fmm["input_force"][1] / K, fm["input_force"][1], rtol=0,
                               atol=REL * scale_f * size * 10)
    assert fmm["input_force"][2] == "N*mm" and fm["input_force"][2] == "N*m"


def test_assembly_limits_and_singular_steps_at_the_same_steps(method):
    t_lim = np.degrees(np.arccos((2.0**2 + 3.5**2 - 4.0**2) / (2 * 2.0 * 3.5)))

    def build(scale, unit):
        return solve_text(fourbar_text(2.0, 2.0, 2.0, 3.5, -t_lim, 360 - t_lim, 37, scale=scale,
                                       units=unit), method)

    m, mm = pair(build)
    assert set(np.unique(m.status)) == {0, 1, 2}  # ok, no_assembly and singular all present
    np.testing.assert_array_equal(m.status, mm.status)
    ok = m.status == 0
    # regular steps to 1e-12; the singular (double-root) steps to their own accuracy, sqrt(eps)
    np.testing.assert_allclose(mm.position[ok] / K, m.position[ok], rtol=0, atol=REL * 5.5)
    np.testing.assert_allclose(mm.position / K, m.position, rtol=0, atol=1e-7 * 5.5, equal_nan=True)


def test_slider_driven_coordinate_driver(method):
    """A coordinate driver: the driver values and the rate scale too; dead centres stay singular."""
    def build(scale, unit):
        return solve_text(slider_driven_text(1.0, 3.5, 0.0, 2.5, 4.5, 41, 179.0, rate=0.5,
                                             scale=scale), method)

    m, mm = pair(build)
    assert m.status[0] == 2 and m.status[-1] == 2
    ok = m.status == 0
    np.testing.assert_array_equal(m.status, mm.status)
    np.testing.assert_allclose(mm.position[ok] / K, m.position[ok], rtol=0, atol=REL * 4.5)
    # velocities are relative to the local crank-pin speed, unbounded near the dead centres
    vs = np.abs(m.velocity[ok]).max(axis=(1, 2))[:, None, None]
    assert (np.abs(mm.velocity[ok] / K - m.velocity[ok]) <= REL * vs).all()
    # and the crank leaves the inner dead centre on the same side in both (the start guess's)
    np.testing.assert_array_equal(np.sign(m.position[ok, 1, 1]), np.sign(mm.position[ok, 1, 1]))


def _shifted(text: str, offset: float) -> str:
    """The scene with every drawn point moved by (offset, offset)."""
    import re
    return re.sub(r"x = ([-0-9.e]+), y = ([-0-9.e]+)", lambda m: (
        f"x = {float(m.group(1)) + offset!r}, y = {float(m.group(2)) + offset!r}"), text)


def test_the_same_mechanism_far_from_the_origin(method):
    """The crank-rocker with a load moved 1e2 ... 1e5 times its size away from the origin:
    float64 holds its coordinates only to eps x the offset, so positions agree to that and
    velocities and the input torque to ~eps x offset / size relative (a handful of
    coordinates' rounding: bound 32 eps offset / size). The Jacobian's coefficients on q are
    read with the fixed points at the origin (they had lost eps x offset / size and were then
    multiplied by q ~ offset: 6.4e-9 relative at 1e4 x the size); where 4 eps x the offset
    passes tol x the size (1e4, 1e5 here) the residual tolerance is floored at what float64
    resolves there, with a warning (at 1e5 every step had been refused)."""
    text = fourbar_text(1.0, 3.5, 3.0, 4.0, 0.0, 360.0, 73, coupler_uv=(1.5, 0.8),
                        extra=LOADS.format(torque=-2.0))
    base = solve_text(text, method)
    size = 4.0
    eps = np.finfo(float).eps
    for offset in (1e2, 1e3, 1e4, 1e5):
        far = solve_text(_shifted(text, offset), method)
        np.testing.assert_array_equal(far.status, base.status)
        assert (far.status == 0).all()
        np.testing.assert_allclose(far.position - offset, base.position, rtol=0,
                                   atol=8 * eps * offset)
        bound = 32 * eps * offset / size
        for name, a, b in (("velocity", far.velocity, base.velocity),
                           ("input torque", far.forces["input_force"][1],
                            base.forces["input_force"][1])):
            err = np.abs(a - b).max() / np.abs(b).max()
            assert err <= bound, (name, offset, err, bound)
        floored = [w for w in far.warnings if "float64 resolves positions there" in w]
        assert len(floored) == (offset >= 1e4), far.warnings  # 4 eps offset > 1e-12 x 4.9
