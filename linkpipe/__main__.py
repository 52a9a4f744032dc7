"""Command line: ``python -m linkpipe run|check|accuracy|fit|study|optimize``. Thin: parses, calls,
reports (the texts: :mod:`linkpipe.report`)."""
from __future__ import annotations

import argparse
import contextlib
import functools
import pathlib
import signal
import sys
import threading
import time

from .errors import LinkpipeError, SceneError
from .report import describe, fit_table, stage_table, summary
from .workers import using


#: --rrd-max-steps's default (stores/rrd's MAX_STEPS, without importing rerun to read it)
RRD_MAX_STEPS = 100_000
#: --rrd-max-mb's default (stores/rrd's MAX_BYTES): no size cap, only the contract's step cap
RRD_MAX_MB = 0.0


def _parser(prog: str) -> argparse.ArgumentParser:
    from .version import __version__

    p = argparse.ArgumentParser(prog=prog, description="Planar linkage analysis pipeline.")
    p.add_argument("--version", action="version", version=f"linkpipe {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="solve scenes and write outputs/<name>.h5 and .rrd")
    run.add_argument("scenes", nargs="+", help="scene TOML files")
    run.add_argument("--out", default="outputs", help="output folder (default: outputs)")
    run.add_argument("--no-h5", action="store_true", help="do not write the HDF5 file")
    run.add_argument("--no-rrd", action="store_true", help="do not write the Rerun recording")
    run.add_argument("--spawn", action="store_true", help="also stream to a new Rerun viewer")
    run.add_argument("--connect", metavar="ADDR", type=_address,
                     help="also stream to a running viewer (rerun+http://host:9876/proxy)")
    run.add_argument("--quiet", action="store_true", help="print only errors")
    run.add_argument("-v", "--verbose", action="store_true",
                     help="also print a table of where the time went, stage by stage")
    run.add_argument("--rrd-max-steps", type=_threads, default=None, metavar="N",
                     help="the most steps a recording keeps; past it a uniform stride (the "
                          ".h5 keeps every step; 0: no limit; default 100,000)")
    run.add_argument("--rrd-max-mb", type=_megabytes, default=None, metavar="MB",
                     help="the largest recording in MB (10^6 bytes); a sweep whose recording "
                          "would be larger keeps a uniform stride of steps (default 0: no "
                          "limit; 100,000 steps with every effect are ~90 MB)")
    run.add_argument("--threads", type=_threads, default=1, metavar="N",
                     help="BLAS threads while solving (default 1: the solves are many small "
                          "systems, where more threads only add overhead; 0: the BLAS "
                          "library's own default)")
    run.add_argument("--chunk-threads", type=_threads, default=0, metavar="N",
                     help="threads that share a sweep's chunks of steps (the Jacobian stage, "
                          "link angles and rates, finiteness checks); results do not depend on "
                          "it (default 0: the CPUs this process may use but one, which the HDF5 "
                          "writer takes, at most 4)")
    run.add_argument("--report", action="store_true",
                     help="also write <name>.html beside the .h5: the page `report` writes")
    _fleet_options(run)
    rep = sub.add_parser("report", help="write a self-contained HTML page of a run's or a "
                         "study's .h5 (NAME.html beside it)")
    rep.add_argument("files", nargs="+", metavar="NAME.h5")
    rep.add_argument("--out", default=None, help="the page's path (one file only; default: "
                     "beside the .h5, .html)")
    chk = sub.add_parser("check", help="validate scenes and describe them without solving")
    chk.add_argument("scenes", nargs="+")
    acc = sub.add_parser("accuracy", help="measure what accuracy costs in time for a scene")
    acc.add_argument("scene")
    acc.add_argument("--out", default="outputs")
    acc.add_argument("--quick", action="store_true", help="a short ladder (seconds)")
    acc.add_argument("--repeats", type=int, default=5)
    fit = sub.add_parser("fit", help="fit [fit] parameters to the scene's [[measurements]]")
    fit.add_argument("scene")
    fit.add_argument("--out", default="outputs", help="output folder (default: outputs)")
    _fleet_options(fit)
    study = sub.add_parser("study", help="solve the variants of a [study]: <name>_study.h5 and .rrd")
    study.add_argument("study", help="a study file (configs/studies/*.toml) or a scene with [study]")
    _variants_options(study)
    opt = sub.add_parser("optimize", help="search [optimize] parameters for the best design: "
                         "<name>_optimize.h5, .toml and .rrd")
    opt.add_argument("file", help="a study file or scene with [optimize] and [study.metrics]")
    _variants_options(opt)
    fol = sub.add_parser("follow", help="follow a log while it is written: <name>.h5 grows, "
                         "the viewer streams")
    fol.add_argument("scene", help="a scene with [time] log = <the growing log>")
    fol.add_argument("--out", default="outputs", help="output folder (default: outputs)")
    view = fol.add_mutually_exclusive_group()
    view.add_argument("--serve", action="store_true", help="serve the recording over gRPC; "
                      "viewers that connect late get the history")
    view.add_argument("--connect", metavar="ADDR", type=_address, help="stream to a running viewer "
                      "(rerun+http://host:9876/proxy)")
    fol.add_argument("--port", type=_positive, default=None, help="--serve's port (default 9876)")
    fol.add_argument("--server-memory", default=None, metavar="SIZE",
                     help="what --serve keeps for late viewers, the oldest rows dropped past "
                          "it (default 512MiB; e.g. 2GiB, 25%%)")
    fol.add_argument("--rrd", action="store_true", help="also write <name>.rrd as it grows")
    fol.add_argument("--idle", type=_seconds, default=None, metavar="S",
                     help="end after S seconds without a new row (default: follow until "
                          "Ctrl-C or SIGTERM)")
    fol.add_argument("--settle", type=_positive, default=None, metavar="N",
                     help="rows held back for the spline's end to settle before a row is "
                          "stored (default 20; a coarsely rounded log needs more: "
                          "docs/follow.md)")
    fol.add_argument("--quiet", action="store_true", help="print only the final line and errors")
    return p


def _fleet_options(p) -> None:
    """--logs GLOB (a fleet: the scene over every log), --log-name, and where tasks run."""
    p.add_argument("--logs", metavar="GLOB", help="a fleet: run the one scene over every log "
                   "file the glob matches (its [[logs]] file replaced); one row per log in "
                   "<name>_fleet.h5 (fit: <name>_fleet_fit.h5)")
    p.add_argument("--log-name", metavar="NAME", help="the [[logs]] entry --logs replaces "
                   "(needed when the scene has several)")
    _executor_options(p)


def _executor_options(p) -> None:
    """--workers / --scheduler: where batches run (default: in this process)."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive, metavar="N",
                       help="run batches on a local Dask cluster of N worker processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run batches on an existing Dask cluster (tcp://host:8786)")


def _variants_options(p) -> None:
    """What ``study`` and ``optimize`` (many variants of a scene) both take: --out, where the
    batches run, --no-rrd, --quiet."""
    p.add_argument("--out", default="outputs", help="output folder (default: outputs)")
    _executor_options(p)
    p.add_argument("--no-rrd", action="store_true", help="do not write the Rerun recording")
    p.add_argument("--quiet", action="store_true", help="print only errors")


def _number(text: str, kind, low, what: str):
    """An option's value of ``kind`` (int or float), finite and >= ``low``; argparse turns the
    ArgumentTypeError into one line naming the option, exit 2."""
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not low <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


def _address(text: str) -> str:
    """``--connect``: a viewer's address as Rerun parses it (rerun+http://host:port/proxy)."""
    from .stores.rrd import check_address

    try:
        check_address(text)
    except LinkpipeError as exc:
        raise argparse.ArgumentTypeError(f"expected a viewer's address like "
                                         f"rerun+http://127.0.0.1:9876/proxy, got {text!r} "
                                         f"({str(exc).split(': ', 1)[1]})") from None
    return text


def _megabytes(text: str) -> float:
    """``--rrd-max-mb``: a number of MB >= 0 (0: no cap)."""
    return _number(text, float, 0.0, "a size in MB >= 0 (0: no cap)")


def _seconds(text: str) -> float:
    """``--idle``: seconds >= 0."""
    return _number(text, float, 0.0, "a number of seconds >= 0")


def _threads(text: str) -> int:
    """``--threads``, ``--rrd-max-steps``: a whole number >= 0."""
    return _number(text, int, 0, "a whole number >= 0")


def _positive(text: str) -> int:
    """``--workers``: a whole number >= 1."""
    return _number(text, int, 1, "a whole number >= 1")


def recording_caps(max_steps: int | None, max_mb: float | None) -> tuple[int, float]:
    """``run``'s recording caps from ``--rrd-max-steps`` and ``--rrd-max-mb`` (None: not
    given): each as given; by default 100,000 steps and no size cap (the contract's: past
    ``--rrd-max-steps`` a uniform stride, and not before)."""
    return ((RRD_MAX_STEPS if max_steps is None else max_steps),
            (RRD_MAX_MB if max_mb is None else max_mb))


def main(argv: list[str] | None = None, prog: str = "python -m linkpipe") -> int:
    """Run the command line and return the exit status: 0 ok, 1 a scene failed inside linkpipe
    or its output could not be written, 2 bad input (scene, option), 130 stopped by Ctrl-C or
    SIGTERM. Temporary output files are removed on every one of these paths."""
    args = _parser(prog).parse_args(argv)
    if args.command == "run":
        args.rrd_max_steps, args.rrd_max_mb = recording_caps(args.rrd_max_steps, args.rrd_max_mb)
    command = {"run": _run, "check": _check, "accuracy": _accuracy, "fit": _fit,
               "study": _study, "optimize": _optimize, "report": _report,
               "follow": _follow}[args.command]
    previous = _signals_as_interrupts()
    try:
        with using(getattr(args, "chunk_threads", 0)):
            return command(args)
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: the writers removed their temporaries
        # one status for a run stopped from outside, whichever signal (130, as for Ctrl-C)
        kept = ("a study's finished batches stay in its .partial file: the same command resumes "
                "from them" if args.command == "study" else
                "outputs written before stay, the one being written was not kept")
        print(f"linkpipe: {'terminated' if isinstance(exc, _Terminated) else 'interrupted'}; "
              f"{kept}", file=sys.stderr)
        return 130
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        sys.unraisablehook = sys.__unraisablehook__


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so that it unwinds like Ctrl-C."""


def _signals_as_interrupts() -> dict:
    """SIGINT and SIGTERM stop the run where it is (KeyboardInterrupt, :class:`_Terminated`)
    and forbid any further rename of a temporary into place (a library that swallowed the
    exception mid-write must not publish the file); returns the previous handlers."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    from .stores import interrupt

    interrupt(False)

    def on_signal(signum, frame):
        interrupt()
        raise _Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()

    def unraisable(info, default=sys.unraisablehook):
        # a signal that lands in a finaliser or weakref callback is swallowed there by Python
        # ("Exception ignored in ..."); interrupt() has marked it, the next write stops the run
        if not isinstance(info.exc_value, KeyboardInterrupt):
            default(info)

    sys.unraisablehook = unraisable
    return {signum: signal.signal(signum, on_signal) for signum in (signal.SIGINT, signal.SIGTERM)}


class _Outcome:
    """The worst exit status met so far, and which inputs failed."""

    def __init__(self):
        self.code = 0
        self.failed: list[str] = []
        self.duplicate_names = False

    def fail(self, path, code: int, message: str) -> None:
        print(f"error: {message}", file=sys.stderr)
        self.code = max(self.code, code)
        self.failed.append(str(path))


@contextlib.contextmanager
def _reporting(path, outcome: _Outcome):
    """The one error handler: a user's mistake (LinkpipeError, MemoryError) is exit 2 with its
    message; anything else is exit 1, one line naming the file and the exception; never a
    traceback. The caller goes on with its next input."""
    try:
        yield
    except LinkpipeError as exc:  # a user's mistake (2), or an output not written (OutputError: 1)
        outcome.fail(path, getattr(exc, "exit_code", 2), str(exc))
    except MemoryError:  # the estimate in memory.check_memory passed, the machine did not
        outcome.fail(path, 2, f"{path}: out of memory for this sweep: use fewer steps, or "
                              "split it into several scenes")
    except OSError as exc:  # a file that cannot be read or written (disk full, permissions)
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        outcome.fail(path, 1, f"{path}:{where} {exc.strerror or exc}".rstrip())
    except Exception as exc:  # noqa: BLE001 - one input's crash must not stop the others
        outcome.fail(path, 1, f"{path}: internal error: {type(exc).__name__}: {exc}")


def _load_all(paths, outcome: _Outcome, out="outputs") -> list:
    """Load every scene first (bad ones reported, the others kept); two scenes that would write
    the same outputs, or a name too long for a file name in ``out``, are an error before any
    work (exit 2, naming the file)."""
    from .scene import load_scene

    scenes, first_path = [], {}
    for path in paths:
        with _reporting(path, outcome):
            scene = _read_scene(load_scene, path)
            _name_fits(path, scene.name, out)
            if scene.name in first_path:
                outcome.duplicate_names = True
                raise SceneError(path, "scene", "name", f"the name {scene.name!r} is also the name "
                                 f"of {first_path[scene.name]}: both would write "
                                 f"{scene.name}.h5 / .rrd", "give each scene its own [scene] name")
            first_path[scene.name] = path
            scenes.append(scene)
    return scenes


def _name_fits(path, name: str, out) -> None:
    """SceneError where the files named after ``name`` in ``out`` (outputs, lock, temporaries)
    would pass the file system's limit on a file name."""
    from .stores import longest_output_name

    longest, limit = longest_output_name(out)
    size = len(name.encode("utf-8"))
    if size > longest:
        raise SceneError(path, "scene", "name", f"{size} bytes long: the files named after it "
                         f"in {out} (its .h5, .rrd, lock and temporaries) would be longer than "
                         f"the file system's limit of {limit} bytes for a file name",
                         f"give [scene] name at most {longest} bytes (characters, in plain ASCII)")


def _read_scene(load, path):
    """``load(path)``, a file nested deeper than the TOML reader follows (it recurses: Python's
    recursion limit) being the file's mistake, not an internal error."""
    try:
        return load(path)
    except RecursionError:
        raise SceneError(path, "", None, "arrays or inline tables nested more deeply than the "
                         "TOML reader can follow", "a scene nests a few levels at most: remove "
                         "the extra brackets") from None


def _run(args) -> int:
    from .memory import check_memory
    from .segments import steps_per_segment

    out = pathlib.Path(args.out)
    if out.exists() and not out.is_dir():
        print(f"error: --out {out}: is a file, not a folder; name a folder (it is created if "
              "missing)", file=sys.stderr)
        return 2
    if args.report and args.no_h5:
        print("error: --report draws its page from the run's .h5, which --no-h5 leaves "
              "unwritten; drop one of them", file=sys.stderr)
        return 2
    if args.logs:
        return _fleet("run", args, args.scenes)
    outcome = _Outcome()
    scenes = _load_all(args.scenes, outcome, out)
    if outcome.duplicate_names:
        return 2  # before any work: two scenes would overwrite each other's outputs
    for scene in scenes:
        with _reporting(scene.path, outcome):
            t0 = time.perf_counter()
            segment = steps_per_segment(scene)
            # before the progress bar: a sweep too big for memory is a scene error
            check_memory(scene, segment, _recorded_steps(scene, args))
            if scene.dynamics is not None:  # its equations of motion hold, before any file
                from .dynamics import equations_of

                equations_of(scene)
            bar = _progress_bar(scene, args)
            from .stores import output_folder, output_lock

            output_folder(out)

            with output_lock(out, scene.name):  # another run of this name waits: .h5, .rrd pair
                result, written, kept = _solve_and_write(scene, out, args, bar, segment)
                if args.report:
                    from .html_report import write_report

                    written.append(str(write_report(out / f"{scene.name}.h5")))
            if bar:
                bar.close()
            if not args.quiet:
                total = time.perf_counter() - t0
                print(summary(result, written, total, kept))
                if args.verbose:
                    print(stage_table(result.seconds, total, result.totals.n_steps))
    if outcome.failed and len(args.scenes) > 1 and not args.quiet:
        print(f"failed: {', '.join(outcome.failed)}", file=sys.stderr)
    return outcome.code


def _report(args) -> int:
    """``report NAME.h5 ...``: each file's HTML page (:mod:`linkpipe.html_report`)."""
    from .html_report import write_report

    if args.out and len(args.files) > 1:
        print("error: --out names one page; give one .h5 with it", file=sys.stderr)
        return 2
    outcome = _Outcome()
    for path in args.files:
        with _reporting(path, outcome):
            if not pathlib.Path(path).is_file():
                outcome.fail(path, 2, f"{path}: no such file; give a .h5 that `run` or "
                             "`study` wrote")
                continue
            print(f"wrote {write_report(path, args.out)}")
    return outcome.code


def _recorded_steps(scene, args) -> int:
    """The most rows a streamed run keeps for its recording (0 without one): a bound for the
    memory check (the size cap usually keeps fewer)."""
    if args.no_rrd and not (args.spawn or args.connect):
        return 0
    return min(scene.n_steps, args.rrd_max_steps) if args.rrd_max_steps else scene.n_steps


def _solve_and_write(scene, out: pathlib.Path, args, bar, segment: int):
    """Solve ``scene`` (in segments where it is long: :mod:`linkpipe.segments`), its .h5
    written segment by segment, then its .rrd (and streams where asked) from the rows the
    recording keeps; return (the Result with every stage's seconds, paths written, the steps
    the recording kept when not every one)."""
    from .segments import stream
    from .stores import stop_if_interrupted

    name = scene.name
    recording = not args.no_rrd or args.spawn or args.connect
    max_bytes = int(args.rrd_max_mb * 10**6)
    plan = None
    if recording:  # the recording's stride, set on the first segment (stores.rrd.plan)
        from .stores import rrd

        plan = functools.partial(rrd.plan, max_steps=args.rrd_max_steps, max_bytes=max_bytes)
    written, kept = [], None
    with contextlib.ExitStack() as files:
        sinks = []
        if not args.no_h5:
            from .stores import hdf5

            sinks.append(files.enter_context(hdf5.SweepWriter(out / f"{name}.h5", scene.n_steps)))
            written.append(str(out / f"{name}.h5"))
        result = stream(scene, sinks, recording=plan, progress=bar.stage if bar else None,
                        threads=args.threads or None, segment=segment,
                        between=stop_if_interrupted, check=False)
        t0 = time.perf_counter()  # then the file closed, on disk (fsync) and renamed into place
    if sinks:
        result.seconds["hdf5"] += time.perf_counter() - t0
    if recording:
        if bar:
            bar.stage("rrd")
        t0 = time.perf_counter()
        target = None if args.no_rrd else out / f"{name}.rrd"
        kept = rrd.write(result, target, spawn=args.spawn, connect=args.connect,
                         max_steps=args.rrd_max_steps, max_bytes=max_bytes,
                         h5_written=not args.no_h5)
        result.seconds["rrd"] = time.perf_counter() - t0
        if target is not None:
            written.append(str(target))
    return result, written, kept


PROGRESS_MIN_STEPS = 20_000  # sweeps at least this long get a progress bar


class _StageBar:
    """A tqdm bar over one scene's steps, its postfix the stage at work (a sweep in segments
    moves the bar at the end of each segment, back to 0 where it starts again on the general
    path; a whole one at its end)."""

    def __init__(self, scene):
        from tqdm import tqdm

        self.bar = tqdm(total=scene.n_steps, desc=scene.name, unit="step", unit_scale=True,
                        leave=False, file=sys.stderr,
                        disable=None)  # None: shown on a terminal only, never in a log

    def stage(self, name, done: int | None = None):
        if done is not None:
            self.bar.n = done
        self.bar.set_postfix_str(name)  # (refreshes the bar)

    def close(self):
        self.bar.update(self.bar.total - self.bar.n)
        self.bar.close()


def _progress_bar(scene, args):
    if args.quiet or scene.n_steps < PROGRESS_MIN_STEPS:
        return None
    return _StageBar(scene)


def _check(args) -> int:
    from .pipeline import preflight
    from .segments import steps_per_segment
    from .study import load_study
    from .study.report import describe_study
    from .study.spec import study_kind

    outcome = _Outcome()
    kinds = {p: study_kind(p) for p in args.scenes}
    from .study.problem import has_optimize, load_problem
    from .study.report import describe_problem

    for path in args.scenes:  # [study] checked as `study` would (its base solved once)
        if kinds[path] or has_optimize(path):
            with _reporting(path, outcome):
                if has_optimize(path):  # and [study.parameters] too, where it has them
                    print(describe_problem(load_problem(path)))
                if kinds[path] and (not has_optimize(path) or _has_study_parameters(path)):
                    print(describe_study(load_study(path)))
    for scene in _load_all([p for p in args.scenes if kinds[p] != "study"], outcome):
        with _reporting(scene.path, outcome):
            # memory (as run's defaults need it), degrees of freedom, the start assembles
            model, mob = preflight(scene, steps_per_segment(scene),
                                   min(scene.n_steps, RRD_MAX_STEPS))
            from .fit import declared_fit_parameters
            from .kinematics.start import drawing_slip, scene_warnings, sweep_reach

            unreached, note = sweep_reach(model)
            reach = ((f"the first {unreached} of {scene.n_steps} steps are out of the drawing's "
                      f"reach and will be no_assembly: {note}",) if note else ())
            print(describe(scene, mob, scene_warnings(model) + reach,
                           declared_fit_parameters(scene), drawing_slip(model)))
    return outcome.code


def _has_study_parameters(path) -> bool:
    import tomllib

    with open(path, "rb") as f:
        return "parameters" in tomllib.load(f).get("study", {})


def _accuracy(args) -> int:
    from .accuracy import run_accuracy

    outcome = _Outcome()
    with _reporting(args.scene, outcome):
        return run_accuracy(args.scene, out=pathlib.Path(args.out), quick=args.quick,
                            repeats=args.repeats)
    return outcome.code


def _fit(args) -> int:
    from tqdm import tqdm

    if args.logs:
        return _fleet("fit", args, [args.scene])  # (with [fit] per_log: one joint fit)
    from .fit import fit
    from .scene import load_scene
    from .stores import fit as fit_store

    outcome = _Outcome()
    with _reporting(args.scene, outcome):
        scene = _read_scene(load_scene, args.scene)
        _name_fits(args.scene, scene.name, args.out)
        from .fit import fit_parameters
        from .stores import output_folder

        fit_parameters(scene)  # the scene's own mistakes first: nothing made for them
        out = output_folder(args.out)  # then, before the fit, a wrong --out
        bar = tqdm(desc=f"fit {scene.name}", unit=" solves", disable=None, leave=False)

        def progress(n, cost):
            bar.update(1)
            bar.set_postfix(cost=f"{cost:.4g}")

        try:
            result = fit(scene, progress=progress)
        finally:
            bar.close()
        paths = [out / f"{scene.name}_fit.toml", out / f"{scene.name}_fit.h5"]
        fit_store.write_toml(result, paths[0])
        fit_store.write_h5(result, paths[1])
        print(fit_table(result))
        print("  wrote " + ", ".join(map(str, paths)))
    return outcome.code


def _fleet(kind: str, args, scenes: list) -> int:
    """``run`` / ``fit`` with ``--logs``: one scene over a glob of logs, one row per log."""
    from tqdm import tqdm

    from .executors import executor_name
    from .fleet import fleet_scene, run_fleet, write_fleet

    outcome = _Outcome()
    if len(scenes) != 1:
        print("error: --logs runs one scene over many logs: give one scene", file=sys.stderr)
        return 2
    with _reporting(scenes[0], outcome):
        scene = fleet_scene(scenes[0], args.logs, args.log_name)
        from .stores import output_folder

        from .fleet import log_files

        log_files(args.logs)  # a glob that matches nothing: said before anything is made
        joint = kind == "fit" and _per_log(scene)  # (a bad [fit] table likewise)
        output_folder(args.out)  # before the fleet: a wrong --out is said at once
        if joint:
            return _joint(scene, args, outcome)
        bar = tqdm(desc=f"{kind} {scene.name}", unit=" logs", disable=None, leave=False)
        try:
            paths, rows = run_fleet(kind, scene, args.logs, args.log_name,
                                    executor_name(args.workers, args.scheduler), args.workers,
                                    args.scheduler, progress=lambda i: bar.update(1))
        finally:
            bar.close()
        path, table = write_fleet(kind, scene, args.logs, paths, rows, pathlib.Path(args.out))
        print(table)
        print(f"  wrote {path}")
        if all(len(r) == 1 for r in rows):  # no log could be taken: the scene's mistake
            outcome.code = 2
    return outcome.code


def _per_log(scene) -> bool:
    """Whether the scene's [fit] names per_log parameters (checked): a joint fit over --logs."""
    import tomllib

    from .fit import fit_options, parameters_of

    data = tomllib.loads(scene.text)
    if "fit" not in data:
        return False
    parameters_of(scene, data)
    return bool(fit_options(scene, data).per_log)


def _joint(scene, args, outcome) -> int:
    """``fit --logs`` with ``[fit] per_log``: one least squares over every log."""
    import tomllib

    from tqdm import tqdm

    from .fit import parameters_of
    from .joint import joint_fit, joint_table, write_joint
    from .output_units import measured_units, parameter_units

    if args.workers or args.scheduler:
        print("note: a joint fit ([fit] per_log) runs in this process; --workers and "
              "--scheduler spread a fleet's separate fits", file=sys.stderr)
    bar = tqdm(desc=f"fit {scene.name} (joint)", unit=" evaluations", disable=None, leave=False)
    try:
        result = joint_fit(scene, args.logs, args.log_name,
                           progress=lambda n, cost: bar.update(1))
    finally:
        bar.close()
    path = write_joint(result, args.logs, pathlib.Path(args.out))
    params = parameters_of(scene, tomllib.loads(scene.text))
    order = {p.address: u for p, u in zip(params, parameter_units(scene, params))}
    print(joint_table(result, {"parameter": [order[p.address] for p in
                                             result.shared + result.per_log],
                               "measurement": measured_units(scene)}))
    print(f"  wrote {path}")
    return outcome.code


def _study(args) -> int:
    from .executors import executor_name
    from .study import load_study, run_study
    from .study.report import study_table

    outcome = _Outcome()
    with _reporting(args.study, outcome):
        t0 = time.perf_counter()
        study = load_study(args.study)
        path = run_study(study, args.out, executor_name(args.workers, args.scheduler),
                         args.workers, args.scheduler,
                         progress=not args.quiet)
        written = [str(path)]
        if not args.no_rrd:
            from .stores.rrd import study as study_rrd
            from .stores.study import read_arrays
            from .study.view import study_view

            rrd_path = path.with_suffix(".rrd")
            study_rrd.write(study_view(study, read_arrays(path)), rrd_path)
            written.append(str(rrd_path))
        if not args.quiet:
            print(study_table(study, path, time.perf_counter() - t0))
            print("  wrote " + ", ".join(written))
    return outcome.code


def _optimize(args) -> int:
    from .executors import Pool
    from .stores import optimize as store, output_folder
    from .study.optimize import optimize
    from .study.problem import load_problem
    from .study.report import optimize_table

    outcome = _Outcome()
    with _reporting(args.file, outcome):
        t0 = time.perf_counter()
        problem = load_problem(args.file)
        out = output_folder(args.out)  # a wrong --out before the search
        from tqdm import tqdm

        bar = tqdm(desc=f"optimize {problem.study.name}", unit=" generations", leave=False,
                   disable=True if args.quiet else None)  # None: on a terminal only

        def progress(generation, best):
            bar.update(1)
            bar.set_postfix_str(f"best {best:.6g}")

        try:
            with Pool(args.workers, args.scheduler) as pool:
                found = optimize(problem, pool, progress)  # Infeasible: exit 1, nothing written
        finally:
            bar.close()
        name = problem.study.name
        paths = [out / f"{name}_optimize.h5", out / f"{name}_optimize.toml"]
        store.write_h5(found, paths[0])
        store.write_toml(found, paths[1])
        if not args.no_rrd:
            from .stores.rrd import study as study_rrd
            from .study.view import optimize_view

            paths.append(out / f"{name}_optimize.rrd")
            study_rrd.write(optimize_view(found), paths[2])
        if not args.quiet:
            print(optimize_table(found, time.perf_counter() - t0))
            print("  wrote " + ", ".join(map(str, paths)))
    return outcome.code


def _follow(args) -> int:
    """``follow``: Ctrl-C and SIGTERM end it as --idle does (the held-back rows solved, the
    file complete), exit 0; a fault of the log ends it likewise, exit 1."""
    from .follow import follow

    stop = threading.Event()
    signals = {}
    if threading.current_thread() is threading.main_thread():
        signals = {s: signal.signal(s, lambda signum, frame: stop.set())
                   for s in (signal.SIGINT, signal.SIGTERM)}
    outcome = _Outcome()
    try:
        with _reporting(args.scene, outcome):
            done = follow(args.scene, args.out, serve=args.serve, connect=args.connect,
                          port=args.port, idle=args.idle, stop=stop, rrd=args.rrd,
                          memory=args.server_memory,
                          **({} if args.settle is None else {"settle": args.settle}),
                          say=(lambda text: None) if args.quiet else print)
            if done.code:
                print(f"error: {done.why}", file=sys.stderr)
            alarms = ", ".join(f"{name} {k:,} row(s)" for name, k in done.alarms.items())
            print(f"{done.path}: {done.rows:,} rows ({done.new:,} new), complete"
                  + (f"; alarms: {alarms}" if alarms else "")
                  + (f"; ended: {done.why}" if done.why and not done.code else ""))
            outcome.code = done.code
    finally:
        for s, handler in signals.items():
            signal.signal(s, handler)
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
