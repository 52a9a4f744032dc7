"""Design studies at scale (issue 17's targets), each case in a fresh process, printed with
verdicts (not a test: timings on a shared machine are noisy):

    .venv/bin/python benchmarks/bench_study.py              # every case (a few minutes)
    .venv/bin/python benchmarks/bench_study.py --quick      # 10,000 variants only

The base is the basketball goal with every effect on (springs with damping, gravity, inertia,
a load at the handle and a couple on the upper link; 25 steps). Its variants vary the left
spring's rate, the spring anchor S1 (x and y), the backboard's mass and the handle load:
force numbers only, so the study takes the vectorised path (stage 1 once, the force stage on
all variants of a batch at once).

1. 10,000 variants in-process: seconds (target <= 5 s).
2. 100,000 variants in-process, streamed to the .h5: seconds and the process's peak memory
   (targets <= 60 s, <= 2 GB).
3. 100,000 variants on a Dask LocalCluster of 1 and of 2 worker processes: scaling efficiency
   t1 / (2 t2) (target >= 80 %), judged on a running cluster (started, and its workers warmed
   by a small study, before the clock starts: the work's scaling); the same with the cluster's
   start and the workers' imports included is printed beside it. Beside it, the machine's own: the same 20 batches in one
   process, then in each of two processes at once (no Dask): what two processes can gain on
   this machine at this moment (the cores are shared with other jobs).
4. For comparison, the variant-by-variant path: 500 variants of +-0.5 mm pin tolerances (the
   pins move and a link length changes), forced variant by variant (every variant its own
   scene; the study itself takes the vectorised path: case 6).
5. Pin tolerances of the pole's pivots only (O2, O4 x and y within +-0.5 mm): the vectorised
   path with the pivots as per-row columns (2,000 variants), against the same study forced
   variant by variant (500 variants): variants/s before -> after.
6. The shipped tolerance study (configs/studies/basketball_goal_tolerance.toml: both pole
   pins and the three links' lengths within +-0.5 mm, force numbers; 1,000 variants): the
   vectorised path (link lengths as per-row constants) against the same study forced variant
   by variant, both in one process (``--lengths`` runs this case alone): variants/s and the
   ratio.
7. Plate side lengths: the shear press's lever (B-P, A-P within +-0.5 mm, its frame length
   A-B and the cutting force; 2,000 variants of 9 steps), vectorised (each variant's lever
   placed again, its model rows built at once) against the same study forced variant by
   variant, in one process (``--plates`` runs cases 7 and 8 alone).
8. Drawn coordinates of moving points: the basketball goal with every effect, its moving
   points B, C and H drawn within +-0.05 ft (the start guess; 1,000 variants), vectorised
   against forced variant by variant, in one process.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
GOAL = ROOT / "configs" / "basketball_goal.toml"

EVERY_EFFECT_TABLES = """
[[loads]]
name = "hand"
point = "H"
force = [0.0, -5.0]

[[loads]]
name = "twist"
link = "upper"
torque = 1.5
"""

FORCES = """[study]
base = "goal_every_effect.toml"
seed = 1
samples = {samples}

[study.parameters]
"springs.left.k" = {{ from = 0.0, to = 600.0, steps = {steps} }}
"points.S1.y" = {{ from = -0.95, to = -0.05, steps = 10 }}
"points.S1.x" = {{ uniform = [-0.3, 0.3] }}
"masses.backboard.mass" = {{ normal = [1.554, 0.02] }}
"loads.hand.force.1" = {{ uniform = [-8.0, -2.0] }}

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"
p95_spring = "percentile(spring_force.left, 95)"
"""

PINS = """[study]
base = "goal_every_effect.toml"
seed = 2
samples = 500

[study.parameters]
"points.O2.y" = { uniform = [-1.00164, -0.99836] }
"points.O4.y" = { uniform = [-2.00164, -1.99836] }
"links.upper.lengths.O2-B" = { uniform = [1.99836, 2.00164] }
"""

PIVOTS = """[study]
base = "goal_every_effect.toml"
seed = 3
samples = {samples}

[study.parameters]
"points.O2.x" = {{ uniform = [-0.00164, 0.00164] }}
"points.O2.y" = {{ uniform = [-1.00164, -0.99836] }}
"points.O4.x" = {{ uniform = [-0.00164, 0.00164] }}
"points.O4.y" = {{ uniform = [-2.00164, -1.99836] }}

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"
"""

PLATES = """[study]
base = "{base}"
seed = 7
samples = 2000

[study.parameters]
"links.lever.lengths.B-P" = {{ uniform = [0.4495, 0.4505] }}
"links.lever.lengths.A-P" = {{ uniform = [0.6495, 0.6505] }}
"links.lever.lengths.A-B" = {{ uniform = [0.2295, 0.2305] }}
"loads.cutting_force.force.1" = {{ uniform = [400.0, 600.0] }}

[study.metrics]
peak_handle = "max(abs(input_force.handle))"
"""

DRAWN = """[study]
base = "goal_every_effect.toml"
seed = 8
samples = 1000

[study.parameters]
"points.B.x" = {{ uniform = [{Bx0!r}, {Bx1!r}] }}
"points.C.y" = {{ uniform = [{Cy0!r}, {Cy1!r}] }}
"points.H.x" = {{ uniform = [{Hx0!r}, {Hx1!r}] }}

[study.metrics]
peak_handle = "max(abs(input_force.theta3a))"
"""

LENGTHS = """
import dataclasses, json, sys, time
sys.path.insert(0, {root!r})
from linkpipe.study import load_study, run_study
study = load_study({path!r})
from linkpipe.study.batch import solve_batch
for warm in (study, dataclasses.replace(study, slots=None)):  # imports, the base scene's solve
    solve_batch(warm, 0, 10)
seconds = {{}}
for name, case in (("one_by_one", dataclasses.replace(study, slots=None,
                                                      path_note="variant by variant (forced)")),
                   ("vectorised", study)):
    t0 = time.perf_counter()
    run_study(case, {out!r} + "_" + name)
    seconds[name] = time.perf_counter() - t0
print(json.dumps(dict(seconds=seconds, variants=study.n_variants, path=study.path_note)))
"""

RUN = """
import dataclasses, json, sys, time
sys.path.insert(0, {root!r})
sys.path.insert(0, {root!r} + '/benchmarks')
from bench_sweep import peak_rss_mb  # VmHWM: ru_maxrss survives exec on Linux
from linkpipe.study import load_study, run_study
t0 = time.perf_counter()
study = load_study({path!r})
if {one_by_one!r}:  # the variant-by-variant path forced (the "before" of a vectorised case)
    study = dataclasses.replace(study, slots=None, path_note="variant by variant (forced)")
path = run_study(study, {out!r}, {executor!r}, workers={workers})
seconds = time.perf_counter() - t0
peak = peak_rss_mb()
print(json.dumps(dict(seconds=seconds, peak_mb=peak, variants=study.n_variants,
                      path=study.path_note)))
"""


def goal_every_effect() -> str:
    """The basketball goal with every effect on (the base of these studies and of
    tests/test_study.py's vectorised cases)."""
    return GOAL.read_text().replace(
        'effects = ["springs", "gravity", "inertia"]',
        'effects = ["springs", "gravity", "inertia", "damping", "loads"]').replace(
        "free_length = 0.5833\n", "free_length = 0.5833\ndamping = 0.3\n") + EVERY_EFFECT_TABLES


def setup(folder: pathlib.Path) -> None:
    (folder / "goal_every_effect.toml").write_text(goal_every_effect())


def case(folder: pathlib.Path, name: str, text: str, executor="in_process", workers=None,
         one_by_one: bool = False) -> dict:
    """Run one study in a fresh process; return its seconds, peak memory and path
    (``one_by_one``: forced onto the variant-by-variant path)."""
    path = folder / f"{name}.toml"
    path.write_text(text)
    out = folder / f"out_{name}_{executor}_{workers}_{one_by_one}"
    code = RUN.format(root=str(ROOT), path=str(path), out=str(out), executor=executor,
                      workers=workers, one_by_one=one_by_one)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


WARM_DASK = """
import json, sys, time
sys.path.insert(0, {root!r})
from linkpipe.executors import dask_client
from linkpipe.study import load_study, run_study
study = load_study({path!r})
with dask_client(workers={workers}) as client:  # the cluster --workers starts
    address = client.scheduler.address
    # warm: each worker imports linkpipe and solves the base scene's stage 1 once
    run_study(load_study({warm!r}), {out!r} + "_warm", "dask", scheduler=address)
    seconds = []
    for rep in range(3):  # best of 3 on the running cluster (a fresh output file each)
        t0 = time.perf_counter()
        run_study(study, {out!r} + f"_{{rep}}", "dask", scheduler=address)
        seconds.append(time.perf_counter() - t0)
    print(json.dumps(dict(seconds=min(seconds))))
"""


def warm_dask(folder: pathlib.Path, workers: int) -> float:
    """Seconds of the 100,000-variant study on a running LocalCluster of ``workers`` (started and
    warmed with a small study first: what a user with a cluster waits for), best of 3 runs."""
    code = WARM_DASK.format(root=str(ROOT), path=str(folder / "v100k.toml"),
                            warm=str(folder / "v10k.toml"), workers=workers,
                            out=str(folder / f"out_warm_{workers}"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])["seconds"]


CEILING = """
import sys, time
sys.path.insert(0, {root!r})
from linkpipe.study import load_study
from linkpipe.study.batch import solve_batch
study = load_study({path!r})
solve_batch(study, 0, 1000)
t0 = time.perf_counter()
for i in range(20):
    solve_batch(study, 0, 1000)
print(time.perf_counter() - t0)
"""


def machine_ceiling(folder: pathlib.Path) -> float:
    """Two processes' efficiency on this machine now: one process's time for 20 batches over
    the slower of two running at once."""
    code = CEILING.format(root=str(ROOT), path=str(folder / "v100k.toml"))

    def start():
        return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)

    alone = float(start().communicate()[0])
    pair = [start(), start()]
    return alone / max(float(p.communicate()[0]) for p in pair)


def verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the 10,000-variant case only")
    ap.add_argument("--pivots", action="store_true", help="the pivot tolerance case only")
    ap.add_argument("--lengths", action="store_true", help="the link-length tolerance case only")
    ap.add_argument("--plates", action="store_true",
                    help="the plate side-length and drawn-point cases only")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        setup(folder)
        if args.pivots:
            return pivots(folder)
        if args.lengths:
            return lengths(folder)
        if args.plates:
            return plates(folder)
        r = case(folder, "v10k", FORCES.format(samples=10, steps=100))
        print(f"10,000 variants in-process: {r['seconds']:.2f} s (target <= 5 s: "
              f"{verdict(r['seconds'] <= 5)}); {r['variants'] / r['seconds']:,.0f} variants/s; "
              f"peak {r['peak_mb']:.0f} MB; {r['path'][:40]}")
        if args.quick:
            return
        text = FORCES.format(samples=100, steps=100)
        r = case(folder, "v100k", text)
        print(f"100,000 variants in-process, streamed: {r['seconds']:.2f} s (target <= 60 s: "
              f"{verdict(r['seconds'] <= 60)}); peak {r['peak_mb']:.0f} MB (target <= 2048: "
              f"{verdict(r['peak_mb'] <= 2048)})")
        t = {n: case(folder, "v100k", text, "dask", n)["seconds"] for n in (1, 2)}
        print(f"100,000 variants on a new Dask LocalCluster (its start and the workers' imports "
              f"included): 1 worker {t[1]:.2f} s, 2 workers {t[2]:.2f} s: "
              f"{100 * t[1] / (2 * t[2]):.0f} %")
        w = {n: min(warm_dask(folder, n) for _ in range(2)) for n in (1, 2)}
        eff = w[1] / (2 * w[2])
        print(f"100,000 variants on a running Dask cluster (started and warmed first; best of 3 "
              f"runs on each of 2 clusters): "
              f"1 worker {w[1]:.2f} s, 2 workers {w[2]:.2f} s; scaling efficiency {100 * eff:.0f} % "
              f"(target >= 80 %: {verdict(eff >= 0.8)}); the machine's own two-process "
              f"efficiency now: {100 * machine_ceiling(folder):.0f} %")
        r = case(folder, "pins", PINS, one_by_one=True)
        print(f"variant by variant (pin tolerances, {r['variants']} variants): "
              f"{r['seconds']:.2f} s, {r['variants'] / r['seconds']:,.0f} variants/s")
        pivots(folder)
        lengths(folder)
        plates(folder)


def one_process(folder: pathlib.Path, path: pathlib.Path, label: str) -> None:
    """A study variant by variant (forced) and vectorised in one process (after one warm run
    of each: imports and the base scene's solve): variants/s and the ratio."""
    code = LENGTHS.format(root=str(ROOT), path=str(path), out=str(folder / f"out_{label}"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    n, t = r["variants"], r["seconds"]
    rate = {k: n / v for k, v in t.items()}
    print(f"{label} ({n:,} variants, one process): variant by variant "
          f"{t['one_by_one']:.2f} s ({rate['one_by_one']:,.0f}/s) -> vectorised "
          f"{t['vectorised']:.2f} s ({rate['vectorised']:,.0f}/s): "
          f"{rate['vectorised'] / rate['one_by_one']:.1f}x; {r['path'][:60]}")


def lengths(folder: pathlib.Path) -> None:
    """Case 6: the shipped tolerance study (pins and link lengths)."""
    one_process(folder, ROOT / "configs" / "studies" / "basketball_goal_tolerance.toml",
                "link-length tolerances")


def plates(folder: pathlib.Path) -> None:
    """Cases 7 and 8: a plate's side lengths (the shear press's lever) and the basketball
    goal's moving points drawn elsewhere."""
    path = folder / "plates.toml"
    path.write_text(PLATES.format(base=(ROOT / "configs" / "shear_press.toml").as_posix()))
    one_process(folder, path, "plate side lengths")
    path = folder / "drawn.toml"
    import linkpipe  # the drawing of the base, for the ranges

    points = {p.name: p for p in linkpipe.load_scene(str(GOAL)).points}
    path.write_text(DRAWN.format(Bx0=points["B"].x - 0.05, Bx1=points["B"].x + 0.05,
                                 Cy0=points["C"].y - 0.05, Cy1=points["C"].y + 0.05,
                                 Hx0=points["H"].x - 0.05, Hx1=points["H"].x + 0.05))
    one_process(folder, path, "drawn moving points")


def pivots(folder: pathlib.Path) -> None:
    """Case 5: the pole's pivot tolerances, variant by variant (before) and vectorised."""
    before = case(folder, "pivots500", PIVOTS.format(samples=500), one_by_one=True)
    after = case(folder, "pivots2000", PIVOTS.format(samples=2000))
    rate = [r["variants"] / r["seconds"] for r in (before, after)]
    print(f"pivot tolerances: variant by variant {before['variants']} variants "
          f"{before['seconds']:.2f} s ({rate[0]:,.0f}/s) -> vectorised {after['variants']} "
          f"variants {after['seconds']:.2f} s ({rate[1]:,.0f}/s): {rate[1] / rate[0]:.1f}x; "
          f"{after['path'][:40]}")


if __name__ == "__main__":
    main()
