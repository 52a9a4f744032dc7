"""A sweep that mostly cannot assemble against one that can (issue 34).

    .venv/bin/python benchmarks/bench_reach.py

The crank-rocker of ``configs/fourbar_crank_rocker.toml`` (crank 1, coupler 3.5, rocker 3,
ground 4; 361 steps over one turn) beside the same scene with a 0.02 m coupler, whose B is
drawn 3.6 m from where it assembles: only the 20 crank angles where the crank's pin is within
0.02 m of 3 m from O4 assemble (``20/361 steps ok; 341 no_assembly``), and the sweep runs on
the general Newton path (the dyads cannot assemble everywhere), whose steps in a gap are
decided by damped least squares. Each row times ``linkpipe.solve(scene)`` (every stage the
scene needs: model, positions, derivatives; no files), best of 5 after one warm-up call, both
in this process. Target: the short coupler costs at most 10x the crank-rocker.
"""
from __future__ import annotations

import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_sweep import best_of  # noqa: E402  (same process, same timing rule)

TARGET = 10.0


def scenes():
    import linkpipe

    path = ROOT / "configs" / "fourbar_crank_rocker.toml"
    text = path.read_text()
    short = text.replace('"A-B" = 3.5', '"A-B" = 0.02')
    assert short != text
    return (linkpipe.parse_scene(text, str(path)),
            linkpipe.parse_scene(short, str(path.with_name("short_coupler.toml"))))


def main() -> int:
    import linkpipe

    good, short = scenes()
    t_good, r_good = best_of(lambda: linkpipe.solve(good), 5)
    t_short, r_short = best_of(lambda: linkpipe.solve(short), 5)
    ratio = t_short / t_good
    print(f"crank-rocker (coupler 3.5 m): {t_good * 1e3:8.1f} ms  {r_good.message}")
    print(f"short coupler (0.02 m):       {t_short * 1e3:8.1f} ms  {r_short.message}")
    print(f"ratio {ratio:.1f}x (target <= {TARGET:g}x): {'PASS' if ratio <= TARGET else 'FAIL'}")
    return 0 if ratio <= TARGET else 1


if __name__ == "__main__":
    raise SystemExit(main())
