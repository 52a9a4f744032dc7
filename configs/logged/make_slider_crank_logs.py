"""Write the slider-crank rig's logs (SYNTHETIC) from an independent closed-form model.

A motor drives the crank of an offset slider-crank (crank 60 mm, rod 240 mm, the slide's line
15 mm above the crank's shaft: the TRUE geometry; the rig's drawing, which the scenes start
from, says 58, 243 and 12 mm). Six runs at six motor voltages, each logged as a rig's logger
writes it:

- ``rig/run1`` .. ``rig/run6``: no suffix, tab-separated, 50 Hz; the header starts with ``%``
  and has one more field (a comment column) than the rows; a units row under it;
- ``wheel``: the encoder's cumulative angle in degrees since power-on (run 1 starts at
  5444.9 deg); the crank angle is the wheel's plus an offset of a few degrees (modulo whole
  turns), different every run (the rig homes the crank to 40 deg, to within a few degrees);
- ``slide``: a string-pot's reading in mm from the slide's outer end (clamped anew each run:
  its zero moves by a few mm), 0.05 mm of noise, and five sensor glitches (spikes of 20 to
  40 mm) per run;
- ``wheel_speed`` in rpm and ``slide_speed`` in mm/s (the slide's speed, measured as the
  string-pot unwinds: minus d(x_B)/dt);
- ``rig_laser/run1.csv``: a second logger (comma-separated, 100 Hz, its clock in ms) with a
  laser's distance to the slide in metres, its stamps 6 ms late.

The model, for a crank angle theta(t) = theta0 + w t + A sin(2 pi f t) (a motor with a speed
ripple), crank a, rod b, offset e:
    x_B = a cos(theta) + sqrt(b^2 - (a sin(theta) - e)^2)
and its time derivative in closed form. Nothing of linkpipe is used.

    python configs/logged/make_slider_crank_logs.py     # rewrites rig/ and rig_laser/
"""
from __future__ import annotations

import math
import pathlib

import numpy as np

#: the true geometry (mm)
CRANK, ROD, OFFSET = 60.0, 240.0, 15.0
#: each run: motor voltage, mean speed (rpm), encoder count at the start (deg), the encoder
#: index's error (deg), the string-pot's zero (mm from the crank's shaft along the slide)
RUNS = [
    (6.0, 40.0, 5444.9, 3.1, 312.4),
    (9.0, 62.0, 11917.5, -4.2, 309.8),
    (12.0, 83.0, 761.7, 1.7, 311.1),
    (15.0, 101.0, 33156.4, -2.6, 313.9),
    (18.0, 124.0, 1845.3, 5.3, 308.7),
    (21.0, 142.0, 90039.2, -0.8, 310.5),
]
#: deg: the crank's angle where the rig homes it before each run, to within the run's homing
#: error (above); the encoder then reads about HOME plus whole turns since power-on, so the
#: offset (crank angle - wheel) is a few degrees modulo a turn, different every run
HOME = 40.0
RATE_HZ, SECONDS = 50.0, 4.0
NOISE_MM = 0.05
LASER_LAG_S, LASER_HZ, LASER_ZERO_MM = 0.006, 100.0, 100.0  # the laser sits 100 mm behind the shaft
SEED = 11


def crank(t: np.ndarray, rpm: float, start_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Crank angle (rad) and rate (rad/s): theta0 + w t + A sin(2 pi f t), a 3 % ripple at
    the turn's frequency (a motor's cogging)."""
    w = rpm * 2.0 * math.pi / 60.0
    f = rpm / 60.0
    A = 0.03 * w / (2.0 * math.pi * f)
    theta = math.radians(start_deg) + w * t + A * np.sin(2.0 * math.pi * f * t)
    rate = w + A * 2.0 * math.pi * f * np.cos(2.0 * math.pi * f * t)
    return theta, rate


def slide(theta: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x_B (mm) and its time derivative (mm/s) of the true slider-crank."""
    h = CRANK * np.sin(theta) - OFFSET
    root = np.sqrt(ROD ** 2 - h ** 2)
    x = CRANK * np.cos(theta) + root
    dx = (-CRANK * np.sin(theta) - h * CRANK * np.cos(theta) / root) * rate
    return x, dx


def write_rig(folder: pathlib.Path, k: int, run, rng) -> None:
    volts, rpm, count0, homing_error, zero = run
    t = np.arange(int(SECONDS * RATE_HZ) + 1) / RATE_HZ
    theta, rate = crank(t, rpm, HOME + homing_error)
    x, dx = slide(theta, rate)
    wheel = np.round(count0 + np.degrees(theta - theta[0]), 2)  # the encoder, to 0.01 deg
    reading = zero - x + rng.normal(0.0, NOISE_MM, len(t))
    spikes = rng.choice(np.arange(5, len(t) - 5), 5, replace=False)
    reading[spikes] += rng.uniform(20.0, 40.0, 5)
    rows = ["%time\twheel\tslide\twheel_speed\tslide_speed\tcomment",
            "s\tdeg\tmm\trpm\tmm/s"]
    rows += [f"{ti:.3f}\t{wi:.2f}\t{ri:.3f}\t{si:.3f}\t{vi:.2f}"
             for ti, wi, ri, si, vi in zip(t, wheel, reading, rate * 60.0 / (2.0 * math.pi), -dx)]
    (folder / f"run{k}").write_text("\n".join(rows) + "\n")


def write_laser(folder: pathlib.Path, run, rng) -> None:
    """Run 1's second logger: 100 Hz, ms, metres, 6 ms late, its clock starting 0.1 s early."""
    _, rpm, _, homing_error, _ = run
    t = np.arange(-0.1, SECONDS + 0.1 + 1e-9, 1.0 / LASER_HZ)
    theta, rate = crank(t, rpm, HOME + homing_error)
    x, _ = slide(theta, rate)
    distance = (x + LASER_ZERO_MM) / 1000.0 + rng.normal(0.0, NOISE_MM / 1000.0, len(t))
    stamps = (t + LASER_LAG_S) * 1000.0
    rows = ["t_ms,distance_m"] + [f"{s:.1f},{d:.7f}" for s, d in zip(stamps, distance)]
    (folder / "run1.csv").write_text("\n".join(rows) + "\n")


def truth(k: int) -> dict:
    """Run ``k``'s (from 1) true values, as the scenes' [fit] addresses name them: the
    geometry, the driver's offset (crank angle - wheel, in (-180, 180]) and the slide
    measurement's (x_B = -reading + offset)."""
    _, _, count0, homing_error, zero = RUNS[k - 1]
    offset = (HOME + homing_error - count0 + 180.0) % 360.0 - 180.0
    return {"links.crank.lengths.O-A": CRANK, "links.rod.lengths.A-B": ROD,
            "sliders.slide.along.through.1": OFFSET, "drivers.crank.offset": offset,
            "measurements.slide.offset": zero, "logs.laser.lag": LASER_LAG_S,
            "measurements.laser.offset": -LASER_ZERO_MM}


def main() -> None:
    here = pathlib.Path(__file__).parent
    rng = np.random.default_rng(SEED)
    (here / "rig").mkdir(exist_ok=True)
    (here / "rig_laser").mkdir(exist_ok=True)
    for k, run in enumerate(RUNS, start=1):
        write_rig(here / "rig", k, run, rng)
    write_laser(here / "rig_laser", RUNS[0], rng)


if __name__ == "__main__":
    main()
