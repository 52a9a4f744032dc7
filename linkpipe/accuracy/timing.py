"""Measuring the ladder: each setting solved round-robin, timed per stage, its errors taken."""
from __future__ import annotations

import dataclasses as dc
import datetime
import gc
import math
import os
import pathlib
import platform
import time

import numpy as np

from ..pipeline import solve
from ..errors import LinkpipeError
from ..scene import Scene, load_scene
from .knobs import KNOBS, settings
from .references import References, _measure_errors, _scales, friction_errors
from .rows import Ladder, Row, _units, driver_force_units


def _timed(fn, repeats: int):
    """Return (last value, median seconds) of ``repeats`` calls, garbage collector paused."""
    times = []
    value = None
    for _ in range(max(1, repeats)):
        gc.collect()
        was = gc.isenabled()
        gc.disable()
        try:
            t0 = time.perf_counter()
            value = fn()
            times.append(time.perf_counter() - t0)
        finally:
            if was:
                gc.enable()
    return value, float(np.median(times))


_NOT_KINEMATIC = {"model", "positions", "forces", "hdf5", "rrd", "fd_derivatives"}


def _stage_seconds(med: dict, finite_difference: bool) -> tuple[float, float]:
    """Return (positions, derivatives) seconds from the pipeline's per-stage medians.

    Derivatives: the linear solves' stage(s) (``jacobian``...), or for finite differences
    along the sweep the ``fd_derivatives`` stage alone (the pipeline still runs the linear
    stage for the step status and the force stage's inverse: that is not the shortcut's cost).
    On the dyad path the closed-form derivatives are part of ``positions``.
    """
    pos = med.get("positions", math.nan)
    if finite_difference and "fd_derivatives" in med:
        return pos, med["fd_derivatives"]
    return pos, sum(v for k, v in med.items() if k not in _NOT_KINEMATIC)


def method_available(result, method: str) -> tuple[bool, str]:
    """Return whether ``result`` was solved by ``method``, and a note on the path it took.

    ``result.solver_method_used`` says which path ran ("dyads" or "newton"); a build without
    it has no fast path, so ``dyads`` is not available there.
    """
    used = str(getattr(result, "solver_method_used", "") or "")
    if method == "dyads" and used != "dyads":
        return False, ("not available: " + (f"solved by {used}" if used
                                            else "no dyads fast path in this build"))
    if method == "auto" and used:
        return True, f"auto took {used}"
    return True, ""


def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (f"{cpu}, {cores} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, numpy {np.__version__}")


def measure(scene: Scene | str, quick: bool = False, repeats: int = 5, echo=None,
            knobs=KNOBS) -> Ladder:
    """Run ``scene`` over the ladder and return the measured :class:`Ladder`.

    The repeats go round-robin over the rows (run 1 of every row, then run 2, ...), so that a
    burst of background load on the machine spreads over all rows instead of skewing one.
    ``echo``: optional callable given a short progress line now and then. ``knobs``: a subset
    of :data:`KNOBS` to measure (all by default).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    tell = echo if callable(echo) else (lambda line: None)
    repeats = max(1, int(repeats))
    with np.errstate(invalid="ignore", divide="ignore"):  # loose rows fail steps on purpose
        return _measure(scene, quick, repeats, tell, tuple(knobs))


def _measure(scene: Scene, quick: bool, repeats: int, tell, knobs) -> Ladder:
    refs = References(scene)
    scales = _scales(refs.at(scene.n_steps),
                     driver_force_units(scene))
    quantities = ("position", "velocity", "acceleration") + (
        ("input_force",) if refs.has_forces else ())
    base_solver = dc.asdict(scene.solver)
    newton_solver = dict(base_solver, method="newton")
    rows: list[Row] = []
    runs = []  # (row, variant, [wall seconds], [stage seconds dicts], [last result])
    for knob, value, variant, stage in settings(scene, quick, knobs):
        row = Row(knob, value, variant.n_steps, stage, dc.asdict(variant.solver))
        # the scene's own run: its solver settings at its steps, its drivers as they are (a
        # log row drives from samples of the laws instead: never the base)
        own_run = variant.n_steps == scene.n_steps and not knob.startswith("log")
        row.base = row.solver == base_solver and own_run
        row.newton_base = row.solver == newton_solver and own_run
        rows.append(row)
        try:  # the first run: does the knob run at all (and warms up its code paths)
            result, first = _timed(lambda: solve(variant), 1)
        except LinkpipeError as exc:  # the scene cannot take this setting: a row that says so
            row.available, row.base = False, False
            row.note = f"not available: {exc}"[:200]
            tell(f"  {row.label}: {row.note}")
            continue
        except Exception as exc:  # noqa: BLE001 - a crashed rung: a row with its error, and
            row.available, row.base = False, False  # the command's exit status says so
            row.failure = f"{type(exc).__name__}: {exc}"[:300]
            row.note = f"FAILED: {row.failure}"
            tell(f"  {row.label}: {row.note}")
            continue
        row.path = str(getattr(result, "solver_method_used", "") or "newton")
        row.linear_algebra = str(getattr(result, "linear_algebra_used", ""))
        if knob == "method":
            row.available, row.note = method_available(result, value)
            if not row.available:
                row.base = row.newton_base = False
                tell(f"  {row.label}: {row.note}")
                continue
        # the full ladder discards the first run as a warm-up; the quick one counts it
        runs.append((row, variant, [] if not quick else [first],
                     [] if not quick else [dict(result.seconds)], [result]))
    tell(f"  {len(runs)} settings x {repeats} runs, round-robin")
    for _ in range(repeats - 1 if quick else repeats):
        for row, variant, walls, stages, last in runs:
            result, wall = _timed(lambda: solve(variant), 1)
            walls.append(wall)
            stages.append(dict(result.seconds))
            last[0] = result
    for row, variant, walls, stages, last in runs:
        result = last[0]
        row.seconds_solve = float(np.median(walls))
        keys = set().union(*stages)
        med = {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in keys}
        row.seconds_positions, row.seconds_derivatives = _stage_seconds(
            med, row.solver["derivatives"] == "finite_difference")
        row.seconds = {"positions": row.seconds_positions,
                       "derivatives": row.seconds_derivatives,
                       "kinematics": row.seconds_positions + row.seconds_derivatives,
                       "forces": med.get("forces", math.nan)}[row.stage]
        it = np.asarray(result.iterations)
        row.iterations_mean = float(it.mean()) if it.size else 0.0
        row.iterations_max = int(it.max()) if it.size else 0
        if row.knob == "friction_velocity_scale":  # against the exact sign law
            exact = refs.exact_sign(variant.n_steps)
            _measure_errors(row, result, exact, scales)
            friction_errors(row, result, exact, scales)
        else:
            _measure_errors(row, result, refs.at(variant.n_steps), scales)
        if result.n_ok < result.n_steps:
            row.note = "; ".join(x for x in (row.note, result.message) if x)
    ladder = Ladder(scene=scene, rows=rows, reference=refs.kind, quantities=quantities,
                    units=_units(scene), scales=scales, checks=refs.checks, repeats=repeats,
                    quick=quick,
                    created=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                    machine=_machine())
    for r in ladder.front():
        r.front = True
    for r in ladder.front(path="newton"):
        r.newton_front = True
    _observed_orders(rows)
    return ladder


def _observed_orders(rows: list[Row]) -> None:
    """Set each finite-difference row's order of convergence against the next coarser one."""
    fd = sorted((r for r in rows if r.knob == "derivatives" and r.value == "finite_difference"
                 and r.available and r.steps > 2), key=lambda r: r.steps)
    for coarse, fine in zip(fd, fd[1:]):
        ratio = (coarse.steps - 1) / (fine.steps - 1)  # h_fine / h_coarse
        for q in ("velocity", "acceleration", "input_force"):  # positions are not differenced
            e1, e2 = coarse.error[q], fine.error[q]
            if np.isfinite(e1) and np.isfinite(e2) and e1 > 0 and e2 > 0:
                fine.observed_order[q] = float(np.log(e1 / e2) / -np.log(ratio))
