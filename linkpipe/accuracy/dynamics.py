"""What accuracy costs for a [dynamics] scene: the integrator's ``rtol`` (and which integrator)
laddered against a tight reference solution, time per rung.

Each rung is the scene with ``[dynamics] rtol`` and ``method`` changed; the reference is the
same scene integrated by DOP853 at the tightest rtol a scene may ask for (1e-13). Errors are
those of every output instant's positions, velocities and accelerations against the
reference's (:func:`.references._measure_errors`, as for sweeps), times the median of
``repeats`` whole solves, round-robin. The rows are the sweep ladder's :class:`.rows.Row`, so
the table, the ``.h5`` and the ``.rrd`` are written as for any ladder; the ``path`` column
names the integrator, ``iter mean/max`` holds its steps and right-hand-side evaluations, and
the note the largest |energy_error|.
"""
from __future__ import annotations

import dataclasses as dc
import datetime
import re

import numpy as np

from ..pipeline import solve
from ..scene import Scene
from ..scene.dynamics import MIN_RTOL
from .references import Reference, _measure_errors, _scales
from .rows import Ladder, Row, _units
from .timing import _machine, _timed

FULL_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
QUICK_RTOLS = (1e-4, 1e-7, 1e-10)
#: the integrators of the ladder; Radau (implicit) only up to 1e-10: beyond, its Newton
#: iterations on a finite-difference Jacobian cost more than they buy on these problems
METHODS = {"DOP853": None, "Radau": 1e-10}
QUANTITIES = ("position", "velocity", "acceleration")


def variant(scene: Scene, rtol: float, method: str) -> Scene:
    return dc.replace(scene, dynamics=dc.replace(scene.dynamics, rtol=rtol, method=method))


def rungs(scene: Scene, quick: bool) -> list[tuple[str, float]]:
    out = []
    for method, tightest in METHODS.items():
        for rtol in (QUICK_RTOLS if quick else FULL_RTOLS):
            if tightest is None or rtol >= tightest:
                out.append((method, rtol))
    return out


def measure_dynamics(scene: Scene, quick: bool = False, repeats: int = 3, tell=None) -> Ladder:
    """Measure ``scene``'s rtol ladder (see the module's docstring)."""
    tell = tell if callable(tell) else (lambda line: None)
    ref_result = solve(variant(scene, MIN_RTOL, "DOP853"))
    ref = Reference({"position": ref_result.position, "velocity": ref_result.velocity,
                     "acceleration": ref_result.acceleration}, float(ref_result.model.size))
    scales = _scales(ref)
    base = dc.asdict(scene.solver)
    rows, runs = [], []
    for method, rtol in rungs(scene, quick):
        # the integrator in the row's settings: rows of other settings are not repeats of one
        # (Ladder.time_noise groups rows by their settings)
        row = Row("rtol", f"{rtol:.0e}", scene.n_steps, "integration",
                  dict(base, dynamics_method=method, dynamics_rtol=rtol), path=method)
        row.base = rtol == scene.dynamics.rtol and method == scene.dynamics.method
        rows.append(row)
        v = variant(scene, rtol, method)
        try:
            result, _ = _timed(lambda: solve(v), 1)  # warm-up, and does the rung run at all
        except Exception as exc:  # noqa: BLE001 - a crashed rung is a row saying so
            row.available, row.base = False, False
            row.failure = f"{type(exc).__name__}: {exc}"[:300]
            row.note = f"FAILED: {row.failure}"
            tell(f"  {row.label}: {row.note}")
            continue
        runs.append((row, v, [], [], [result]))
    tell(f"  {len(runs)} settings x {repeats} runs, round-robin, against DOP853 at rtol "
         f"{MIN_RTOL:g}")
    for _ in range(max(1, repeats)):
        for row, v, walls, stages, last in runs:
            result, wall = _timed(lambda: solve(v), 1)
            walls.append(wall)
            stages.append(result.seconds.get("integration", np.nan))
            last[0] = result
    for row, v, walls, stages, last in runs:
        result = last[0]
        row.seconds_solve = float(np.median(walls))
        row.seconds = float(np.median(stages))
        row.seconds_positions = row.seconds
        # "dynamics: METHOD, rtol R, N steps, E evaluations; ..." (dynamics.finish.describe)
        counts = re.search(r"(\d+) steps, (\d+) evaluations", result.time_note)
        if counts:
            row.iterations_mean, row.iterations_max = float(counts[1]), int(counts[2])
        err = result.forces["energy_error"][1]
        finite = err[np.isfinite(err)]
        row.note = f"max |energy_error| {np.abs(finite).max():.2e}" if len(finite) else ""
        _measure_errors(row, result, ref, scales)
        if result.n_ok < result.n_steps:
            row.note = "; ".join(x for x in (row.note, result.message) if x)
    ladder = Ladder(scene=scene, rows=rows,
                    reference=f"the same scene by DOP853 at rtol {MIN_RTOL:g} ({ref_result.time_note})",
                    quantities=QUANTITIES, units=_units(scene), scales=scales, checks={},
                    repeats=repeats, quick=quick,
                    created=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                    machine=_machine())
    for r in ladder.front():
        r.front = True
    return ladder


def header(ladder: Ladder, markdown: bool = False) -> str:
    """The lines that say what a dynamics ladder's numbers are."""
    sc = ladder.scene
    scales = ", ".join(f"{q} {ladder.scales[q]:.4g} {ladder.units[q]}" for q in ladder.quantities)
    first = (f"{sc.name}: what accuracy costs in forward dynamics ({'quick' if ladder.quick else 'full'} "
             f"ladder, {sc.n_steps} output instants over {sc.dynamics.to:g} s, median of "
             f"{ladder.repeats} runs)")
    rest = [f"reference: {ladder.reference}",
            f"errors: max error over the output instants / scale, with scales {scales} "
            "(position: the mechanism's size)",
            "rtol: [dynamics] rtol; path: the integrator ([dynamics] method); iter mean/max: "
            "its accepted steps / right-hand-side evaluations; stage ms: the integration, "
            "solve ms: the whole solve",
            f"machine: {ladder.machine}; {ladder.created}"]
    if markdown:
        return "\n".join([f"**{first}**", ""] + [f"- {line}" for line in rest])
    return "\n".join([first] + [f"  {line}" for line in rest])
