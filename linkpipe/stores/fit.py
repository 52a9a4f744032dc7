"""Write a fit (:class:`linkpipe.fit.FitResult`): ``<name>_fit.toml`` and ``<name>_fit.h5``.

The TOML is the scene's own text edited with tomlkit (comments and layout kept), the fitted
values put in place and the ``[[logs]]`` file paths rewritten so that the file works from the
output folder. The HDF5 (netCDF-4 layout like ``<name>.h5``) holds ``initial``, ``fitted``,
``standard_error`` and ``identifiable`` on dimension ``parameter`` (the addresses), ``cost`` on
``iteration`` (the objective at the start values, then at each iteration's point), and the measurements' residuals before and
after (``measured_residual_before``, ``measured_residual_after``: step, measurement).
"""
from __future__ import annotations

import os
import pathlib

import numpy as np
from . import hdf5, scene_toml
from ..result import Variable
from ..output_units import common_unit, parameter_units


def write_toml(fit, path: str | os.PathLike) -> None:
    head = (f"# linkpipe fit {fit.scene.path}: the fitted values in place, each line that changed "
            f"marked. Its [scene] name is the original's: run it with --out <another folder> "
            f"to keep the original's outputs.\n")
    out_dir = pathlib.Path(path).resolve().parent
    scene_toml.write(head + scene_toml.with_values(
        fit.scene, [(p.path, v) for p, v in zip(fit.parameters, fit.fitted)], out_dir, "fitted"),
        path)


def write_h5(fit, path: str | os.PathLike) -> None:
    names = np.array(fit.names, dtype=object)
    before, after = fit.before.measurements, fit.after.measurements
    units = common_unit(before["units"])
    per = {"measurement_units": ",".join(before["units"])}
    p_units = parameter_units(fit.scene, fit.parameters)
    p_unit, p_per = common_unit(p_units), {"parameter_units": ",".join(p_units)}
    coords = [Variable("parameter", ("parameter",), names, ""),
              Variable("parameter_2", ("parameter_2",), names, ""),
              Variable("measurement", ("measurement",), np.array(before["names"], dtype=object), ""),
              Variable("step", ("step",), np.arange(len(before["residual"])), "1"),
              Variable("iteration", ("iteration",), np.arange(len(fit.cost)), "1")]
    variables = [
        Variable("initial", ("parameter",), np.array([p.initial for p in fit.parameters]),
                 p_unit, dict(p_per)),
        Variable("fitted", ("parameter",), np.asarray(fit.fitted, float), p_unit, dict(p_per)),
        Variable("standard_error", ("parameter",), np.asarray(fit.standard_error, float), p_unit,
                 {**p_per, "long_name": "one standard error; NaN where the data cannot identify it"}),
        Variable("identifiable", ("parameter",), fit.identifiable.astype(np.int8), "1"),
        Variable("correlation", ("parameter", "parameter_2"),
                 np.asarray(fit.correlation if fit.correlation is not None
                            else np.full((len(names),) * 2, np.nan), float), "1",
                 {"long_name": "the parameters' correlation matrix from the Jacobian at the "
                  "solution; NaN where not identifiable"}),
        Variable("cost", ("iteration",), np.asarray(fit.cost, float), "1",
                 {"long_name": "sum(((computed - measured) / sigma)^2), the objective: at the start "
                  "values (iteration 0), then at each iteration's point"}),
        Variable("measured_residual_before", ("step", "measurement"), before["residual"], units,
                 {**per, "rms": before["rms"], "max_abs": before["max_abs"]}),
        Variable("measured_residual_after", ("step", "measurement"), after["residual"], units,
                 {**per, "rms": after["rms"], "max_abs": after["max_abs"]}),
    ]
    attrs = {"scene_name": fit.scene.name, "optimizer_message": str(fit.message),
             "evaluations": int(fit.n_evaluations), "solves": int(fit.solves),
             "stage1_solves": int(fit.stage1_solves),
             "reduced_chi_square": float(fit.reduced_chi_square),
             "warnings": "\n".join(fit.warnings), "loss": str(fit.loss),
             "f_scale": float(fit.f_scale)}
    hdf5.write_layout(path, attrs, coords, variables)
