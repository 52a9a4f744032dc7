"""Write configs/logged/logs/tipper_raise_lower.csv: a synthetic rig log of the tipper of
configs/dump_truck.toml raised and lowered again, with seal and pin friction.

Not a measurement, and not made by linkpipe: an independent closed-form model (the geometry
of make_tipper_log.py, which this imports: law of cosines, power balance), with

* the stroke raised by a cycloidal law from 1.35 m to 5.2 m over 40 s, then lowered back
  over the next 40 s;
* the hinge pin H's friction: a torque mu r |F_H| opposing the body's rotation (mu = 0.15,
  r = 0.04 m), F_H the hinge's force on the body from the body's Newton equation
  (F_H = m a_G - m g - F_net e, e the cylinder's direction), solved with the cylinder's net
  force by fixed-point iteration, F_net s' = d/dt(kinetic + potential) + mu r |F_H| |w|;
* the seal's friction added to the net force: coulomb 3000 N x sign(s') + viscous
  20000 N s/m x s' (the pressure pushes the piston against it);
* the pressure on a 120 mm bore, with 2 bar of Gaussian noise (seed 11), the true loaded mass
  17,500 kg.

Raising, the pressure carries the load plus the friction; lowering, the load minus it: the
difference at one stroke is twice the friction. Run from the repository root:
python configs/logged/make_tipper_friction_log.py
"""
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_tipper_log import (BORE_AREA, C, G, H, INERTIA_G, MASS_TRUE, P, S0, S1,  # noqa: E402
                             body_angle)

COULOMB, VISCOUS = 3000.0, 20000.0  # N, N s/m
MU, PIN_RADIUS = 0.15, 0.04
NOISE_BAR, HALF = 2.0, 40.0  # bar; s per stroke


def stroke(t):
    """Raise over [0, HALF], lower over [HALF, 2 HALF]: s, s', s'' (cycloidal each way)."""
    up = t <= HALF
    tau = np.where(up, t, t - HALF) / HALF
    ds = np.where(up, S1 - S0, S0 - S1)
    start = np.where(up, S0, S1)
    s = start + ds * (tau - np.sin(2 * np.pi * tau) / (2 * np.pi))
    v = ds / HALF * (1 - np.cos(2 * np.pi * tau))
    a = ds / HALF ** 2 * 2 * np.pi * np.sin(2 * np.pi * tau)
    return s, v, a


def rotate(vec, theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * vec[0] - s * vec[1], s * vec[0] + c * vec[1]], axis=-1)


def cylinder_force(t, mass=MASS_TRUE, coulomb=COULOMB, viscous=VISCOUS, mu=MU):
    """The pressure force (N) at times t: net force (load, inertia, pin friction) + seal."""
    s, v, a = stroke(t)
    theta, d1, d2 = body_angle(s)
    w, alpha = d1 * v, d2 * v * v + d1 * a
    g_rel = rotate(G - H, theta)
    p_rel = rotate(P - H, theta)
    inertia_h = INERTIA_G + mass * float(np.dot(G - H, G - H))
    a_g = (alpha[:, None] * np.stack([-g_rel[:, 1], g_rel[:, 0]], axis=1)
           - (w * w)[:, None] * g_rel)
    e = (H + p_rel) - C
    e /= np.hypot(e[:, 0], e[:, 1])[:, None]
    # frictionless: F s' = I_H w alpha + m g dy_G/dt, dy_G/dt = w x_G (G turning about H)
    base = inertia_h * d1 * alpha + mass * 9.81 * g_rel[:, 0] * d1
    net = base.copy()
    for _ in range(60):  # F_H depends on the net force, the friction on F_H
        f_h = mass * a_g - mass * np.array([0.0, -9.81]) - net[:, None] * e
        net = base + mu * PIN_RADIUS * np.hypot(f_h[:, 0], f_h[:, 1]) * np.abs(d1) * np.sign(v)
    return net + coulomb * np.sign(v) + viscous * v


def write(path, rate_hz=25.0, seed=11):
    t = np.arange(0.0, 2 * HALF + 1e-9, 1.0 / rate_hz)
    s, _, _ = stroke(t)
    pressure = cylinder_force(t) / BORE_AREA / 1e5
    pressure += np.random.default_rng(seed).normal(0.0, NOISE_BAR, len(t))
    lines = ["t_s,stroke_mm,pressure_bar"] + [
        f"{ti:.6f},{1000 * si:.4f},{pi:.4f}" for ti, si, pi in zip(t, s, pressure)]
    pathlib.Path(path).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write(HERE / "logs" / "tipper_raise_lower.csv")
