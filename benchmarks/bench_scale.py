"""Cost and memory against mechanism size (issue 16): chains of N four-bar loops on the general
path, N = 8 ... 64, kinematics only and with gravity on every link (the force stage with its
Lagrange multipliers and reactions); each case in a fresh process, the cases alternating.

    .venv/bin/python benchmarks/bench_scale.py [--loops 8 16 32 64] [--steps 2000] [--repeats 3]
    .venv/bin/python benchmarks/bench_scale.py --repo /path/to/other/checkout   # e.g. before

Prints per case the seconds of ``linkpipe.solve`` (min / median / max over the repeats; imports
and a warm-up are not timed), the stage seconds of the fastest run and the process's peak
resident memory (interpreter and imports included); then the exponent k of time ~ N^k (least
squares on log-log of the minima) for each mode, the peak at the largest N, and BLAS threads:
the library's own thread pool (threadpoolctl limit None: every core) against one thread, at the
two largest N with gravity. Targets (issue 16): k <= 1.3 (kinematics), k <= 1.5 (with gravity),
peak <= 1 GB at N = 64, every-core threads <= 1.1x one thread. ``--linear-algebra dense`` runs
the same cases with ``[solver] linear_algebra = "dense"`` (the one-step work on dense
Jacobians at every size).
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent

#: one case, run in a fresh process: prints a JSON line
CASE = r"""
import json, sys, time
sys.path.insert(0, {bench!r})
from bench_threads import chain_text  # (puts this checkout first on sys.path)
from bench_sweep import peak_rss_mb  # VmHWM: ru_maxrss survives exec on Linux
sys.path.insert(0, {repo!r})  # import linkpipe from {repo!r}
import linkpipe
import scipy.sparse.linalg  # noqa: F401  imported by the sparse path: not timed
from linkpipe.scene import parse_scene

loops, steps, gravity, threads, la = {loops}, {steps}, {gravity}, {threads}, {la!r}
text = chain_text(loops, steps)
if la:
    text = text.replace("[solver]\n", f'[solver]\nlinear_algebra = "{{la}}"\n')
if gravity:
    text += '[analysis]\neffects = ["gravity"]\n[gravity]\ng = [0.0, -9.81]\n'
    names = ([f"crank{{k}}" for k in range(loops)] + [f"coupler{{k}}" for k in range(loops)]
             + ["rocker_last"])
    for name in names:
        text += f'[[masses]]\nlink = "{{name}}"\nmass = 1.0\ncenter = [0.5, 0.1]\ninertia = 0.1\n'
linkpipe.solve(parse_scene(chain_text(4, 1200), "warm.toml"), threads=threads)  # warm-up
scene = parse_scene(text, "chain.toml")
t0 = time.perf_counter()
r = linkpipe.solve(scene, threads=threads)
seconds = time.perf_counter() - t0
assert linkpipe.__file__.startswith({repo!r}), linkpipe.__file__
print(json.dumps(dict(seconds=seconds, stages=r.seconds, message=r.message,
                      rss=peak_rss_mb() * 2**20,
                      linear_algebra=getattr(r, "linear_algebra_used", ""))))
"""


def run_case(repo, loops, steps, gravity, threads, la) -> dict:
    code = CASE.format(bench=str(ROOT / "benchmarks"), repo=str(repo), loops=loops, steps=steps,
                       gravity=gravity, threads=threads, la=la)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def exponent(sizes, seconds) -> float:
    """k of seconds ~ sizes^k: least squares on the logarithms."""
    return float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0])


def _spread(ts) -> str:
    ts = sorted(ts)
    return f"{ts[0]:.3f} / {ts[len(ts) // 2]:.3f} / {ts[-1]:.3f}"


def measure_sizes(args) -> dict:
    """{(mode, N): [runs]}, the cases alternating within each repeat."""
    runs: dict = {}
    for _ in range(args.repeats):
        for loops in args.loops:
            for gravity in (False, True):
                r = run_case(args.repo, loops, args.steps, gravity, 1, args.linear_algebra)
                runs.setdefault((gravity, loops), []).append(r)
    return runs


def report_sizes(args, runs) -> None:
    print(f"chains of N four-bar loops, {args.steps:,} steps, general path, 1 BLAS thread; "
          f"seconds of solve min / median / max of {args.repeats}; stages of the fastest run")
    print("| N | unknowns | mode | seconds | positions | jacobian | forces | peak RSS | linear algebra |")
    print("|---:|---:|---|---|---:|---:|---:|---:|---|")
    for gravity in (False, True):
        for loops in args.loops:
            rs = runs[(gravity, loops)]
            best = min(rs, key=lambda r: r["seconds"])
            st = best["stages"]
            print(f"| {loops} | {4 * loops} | {'gravity' if gravity else 'kinematics'} | "
                  f"{_spread([r['seconds'] for r in rs])} | {st.get('positions', 0):.3f} | "
                  f"{st.get('jacobian', 0):.3f} | {st.get('forces', 0):.3f} | "
                  f"{max(r['rss'] for r in rs) / 2**20:.0f} MB | {best['linear_algebra'] or '-'} |")
    for gravity, target in ((False, 1.3), (True, 1.5)):
        mins = [min(r["seconds"] for r in runs[(gravity, n)]) for n in args.loops]
        meds = [float(np.median([r["seconds"] for r in runs[(gravity, n)]])) for n in args.loops]
        k, k_med = exponent(args.loops, mins), exponent(args.loops, meds)
        mode = "with gravity on every link" if gravity else "kinematics only"
        print(f"- time ~ N^k, {mode}: k = {k:.2f} (minima; medians {k_med:.2f}), target <= "
              f"{target}: {'met' if max(k, k_med) <= target else 'MISSED'}")
    top = args.loops[-1]
    peak = max(r["rss"] for g in (False, True) for r in runs[(g, top)]) / 2**30
    print(f"- peak memory at N = {top}: {peak:.2f} GB, target <= 1 GB: "
          f"{'met' if peak <= 1.0 else 'MISSED'}")


def measure_threads(args) -> None:
    """Every core (threadpoolctl limit None) against 1 BLAS thread, alternating."""
    cores = os.cpu_count() or 1
    for loops in args.loops[-2:]:
        runs = {1: [], None: []}
        for _ in range(args.repeats):
            for threads in runs:
                runs[threads].append(run_case(args.repo, loops, args.steps, True, threads,
                                              args.linear_algebra))
        times = {k: [r["seconds"] for r in v] for k, v in runs.items()}
        ratio = min(times[None]) / min(times[1])
        ratio_med = float(np.median(times[None]) / np.median(times[1]))
        print(f"- N = {loops} with gravity: 1 thread {_spread(times[1])} s, the library's own "
              f"({cores} cores) {_spread(times[None])} s: {ratio:.2f}x (medians {ratio_med:.2f}x), "
              f"target <= 1.1x: {'met' if max(ratio, ratio_med) <= 1.1 else 'MISSED'} "
              f"(run's default: 1 thread)")
        for threads, rs in runs.items():  # where the slowest run's time went
            worst = max(rs, key=lambda r: r["seconds"])
            outside = worst["seconds"] - sum(worst["stages"].values())
            print(f"    slowest with threads {threads or cores}: "
                  + ", ".join(f"{k} {v:.3f}" for k, v in worst["stages"].items())
                  + f", outside the stages {outside:.3f}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--loops", type=int, nargs="+", default=[8, 16, 32, 64])
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--repo", type=pathlib.Path, default=ROOT, help="checkout to import linkpipe from")
    p.add_argument("--linear-algebra", default="", choices=["", "auto", "dense", "sparse"],
                   help='[solver] linear_algebra for every case ("": the scene default)')
    p.add_argument("--no-threads", action="store_true", help="skip the threads comparison")
    p.add_argument("--no-sizes", action="store_true", help="only the threads comparison")
    args = p.parse_args(argv)
    if not args.no_sizes:
        report_sizes(args, measure_sizes(args))
    if not args.no_threads:
        measure_threads(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
