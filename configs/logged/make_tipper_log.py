"""Write configs/logged/logs/tipper_run.csv: a synthetic test-rig log of a tipper's lift.

Not a measurement, and not made by linkpipe: an independent model of the tipper of
configs/dump_truck.toml (body hinged at H = (0, 0), cylinder base C = (4.6, -0.9), top pin
P = (4.9, 0.4) and centre of mass G = (2.6, 0.85) on the body as drawn, metres):

* the cylinder's stroke follows a cycloidal law from 1.35 m to 5.2 m over 40 s;
* the body's angle theta(s) by the law of cosines in triangle H, C, P, with its derivatives
  in s written out by hand;
* the cylinder force from the power balance F s' = d/dt(I_H w^2 / 2 + m g y_G):
  F = I_H theta' (theta'' s'^2 + theta' s'') + m g dy_G/ds,
  with the true loaded mass m = 17,500 kg (the scene starts from a guess) and
  I_H = 52,000 kg m2 + m |HG|^2 about the hinge;
* the log holds what a rig records at 25 Hz: the stroke in millimetres (to 0.1 micrometre, a
  linear encoder's resolution: coarser steps are amplified in the spline's acceleration) and the
  cylinder's pressure in bar on a 120 mm bore (area pi 0.06^2 m2), with Gaussian noise of
  standard deviation 2 bar (seed 7) on the pressure.

Run from the repository root: python configs/logged/make_tipper_log.py
"""
import math
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
H, C, P, G = (np.array(v) for v in ([0.0, 0.0], [4.6, -0.9], [4.9, 0.4], [2.6, 0.85]))
MASS_TRUE = 17500.0
INERTIA_G = 52000.0
BORE_AREA = math.pi * 0.06 ** 2  # m2
PRESSURE_NOISE_BAR = 2.0
S0, S1, DURATION, RATE_HZ = 1.35, 5.2, 40.0, 25.0


def stroke(t):
    """Cycloidal law: s, s', s'' at times t."""
    tau = t / DURATION
    ds = S1 - S0
    s = S0 + ds * (tau - np.sin(2 * np.pi * tau) / (2 * np.pi))
    v = ds / DURATION * (1 - np.cos(2 * np.pi * tau))
    a = ds / DURATION ** 2 * 2 * np.pi * np.sin(2 * np.pi * tau)
    return s, v, a


def body_angle(s):
    """theta(s) (0 as drawn), theta', theta'' by the law of cosines."""
    rp, rc = np.hypot(*(P - H)), np.hypot(*(C - H))
    k = 1.0 / (rp * rc)
    x = (rp * rp + rc * rc - s * s) * 0.5 * k
    root = np.sqrt(1 - x * x)
    theta = math.atan2(C[1], C[0]) + np.arccos(x) - math.atan2(P[1], P[0])
    d1 = s * k / root
    d2 = k / root - s * s * k * k * x / root ** 3
    return theta, d1, d2


def cylinder_force(t, mass=MASS_TRUE):
    s, v, a = stroke(t)
    theta, d1, d2 = body_angle(s)
    gx, gy = G - H
    dy_ds = (gx * np.cos(theta) - gy * np.sin(theta)) * d1  # y_G = gx sin + gy cos
    inertia_h = INERTIA_G + mass * (gx * gx + gy * gy)
    return inertia_h * d1 * (d2 * v * v + d1 * a) + mass * 9.81 * dy_ds


def main() -> None:
    t = np.arange(0.0, DURATION + 1e-9, 1.0 / RATE_HZ)
    s, _, _ = stroke(t)
    pressure = cylinder_force(t) / BORE_AREA / 1e5
    pressure += np.random.default_rng(7).normal(0.0, PRESSURE_NOISE_BAR, len(t))
    lines = ["t_s,stroke_mm,pressure_bar"] + [
        f"{ti:.3f},{1000 * si:.4f},{pi:.3f}" for ti, si, pi in zip(t, s, pressure)]
    (HERE / "logs" / "tipper_run.csv").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
