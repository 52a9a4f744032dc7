"""Command line: ``python -m linkpipe run|check|accuracy``. Thin: parses, calls, reports."""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

from .errors import LinkpipeError


def _parser(prog: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Planar linkage analysis pipeline.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="solve scenes and write outputs/<name>.h5 and .rrd")
    run.add_argument("scenes", nargs="+", help="scene TOML files")
    run.add_argument("--out", default="outputs", help="output folder (default: outputs)")
    run.add_argument("--no-h5", action="store_true", help="do not write the HDF5 file")
    run.add_argument("--no-rrd", action="store_true", help="do not write the Rerun recording")
    run.add_argument("--spawn", action="store_true", help="also stream to a new Rerun viewer")
    run.add_argument("--connect", metavar="ADDR", help="also stream to a running viewer (rerun+http://...)")
    run.add_argument("--quiet", action="store_true", help="print only errors")
    chk = sub.add_parser("check", help="validate scenes and describe them without solving")
    chk.add_argument("scenes", nargs="+")
    acc = sub.add_parser("accuracy", help="measure what accuracy costs in time for a scene")
    acc.add_argument("scene")
    acc.add_argument("--out", default="outputs")
    acc.add_argument("--quick", action="store_true", help="a short ladder (seconds)")
    acc.add_argument("--repeats", type=int, default=5)
    return p


def main(argv: list[str] | None = None, prog: str = "python -m linkpipe") -> int:
    """Run the command line and return the exit status (0 ok, 1 a scene failed, 2 bad input)."""
    args = _parser(prog).parse_args(argv)
    if args.command == "run":
        return _run(args)
    if args.command == "check":
        return _check(args)
    if args.command == "accuracy":
        return _accuracy(args)
    return 2  # pragma: no cover - argparse rejects unknown commands


def _err(msg: str) -> None:
    print(f"error: {msg}", file=sys.stderr)


def _run(args) -> int:
    from .pipeline import check_memory, solve
    from .scene import load_scene

    out = pathlib.Path(args.out)
    if out.exists() and not out.is_dir():
        _err(f"--out {out}: is a file, not a folder; name a folder (it is created if missing)")
        return 2
    worst = 0
    for path in args.scenes:
        try:
            t0 = time.perf_counter()
            scene = load_scene(path)
            check_memory(scene)  # before the progress bar: a sweep too big for memory is a scene error
            bar = _progress_bar(scene, args)
            result = solve(scene, progress=bar.stage if bar else None)
            written = []
            out.mkdir(parents=True, exist_ok=True)
            if not args.no_h5:
                from .stores import hdf5

                if bar:
                    bar.stage("hdf5")
                t1 = time.perf_counter()
                target = out / f"{scene.name}.h5"
                hdf5.write(result, target)
                result.seconds["hdf5"] = time.perf_counter() - t1
                written.append(str(target))
            if not args.no_rrd or args.spawn or args.connect:
                from .stores import rrd

                if bar:
                    bar.stage("rrd")
                t1 = time.perf_counter()
                target = None if args.no_rrd else out / f"{scene.name}.rrd"
                rrd.write(result, target, spawn=args.spawn, connect=args.connect)
                result.seconds["rrd"] = time.perf_counter() - t1
                if target is not None:
                    written.append(str(target))
            if bar:
                bar.close()
            if not args.quiet:
                print(summary(result, written, time.perf_counter() - t0))
        except LinkpipeError as exc:
            _err(str(exc))
            worst = max(worst, 2)
        except MemoryError:  # the estimate in pipeline.check_memory passed, the machine did not
            _err(f"{path}: out of memory for this sweep: use fewer steps, or split it into "
                 "several scenes")
            worst = max(worst, 2)
        except Exception as exc:  # noqa: BLE001 - one scene's crash must not stop the others
            _err(f"{path}: internal error: {type(exc).__name__}: {exc}")
            worst = max(worst, 1)
    return worst


PROGRESS_MIN_STEPS = 20_000  # sweeps at least this long get a progress bar


class _StageBar:
    """A tqdm bar over one scene's stages (solve stages, then the writers)."""

    def __init__(self, scene, total):
        from tqdm import tqdm

        self.bar = tqdm(total=total, desc=scene.name, unit="stage", leave=False, file=sys.stderr)
        self.started = False

    def stage(self, name):
        if self.started:
            self.bar.update(1)
        self.started = True
        self.bar.set_postfix_str(name)

    def close(self):
        self.bar.update(1)
        self.bar.close()


def _progress_bar(scene, args):
    if args.quiet or scene.n_steps < PROGRESS_MIN_STEPS:
        return None
    from .pipeline import Plan

    writers = (0 if args.no_h5 else 1) + (0 if args.no_rrd else 1)
    return _StageBar(scene, len(Plan.of(scene).stages) + 1 + writers)


def summary(result, written=(), seconds_total=None) -> str:
    """Return the short per-scene report printed by ``run``."""
    sc = result.scene
    lines = [f"{sc.name}: {result.message} ({result.n_steps} steps, {result.n_ok} ok, "
             f"{result.n_steps - result.n_ok} failed)"]
    solved = np.isfinite(result.position).all(axis=(1, 2))  # not no_assembly / not_converged
    if np.isfinite(result.residual[solved]).any():
        how = ("closed-form dyads, no iterations" if result.solver_method_used == "dyads" else
               f"Newton iterations mean {result.iterations.mean():.2f} max {result.iterations.max()}")
        lines.append(f"  max residual {np.nanmax(result.residual[solved]):.2e} {result.units()['length']}"
                     f" (solved steps), {how}")
    if result.velocity_residual is not None and np.isfinite(result.velocity_residual).any():
        extra = f"  max linear-equation residuals: velocity {np.nanmax(result.velocity_residual):.1e}"
        if result.acceleration_residual is not None and np.isfinite(result.acceleration_residual).any():
            extra += f", acceleration {np.nanmax(result.acceleration_residual):.1e}"
        lines.append(extra)
    from .scene import Solver

    changed = {k: v for k, v in vars(sc.solver).items() if v != getattr(Solver, k)}
    used = getattr(result, "solver_method_used", "")
    path = [f"path {used}"] if used else []
    if changed or path:  # the path taken, and the [solver] knobs not at linkpipe's defaults
        lines.append("  solver: " + ", ".join(path + [f"{k} {v}" for k, v in changed.items()]))
    if result.mobility.redundant:
        line = (f"  redundant constraints: {result.mobility.redundant} (solved by least squares; "
                f"'singular' only beyond them)")
        names = result.forces_not_unique()
        if names:
            line += f"; not unique (minimum-norm choice): {', '.join(names)}"
        lines.append(line)
    if result.time_note:
        lines.append(f"  {result.time_note}")
    if sc.effects:
        lines.append(f"  effects: {', '.join(sc.effects)}")
    if sc.present_but_off:
        lines.append(f"  present but off: {', '.join(sc.present_but_off)}")
    if result.forces and "input_force" in result.forces:
        _, f, unit = result.forces["input_force"]
        for j, name in enumerate(result.driver_names):
            col = f[:, j]
            if np.isfinite(col).any():
                lines.append(f"  input force {name}: {np.nanmin(col):.6g} .. {np.nanmax(col):.6g} {unit}")
    if written:
        lines.append("  wrote " + ", ".join(written))
    secs = ", ".join(f"{k} {v:.3f}" for k, v in result.seconds.items())
    if seconds_total is not None:
        secs += f"; total {seconds_total:.3f}"
    lines.append(f"  seconds: {secs}")
    return "\n".join(lines)


def _check(args) -> int:
    from .pipeline import preflight
    from .scene import load_scene

    worst = 0
    for path in args.scenes:
        try:
            scene = load_scene(path)
            model, mob = preflight(scene)  # memory, degrees of freedom, the start assembles
            print(f"{path}: scene {scene.name!r} is valid")
            print(f"  points: {', '.join(p.name + (' (fixed)' if p.fixed else '') for p in scene.points)}")
            print(f"  links: {', '.join(l.name + '[' + ' '.join(l.points) + ']' for l in scene.links)}")
            if scene.sliders:
                print(f"  sliders: {', '.join(s.name for s in scene.sliders)}")
            print(f"  degrees of freedom: {mob.dof} ({mob.n_q} unknowns, {mob.n_constraints} constraints, "
                  f"rank {mob.rank}, {mob.redundant} redundant); drivers: "
                  + ", ".join(f"{d.name} ({d.steps} steps)" for d in scene.drivers))
            if mob.redundant:
                print(f"  redundant: {mob.redundant} constraint(s) implied by the others (e.g. a link "
                      "parallel to two others); solved by least squares, 'singular' flags only rank "
                      "loss beyond them, and the forces they share are a minimum-norm choice")
            print(f"  effects: {', '.join(scene.effects) or 'none (kinematics only)'}")
            if scene.present_but_off:
                print(f"  present but off: {', '.join(scene.present_but_off)}")
        except LinkpipeError as exc:
            _err(str(exc))
            worst = 2
    return worst


def _accuracy(args) -> int:
    try:
        from .accuracy import run_accuracy
    except ImportError:  # pragma: no cover
        _err("the accuracy command is not available in this build")
        return 2
    try:
        return run_accuracy(args.scene, out=pathlib.Path(args.out), quick=args.quick, repeats=args.repeats)
    except LinkpipeError as exc:
        _err(str(exc))
        return 2


if __name__ == "__main__":
    sys.exit(main())
