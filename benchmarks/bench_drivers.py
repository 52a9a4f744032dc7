"""Sweep speed of the version 2 drivers: a cylinder-driven rocker and a two-link arm with a
motor between its links, in one run, against plain-numpy closed forms of the same machines.

    .venv/bin/python benchmarks/bench_drivers.py            # 36k and 360k steps (~10 s)
    .venv/bin/python benchmarks/bench_drivers.py --quick    # 36k steps

The cylinder-driven rocker is ``configs/dump_truck.toml`` (body hinged at H, cylinder C -> P)
with its sweep resampled to S steps; every tool returns positions, velocities and
accelerations of every point, arrays (S, n_points, 2):

* linkpipe dyads kernel: ``kinematics.solve_sweep`` alone (``method = "auto"``: the cylinder
  closes as a circle of the dyad chain) with order 2: the positions part of stage 1, without
  its link angles, condition estimate and link rates;
* linkpipe general path: ``method = "newton"`` positions, then ``kinematics.derivatives``;
* the closed form: the law of cosines for the body's angle and its two time derivatives, in
  plain numpy for this one machine.

The two-link arm (``angle`` shoulder + ``relative_to`` elbow) has no dyad plan (a relative
angle is not a dyad rule): it is timed on the general path against its forward kinematics.

Target (issue 13): the cylinder-driven rocker at >= 1 M configurations/s with velocities and
accelerations.
"""
from __future__ import annotations

import argparse
import dataclasses as dc
import math
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_sweep import best_of  # noqa: E402  (same process, same timing rule)

RATE = 0.1  # m/s, the config's own


def tipper_model(S: int, method: str):
    import linkpipe
    from linkpipe.model import build_model

    scene = linkpipe.load_scene(str(ROOT / "configs" / "dump_truck.toml"))
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=S, step=None) for d in scene.drivers),
                       solver=dc.replace(scene.solver, method=method))
    return build_model(scene)


def tipper_closed_form(model, s: np.ndarray):
    """Positions, velocities, accelerations (S, P, 2) of the tipper at cylinder lengths s."""
    X0 = model.start_position
    names = model.point_names
    H, C, P = (X0[names.index(n)] for n in "HCP")
    rp, rc = math.hypot(*(P - H)), math.hypot(*(C - H))
    a_p0, a_c = math.atan2(P[1] - H[1], P[0] - H[0]), math.atan2(C[1] - H[1], C[0] - H[0])
    k = 1.0 / (rp * rc)
    x = (rp * rp + rc * rc - s * s) * (0.5 * k)
    root = np.sqrt(1.0 - x * x)
    theta = a_c + np.arccos(x) - a_p0
    dtheta_ds = s * k / root
    w = dtheta_ds * RATE
    # d2theta/ds2 = k / root + s k x (dx/ds) / root^3 with dx/ds = -s k
    al = (k / root - s * s * k * k * x / root ** 3) * RATE * RATE
    c, sn = np.cos(theta), np.sin(theta)
    R = X0 - H  # (P, 2) body points from the hinge, as drawn
    rx = c[:, None] * R[:, 0] - sn[:, None] * R[:, 1]
    ry = sn[:, None] * R[:, 0] + c[:, None] * R[:, 1]
    X = np.stack([H[0] + rx, H[1] + ry], axis=2)
    V = np.stack([-w[:, None] * ry, w[:, None] * rx], axis=2)
    A = np.stack([-al[:, None] * ry - (w * w)[:, None] * rx,
                  al[:, None] * rx - (w * w)[:, None] * ry], axis=2)
    fixed = model.fixed
    X[:, fixed] = X0[fixed]
    V[:, fixed] = 0.0
    A[:, fixed] = 0.0
    return X, V, A


def linkpipe_run(model, s, method):
    from linkpipe import kinematics as kin

    S = len(s)
    sv, sd, sdd = s[:, None], np.full((S, 1), RATE), np.zeros((S, 1))
    out = kin.solve_sweep(model, sv, sd, sdd, order=2)
    assert out.method == method, out.method
    if method == "dyads":
        return out.position, out.velocity, out.acceleration
    der = kin.derivatives(model, out.position, sv, sd, sdd, out.status, True)
    return out.position, der["velocity"], der["acceleration"]


def rel_err(got, ref):
    return [float(np.abs(g - r).max() / max(np.abs(r).max(), 1e-300)) for g, r in zip(got, ref)]


def arm_rows(S, repeats):
    from linkpipe import kinematics as kin
    from linkpipe.model import build_model
    sys.path.insert(0, str(ROOT / "tests"))
    from test_drivers_v2 import two_link_arm

    scene = two_link_arm(method="newton")
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=S, step=None) for d in scene.drivers))
    model = build_model(scene)
    s = np.stack([np.radians(np.linspace(0, 90, S)), np.radians(np.linspace(120, 30, S))], axis=1)
    sd = np.broadcast_to(np.radians([10.0, -9.0]), (S, 2)).copy()
    sdd = np.zeros((S, 2))

    def run():
        out = kin.solve_sweep(model, s, sd, sdd, order=2)
        der = kin.derivatives(model, out.position, s, sd, sdd, out.status, True)
        return out.position, der["velocity"], der["acceleration"]

    t, (X, V, A) = best_of(run, repeats)
    L2 = math.hypot(0.5, 0.8)
    phi = s[:, 0] + math.pi + s[:, 1]
    B = np.stack([np.cos(s[:, 0]) + L2 * np.cos(phi), np.sin(s[:, 0]) + L2 * np.sin(phi)], axis=1)
    err = float(np.abs(X[:, model.point_names.index("B")] - B).max())
    return t, err


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    sizes = (36_000,) if args.quick else (36_000, 360_000)
    print("Cylinder-driven rocker (configs/dump_truck.toml): positions + velocities + "
          "accelerations of every point\n")
    print("| tool | steps | seconds | configurations/s | vs closed form | max rel. error x / v / a |")
    print("|---|---:|---:|---:|---:|---|")
    verdict = None
    for S in sizes:
        fast, newton = tipper_model(S, "auto"), tipper_model(S, "newton")
        s = np.linspace(1.35, 5.2, S)
        t_cf, ref = best_of(lambda: tipper_closed_form(fast, s), args.repeats)
        t_fast, got_fast = best_of(lambda: linkpipe_run(fast, s, "dyads"), args.repeats)
        t_newton, got_newton = best_of(lambda: linkpipe_run(newton, s, "newton"), args.repeats)
        for name, t, got in (("linkpipe dyads kernel (kinematics.solve_sweep alone)", t_fast, got_fast),
                             ("linkpipe general path kernel (Newton + derivatives)", t_newton, got_newton),
                             ("closed form, plain numpy", t_cf, ref)):
            e = " / ".join(f"{x:.1e}" for x in rel_err(got, ref))
            print(f"| {name} | {S:,} | {t:.4f} | {S / t / 1e6:.2f} M | {t_cf / t:.2f}x | {e} |")
        verdict = (S, S / t_fast)
    S, cps = verdict
    print(f"\nTarget: cylinder-driven rocker >= 1 M configurations/s with velocities and "
          f"accelerations: {cps / 1e6:.2f} M at {S:,} steps: {'met' if cps >= 1e6 else 'MISSED'}")
    S = sizes[-1]
    t, err = arm_rows(S, args.repeats)
    print(f"\nTwo-link arm, shoulder angle + elbow relative_to (general path, {S:,} steps): "
          f"{t:.3f} s, {S / t / 1e6:.2f} M configurations/s; max position error against the "
          f"forward kinematics {err:.1e} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
