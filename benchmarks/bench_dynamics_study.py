"""A study of a dynamics scene (issue 31, item 4: "vectorised where it can be"): where a
variant's time goes, and whether running the variants on the study's Dask executor makes the
study cheaper than one by one in this process. Not a test: timings on a shared machine are
noisy; each row says what it times, with wall and CPU seconds and the load average.

    .venv/bin/python benchmarks/bench_dynamics_study.py              # 24 variants (~1 minute)
    .venv/bin/python benchmarks/bench_dynamics_study.py --variants 12

The study is configs/studies/hatch_closing.toml (the tailgate closing on one gas strut; each
variant integrated until its stop ends it) with ``--variants`` strut forces from 50 to 300 N,
in batches of a quarter of them.

1. One variant's parts (``Result.seconds`` over the variants, run in this process): building
   the model and the equations of motion (``model``: what reusing the model between variants
   that change only force numbers could save at most), the integration, the output instants'
   positions and the force stage. Target: none (it says where the time goes).
2. The whole study in this process (``python -m linkpipe study``), wall and CPU seconds.
3. The same on a local Dask cluster of 2 worker processes (``--workers 2``), wall seconds, the
   CPU of this process and that of the workers (the children's CPU once the cluster closed).
   Target: faster than row 2 (the verdict says by how much or why not).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import resource
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import linkpipe  # noqa: E402
from linkpipe.__main__ import main as cli  # noqa: E402
from linkpipe.study import variants  # noqa: E402
from linkpipe.study.spec import load_study  # noqa: E402


def study_file(folder: pathlib.Path, n: int) -> pathlib.Path:
    text = (ROOT / "configs" / "studies" / "hatch_closing.toml").read_text()
    text = text.replace('base = "../dynamics/hatch_closing.toml"',
                        f'base = "{ROOT / "configs" / "dynamics" / "hatch_closing.toml"}"\n'
                        f"batch_size = {max(1, n // 4)}")
    text = text.replace("steps = 6", f"steps = {n}")
    path = folder / "hatch_closing.toml"
    path.write_text(text)
    return path


def timed(fn):
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0, c0 = time.perf_counter(), time.process_time()
    value = fn()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    child = (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime)
    return value, wall, cpu, child


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", type=int, default=24)
    args = ap.parse_args(argv)
    n = args.variants
    print(f"load average at start: {os.getloadavg()[0]:.2f} (2 cores)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        path = study_file(folder, n)
        study = load_study(path)
        parts = {"model": [], "integration": [], "positions": [], "forces": []}
        for v in range(n):
            r = linkpipe.solve(variants.variant_scene(study, v))
            for key in parts:
                parts[key].append(r.seconds.get(key, 0.0))
        total = sum(np.mean(x) for x in parts.values())
        print(f"1. one variant's parts (mean over {n}, wall ms): " + ", ".join(
            f"{k} {1e3 * np.mean(x):.1f} ({100 * np.mean(x) / total:.1f}%)"
            for k, x in parts.items()))
        print(f"   reusing the model between force-only variants saves at most "
              f"{100 * np.mean(parts['model']) / total:.1f}% of a variant")
        code, wall1, cpu1, _ = timed(lambda: cli(["study", str(path), "--out",
                                                   str(folder / "in"), "--quiet"]))
        assert code == 0
        print(f"2. study of {n} variants in this process: wall {wall1:.2f} s, CPU {cpu1:.2f} s")
        code, wall2, cpu2, child = timed(lambda: cli(["study", str(path), "--out",
                                                       str(folder / "dask"), "--workers", "2",
                                                       "--quiet"]))
        assert code == 0
        print(f"3. the same on 2 Dask workers: wall {wall2:.2f} s, CPU here {cpu2:.2f} s, "
              f"workers' CPU {child:.2f} s")
        ratio = wall1 / wall2
        print(f"   verdict: Dask {ratio:.2f}x the in-process speed ("
              + ("faster" if ratio > 1 else "slower") + f"; load average now "
              f"{os.getloadavg()[0]:.2f} on 2 cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
