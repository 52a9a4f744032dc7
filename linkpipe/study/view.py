"""What a study's (or an optimisation's) recording shows, computed here (stores only draw it):
each metric against each parameter coloured by the objective, the Pareto set of two metrics,
the best variants solved again for their motion, and an optimisation's progress per
generation."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..output_units import input_force_units, units_of

#: best variants solved again for their motion in the recording; bins of a metric's histogram
N_MOTION, N_BINS = 3, 30


@dataclass
class StudyView:
    """``metrics`` {label: (V,)}; ``parameters`` {address: (V,)}; ``status`` (V,) worst
    status; ``pareto`` (labels of the two metrics, indices of the Pareto set ordered by the
    first); ``best`` [(variant, Result)] by the first metric; ``spread`` each metric's
    histogram over the variants (how tolerances spread it); ``parameter_units`` {address:
    unit} ("" where the key has none)."""

    name: str
    metrics: dict
    units: dict
    parameters: dict
    status: np.ndarray
    pareto: tuple
    best: list
    spread: dict  # {metric: (counts (n,), bin centres (n,), bin widths (n,))}
    parameter_units: dict
    #: the metric that colours every point (lower is better), and the generations' best of it
    #: (an optimisation; None for a study); the tab names a study or an optimisation
    objective: str | None = None
    progress: np.ndarray | None = None
    kind: str = "study"
    #: (V,) bool: variants that break a constraint (an optimisation; None for a study)
    infeasible: np.ndarray | None = None

    def label(self, name: str) -> str:
        """A metric's or parameter's axis label, with its unit where it has one."""
        unit = self.units.get(name) or self.parameter_units.get(name)
        return f"{name} [{unit}]" if unit else name


def pareto_set(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Indices of the variants no other variant beats in both ``a`` and ``b`` (lower is
    better; NaN rows left out), ordered by ``a`` (ties by ``b``)."""
    idx = np.flatnonzero(np.isfinite(a) & np.isfinite(b))
    order = idx[np.lexsort((b[idx], a[idx]))]
    best_b = np.minimum.accumulate(b[order]) if len(order) else b[order]
    keep = np.ones(len(order), dtype=bool)
    keep[1:] = b[order][1:] < best_b[:-1]  # strictly lower b than every variant before it
    return order[keep]


def ranked(key: np.ndarray, worst_status: np.ndarray) -> np.ndarray:
    """Variant indices by ``key`` (lowest first) among those whose every step is ok; when no
    variant has all steps ok, among those with a finite key (a variant that cannot finish the
    sweep is never ranked above one that can: its metrics cover only the steps it reached)."""
    whole = np.flatnonzero(np.isfinite(key) & (np.asarray(worst_status) == 0))
    pool = whole if len(whole) else np.flatnonzero(np.isfinite(key))
    return pool[np.argsort(key[pool], kind="stable")]


def study_view(study, columns: dict) -> StudyView:
    """The view of a finished study's file (``columns``: its arrays, as read back)."""
    from .variants import solve_variant

    force = input_force_units(study.scene.drivers, units_of(study.scene))
    metrics, units = {}, {}
    for name in ("peak_input_force", "input_force_range", "rms_input_force"):
        for j, driver in enumerate(study.driver_names):
            if np.isfinite(columns[name][:, j]).any():
                metrics[f"{name}.{driver}"], units[f"{name}.{driver}"] = columns[name][:, j], force[j]
    metric_units = study.metric_units()
    for m in study.metrics:
        metrics[m.name], units[m.name] = np.asarray(columns[m.name], float), metric_units[m.name]
    if np.isfinite(columns["min_transmission_angle"]).any():
        metrics["min_transmission_angle"] = columns["min_transmission_angle"]
        units["min_transmission_angle"] = "degree"
    names = list(metrics)
    status = np.asarray(columns["worst_status"])
    whole = status == 0  # the Pareto set of the variants that finish the sweep, when any do
    pool = np.flatnonzero(whole) if whole.any() else np.arange(len(status))
    pareto = ((names[0], names[1]), pool[pareto_set(metrics[names[0]][pool],
                                                    metrics[names[1]][pool])]) \
        if len(names) >= 2 else ((None, None), np.zeros(0, dtype=np.intp))
    best = []
    if names:
        for v in ranked(metrics[names[0]], status)[:N_MOTION]:
            result = solve_variant(study, int(v))
            if result is not None:
                best.append((int(v), result))
    params = {p: study.values[:, j] for j, p in enumerate(study.names)
              if study.parameters[j].kind != "tie"}  # a tied one draws its twin again
    return StudyView(study.name, metrics, units, params, np.asarray(columns["worst_status"]),
                     pareto, best, {m: histogram(x) for m, x in metrics.items()},
                     dict(zip(study.names, study.parameter_units())),
                     objective=names[0] if names else None)


def optimize_view(outcome) -> StudyView:
    """The view of an optimisation: every evaluated variant (a failed step: status 1 here),
    coloured by the (first) objective, the Pareto set of two objectives, the best variant
    solved again for its motion, the generations' best."""
    import dataclasses

    from .batch import solve_variant

    problem = outcome.problem
    study = problem.study
    units = study.metric_units()
    names = [m.name for m in study.metrics if not m.name.startswith("_")]
    names = list(problem.objectives) + [n for n in names if n not in problem.objectives]
    metrics = {n: outcome.metrics[n] for n in names}
    status = (outcome.metrics["_failed_steps"] > 0).astype(np.int8)
    pareto = (tuple(problem.objectives), outcome.pareto) if len(problem.objectives) == 2 \
        else ((None, None), np.zeros(0, dtype=np.intp))
    one = dataclasses.replace(study, values=outcome.values[[outcome.best]])
    result = solve_variant(one, 0)
    params = {p.address: outcome.values[:, j] for j, p in enumerate(study.parameters)
              if p.kind != "tie"}
    return StudyView(study.name, metrics, {n: units[n] for n in names}, params, status, pareto,
                     [] if result is None else [(outcome.best, result)], {},
                     dict(zip(study.names, study.parameter_units())),
                     objective=problem.objectives[0], progress=outcome.population_best,
                     kind="optimisation", infeasible=~outcome.feasible & (status == 0))


def histogram(x: np.ndarray, bins: int = N_BINS) -> tuple:
    """(counts, bin centres, bin widths) of the finite values of x (empty without any)."""
    x = x[np.isfinite(x)]
    if not len(x):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    counts, edges = np.histogram(x, bins=bins if np.ptp(x) > 0 else 1)
    return counts.astype(float), 0.5 * (edges[1:] + edges[:-1]), np.diff(edges)
