"""Logged data at scale (issue 14's targets), each case in a fresh process:

    .venv/bin/python benchmarks/bench_logs.py            # 1,000,000-row run and 100,000-row fit
    .venv/bin/python benchmarks/bench_logs.py --rows 200000 --fit-rows 20000   # quicker

1. A crank-encoder log of R rows (CSV, written here: angle(t) = 180 t + 10 sin(pi t) degrees
   at uneven 1 ms stamps)
   drives the crank-rocker of configs/fourbar_crank_rocker.toml with every effect (springs,
   gravity, inertia, damping, loads) to ``.h5``: seconds reading the scene and its log
   (pandas), then solving and writing; rows/s beyond reading the file; peak memory of the
   process. Target: >= 200,000 rows/s, peak <= 1 GB.
2. A fit of three force parameters (a spring rate, a mass, a load) to a measured input torque
   over F rows (the torque made by linkpipe at known values, so the fit has an exact answer):
   seconds for the whole fit, stage-1 solves (must be 1). Target: <= 2 s.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_sweep import EFFECTS, peak_rss_mb, scratch  # noqa: E402  (the same every-effect tables as its pipeline case)


def scene_text(measure: bool = False, k=200.0, mass=3.0, load=20.0) -> str:
    base = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    head = base[:base.index("[[drivers]]")]
    text = head + ('[time]\nlog = "enc"\n[[logs]]\nname = "enc"\nfile = "enc.csv"\ntime = "t"\n'
                   '[[drivers]]\nname = "crank"\nangle = ["O2", "A"]\nlog = "enc.deg"\n')
    text += (EFFECTS.replace("k = 200.0", f"k = {k}").replace("mass = 3.0", f"mass = {mass}")
             .replace("force = [-50.0, 20.0]", f"force = [-50.0, {load}]"))
    if measure:
        text += ('\n[[measurements]]\nname = "torque"\nlog = "enc.torque"\n'
                 'of = "input_force.crank"\nsigma = 1.0\n[fit]\nparameters = '
                 '["springs.return.k", "masses.coupler.mass", "loads.tool.force.1"]\n')
    return text.replace("[outputs]", "[outputs_unused]") if "[outputs]" in text else text


def write_log(folder: pathlib.Path, rows: int, torque=None) -> None:
    t = np.arange(rows) * 1e-3 + np.random.default_rng(1).uniform(0, 4e-4, rows)
    t[0] = 0.0
    deg = 180.0 * t + 10.0 * np.sin(np.pi * t)  # half a turn per second, with a ripple
    cols = {"t": t, "deg": deg}
    if torque is not None:
        cols["torque"] = torque
    import pandas as pd
    pd.DataFrame(cols).to_csv(folder / "enc.csv", index=False, float_format="%.9g")


def child_run(rows: int, folder: pathlib.Path) -> None:
    """In a fresh process: the log is already written (by the parent: its pandas frame is not
    this process's memory); imports are paid before the clock starts (scipy.interpolate, which
    the log driver's spline imports on first use: a fixed ~0.4 s per process, not per row)."""
    import scipy.interpolate  # noqa: F401

    import linkpipe
    from linkpipe.stores import hdf5
    (folder / "s.toml").write_text(scene_text())
    t0 = time.perf_counter()
    scene = linkpipe.load_scene(str(folder / "s.toml"))
    t_read = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = linkpipe.solve(scene)
    hdf5.write(result, folder / "s.h5")
    t_work = time.perf_counter() - t0
    peak = peak_rss_mb()
    print(json.dumps(dict(rows=rows, read=t_read, work=t_work, peak_mb=peak,
                          message=result.message, seconds=result.seconds)))


def child_fit(rows: int) -> None:
    import linkpipe
    from linkpipe.fit import fit
    folder = scratch()
    write_log(folder, rows)
    (folder / "truth.toml").write_text(scene_text(k=250.0, mass=3.6, load=35.0))
    torque = linkpipe.solve(str(folder / "truth.toml")).forces["input_force"][1][:, 0]
    write_log(folder, rows, torque)
    (folder / "s.toml").write_text(scene_text(measure=True))
    scene = linkpipe.load_scene(str(folder / "s.toml"))
    t0 = time.perf_counter()
    res = fit(scene)
    sec = time.perf_counter() - t0
    print(json.dumps(dict(rows=rows, seconds=sec, stage1=res.stage1_solves,
                          fitted=list(map(float, res.fitted)), evaluations=int(res.n_evaluations))))


def run_child(kind: str, rows: int, folder: str = "") -> dict:
    out = subprocess.run([sys.executable, __file__, "--child", kind, "--rows", str(rows),
                          "--folder", folder], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--rows", type=int, default=1_000_000)
    p.add_argument("--fit-rows", type=int, default=100_000)
    p.add_argument("--child")
    p.add_argument("--folder", default="")
    args = p.parse_args(argv)
    if args.child == "run":
        return child_run(args.rows, pathlib.Path(args.folder)) or 0
    if args.child == "fit":
        return child_fit(args.rows) or 0
    folder = scratch()
    write_log(folder, args.rows)
    r = run_child("run", args.rows, str(folder))
    rate = r["rows"] / r["work"]
    print(f"1. {r['rows']:,}-row log, four-bar with every effect, to .h5: read {r['read']:.2f} s, "
          f"solve + write {r['work']:.2f} s = {rate:,.0f} rows/s beyond reading "
          f"(target >= 200,000: {'met' if rate >= 2e5 else 'MISSED'}); peak {r['peak_mb']:.0f} MB "
          f"(target <= 1024: {'met' if r['peak_mb'] <= 1024 else 'MISSED'}); {r['message']}")
    print("   stages: " + ", ".join(f"{k} {v:.2f}" for k, v in r["seconds"].items()))
    f = run_child("fit", args.fit_rows)
    print(f"2. fit of 3 force parameters over {f['rows']:,} rows: {f['seconds']:.2f} s, "
          f"{f['evaluations']} evaluations, stage 1 solved {f['stage1']} time(s) (target <= 2 s: "
          f"{'met' if f['seconds'] <= 2 else 'MISSED'}); fitted {f['fitted']} "
          "(true 250, 3.6, 35)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
