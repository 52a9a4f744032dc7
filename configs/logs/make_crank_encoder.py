"""Write configs/logs/crank_encoder.csv: a synthetic crank-encoder log (not a measurement).

The crank of the four-bar in configs/fourbar_crank_encoder.toml spins up from rest:
    angle(t) = 90 t^2 + 3 sin(2 pi 1.5 t)   degrees,  t in [0, 2] s
(one revolution in 2 s, with a 3-degree ripple at 1.5 Hz, as a drive with backlash might
give). The stamps are uneven: nominally every 5 ms with a uniform jitter of +-2 ms (seed 14),
first at 0 and last at exactly 2 s. The angle is written in millidegrees (column
``crank_mdeg``; the scene's scale = 0.001 turns it into degrees) with no quantisation or
noise. Sample 200 is left empty: a dropped encoder reading (the scene's step there is
no_input). Run from the repository root: python configs/logs/make_crank_encoder.py
"""
import pathlib

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent


def angle(t):
    return 90.0 * t ** 2 + 3.0 * np.sin(2 * np.pi * 1.5 * t)


def main() -> None:
    rng = np.random.default_rng(14)
    nominal = np.arange(0.0, 2.0 + 1e-12, 0.005)
    t = nominal + rng.uniform(-0.002, 0.002, len(nominal))
    t[0], t[-1] = 0.0, 2.0
    t = np.round(t, 6)  # the stamps as written: the angle is that of the written stamp
    mdeg = [f"{1000.0 * a:.6f}" for a in angle(t)]
    mdeg[200] = ""  # a dropped reading
    lines = ["t,crank_mdeg"] + [f"{ti:.6f},{m}" for ti, m in zip(t, mdeg)]
    (HERE / "crank_encoder.csv").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
