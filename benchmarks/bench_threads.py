"""What BLAS threads do to the general path: a chain of N four-bar loops on the Newton path,
solved with the BLAS thread pool limited (threadpoolctl) to 1 thread and to every core, in one
process, alternating.

    .venv/bin/python benchmarks/bench_threads.py [--loops 32] [--steps 5000]

Loop k is a crank-rocker (crank 1, coupler 3.5, rocker 3, ground 4) whose rocker carries the
next loop's crank (the two arms of one rigid link, half a turn apart): one driver turns the
first crank, every other loop follows. ``method = "newton"``: the coarse continuation solves
its steps with batched dense blocks of the chain's size, the kind of small batched solve
where a multi-threaded BLAS only adds overhead (issue 16).
"""
from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def chain_text(loops: int, steps: int, first=(1.0, 3.5, 3.0, 4.0), start_deg=17.188733853924695,
               to_deg=None, method="newton") -> str:
    """The chain as scene text; ``first``: the first loop's (crank, coupler, rocker, ground)."""
    pts, links = [], []
    t = math.radians(start_deg)  # the first crank's angle as drawn
    to_deg = start_deg + 360.0 if to_deg is None else to_deg
    for k in range(loops):
        a, b, c, d = first if k == 0 else (1.0, 3.5, 3.0, 4.0)
        O = np.array([4.0 * k, 0.0]) + ([0.0, 0.0] if k == 0 else [first[3] - 4.0, 0.0])
        O_next = O + [d, 0.0]
        A = O + a * np.array([math.cos(t), math.sin(t)])
        v = O_next - A
        L = np.hypot(*v)
        along = (b * b - c * c + L * L) / (2 * L)
        h = math.sqrt(b * b - along * along)
        B = A + along * v / L + h * np.array([-v[1], v[0]]) / L
        pts.append(f'O{k} = {{ x = {float(O[0])!r}, y = {float(O[1])!r}, fixed = true }}')
        pts.append(f'A{k} = {{ x = {float(A[0])!r}, y = {float(A[1])!r} }}')
        pts.append(f'B{k} = {{ x = {float(B[0])!r}, y = {float(B[1])!r} }}')
        crank = [f"O{k}", f"A{k}"] + ([f"B{k - 1}"] if k else [])
        links.append(f'[[links]]\nname = "crank{k}"\npoints = {crank!r}'.replace("'", '"'))
        links.append(f'[[links]]\nname = "coupler{k}"\npoints = ["A{k}", "B{k}"]')
        t = math.atan2(B[1] - O_next[1], B[0] - O_next[0]) + math.pi  # the next crank's arm
    pts.append(f'O{loops} = {{ x = {float(O_next[0])!r}, y = 0.0, fixed = true }}')
    links.append(f'[[links]]\nname = "rocker_last"\npoints = ["O{loops}", "B{loops - 1}"]')
    return ("[scene]\nname = \"chain\"\n[points]\n" + "\n".join(pts) + "\n" + "\n".join(links)
            + f'\n[[drivers]]\nname = "crank"\nangle = ["O0", "A0"]\nfrom = {start_deg!r}\n'
            f'to = {to_deg!r}\nsteps = {steps}\nrate = 60.0\n[solver]\nmethod = "{method}"\n')


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--loops", type=int, default=32)
    p.add_argument("--steps", type=int, default=5000)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    import linkpipe
    from linkpipe.scene import parse_scene

    scene = parse_scene(chain_text(args.loops, args.steps), "chain.toml")
    cores = os.cpu_count() or 1
    times = {1: [], cores: []}
    for _ in range(args.repeats):
        for threads in times:
            t0 = time.perf_counter()
            r = linkpipe.solve(scene, threads=threads)
            times[threads].append(time.perf_counter() - t0)
    print(f"chain of {args.loops} four-bar loops, {args.steps:,} steps, Newton path "
          f"({r.message}); seconds per solve, min / median / max of {args.repeats}:")
    for threads, ts in times.items():
        ts = sorted(ts)
        print(f"  BLAS threads {threads}: {ts[0]:.2f} / {ts[len(ts) // 2]:.2f} / {ts[-1]:.2f}")
    ratio = min(times[cores]) / min(times[1])
    print(f"  {cores} threads take {ratio:.2f}x the time of 1 thread (run's default: "
          f"{linkpipe.workers.DEFAULT_THREADS} thread)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
