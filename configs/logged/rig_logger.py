"""A demo logger: writes a four-bar rig's log in real time, as a test rig's data logger does.

The rig is the crank-rocker of configs/fourbar_crank_rocker.toml (crank 1, coupler 3.5,
rocker 3, ground 4; coupler point P at (1.5, 0.8) on the coupler) turned by a motor at about
2 rev/s with a 5 % speed ripple. Every row holds the crank encoder's angle, a rocker encoder
(the rocker's angle, 0.05 deg of noise) and a laser that measures the height of P (0.5 mm of
noise): both computed here in closed form (law of cosines), independently of linkpipe. At
``--jam-at`` seconds the rocker encoder slips by 2 degrees (an alarm for follow to find).

    python configs/logged/rig_logger.py configs/logged/logs/live_rig.csv --rate 200 --seconds 60

Rows are written one at a time and flushed in bursts of ``--burst`` rows (a logger's
buffer); the file is started afresh (a new log) unless ``--append``.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time

A, B, C, D = 1.0, 3.5, 3.0, 4.0  # crank, coupler, rocker, ground (O2 at 0, O4 at (4, 0))
PX, PY = 1.5, 0.8                  # P on the coupler, in the frame A -> B


def pose(theta: float) -> tuple[float, float]:
    """The rocker's angle (rad) and P's height for crank angle ``theta`` (rad), the open
    branch (B above the ground line, as drawn)."""
    ax, ay = A * math.cos(theta), A * math.sin(theta)
    dx, dy = D - ax, -ay
    e = math.hypot(dx, dy)
    # B on the circle of radius B about A and C about O4: the branch with B above
    cos_a = (B * B + e * e - C * C) / (2 * B * e)
    alpha = math.atan2(dy, dx) + math.acos(max(-1.0, min(1.0, cos_a)))
    bx, by = ax + B * math.cos(alpha), ay + B * math.sin(alpha)
    rocker = math.atan2(by, bx - D)
    ux, uy = (bx - ax) / B, (by - ay) / B
    p_y = ay + PX * uy + PY * ux
    return rocker, p_y


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("path")
    p.add_argument("--rate", type=float, default=200.0, help="rows per second (default 200)")
    p.add_argument("--seconds", type=float, default=60.0, help="how long to log (default 60)")
    p.add_argument("--burst", type=int, default=1, help="rows per flush (default 1)")
    p.add_argument("--jam-at", type=float, default=20.0, help="when the rocker encoder slips")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--append", action="store_true", help="go on after the file's last row")
    p.add_argument("--fast", action="store_true", help="no waiting: write as fast as possible")
    args = p.parse_args(argv)
    rng = random.Random(args.seed)
    first = 0
    if args.append and os.path.exists(args.path):
        with open(args.path) as f:
            first = sum(1 for _ in f) - 1
    out = open(args.path, "a" if args.append else "w", buffering=1 << 16)
    if not first:
        out.write("t,crank_deg,rocker_deg,p_height_mm\n")
        out.flush()
    dt = 1.0 / args.rate
    n = int(round(args.seconds * args.rate))
    start = time.monotonic() - first * dt
    try:
        for i in range(first, first + n):
            t = i * dt
            theta = 2 * math.pi * 2.0 * t + 0.05 * math.sin(2 * math.pi * 0.5 * t)
            rocker, p_y = pose(theta)
            slip = 2.0 if t >= args.jam_at else 0.0
            out.write(f"{t:.6f},{math.degrees(theta):.9f},"
                      f"{math.degrees(rocker) + slip + rng.gauss(0, 0.05):.6f},"
                      f"{1000 * p_y + rng.gauss(0, 0.5):.4f}\n")
            if (i + 1) % args.burst == 0:
                out.flush()
                if not args.fast:
                    time.sleep(max(0.0, start + (i + 1) * dt - time.monotonic()))
    except KeyboardInterrupt:
        pass
    finally:
        out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
