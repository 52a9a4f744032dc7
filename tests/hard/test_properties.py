"""Hard case 8: property tests over random mechanisms.

* Grashof four-bars whose crank turns fully, on both branches, any size, either sweep direction:
  full sweeps equal the closed form (positions, velocities, accelerations, a coupler point).
* Non-Grashof four-bars: the steps inside the assembly range (with a margin) are ok and on the
  branch the sweep started on (also after re-entering the range), the ones outside are
  no_assembly.
* Offset slider-cranks, both branches: full sweeps equal the closed form.
* Random six-bars (no closed form): velocities and accelerations equal finite differences of the
  positions along the sweep.

Tolerances are relative to each example's size L and speed W. A margin keeps the examples away
from change points and assembly limits, where the Jacobian's condition (and with it the error
bound: condition x residual tolerance 1e-12 L) grows without bound; with the margins below the
condition stays under ~1e4, so 1e-7 L covers it with room to spare.
"""
import numpy as np
from hypothesis import HealthCheck, assume, example, given, settings, strategies as st

from linkpipe.closed_forms import fourbar, slider_crank
from hard_scenes import (acceleration, fourbar_B, fourbar_text, point, six_bar_text,
                         slider_crank_text, solve_text, velocity)
from linkpipe.status import NO_ASSEMBLY, OK

W = 10.0  # the builders' crank speed, rad/s
MARGIN = 0.05  # relative distance kept from change points and assembly limits
SETTINGS = dict(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])

lengths = st.floats(0.2, 3.0)
scales = st.sampled_from([1e-3, 1.0, 1e3])
methods = st.sampled_from(["auto", "newton"])
branches = st.sampled_from([+1, -1])
starts = st.floats(0.0, 360.0)
directions = st.sampled_from([+1, -1])


def full_rotation(a, d, sum_frac, diff_frac):
    """Return (b, c) for which a crank a on a ground d turns fully, keeping MARGIN from the
    coupler-rocker angle reaching 0 or 180 deg: b + c >= (d + a) / (1 - MARGIN) and
    |b - c| <= |d - a| (1 - MARGIN) - MARGIN d, with b + c and b - c placed by the fractions."""
    s = (d + a) / (1 - MARGIN) * (1 + 2 * sum_frac)
    t = (abs(d - a) * (1 - MARGIN) - MARGIN * d) * (2 * diff_frac - 1)
    return (s + t) / 2, (s - t) / 2


def compare_fourbar(r, a, b, c, d, branch, scale, uv):
    cf = fourbar(a, b, c, d, np.deg2rad(r.driver_value[:, 0]), W, 0.0, branch=branch,
                 coupler_uv=uv)
    L = max(a, b, c, d) * scale
    ok = r.status == OK
    for name in ("A", "B", "P"):
        np.testing.assert_allclose(point(r, name)[ok], scale * cf[name][ok], rtol=0, atol=1e-7 * L)
        np.testing.assert_allclose(velocity(r, name)[ok], scale * cf["V" + name][ok], rtol=0,
                                   atol=1e-7 * L * W)
        np.testing.assert_allclose(acceleration(r, name)[ok], scale * cf["A" + name][ok], rtol=0,
                                   atol=1e-6 * L * W**2)


@settings(**SETTINGS)
@given(a=st.floats(0.05, 0.8), sf=st.floats(0, 1), df=st.floats(0, 1), branch=branches,
       scale=scales, start=starts, direction=directions, method=methods, u=st.floats(-1, 2),
       v=st.floats(-1, 1))
def test_grashof_fourbar_full_sweeps(a, sf, df, branch, scale, start, direction, method, u, v):
    d = 1.0
    b, c = full_rotation(a, d, sf, df)
    # a coupler point on top of A or B is refused (two points at the same place)
    assume(np.hypot(u, v) > 0.05 and np.hypot(u - 1, v) > 0.05)
    text = fourbar_text(a, b, c, d, start, start + direction * 360.0, 37, branch=branch,
                        scale=scale, coupler_uv=(u * b, v * b))
    r = solve_text(text, method)
    assert (r.status == OK).all()
    compare_fourbar(r, a, b, c, d, branch, scale, (u * b, v * b))


@settings(**SETTINGS)
@given(a=lengths, b=lengths, c=lengths, d=lengths, branch=branches, scale=scales,
       frac=st.floats(0.1, 0.9), direction=directions, method=methods)
# found by hypothesis: a crank passing within 0.03 of the rocker's pivot, 10 deg steps. A step
# too long for the continuation (retried in sub-steps now), and a re-entry right at the assembly
# limit whose next step changed the assembly mode (the mode is kept until a step is well clear)
@example(a=2.7265625, b=1.5153784357667286, c=1.1592445705800904, d=2.6953125, branch=1,
         scale=0.001, frac=0.1, direction=-1, method="auto")
@example(a=2.7259002720813865, b=1.1592445705800904, c=1.5153784357667286,
         d=2.6949634338514645, branch=-1, scale=0.001, frac=0.1, direction=-1, method="auto")
def test_non_grashof_fourbar_full_sweeps(a, b, c, d, branch, scale, frac, direction, method):
    # the crank cannot turn fully: |A - O4| leaves [|b - c|, b + c] somewhere on the turn
    lo, hi = abs(b - c), b + c
    assume(d + a > hi * (1 + MARGIN) or abs(d - a) < lo * (1 - MARGIN))
    # keep off the Grashof equality s + l = p + q (change points, a folding kite at b = c, a = d)
    s_, p_, q_, l_ = sorted((a, b, c, d))
    assume(abs(s_ + l_ - p_ - q_) > MARGIN * l_)
    # the range of |A - O4| the crank reaches must overlap the assembly range with room to spare
    r_min, r_max = max(abs(d - a), lo * (1 + MARGIN)), min(d + a, hi * (1 - MARGIN))
    assume(r_max - r_min > MARGIN * d)
    # start inside: |A - O4| = r0 -> cos t = (a^2 + d^2 - r0^2) / (2 a d)
    r0 = r_min + frac * (r_max - r_min)
    start = np.degrees(np.arccos(np.clip((a * a + d * d - r0 * r0) / (2 * a * d), -1, 1)))
    text = fourbar_text(a, b, c, d, start, start + direction * 360.0, 37, branch=branch, scale=scale,
                        coupler_uv=(0.5 * b, 0.2 * b))
    # a gap narrower than a step is invisible to any stepper (the branch after it is then a
    # guess): leave out sweeps that jump over one
    fine = np.deg2rad(start + direction * np.linspace(0.0, 360.0, 36 * 50 + 1))
    fd = np.hypot(a * np.cos(fine) - d, a * np.sin(fine)).reshape(-1)
    in_range = (fd >= lo) & (fd <= hi)
    ends = in_range[::50]
    assume(all(in_range[50 * k:50 * k + 51].all() or not (ends[k] and ends[k + 1])
               for k in range(36)))
    r = solve_text(text, method)
    t = np.deg2rad(r.driver_value[:, 0])
    dist = np.hypot(a * np.cos(t) - d, a * np.sin(t))
    inside = (dist > lo * (1 + MARGIN) + MARGIN * 1e-3) & (dist < hi * (1 - MARGIN))
    outside = (dist < lo * (1 - MARGIN)) | (dist > hi * (1 + MARGIN))
    assert (r.status[inside] == OK).all()
    assert (r.status[outside] == NO_ASSEMBLY).all()
    # every assembled step of the margin is on the start's branch, re-entries included
    cf = fourbar(a, b, c, d, t, W, 0.0, branch=branch, coupler_uv=(0.5 * b, 0.2 * b))
    L = max(a, b, c, d) * scale
    np.testing.assert_allclose(point(r, "B")[inside], scale * cf["B"][inside], rtol=0, atol=1e-7 * L)
    np.testing.assert_allclose(velocity(r, "B")[inside], scale * cf["VB"][inside], rtol=0,
                               atol=1e-6 * L * W)


@settings(**SETTINGS)
@given(a=st.floats(0.05, 1.0), b=st.floats(1.2, 4.0), e=st.floats(-1.0, 1.0), branch=branches,
       scale=scales, start=starts, direction=directions, method=methods)
def test_slider_crank_full_sweeps(a, b, e, branch, scale, start, direction, method):
    assume(a + abs(e) <= b * (1 - MARGIN))
    r = solve_text(slider_crank_text(a, b, e, start, start + direction * 360.0, 37, branch=branch,
                                     scale=scale), method)
    assert (r.status == OK).all()
    cf = slider_crank(a, b, e, np.deg2rad(r.driver_value[:, 0]), W, 0.0, branch=branch)
    L = (a + b) * scale
    for name in ("A", "B"):
        np.testing.assert_allclose(point(r, name), scale * cf[name], rtol=0, atol=1e-7 * L)
        np.testing.assert_allclose(velocity(r, name), scale * cf["V" + name], rtol=0,
                                   atol=1e-7 * L * W)
        np.testing.assert_allclose(acceleration(r, name), scale * cf["A" + name], rtol=0,
                                   atol=1e-6 * L * W**2)


@settings(**SETTINGS)
@given(a=st.floats(0.1, 0.5), sf=st.floats(0, 0.5), df=st.floats(0, 1), start=starts,
       u=st.floats(0.2, 1.0), v=st.floats(-0.5, 0.5), qx=st.floats(-1.0, 1.0),
       qy=st.floats(0.5, 2.0), ox=st.floats(-1.0, 2.0), oy=st.floats(1.0, 3.0), method=methods)
def test_random_six_bar_velocities_equal_finite_differences(a, sf, df, start, u, v, qx, qy, ox, oy,
                                                            method):
    """No closed form: the derivatives must be those of the solved positions along the sweep."""
    d = 1.5
    b, c = full_rotation(a, d, sf, df)
    assume(np.hypot(u - 1, v) > 0.05)  # P on top of B is refused (two points at the same place)
    # Q somewhere above the coupler point, O6 on the frame; lengths from this start
    th = np.deg2rad(start)
    A = np.array([a * np.cos(th), a * np.sin(th)])
    B = fourbar_B(a, b, c, d, th)
    e_ = (B - A) / np.hypot(*(B - A))
    P = A + u * b * e_ + v * b * np.array([-e_[1], e_[0]])
    Q, O6 = P + [qx, qy], np.array([ox, oy])
    assume(np.hypot(*(Q - O6)) > 0.3 and np.hypot(*(Q - P)) > 0.3)
    # the dyad P-Q-O6 well away from in line (its transmission angle between 30 and 150 deg)
    e1, e2 = (Q - P) / np.hypot(*(Q - P)), (Q - O6) / np.hypot(*(Q - O6))
    assume(abs(e1[0] * e2[1] - e1[1] * e2[0]) > 0.5)
    h = 0.01  # deg between steps: 5-point stencils, truncation ~ h^4 (h = 1.7e-4 rad)
    # positions solved to 1e-15 of the size, so that rounding over h (and h^2) stays small
    r = solve_text(six_bar_text(a, b, c, d, (u * b, v * b), O6, Q, start - 10 * h, start + 10 * h,
                                21), method, tol=1e-15)
    L = 3.0
    hs = np.deg2rad(h) / W  # seconds per step at W rad/s
    X = r.position
    good = (r.status == OK) & (r.condition < 1e4)
    checked = 0
    for i in range(2, r.n_steps - 2):
        if not good[i - 2:i + 3].all():
            continue
        fd_v = (-X[i + 2] + 8 * X[i + 1] - 8 * X[i - 1] + X[i - 2]) / (12 * hs)
        fd_a = (-X[i + 2] + 16 * X[i + 1] - 30 * X[i] + 16 * X[i - 1] - X[i - 2]) / (12 * hs**2)
        # rounding: 1e-15 L / h ~ 2e-11 L W, / h^2 ~ 1e-7 L W^2; truncation ~ h^4 x^(5) / 30,
        # ~1e-8 L W on the most violent examples seen: 1e-7 and 1e-5 relative leave room
        np.testing.assert_allclose(r.velocity[i], fd_v, rtol=0, atol=1e-7 * L * W)
        np.testing.assert_allclose(r.acceleration[i], fd_a, rtol=0, atol=1e-5 * L * W**2)
        checked += 1
    assume(checked > 0)
