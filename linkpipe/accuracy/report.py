"""The ladder as text (table, header, observed orders) and the ``accuracy`` command."""
from __future__ import annotations

import pathlib
import sys

import numpy as np

from ..scene import load_scene
from .rows import ERROR_FLOOR, Ladder, Row
from .timing import measure


def orders_line(ladder: Ladder) -> str:
    """Return one line with the observed orders of the finite-difference derivatives."""
    fd = [r for r in ladder.rows if np.isfinite(r.observed_order["velocity"])]
    if not fd:
        return ""
    parts = []
    for q in ("velocity", "acceleration"):
        vals = [f"{r.observed_order[q]:.2f}" for r in fd if np.isfinite(r.observed_order[q])]
        if vals:
            parts.append(f"{q} {', '.join(vals)}")
    everything = sorted((r for r in ladder.rows if r.knob == "derivatives"
                         and r.value == "finite_difference" and r.available),
                        key=lambda r: r.steps)
    steps = " -> ".join(str(r.steps) for r in everything)
    line = (f"  finite differences along the sweep, observed order of convergence (steps "
            f"{steps}): " + "; ".join(parts))
    logged = sorted({d.log[0] for d in ladder.scene.drivers if d.timed == "log"})
    if logged:
        samples = {log.name: len(log.t) for log in ladder.scene.logs}
        where = ", ".join(f"{samples[name]} in log {name}" for name in logged)
        line += ("\n  (logged drivers move on cubic splines through their samples (" + where
                 + "): differences of the positions approach the splines' rates only on "
                 "instants finer than the samples, then at order 2 (velocity) and 1 "
                 "(acceleration: a cubic's third derivative jumps at every sample); the "
                 "ladder's other step counts resample the instants, evenly where the count "
                 "is not a whole refinement of the log's)")
    return line


def _fmt_err(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{max(v, 0.0):.1e}" if v >= ERROR_FLOOR or v == 0 else f"<{ERROR_FLOOR:.0e}"


def _fmt_ms(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{v * 1e3:.3g}"


def _front(r: Row) -> str:
    return ("*" if r.front else "") + ("n" if r.newton_front else "")


def table(ladder: Ladder, markdown: bool = False, compact: bool = False) -> str:
    """Return the ladder as a text table (or a Markdown table): one line per row.

    Errors are relative (see :func:`header`); a row whose knob cannot run says why instead.
    ``compact``: only knob, value, steps, solve time, worst error, failed steps and the front.
    Value marks: "(base)" the scene's own settings, "(newton base)" the same on the general
    path. Front: "*" on the Pareto front of all rows, "n" on the front of the Newton-path rows.
    """
    short = {"position": "pos", "velocity": "vel", "acceleration": "acc", "input_force": "force"}
    if compact:
        head = ["knob", "value", "path", "steps", "solve ms", "worst err", "failed", "front"]
    else:
        head = (["knob", "value", "path", "steps", "stage", "stage ms", "solve ms",
                 "iter mean/max",
                 "failed", "branch"] + [f"{short[q]} err" for q in ladder.quantities]
                + ["front", "note"])
    lines = []
    for r in ladder.rows:
        mark = " (base)" if r.base else " (newton base)" if r.newton_base else ""
        sparse = " (sparse LU)" if r.linear_algebra.startswith("sparse") else ""
        cells = [r.knob, r.value + mark, r.path + sparse, str(r.steps)]
        if not compact:
            cells.append(r.stage)
        if not r.available:
            lines.append((cells, r.note))
            continue
        if compact:
            cells += [_fmt_ms(r.seconds_solve), _fmt_err(r.worst_relative_error),
                      str(r.steps_failed), _front(r)]
            lines.append((cells, None))
            continue
        cells += [_fmt_ms(r.seconds), _fmt_ms(r.seconds_solve),
                  f"{r.iterations_mean:.2f}/{r.iterations_max}", str(r.steps_failed),
                  "kept" if r.branch_kept else "LOST"]
        cells += [_fmt_err(r.relative_error[q]) for q in ladder.quantities]
        cells += [_front(r), r.note]
        lines.append((cells, None))
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        for cells, unavailable in lines:
            if unavailable:
                cells = cells + [unavailable] + [""] * (len(head) - len(cells) - 1)
            out.append("| " + " | ".join(cells) + " |")
        return "\n".join(out)
    widths = [max([len(h)] + [len(c[i]) for c, u in lines if u is None]) for i, h in enumerate(head)]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths)).rstrip(),
           "  ".join("-" * w for w in widths)]
    for cells, unavailable in lines:
        text = "  ".join(c.ljust(w) for c, w in zip(cells, widths))
        out.append((text + "  " + unavailable) if unavailable else text.rstrip())
    return "\n".join(out)


def _scale_text(ladder: Ladder, q: str) -> str:
    """``q``'s scale as the header prints it: the input force's per unit where drivers'
    units differ (each driver's error is divided by its own unit's scale)."""
    if q != "input_force" or np.isfinite(ladder.scales[q]):
        return f"{q} {ladder.scales[q]:.4g} {ladder.units[q]}"
    units = ladder.force_units
    per = ladder.scales.get("input_force_per_driver")
    by_unit = {u: per[j] for j, u in enumerate(units)} if per is not None else {}
    return ("input_force by unit " + " and ".join(f"{v:.4g} {u}" for u, v in by_unit.items())
            + " (each driver against its own unit's)")


def header(ladder: Ladder, markdown: bool = False) -> str:
    """Return the lines that say what the table's numbers are."""
    sc = ladder.scene
    scales = ", ".join(_scale_text(ladder, q) for q in ladder.quantities)
    first = (f"{sc.name}: what accuracy costs ({'quick' if ladder.quick else 'full'} ladder, "
             f"{sc.n_steps} steps, median of {ladder.repeats} runs)")
    rest = [
        f"reference: {ladder.reference}",
        f"errors: max error / scale, with scales {scales} (position: the mechanism's size)",
        "tol, max_iter, jacobian, derivatives and predictor act on the general Newton path "
        "(method = newton); method compares the paths (auto takes closed-form dyads where "
        "the scene decomposes)",
        "stage ms: the stage the knob acts on; solve ms: the whole solve; front: * on the "
        "Pareto front of solve time vs worst error among rows at the scene's step count, n "
        "on that front among the Newton-path rows (times within "
        f"{100 * ladder.time_noise:.0f} %, the spread of rows that repeat one setting, and "
        "errors within 2x count as equal)",
        f"machine: {ladder.machine}; {ladder.created}",
    ]
    from ..kinematics import linear_algebra_used
    from ..model import build_model

    # which linear algebra the scene's own settings take on the general path
    rest.insert(3, f"linear algebra of the general path's one-step solves: "
                   f"{linear_algebra_used(build_model(sc))}; linear_algebra rows force dense or "
                   f"sparse LU")
    if markdown:
        return "\n".join([f"**{first}**", ""] + [f"- {line}" for line in rest])
    return "\n".join([first] + [f"  {line}" for line in rest])


def run_accuracy(path, out: pathlib.Path = pathlib.Path("outputs"), quick: bool = False,
                 repeats: int = 5) -> int:
    """Measure ``path``'s ladder, print the table, write the .h5 and .rrd; return exit status."""
    from ..stores import accuracy as store, output_folder

    scene = load_scene(path)
    out = output_folder(out)  # before the ladder: a wrong --out is said at once
    if quick:
        repeats = min(repeats, 3)
    echo = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    if scene.dynamics is not None:  # the integrator's rtol ladder (accuracy/dynamics.py)
        from .dynamics import header as describe, measure_dynamics

        ladder = measure_dynamics(scene, quick=quick, repeats=min(repeats, 3), tell=echo)
    else:
        ladder, describe = measure(scene, quick=quick, repeats=repeats, echo=echo), header
    print(describe(ladder))
    print(table(ladder))
    if orders_line(ladder):
        print(orders_line(ladder))
    for name, front in (("Pareto front", ladder.front()),
                        ("Pareto front of the Newton path", ladder.front(path="newton"))):
        if front:
            print(f"  {name}: " + ", ".join(
                r.label for r in sorted(front, key=lambda r: r.seconds_solve)))

    h5 = out / f"{scene.name}_accuracy.h5"
    rrd = out / f"{scene.name}_accuracy.rrd"
    store.write_h5(ladder, h5)
    store.write_rrd(ladder, rrd, table_markdown=describe(ladder, True) + "\n\n" + table(ladder, True, compact=True))
    print(f"  wrote {h5}, {rrd}")
    failed = [r.label for r in ladder.rows if r.failure]
    if failed:
        print(f"error: {len(failed)} setting(s) failed: {', '.join(failed)} (see their rows)",
              file=sys.stderr)
    return 1 if failed else 0
