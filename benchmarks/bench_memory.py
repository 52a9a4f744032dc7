"""The memory estimate against measured peaks (issue 16): each case in a fresh process, twice:
``linkpipe.solve`` writing the ``.h5`` from the whole Result (what a Python user of the API
holds), and ``python -m linkpipe run --no-rrd`` (the sweep streamed in segments:
``linkpipe.segments``); each prints the process's peak resident memory next to
``memory.memory_needed`` (the upper bound ``run`` and ``check`` refuse a sweep by: of the
whole sweep for the API, of one segment and what stays whole for ``run``).

    .venv/bin/python benchmarks/bench_memory.py            # about a minute
    .venv/bin/python benchmarks/bench_memory.py --scale 0.1   # a tenth of the steps

Cases: the crank-rocker's kinematics (positions, velocities, accelerations) at 2M steps; the
same with every effect at 1M; the basketball goal with springs, gravity and inertia at 1M;
Jansen's linkage (general Newton path, 8 links) at 200k. Verdict per case: the estimate must be
at least the peak (an estimate below it could let the kernel kill a run half-way) and is
reported as a ratio (how much it over-asks).
"""
from __future__ import annotations

import argparse
import json
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

CASES = {  # name: (config, steps, extra TOML)
    "crank_rocker kinematics": ("fourbar_crank_rocker", 2_000_000, ""),
    "crank_rocker every effect": ("fourbar_crank_rocker", 1_000_000, "EFFECTS"),
    "basketball goal": ("basketball_goal", 1_000_000, ""),
    "jansen (newton)": ("jansen", 200_000, ""),
}


def scene_text(config: str, steps: int, extra: str) -> str:
    text = (ROOT / "configs" / f"{config}.toml").read_text()
    text = re.sub(r"^(steps|step) = [\d.]+", f"steps = {steps}", text, count=1, flags=re.M)
    if extra == "EFFECTS":
        from bench_sweep import EFFECTS
        text += EFFECTS
    return text


def child(name: str, scale: float, mode: str) -> None:
    import linkpipe
    from linkpipe.memory import memory_needed
    from linkpipe.stores import hdf5
    from bench_sweep import scratch
    config, steps, extra = CASES[name]
    folder = scratch()
    path = folder / "s.toml"
    path.write_text(scene_text(config, int(steps * scale), extra))
    scene = linkpipe.load_scene(str(path))
    if mode == "run":
        from linkpipe.__main__ import main as cli
        from linkpipe.segments import steps_per_segment

        segment = steps_per_segment(scene)
        code = cli(["run", str(path), "--out", str(folder), "--quiet", "--no-rrd"])
        message, estimate = f"exit {code}", memory_needed(scene, segment)
    else:
        result = linkpipe.solve(scene)
        hdf5.write(result, folder / "s.h5")
        message, estimate = result.message, memory_needed(scene)
    from bench_sweep import peak_rss_mb  # VmHWM: ru_maxrss survives exec on Linux

    peak = peak_rss_mb() * 2**20
    print(json.dumps(dict(steps=scene.n_steps, peak=peak, estimate=estimate, message=message)))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--child")
    p.add_argument("--mode", choices=("solve", "run"), default="solve")
    args = p.parse_args(argv)
    if args.child:
        return child(args.child, args.scale, args.mode) or 0
    print(f"{'case':<28}{'how':>6}{'steps':>11}{'peak MB':>10}{'estimate MB':>13}{'ratio':>7}  verdict")
    for name in CASES:
        for mode in ("solve", "run"):
            out = subprocess.run([sys.executable, __file__, "--child", name, "--scale",
                                  str(args.scale), "--mode", mode],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            ratio = r["estimate"] / r["peak"]
            print(f"{name:<28}{mode:>6}{r['steps']:>11,}{r['peak'] / 2**20:>10.0f}"
                  f"{r['estimate'] / 2**20:>13.0f}{ratio:>7.2f}  "
                  f"{'upper bound' if ratio >= 1 else 'BELOW THE PEAK'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
