"""What the command line prints about a run, a check and a fit: the per-scene summary, the
table of stage times (``run -v``), a scene's description (``check``) and a fit's table. Text
only; the numbers come from a :class:`~linkpipe.result.Result` (or a fit's result)."""
from __future__ import annotations

import numpy as np

from .output_units import driver_units_of, input_force_units, units_of


def slip_clause(slip: str) -> str:
    """`` — but B assembles 3.55 m from its drawing`` (a geometry slip said first), or ""."""
    return f" \u2014 but {slip}" if slip else ""


def headline(result) -> str:
    """The run's first words: the steps' message and, where the drawing is far from its own
    assembly, that slip (``all 61 steps ok — but E assembles 2.1 m from its drawing``)."""
    from .kinematics.start import drawing_slip

    return result.totals.message + slip_clause(drawing_slip(result.model))


def _out_of_stroke(result) -> list[str]:
    """One line per actuator or gas spring that leaves its stroke: by how much at most, and
    where (a streamed sweep: over the rows its recording keeps)."""
    margin = result.stroke_margin
    if margin is None or not (result.status == 7).any():
        return []
    from .stroke import names, units

    steps = result.step_numbers if result.step_numbers is not None else np.arange(result.n_steps)
    out = []
    for j, (name, unit) in enumerate(zip(names(result.scene), units(result.scene,
                                                                     result.units()["length"]))):
        column = np.where(np.isfinite(margin[:, j]), margin[:, j], np.inf)
        k = int(np.argmin(column))
        if column[k] < 0:
            out.append(f"  out_of_stroke: {name} beyond its stroke by up to {-column[k]:.4g} "
                       f"{unit} (step {int(steps[k])}; stroke_margin holds every step's)")
    return out


def summary(result, written=(), seconds_total=None, recording_kept=None) -> str:
    """Return the short per-scene report printed by ``run`` (``written``: the files' paths)."""
    sc, totals = result.scene, result.totals
    lines = [f"{sc.name}: {headline(result)} ({totals.n_steps} steps, {totals.n_ok} ok, "
             f"{totals.n_steps - totals.n_ok} failed)"]
    lines += [f"  warning: {w}" for w in result.warnings]
    if totals.first_non_finite >= 0:
        causes, names = totals.non_finite_causes, totals.non_finite_there
        shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        lines.append(f"  non_finite: first at step {totals.first_non_finite}"
                     + (f"; {'; '.join(causes)}" if causes else "")
                     + (f"; not finite there: {shown}" if shown else ""))
    lines += _out_of_stroke(result)
    if np.isfinite(totals.max_residual_solved):
        how = ("closed-form dyads, no iterations" if result.solver_method_used == "dyads" else
               f"Newton iterations mean {totals.iterations_sum / totals.n_steps:.2f} max "
               f"{totals.iterations_max}")
        lines.append(f"  max residual {totals.max_residual_solved:.2e} {result.units()['length']}"
                     f" (solved steps), {how}")
    vres, ares = totals.max_velocity_residual, totals.max_acceleration_residual
    if vres is not None and np.isfinite(vres):
        extra = f"  max linear-equation residuals: velocity {vres:.1e}"
        if ares is not None and np.isfinite(ares):
            extra += f", acceleration {ares:.1e}"
        lines.append(extra)
    from .scene import Solver

    changed = {k: v for k, v in vars(sc.solver).items() if v != getattr(Solver, k)}
    used = getattr(result, "solver_method_used", "")
    path = [f"path {used}"] if used else []
    if getattr(result, "linear_algebra_used", ""):
        path.append(f"linear algebra {result.linear_algebra_used}")
    if changed or path:  # the path taken, and the [solver] knobs not at linkpipe's defaults
        lines.append("  solver: " + ", ".join(path + [f"{k} {v}" for k, v in changed.items()]))
    if used == "newton" and result.solver_note:  # why not the fast path, why not sparse
        lines.append(f"  solver note: {result.solver_note}")
    if result.mobility.redundant:
        line = (f"  redundant constraints: {result.mobility.redundant} (solved by least squares; "
                f"'singular' only beyond them)")
        names = result.forces_not_unique()
        if names:
            line += f"; not unique (minimum-norm choice): {', '.join(names)}"
        lines.append(line)
    if result.time_note:
        lines.append(f"  {result.time_note}")
    if result.reach_note:
        lines.append(f"  no_assembly until in reach: {result.reach_note}")
    if sc.effects:
        lines.append(f"  effects: {', '.join(sc.effects)}")
    if sc.present_but_off:
        lines.append(f"  present but off: {', '.join(sc.present_but_off)}")
    if totals.input_force_min is not None:
        units = input_force_units(sc.drivers, result.units())
        for j, name in enumerate(result.driver_names):
            if np.isfinite(totals.input_force_min[j]):
                lines.append(f"  input force {name}: {totals.input_force_min[j]:.6g} .. "
                             f"{totals.input_force_max[j]:.6g} {units[j]}")
    if result.measurements:
        m = result.measurements
        for k, (name, meas) in enumerate(zip(m["names"], result.scene.measurements)):
            lines.append(f"  measurement {name} (of {meas.address}): computed - measured rms "
                         f"{m['rms'][k]:.4g}, max {m['max_abs'][k]:.4g} {m['units'][k]}")
    if recording_kept:
        h5 = any(str(w).endswith(".h5") for w in written)
        lines.append(f"  recording: {recording_kept}; "
                     + ("the .h5 keeps every step" if h5 else "no .h5 written"))
    if written:
        lines.append("  wrote " + ", ".join(written))
    secs = ", ".join(f"{k} {v:.3f}" for k, v in result.seconds.items())
    if seconds_total is not None:
        secs += f"; total {seconds_total:.3f}"
    lines.append(f"  seconds: {secs}")
    return "\n".join(lines)


def stage_table(seconds: dict, total: float, n_steps: int) -> str:
    """The time of each stage, its share of the scene's total and its rate in steps per second;
    "other" is what no stage timed: first imports of the writers (h5py, rerun), the memory
    check, statuses, the Result."""
    rows = dict(seconds)
    rows["other"] = max(total - sum(seconds.values()), 0.0)
    lines = [f"  {'stage':<14}{'seconds':>9}{'share':>8}{'steps/s':>12}"]
    for stage, sec in rows.items():
        rate = f"{n_steps / sec:,.0f}" if sec > 0 and stage != "other" else ""
        lines.append(f"  {stage:<14}{sec:>9.3f}{sec / total if total else 0:>8.0%}{rate:>12}")
    lines.append(f"  {'total':<14}{total:>9.3f}{'100%':>8}{n_steps / total if total else 0:>12,.0f}")
    return "\n".join(lines)


def describe(scene, mob, warnings=(), fit_parameters=(), slip: str = "") -> str:
    """What ``check`` prints of a valid scene (``warnings``: what is legal but probably not
    meant, the scene's and its drawing's; ``fit_parameters``: its checked [fit] parameters;
    ``slip``: a drawing far from its assembly, said on the first line)."""
    lines = [f"{scene.path}: scene {scene.name!r} is valid{slip_clause(slip)}",
             f"  points: {', '.join(p.name + (' (fixed)' if p.fixed else '') for p in scene.points)}",
             f"  links: {', '.join(l.name + '[' + ' '.join(l.points) + ']' for l in scene.links)}"]
    if scene.sliders:
        lines.append(f"  sliders: {', '.join(s.name for s in scene.sliders)}")
    lines.append(f"  degrees of freedom: {mob.dof} ({mob.n_q} unknowns, {mob.n_constraints} "
                 f"constraints, rank {mob.rank}, {mob.redundant} redundant); drivers: "
                 + ", ".join(f"{d.name} ({d.steps} steps)" for d in scene.drivers))
    if mob.redundant:
        lines.append(f"  redundant: {mob.redundant} constraint(s) implied by the others (e.g. a "
                     "link parallel to two others); solved by least squares, 'singular' flags only "
                     "rank loss beyond them, and the forces they share are a minimum-norm choice")
    lines.append(f"  effects: {', '.join(scene.effects) or 'none (kinematics only)'}")
    if scene.dynamics is not None:
        dyn = scene.dynamics
        lines.append(f"  dynamics: 0 .. {dyn.to:g} s, output every {dyn.output_step:g} s "
                     f"({len(dyn.instants)} instants), {dyn.method} at rtol {dyn.rtol:g}; "
                     + ", ".join(f"{d.name} from {d.from_value:g} {u} at {d.start_rate:g} {u}/s, "
                                 + _driver_force(d, f) for d, u, f in
                                 zip(scene.drivers, driver_units_of(scene),
                                     input_force_units(scene.drivers, units_of(scene)))))
    if scene.present_but_off:
        lines.append(f"  present but off: {', '.join(scene.present_but_off)}")
    if fit_parameters:
        each = [f"{p.address} (from {p.initial:g}, bounds {p.bounds[0]:g} .. {p.bounds[1]:g})"
                for p in fit_parameters]
        lines.append(f"  fit: {', '.join(each)} to {len(scene.measurements)} measurement(s)")
        import tomllib

        from .fit import fit_options

        options = fit_options(scene, tomllib.loads(scene.text))
        if options.per_log:
            lines.append(f"  per log (with fit --logs: one joint fit): {', '.join(options.per_log)}")
        if options.loss != "linear":
            lines.append(f"  loss: {options.loss}, f_scale {options.f_scale:g} sigma")
    lines += [f"  warning: {w}" for w in warnings]
    return "\n".join(lines)


def _driver_force(driver, unit: str) -> str:
    """A dynamics driver's force as ``check`` says it (``unit``: its force's, N or N*m)."""
    if driver.force is not None:
        return f"force {driver.force:g} {unit}"
    if driver.force_law is not None:
        fl = driver.force_law
        return (f"force {fl.law} {fl.from_value:g} -> {fl.to_value:g} {unit} over "
                f"{fl.duration:g} s")
    if driver.force_log is not None:
        factor = driver.unit_factor * driver.scale
        return (f"force from log {'.'.join(driver.force_log)} x {factor:g}"
                + (f" {'-' if driver.offset < 0 else '+'} {abs(driver.offset):g}"
                   if driver.offset else "") + f" {unit}")
    return "free"


def fit_table(result) -> str:
    """What ``fit`` prints: each parameter initial -> fitted +- standard error, and the
    measurements' RMS residual before and after."""
    lines = [f"{result.scene.name}: fit of {len(result.parameters)} parameter(s) to "
             f"{len(result.scene.measurements)} measurement(s): {result.message}",
             f"  {len(result.cost) - 1} iterations, {result.n_evaluations} evaluations "
             f"({result.solves} solves of the scene with the start, the Jacobian's finite "
             f"differences and the fitted values), stage 1 solved {result.stage1_solves} time(s)"]
    if getattr(result, "loss", "linear") != "linear":  # standard errors are the loss's
        lines.append(f"  loss {result.loss} (f_scale {result.f_scale:g} sigma): standard errors "
                     "for that loss")
    lines += [f"  warning: {w}" for w in result.warnings]
    width = max(len(n) for n in result.names)
    for k, p in enumerate(result.parameters):
        err = (f"± {result.standard_error[k]:.4g}" if result.identifiable[k]
               else "not identifiable from these measurements")
        lines.append(f"  {p.address:<{width}}  {p.initial:.6g} -> {result.fitted[k]:.6g} {err}")
    b, a = result.before.measurements, result.after.measurements
    for k, name in enumerate(b["names"]):
        lines.append(f"  measurement {name}: rms {b['rms'][k]:.4g} -> {a['rms'][k]:.4g} {b['units'][k]}")
    return "\n".join(lines)
