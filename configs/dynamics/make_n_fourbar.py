"""Write the IFToMM A02 N-four-bar scene (configs/dynamics/n_fourbar_a02.toml) or a hanging
variant for the chain benchmark: ``python make_n_fourbar.py [N] [--hanging] [--to T]``.

A02 (library of computational benchmark problems, Universidad de La Coruña,
http://lim.ii.udc.es/mbsbenchmark/, problem A02): N four-bar windows of 2N + 1 links, each 1 m
long with 1 kg spread uniformly (centre at mid-length, inertia m L^2 / 12), ground pivots A_i 1 m
apart, gravity 9.81 N/kg along -y; here started with the rods upright and B0 moving at 1 m/s
along +x. It falls to the horizontal pose, where every link is collinear and the mechanism has
N + 1 degrees of freedom for an instant: a singular pose (docs/dynamics.md, "A02").
``--hanging``: the rods hang 30 degrees off straight down, at rest (a pendulum that never reaches
the horizontal pose: benchmarks/bench_dynamics.py's chain of 2N + 1 links)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path


def scene_text(n: int, hanging: bool = False, to: float = 10.0, output_step: float = 0.01,
               rtol: float = 1e-9) -> str:
    start = -60.0 if hanging else 90.0
    rate = 0.0 if hanging else -math.degrees(1.0)  # B0's x velocity 1 m/s: theta' = -1 rad/s
    c, s = math.cos(math.radians(start)), math.sin(math.radians(start))
    name = f"n_fourbar_{n}_hanging" if hanging else "n_fourbar_a02"
    lines = [f"# Written by configs/dynamics/make_n_fourbar.py {n}{' --hanging' if hanging else ''}"
             " (see its docstring).",
             "[scene]", f'name = "{name}"',
             f'description = "IFToMM A02: {n} four-bar windows, {2 * n + 1} links of 1 m, 1 kg"',
             'units = { length = "m", mass = "kg", time = "s", force = "N" }', "", "[points]"]
    for i in range(n + 1):
        lines.append(f"A{i} = {{ x = {float(i)!r}, y = 0.0, fixed = true }}")
        lines.append(f"B{i} = {{ x = {i + c!r}, y = {s!r} }}")
    for i in range(n + 1):
        lines += ["", "[[links]]", f'name = "rod{i}"', f'points = ["A{i}", "B{i}"]',
                  f'lengths = {{ "A{i}-B{i}" = 1.0 }}']
    for i in range(n):
        lines += ["", "[[links]]", f'name = "coupler{i}"', f'points = ["B{i}", "B{i + 1}"]',
                  f'lengths = {{ "B{i}-B{i + 1}" = 1.0 }}']
    lines += ["", "[[drivers]]", 'name = "rod0"', 'angle = ["A0", "B0"]', f"from = {start!r}",
              f"start_rate = {rate!r}", "", "[dynamics]", f"to = {to!r}",
              f"output_step = {output_step!r}", f"rtol = {rtol!r}", "", "[analysis]",
              'effects = ["gravity", "inertia"]', "", "[gravity]", "g = [0.0, -9.81]"]
    for name in [f"rod{i}" for i in range(n + 1)] + [f"coupler{i}" for i in range(n)]:
        lines += ["", "[[masses]]", f'link = "{name}"', "mass = 1.0", "center = [0.5, 0.0]",
                  "inertia = 0.08333333333333333"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("n", type=int, nargs="?", default=40)
    ap.add_argument("--hanging", action="store_true")
    ap.add_argument("--to", type=float, default=10.0)
    args = ap.parse_args()
    out = Path(__file__).with_name("n_fourbar_a02.toml" if not args.hanging
                                   else f"n_fourbar_{args.n}_hanging.toml")
    out.write_text(scene_text(args.n, args.hanging, args.to))
    print(f"wrote {out}")
