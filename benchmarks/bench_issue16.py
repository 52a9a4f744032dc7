"""Every target of issue 16 (scale) with its measured figure and verdict, in one command:

    .venv/bin/python benchmarks/bench_issue16.py            # about 5 minutes on 2 cores
    .venv/bin/python benchmarks/bench_issue16.py --quick    # smaller sizes; verdicts indicative

1. CLI end to end: ``python -m linkpipe run`` on the 360,001-step crank-rocker (positions,
   velocities, accelerations, ``.h5``, ``--no-rrd``), wall time of the process minus that of a
   2-step run of the same scene (imports and fixed costs cancel), best of 3 each; against
   pylinkage + numba's warm kernel (``step_fast_with_kinematics``) in this process, best of 3.
   Target: pylinkage's seconds / linkpipe's marginal seconds >= 2. Also printed, to show
   where the marginal goes: the same runs writing no file (``--no-h5``), and this disk's own
   time to make the run's .h5 durable as ``run`` does (write, fsync, rename over the old one).
2. Force stage memory: the basketball goal (springs, gravity, inertia) at 200k and 1M steps,
   peak resident memory of each ``run`` (fresh process, the sweep streamed in segments), to
   .h5 alone and to .h5 and .rrd. Target: 1M <= 1.5 x 200k.
3. 10M-step kinematics (the crank-rocker, positions, velocities, accelerations, ``run`` to
   .h5): peak memory. Target <= 2 GB. (--quick: 2M steps, the target scaled to 0.4 GB.)
4. Chains of N four-bar loops, N = 8..64, 2k steps: benchmarks/bench_scale.py's exponents,
   peak at N = 64 and threads verdicts (run as a subprocess; its own lines).
5. Recordings: the 360k-step crank-rocker with every effect and the basketball goal at 200k
   steps through ``run``: file size with ``--rrd-max-mb 50``, target <= 50 MB each; and with
   the defaults (the contract's: 100,000 steps, no size cap), printed beside it.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from linkpipe.segments import SEGMENT_BYTES  # noqa: E402
from bench_memory import scene_text  # noqa: E402  (a shipped config with its step count set)
from bench_sweep import pylinkage_available, pylinkage_run, scratch  # noqa: E402


def verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


def write_scene(folder: pathlib.Path, config: str, steps: int, extra: str = "") -> pathlib.Path:
    path = folder / f"{config}_{steps}.toml"
    path.write_text(scene_text(config, steps, extra))
    return path


def cli_seconds(scene: pathlib.Path, out: pathlib.Path, *flags: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "linkpipe", "run", str(scene), "--out", str(out),
                    "--quiet", *flags], check=True, cwd=ROOT)
    return time.perf_counter() - t0


def cli_target(folder: pathlib.Path, steps: int) -> None:
    big, small = (write_scene(folder, "fourbar_crank_rocker", n) for n in (steps, 2))
    kinds = {"h5": ("--no-rrd",), "none": ("--no-rrd", "--no-h5")}
    runs = {(k, n): [] for k in kinds for n in ("big", "small")}
    for _ in range(3):  # alternating, best of 3 each
        for kind, flags in kinds.items():
            runs[kind, "small"].append(cli_seconds(small, folder / "out", *flags))
            runs[kind, "big"].append(cli_seconds(big, folder / "out", *flags))
    best = {key: min(v) for key, v in runs.items()}
    marginal = best["h5", "big"] - best["h5", "small"]
    compute = best["none", "big"] - best["none", "small"]
    h5 = folder / "out" / "fourbar_crank_rocker.h5"
    disk = disk_seconds(h5, folder)
    size_mb = h5.stat().st_size / 1e6
    have = pylinkage_available()
    if not have.startswith("pylinkage"):
        print(f"1. CLI end to end, {steps:,} steps: {marginal:.3f} s marginal "
              f"({best['h5', 'big']:.3f} - {best['h5', 'small']:.3f}); pylinkage {have}")
        return
    pylinkage_run(1000)  # JIT or cache load
    peer = min(pylinkage_run(steps)[3] for _ in range(3))
    ratio = peer / marginal
    print(f"1. CLI end to end, {steps:,}-step crank-rocker, pos+vel+acc, .h5: {marginal:.3f} s "
          f"marginal (run {best['h5', 'big']:.3f} s - 2-step run {best['h5', 'small']:.3f} s); "
          f"pylinkage+numba warm kernel {peer:.3f} s ({have}): {ratio:.2f}x, target >= 2x: "
          f"{verdict(ratio >= 2)}")
    print(f"   - where it goes: the same runs with no file written (--no-h5) {compute:.3f} s "
          f"marginal ({peer / compute:.2f}x the peer); this disk alone, writing the run's "
          f"{size_mb:.0f} MB .h5 again with fsync and renaming it over the previous one (plain "
          f"os.write, best of 3) {disk:.3f} s; the 2x budget is {peer / 2:.3f} s")


def disk_seconds(h5: pathlib.Path, folder: pathlib.Path) -> float:
    """Seconds this disk takes to make ``h5``'s bytes durable as ``run`` does (write to a
    temporary name, fsync, rename over the previous file of the same size), best of 3: the
    floor under any run that writes that file, whatever its compute."""
    data = h5.read_bytes()
    target, tmp = folder / "disk_floor.bin", folder / "disk_floor.tmp"
    target.write_bytes(data)
    piece = SEGMENT_BYTES  # the run's parts
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view[:piece]):]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
        times.append(time.perf_counter() - t0)
    target.unlink()
    return min(times)


def peak_mb(config: str, steps: int, *flags: str) -> float:
    """Peak resident memory (MB, VmHWM: ru_maxrss survives exec on Linux, so a child would
    report its parent's peak) of ``python -m linkpipe run`` (``.h5``, the sweep streamed in
    segments) in a fresh process."""
    code = ("import sys, json, pathlib, tempfile; sys.path[:0] = [{r!r}, {b!r}];"
            "from linkpipe.__main__ import main; from bench_memory import scene_text;"
            "from bench_sweep import peak_rss_mb, scratch;"
            "d = scratch(); p = d / 's.toml';"
            "p.write_text(scene_text({c!r}, {n}, '')); "
            "assert main(['run', str(p), '--out', str(d), '--quiet', *{f!r}]) == 0;"
            "print(json.dumps(peak_rss_mb()))").format(
        r=str(ROOT), b=str(ROOT / "benchmarks"), c=config, n=steps, f=list(flags))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def memory_targets(quick: bool) -> None:
    small, large = (40_000, 200_000) if quick else (200_000, 1_000_000)
    for flags, what in ((("--no-rrd",), ".h5"), ((), ".h5 and .rrd")):
        a, b = peak_mb("basketball_goal", small, *flags), peak_mb("basketball_goal", large, *flags)
        print(f"2. force stage memory, basketball goal (springs, gravity, inertia), run to {what}: "
              f"{small:,} steps {a:.0f} MB, {large:,} steps {b:.0f} MB: {b / a:.2f}x, target "
              f"<= 1.5x: {verdict(b / a <= 1.5)}")
    steps, limit = (2_000_000, 0.4) if quick else (10_000_000, 2.0)
    peak = peak_mb("fourbar_crank_rocker", steps, "--no-rrd") / 1024
    print(f"3. {steps:,}-step kinematics (crank-rocker, pos+vel+acc, run to .h5): peak "
          f"{peak:.2f} GB, target <= {limit} GB: {verdict(peak <= limit)}")


def recording_targets(folder: pathlib.Path, quick: bool) -> None:
    cases = [("fourbar_crank_rocker", 36_000 if quick else 360_000, "EFFECTS"),
             ("basketball_goal", 20_000 if quick else 200_000, "")]
    for config, steps, extra in cases:
        scene = write_scene(folder, config, steps, extra)
        sizes = []
        for flags in (("--rrd-max-mb", "50"), ()):
            out = folder / f"rrd_{config}_{len(flags)}"
            cli_seconds(scene, out, "--no-h5", *flags)
            sizes.append(max(p.stat().st_size for p in out.glob("*.rrd")) / 1e6)
        print(f"5. recording of {config} ({steps:,} steps{', every effect' if extra else ''}), "
              f"--rrd-max-mb 50: {sizes[0]:.1f} MB, target <= 50 MB: {verdict(sizes[0] <= 50)} "
              f"(the defaults, 100,000 steps and no size cap: {sizes[1]:.1f} MB)")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    folder = scratch("linkpipe_issue16_")
    print(f"issue 16 targets, {time.strftime('%Y-%m-%d %H:%M')}{' (--quick)' if args.quick else ''}")
    cli_target(folder, 36_001 if args.quick else 360_001)
    memory_targets(args.quick)
    print("4. chains of N loops (benchmarks/bench_scale.py):")
    scale = [sys.executable, str(ROOT / "benchmarks" / "bench_scale.py"), "--repeats", "1" if args.quick else "2"]
    if args.quick:
        scale += ["--loops", "8", "16", "32"]
    lines = subprocess.run(scale, capture_output=True, text=True, check=True).stdout.splitlines()
    for line in lines:
        if re.match(r"- ", line):
            print("   " + line)
    recording_targets(folder, args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
