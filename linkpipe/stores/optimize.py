"""Write an optimisation (:class:`linkpipe.study.optimize.Outcome`): ``<name>_optimize.h5`` and
``<name>_optimize.toml``.

The HDF5 (netCDF-4 layout like ``<name>.h5``): ``best``, ``initial``, ``lower``, ``upper`` on
``parameter`` (the addresses, bounded then tied; a tied one's bounds NaN, its attribute
``kind`` "bound" or "tie"); ``objective``, ``parameter_value``, ``metric_value``,
``failed_steps``, ``feasible``, ``violation``, ``evaluation_generation`` on ``evaluation``
(every variant the search and the polish solved, in order); ``population_best`` on
``generation``; ``best_metric`` on ``metric``; with two objectives ``objective_value``
(evaluation, objective) and the Pareto set ``pareto_evaluation``, ``pareto_objective``,
``pareto_parameter_value`` on ``pareto``. Root attributes ``active_constraints``,
``on_bound`` (lists of strings: the constraints as written, the addresses of the values on a
bound) and ``on_bound_side`` ("lower" / "upper" for each), ``objective_name``,
``best_objective``, ``best_evaluation``.

The TOML is the base scene's own text edited with tomlkit (comments and layout kept): the
best values in place and the ``[[logs]]`` file paths rewritten to work from the output folder.
"""
from __future__ import annotations

import os
import pathlib

import numpy as np

from . import hdf5, scene_toml
from ..output_units import common_unit
from ..result import Variable
from ..version import __version__


def write_toml(outcome, path: str | os.PathLike) -> None:
    problem = outcome.problem
    study = problem.study
    name = problem.objectives[0]
    head = (f"# linkpipe optimize {study.path}: {name} = {outcome.objective[outcome.best]:.12g} "
            f"at the values below ({name} = \"{_text(study, name)}\"), each line that changed "
            f"marked. Its [scene] name is the original's: run it with --out <another folder> "
            f"to keep the original's outputs.\n")
    out_dir = pathlib.Path(path).resolve().parent
    scene_toml.write(head + scene_toml.with_values(
        study.scene, [(p.path, v) for p, v in zip(study.parameters, outcome.best_values)],
        out_dir, "optimized"), path)


def _text(study, name: str) -> str:
    return next(m.text for m in study.metrics if m.name == name)


def write_h5(outcome, path: str | os.PathLike) -> None:
    problem = outcome.problem
    study = problem.study
    params = study.parameters
    F, P = problem.n_free, len(params)
    names = [m.name for m in study.metrics if not m.name.startswith("_")]
    p_units = study.parameter_units()
    m_units = study.metric_units()
    p_unit, p_per = common_unit(p_units), {"parameter_units": ",".join(p_units)}
    m_per = {"metric_units": ",".join(m_units[n] for n in names)}
    E, G = len(outcome.values), len(outcome.population_best)
    objective = problem.objectives[0]
    o_unit = m_units[objective]
    bounds = np.full((2, P), np.nan)
    bounds[0, :F], bounds[1, :F] = problem.lower, problem.upper
    coords = [Variable("parameter", ("parameter",), np.array(study.names, dtype=object), "",
                       {"kind": [p.kind for p in params],
                        "tied_to": [p.spec[0] if p.kind == "tie" else "" for p in params]}),
              Variable("evaluation", ("evaluation",), np.arange(E, dtype=np.int64), "1"),
              Variable("generation", ("generation",), np.arange(G, dtype=np.int64), "1"),
              Variable("metric", ("metric",), np.array(names, dtype=object), "")]
    best = outcome.best
    variables = [
        Variable("best", ("parameter",), outcome.best_values.astype(float), p_unit,
                 {**p_per, "long_name": "the best values found (tied ones follow theirs)"}),
        Variable("initial", ("parameter",), np.array([p.initial for p in params]), p_unit, dict(p_per)),
        Variable("lower", ("parameter",), bounds[0], p_unit, {**p_per, "long_name": "lower bound (NaN: tied)"}),
        Variable("upper", ("parameter",), bounds[1], p_unit, {**p_per, "long_name": "upper bound (NaN: tied)"}),
        Variable("objective", ("evaluation",), outcome.objective.astype(float), o_unit,
                 {"long_name": f"{objective} of every evaluated variant, in order",
                  "reduction": _text(study, objective)}),
        Variable("parameter_value", ("evaluation", "parameter"), outcome.values, p_unit, dict(p_per)),
        Variable("metric_value", ("evaluation", "metric"),
                 np.column_stack([outcome.metrics[n] for n in names]) if names else np.zeros((E, 0)),
                 common_unit([m_units[n] for n in names]), m_per),
        Variable("failed_steps", ("evaluation",),
                 outcome.metrics["_failed_steps"].astype(np.int32), "1",
                 {"long_name": "steps that are not ok (a variant with any fails)"}),
        Variable("feasible", ("evaluation",), outcome.feasible.astype(np.int8), "1",
                 {"long_name": "1 where every step is ok and every constraint holds"}),
        Variable("violation", ("evaluation",), outcome.violation, "1",
                 {"long_name": "the constraints' excesses, each over its metric's spread, plus "
                               "the failed steps' fraction (0: feasible)"}),
        Variable("evaluation_generation", ("evaluation",), outcome.generation.astype(np.int32), "1",
                 {"long_name": "the search's generation that evaluated it (-1: the polish)"}),
        Variable("population_best", ("generation",), outcome.population_best, o_unit,
                 {"long_name": f"the lowest {objective} of a feasible variant after each "
                               "generation (NaN before the first)"}),
        Variable("best_metric", ("metric",),
                 np.array([outcome.metrics[n][best] for n in names], dtype=float),
                 common_unit([m_units[n] for n in names]), m_per),
    ]
    if len(problem.objectives) == 2:
        front = outcome.pareto
        both = np.column_stack([outcome.metrics[o] for o in problem.objectives])
        o_units = {"objective_units": ",".join(m_units[o] for o in problem.objectives)}
        coords += [Variable("objective_name", ("objective_name",),
                            np.array(problem.objectives, dtype=object), ""),
                   Variable("pareto", ("pareto",), np.arange(len(front), dtype=np.int64), "1")]
        variables += [
            Variable("objective_value", ("evaluation", "objective_name"), both,
                     common_unit(list(o_units["objective_units"].split(","))), o_units),
            Variable("pareto_evaluation", ("pareto",), front.astype(np.int64), "1",
                     {"long_name": "the evaluations no feasible other beats in both objectives, "
                                   "by the first"}),
            Variable("pareto_objective", ("pareto", "objective_name"), both[front],
                     common_unit(list(o_units["objective_units"].split(","))), o_units),
            Variable("pareto_parameter_value", ("pareto", "parameter"), outcome.values[front],
                     p_unit, dict(p_per)),
        ]
    attrs = {"linkpipe_version": __version__, "scene_name": study.name,
             "optimize_path": study.path, "optimize_toml": study.text,
             "base_scene_path": study.scene.path, "base_scene_toml": study.scene.text,
             "objective_name": list(problem.objectives),
             "best_objective": float(outcome.objective[best]), "best_evaluation": int(best),
             "constraints": [c.text for c in problem.constraints],
             "active_constraints": list(outcome.active),
             "on_bound": [a for a, _ in outcome.on_bound],
             "on_bound_side": [side for _, side in outcome.on_bound],
             "seed": problem.seed, "seconds": float(outcome.seconds),
             "search_message": list(outcome.messages), "solved": study.path_note}
    n_bytes = sum(np.asarray(v.data).nbytes for v in variables) + (1 << 16)
    hdf5.write_layout(path, attrs, coords, variables, n_bytes)
