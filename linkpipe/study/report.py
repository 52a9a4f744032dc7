"""What ``linkpipe study`` prints: the variants, how many failed, the best ones."""
from __future__ import annotations

import numpy as np

from ..output_units import input_force_units, units_of

#: variants listed under "best"
N_BEST = 3


def describe_study(study) -> str:
    """What ``check`` prints for a study file: its base scene, each parameter and how it
    varies, the variants, batches and metrics, and the path that will solve them."""
    V = study.n_variants
    lines = [f"{study.name}: study of {study.scene.name} ({study.scene.path}), {V:,} variant(s) "
             f"of {study.scene.n_steps} steps in {len(study.batches())} batch(es) of up to "
             f"{study.batch_size:,}"]
    for j, (p, unit) in enumerate(zip(study.parameters, study.parameter_units())):
        how = (f"{p.spec[0]:g} .. {p.spec[1]:g} in {p.spec[2]} steps" if p.kind == "grid"
               else f"tied to {p.spec[0]}" if p.kind == "tie"
               else f"{p.kind} {', '.join(f'{v:g}' for v in p.spec)}")
        lines.append(f"  parameter {p.address} = {p.initial:g} in the base: {how} "
                     f"(variants {study.values[:, j].min():.6g} .. {study.values[:, j].max():.6g}"
                     + (f" {unit})" if unit else ")"))
    m_units = study.metric_units()
    for m in study.metrics:
        lines.append(f"  metric {m.name} = {m.text}" + (f" [{m_units[m.name]}]" if m_units[m.name]
                                                          else ""))
    lines.append(f"  will solve {study.path_note}")
    return "\n".join(lines)


def study_table(study, path, seconds: float | None = None) -> str:
    """The summary of a written study file: counts, each metric's range and the variants with
    the lowest peak input force (first driver), or the first metric without forces."""
    from ..stores.study import read_arrays

    f = read_arrays(path)
    V = study.n_variants
    failed = int((f["worst_status"] != 0).sum())
    lines = [f"{study.name}: {V:,} variants of {study.scene.name} ({len(study.parameters)} "
             f"parameter(s), {study.scene.n_steps} steps each), {V - failed:,} all ok, "
             f"{failed:,} with failed steps"
             + (f"; {seconds:.2f} s ({V / seconds:,.0f} variants/s)" if seconds else ""),
             f"  solved {study.path_note}"]
    names = ["peak_input_force", "rms_input_force"] + [m.name for m in study.metrics]
    force = input_force_units(study.scene.drivers, units_of(study.scene))
    p_units, m_units = study.parameter_units(), study.metric_units()
    for name in names:
        data = np.asarray(f[name], dtype=float).reshape(V, -1)
        for j in range(data.shape[1]):
            col = data[:, j]
            forces = name in ("peak_input_force", "rms_input_force")
            label = name + (f".{study.driver_names[j]}" if data.shape[1] > 1 or forces else "")
            unit = f" {force[j]}" if forces else f" {m_units[name]}" if m_units.get(name) else ""
            fin = col[np.isfinite(col)] + 0.0  # + 0.0: a -0.0 prints as 0
            if len(fin):
                lines.append(f"  {label}: {fin.min():.6g} .. {fin.max():.6g}{unit} (mean "
                             f"{fin.mean():.6g}, sd {fin.std():.3g}, 5-95 % "
                             f"{np.percentile(fin, 5):.6g} .. {np.percentile(fin, 95):.6g})")
            if len(fin) < len(col):
                infinite = int(np.isinf(col).sum())
                lines.append(f"  {label}: not finite at {len(col) - len(fin):,} variant(s)"
                             + (f" ({infinite:,} infinite: a division by zero or an overflow in "
                                "the reduction?)" if infinite else " (no ok step, or NaN)"))
    # with [dynamics] the input force is the force applied, not one to keep low
    by_force = (len(study.driver_names) > 0 and np.isfinite(f["peak_input_force"]).any()
                and study.scene.dynamics is None)
    key_name = "peak_input_force" if by_force else study.metrics[0].name if study.metrics else None
    key = f["peak_input_force"][:, 0] if by_force else f[key_name] if key_name else None
    if key is not None and np.isfinite(key).any():
        from .view import ranked

        order = ranked(key, f["worst_status"])[:N_BEST]
        whole = bool((f["worst_status"][order] == 0).all())
        lines.append(f"  best (lowest {key_name}"
                     + ("" if whole else "; no variant has every step ok: these fail some") + "):")
        varied = [j for j in range(len(study.names)) if np.ptp(study.values[:, j]) > 0]
        for v in order:
            values = ", ".join(f"{study.names[j]} = {study.values[v, j]:.6g}"
                               + (f" {p_units[j]}" if p_units[j] else "") for j in varied)
            unit = force[0] if by_force else m_units.get(key_name, "")
            unit = f" {unit}" if unit else ""
            lines.append(f"    variant {v}: {key[v] + 0.0:.6g}{unit}" + (f" at {values}" if values else ""))
        if len(order):
            lines += on_the_edge(study, int(order[0]))
    return "\n".join(lines)


def on_the_edge(study, v: int) -> list[str]:
    """Lines saying which grid parameters the best variant ``v`` takes at an end of its range
    (the optimum may lie beyond: widen that range), [] where none does."""
    out = []
    for j, p in enumerate(study.parameters):
        if p.kind != "grid" or p.spec[2] < 2:
            continue
        lo, hi = min(p.spec[:2]), max(p.spec[:2])
        value = study.values[v, j]
        for end, name in ((lo, "lowest"), (hi, "highest")):
            if abs(value - end) <= 1e-12 * max(1.0, abs(hi - lo)):
                out.append(f"  best on the edge: {p.address} = {value:.6g} is the {name} value "
                           f"of its range ({lo:.6g} .. {hi:.6g}); the optimum may lie beyond it: "
                           "widen the range, or search it with optimize")
    return out


def optimize_table(outcome, seconds: float | None = None) -> str:
    """What ``linkpipe optimize`` prints: the evaluations, the best values (tied ones with
    what they follow, a bound where one sits on it), the objective and every named metric
    there, each constraint (active or not) and, with two objectives, the Pareto set."""
    problem = outcome.problem
    study = problem.study
    E = len(outcome.values)
    polished = int((outcome.generation < 0).sum())
    G = int(outcome.generation.max()) + 1
    p_units, m_units = study.parameter_units(), study.metric_units()
    free = problem.n_free
    lines = [f"{study.name}: optimised {' and '.join(problem.objectives)} over {free} "
             f"parameter(s)" + (f" ({len(study.parameters) - free} tied)"
                                if len(study.parameters) > free else "")
             + f" of {study.scene.name}: {E - polished:,} variants in {G} generation(s), "
             f"{polished:,} in the polish, {int((~outcome.feasible).sum()):,} infeasible"
             + (f"; {seconds:.2f} s" if seconds else ""),
             f"  solved {study.path_note}"]
    bound = dict(outcome.on_bound)
    lines.append("  best:")
    for j, p in enumerate(study.parameters):
        unit = f" {p_units[j]}" if p_units[j] else ""
        note = (f" (tied to {p.spec[0]})" if p.kind == "tie" else
                f" (on its {bound[p.address]} bound)" if p.address in bound else
                f" (within {p.spec[0]:g} .. {p.spec[1]:g})")
        lines.append(f"    {p.address} = {outcome.best_values[j]:.10g}{unit}{note}")
    for m in study.metrics:
        if m.name.startswith("_"):
            continue
        unit = f" {m_units[m.name]}" if m_units[m.name] not in ("", "1") else ""
        mark = "  <- objective" if m.name in problem.objectives else ""
        lines.append(f"    {m.name} = {outcome.metrics[m.name][outcome.best]:.10g}{unit}{mark}")
    for c in problem.constraints:
        value = outcome.metrics[c.metric][outcome.best]
        lines.append(f"  constraint {c.text}: {c.metric} = {value:.6g} "
                     + ("(active: on its limit)" if c.text in outcome.active else "(inactive)"))
    if not outcome.on_bound:
        lines.append("  no parameter sits on a bound")
    if len(problem.objectives) == 2:
        a, b = problem.objectives
        fa, fb = outcome.metrics[a][outcome.pareto], outcome.metrics[b][outcome.pareto]
        lines.append(f"  Pareto set: {len(outcome.pareto)} variants, {a} {fa.min():.6g} .. "
                     f"{fa.max():.6g} while {b} {fb.max():.6g} .. {fb.min():.6g} (the best: "
                     f"the lowest {a})")
    return "\n".join(lines)


def describe_problem(problem) -> str:
    """What ``check`` prints for a file with ``[optimize]``: the base scene, what is minimised,
    each searched value's bounds (and the tied ones), the constraints and the search's
    settings, and the path that will solve each generation."""
    study = problem.study
    units = study.parameter_units()
    lines = [f"{study.name}: optimisation of {study.scene.name} ({study.scene.path}): minimise "
             + " and ".join(problem.objectives) + f" over {problem.n_free} value(s), "
             f"{study.scene.n_steps} steps each; {problem.population} variants a generation, "
             f"at most {problem.generations} generations, seed {problem.seed}"]
    for j, p in enumerate(study.parameters):
        unit = f" {units[j]}" if units[j] else ""
        lines.append(f"  parameter {p.address} = {p.initial:g} in the base: "
                     + (f"tied to {p.spec[0]}" if p.kind == "tie" else
                        f"{p.spec[0]:g} .. {p.spec[1]:g}{unit}"))
    m_units = study.metric_units()
    for m in study.metrics:
        if not m.name.startswith("_"):
            lines.append(f"  metric {m.name} = {m.text}" + (f" [{m_units[m.name]}]"
                                                              if m_units[m.name] else ""))
    for c in problem.constraints:
        lines.append(f"  constraint {c.text}: {c.metric} {c.op} {c.limit:g}")
    lines.append(f"  will solve {study.path_note}")
    return "\n".join(lines)
