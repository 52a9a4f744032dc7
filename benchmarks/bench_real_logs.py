"""Real logs (issue 30's targets), each case in a fresh process:

    .venv/bin/python benchmarks/bench_real_logs.py              # both cases, as the targets say
    .venv/bin/python benchmarks/bench_real_logs.py --logs 10 --rows 500 --read-rows 200000  # quicker
    .venv/bin/python benchmarks/bench_real_logs.py --dense-evaluations 1    # dense fit estimated

1. Joint fit: the slider-crank rig of configs/logged/slider_crank_rig.toml fitted to L logs
   of R rows (tab-separated, units row, written here by the closed-form model of
   configs/logged/make_slider_crank_logs.py with each log's own zeros and 0.05 mm of noise):
   3 shared parameters (crank, rod, the slide line's height) and 2 per log (the encoder's and
   the string-pot's zeros), 3 + 2 L unknowns, loss linear. Times the whole ``joint_fit``
   (reading every log's scene, the fit, the standard errors, the solves at the fitted values)
   with the block-sparse Jacobian (s + q evaluations of every log per Jacobian), and the same
   problem with scipy's dense "2-point" Jacobian (s + L q evaluations per Jacobian). Targets:
   sparse <= 10 s; dense / sparse >= 10. With ``--dense-evaluations N`` the dense fit stops
   after N of scipy's evaluations and its time beyond reading the logs is scaled by the
   sparse fit's Jacobians over its own (an estimate, said so in its row; the dense fit
   needs as many iterations or more). Times are wall and CPU (the process's): on a shared
   machine the CPU time is the steadier figure.
2. Reading a tab-separated log of N rows with a units row and ``[[logs]] units`` (5 columns:
   time in ms, degrees, mm, rpm, mm/s), as a scene reads it: pandas' C parser, the time
   column checked, every column to floats and converted to the scene's units. Rows per second
   and the process's peak memory (ru_maxrss) beyond its size before reading, against the
   data's float64 size (N x 5 x 8 bytes). Targets: >= 1,000,000 rows/s; peak <= 3x the data.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def generator():
    """configs/logged/make_slider_crank_logs.py as a module (the closed-form rig model)."""
    path = ROOT / "configs" / "logged" / "make_slider_crank_logs.py"
    spec = importlib.util.spec_from_file_location("make_slider_crank_logs", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_fleet(folder: pathlib.Path, n_logs: int, rows: int) -> None:
    """``n_logs`` rig logs of ``rows`` rows at 50 Hz: each its own speed and zeros."""
    gen = generator()
    rng = np.random.default_rng(5)
    t = np.arange(rows) / 50.0
    for k in range(n_logs):
        rpm = 40.0 + 100.0 * k / max(n_logs - 1, 1)
        start = gen.HOME + rng.uniform(-5.0, 5.0)
        theta, rate = gen.crank(t, rpm, start)
        x, dx = gen.slide(theta, rate)
        count0 = 360.0 * rng.integers(1, 200) + gen.HOME
        wheel = np.round(count0 + np.degrees(theta - theta[0]), 2)
        zero = 310.0 + rng.uniform(-4.0, 4.0)
        reading = zero - x + rng.normal(0.0, gen.NOISE_MM, rows)
        lines = ["%time\twheel\tslide\twheel_speed\tslide_speed\tcomment",
                 "s\tdeg\tmm\trpm\tmm/s"]
        lines += [f"{a:.3f}\t{b:.2f}\t{c:.3f}\t{d:.3f}\t{e:.2f}" for a, b, c, d, e in
                  zip(t, wheel, reading, rate * 60.0 / (2.0 * np.pi), -dx)]
        (folder / f"run{k:03d}").write_text("\n".join(lines) + "\n")


def joint_case(rows: int, n_logs: int, dense_evaluations: int | None) -> dict:
    from linkpipe.joint import joint_fit
    from linkpipe.scene import load_scene

    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        write_fleet(folder, n_logs, rows)
        text = (ROOT / "configs" / "logged" / "slider_crank_rig.toml").read_text()
        text = (text.replace('file = "rig/run1"', 'file = "run000"')
                .replace('loss = "soft_l1"', 'loss = "linear"'))
        (folder / "rig.toml").write_text(text)
        scene = load_scene(str(folder / "rig.toml"))
        pattern = str(folder / "run*")
        t0, c0 = time.perf_counter(), time.process_time()
        sparse = joint_fit(scene, pattern)
        t_sparse, c_sparse = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        dense = joint_fit(scene, pattern, sparse=False,
                          max_evaluations=dense_evaluations or 200)
        t_dense, c_dense = time.perf_counter() - t0, time.process_time() - c0
        if dense_evaluations:  # one Jacobian's worth per Jacobian the sparse fit took
            jacobians = max(dense.n_jacobians, 1)
            scale = sparse.n_jacobians / jacobians
            t_dense = dense.setup_seconds + (t_dense - dense.setup_seconds) * scale
            c_dense = c_dense * scale
    return {"sparse_s": t_sparse, "sparse_cpu": c_sparse, "dense_cpu": c_dense,
            "sparse_jac": sparse.n_jacobians, "dense_jac": dense.n_jacobians,
            "sparse_nfev": sparse.n_evaluations,
            "sparse_solves": sparse.solves, "dense_s": t_dense,
            "dense_nfev": dense.n_evaluations, "dense_solves": dense.solves,
            "dense_message": dense.message, "sparse_message": sparse.message,
            "fitted": sparse.fitted.tolist(), "se": sparse.standard_error.tolist(),
            "dense_fitted": dense.fitted.tolist()}


def write_big(path: pathlib.Path, rows: int) -> None:
    """A tab-separated log of ``rows`` rows (ms, deg, mm, rpm, mm/s), written with numpy."""
    t = np.arange(rows, dtype=float)
    data = np.column_stack([t, 0.36 * t, 100.0 + 50.0 * np.sin(t * 1e-3), np.full(rows, 60.0),
                            50.0 * np.cos(t * 1e-3)])
    with open(path, "w") as f:
        f.write("%t_ms\twheel\tslide\twheel_speed\tslide_speed\n")
        f.write("ms\tdeg\tmm\trpm\tmm/s\n")
        np.savetxt(f, data, fmt="%.6g", delimiter="\t")


def read_case(path: str) -> dict:
    """Read the log as a scene does; peak RSS beyond the process's size before reading."""
    import tomllib

    import pandas  # noqa: F401  (imported before the baseline: its code is not the data)

    from linkpipe.scene import logs as logfiles
    from linkpipe.scene.parse import _Parser

    text = (f'[[logs]]\nname = "big"\nfile = "{path}"\ndelimiter = "\\t"\ntime = "%t_ms"\n'
            'skip_rows = 1\nunits = { "%t_ms" = "ms", wheel = "deg", slide = "mm", '
            'wheel_speed = "rpm", slide_speed = "mm/s" }\n')
    parser = _Parser(tomllib.loads(text), text, "<string>")
    parser.units = {"length": "m", "time": "s", "force": "N", "mass": "kg"}
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t0, c0 = time.perf_counter(), time.process_time()
    log = parser.log_tables()["big"]
    table = parser.entries("logs")[0]
    frame = parser.frames["big"]
    out = {}
    for column in ("wheel", "slide", "wheel_speed", "slide_speed"):
        values = logfiles.numeric_column(frame, column, pathlib.Path(path), table, "log")
        out[column] = values * parser.unit_factor(table, "log", log, column)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    rows = len(log.t)
    assert abs(out["slide"][0] - 0.1) < 1e-12 and abs(log.t[1] - 1e-3) < 1e-15
    return {"rows": rows, "seconds": seconds, "cpu": cpu, "peak_mb": peak - base,
            "data_mb": rows * 5 * 8 / 2 ** 20}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=50)
    ap.add_argument("--rows", type=int, default=2000)
    ap.add_argument("--read-rows", type=int, default=1_000_000)
    ap.add_argument("--dense-evaluations", type=int, default=None)
    ap.add_argument("--only", choices=("joint", "read"))
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.case:  # a child process: one case, its figures as JSON
        kind, *rest = args.case.split(":")
        out = (joint_case(int(rest[0]), int(rest[1]), int(rest[2]) or None) if kind == "joint"
               else read_case(":".join(rest)))
        print(json.dumps(out))
        return

    def child(case: str) -> dict:
        run = subprocess.run([sys.executable, __file__, "--case", case], capture_output=True,
                             text=True, check=True)
        return json.loads(run.stdout.strip().splitlines()[-1])

    if args.only in (None, "joint"):
        r = child(f"joint:{args.rows}:{args.logs}:{args.dense_evaluations or 0}")
        dense = r["dense_s"]
        estimated = args.dense_evaluations is not None
        ratio = dense / r["sparse_s"]
        print(f"joint fit, 3 shared + 2 per-log parameters over {args.logs} logs x {args.rows} "
              f"rows ({3 + 2 * args.logs} unknowns):")
        print(f"  block-sparse Jacobian: {r['sparse_s']:.2f} s wall, {r['sparse_cpu']:.2f} s CPU "
              f"({r['sparse_nfev']} evaluations, {r['sparse_jac']} Jacobians, "
              f"{r['sparse_solves']} solves of a log's scene; {r['sparse_message']})")
        print(f"  dense Jacobian:        {r['dense_s']:.2f} s wall, {r['dense_cpu']:.2f} s CPU "
              + (f"(ESTIMATE: cut short after {args.dense_evaluations} evaluation(s), "
                 f"{r['dense_jac']} Jacobian(s), scaled to the sparse fit's {r['sparse_jac']} "
                 "Jacobians)" if estimated else
                 f"({r['dense_nfev']} evaluations, {r['dense_jac']} Jacobians, "
                 f"{r['dense_solves']} solves; {r['dense_message']})"))
        print(f"  fitted (sparse) {np.round(r['fitted'], 4).tolist()} ± "
              f"{np.round(r['se'], 4).tolist()}; (dense) {np.round(r['dense_fitted'], 4).tolist()}")
        print(f"  target <= 10 s: {'PASS' if r['sparse_s'] <= 10 else 'FAIL'} "
              f"({r['sparse_s']:.2f} s); target dense/sparse >= 10: "
              f"{'PASS' if ratio >= 10 else 'FAIL'} ({ratio:.1f}x wall, "
              f"{r['dense_cpu'] / r['sparse_cpu']:.1f}x CPU)")
    if args.only in (None, "read"):
        with tempfile.TemporaryDirectory() as tmp:
            path = pathlib.Path(tmp) / "big_log"
            write_big(path, args.read_rows)
            size = path.stat().st_size / 2 ** 20
            r = child(f"read:{path}")
        rate = r["rows"] / r["seconds"]
        ratio = r["peak_mb"] / r["data_mb"]
        print(f"reading a {r['rows']:,}-row tab-separated log with units ({size:.0f} MB of text, "
              f"{r['data_mb']:.0f} MB as float64):")
        print(f"  {r['seconds']:.2f} s wall ({r['cpu']:.2f} s CPU), {rate:,.0f} rows/s "
              f"({r['rows'] / r['cpu']:,.0f} per CPU second); peak memory {r['peak_mb']:.0f} MB "
              f"beyond the process before reading = {ratio:.2f}x the data")
        print(f"  target >= 1,000,000 rows/s: {'PASS' if rate >= 1e6 else 'FAIL'}; "
              f"target peak <= 3x the data: {'PASS' if ratio <= 3 else 'FAIL'}")


if __name__ == "__main__":
    main()
