"""Write configs/logs/crank_encoder.csv: a synthetic crank-encoder log (not a measurement).

The crank of the four-bar in configs/fourbar_crank_encoder.toml spins up from rest:
    angle(t) = 90 t^2 + 3 sin(2 pi 1.5 t)   degrees,  t in [0, 2] s
(one revolution in 2 s, with a 3-degree ripple at 1.5 Hz, as a drive with backlash might
give). The stamps are uneven: nominally every 5 ms with a uniform jitter of +-2 ms (seed 14),
first at 0 and last at exactly 2 s. The angle is written in millidegrees (column
``crank_mdeg``; the scene's scale = 0.001 turns it into degrees) with no quantisation or
noise. Sample 200 is left empty: a dropped encoder reading (the scene's step there is
no_input). A second column, ``rocker_deg``, is a rocker encoder: the rocker's angle from +x
(degrees) that the four-bar's geometry gives at each stamp (crank 1, coupler 3.5, rocker 3,
ground 4, B above the ground line: circle intersection written out below), plus Gaussian
noise of standard deviation 0.05 degrees (seed 15): the scene's [[measurements]] example.
Run from the repository root: python configs/logs/make_crank_encoder.py
"""
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent


def angle(t):
    return 90.0 * t ** 2 + 3.0 * np.sin(2 * np.pi * 1.5 * t)


ROCKER_NOISE_DEG = 0.05


def rocker_angle(crank_deg):
    """The rocker's direction O4 -> B (degrees) at crank angles (degrees): B is where the
    circle of radius 3.5 about A meets the circle of radius 3 about O4 = (4, 0), above."""
    t = np.radians(crank_deg)
    A = np.stack([np.cos(t), np.sin(t)], axis=-1)
    O4 = np.array([4.0, 0.0])
    v = O4 - A
    d = np.hypot(v[..., 0], v[..., 1])
    along = (3.5 ** 2 - 3.0 ** 2 + d ** 2) / (2 * d)
    h = np.sqrt(3.5 ** 2 - along ** 2)
    e = v / d[..., None]
    B = A + along[..., None] * e + h[..., None] * np.stack([-e[..., 1], e[..., 0]], axis=-1)
    return np.degrees(np.arctan2(B[..., 1] - O4[1], B[..., 0] - O4[0]))


def main() -> None:
    rng = np.random.default_rng(14)
    nominal = np.arange(0.0, 2.0 + 1e-12, 0.005)
    t = nominal + rng.uniform(-0.002, 0.002, len(nominal))
    t[0], t[-1] = 0.0, 2.0
    t = np.round(t, 6)  # the stamps as written: the angle is that of the written stamp
    mdeg = [f"{1000.0 * a:.6f}" for a in angle(t)]
    mdeg[200] = ""  # a dropped reading
    noise = np.random.default_rng(15).normal(0.0, ROCKER_NOISE_DEG, len(t))
    rocker = rocker_angle(angle(t)) + noise
    lines = ["t,crank_mdeg,rocker_deg"] + [f"{ti:.6f},{m},{r:.9f}"
                                           for ti, m, r in zip(t, mdeg, rocker)]
    (HERE / "crank_encoder.csv").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
