"""Fleets of logs: one scene run (or fitted) over many logs, one row per log.

A test engineer with many machines has one scene and a folder of logs. ``python -m linkpipe
run SCENE --logs 'rig/*.csv'`` (and ``fit``) reads the scene once and, for every file the glob
matches (sorted by name), the scene with its ``[[logs]]`` entry's ``file`` replaced by that
file (``--log-name`` picks the entry when the scene has several), parsed and checked as a
scene file is. Each log is one task on the same executors as a study
(:mod:`linkpipe.executors`: in-process, or Dask with ``--workers`` / ``--scheduler``). A log
the scene cannot take (a missing column, too few rows) is a row with its message, never the
end of the fleet.

Rows (one per log): ``run``: the steps and how many are ok, the worst status and first failed
step, peak and RMS input force per driver over the ok steps, each measurement's RMS residual;
``fit``: the fitted values and standard errors per parameter, each measurement's RMS residual
before and after. Written to ``<name>_fleet.h5`` / ``<name>_fleet_fit.h5`` with dimension
``log`` (the log files' names) by :mod:`linkpipe.stores.fleet`.
"""
from __future__ import annotations

import copy
import glob
import os
import pathlib
import tomllib

import numpy as np

from .errors import LinkpipeError, SceneError
from .scene import Scene
from .scene.keys import _suggest
from .status import OK


def log_files(pattern: str) -> list[str]:
    """The files a glob matches, sorted; an error naming the pattern when none does."""
    found = sorted(p for p in glob.glob(pattern, recursive=True) if os.path.isfile(p))
    if not found:
        raise LinkpipeError(f"--logs {pattern}: no file matches; give a glob of log files "
                            "(quoted, e.g. 'rig/*.csv')")
    return found


def log_entry(path: str, data: dict, log_name: str | None) -> int:
    """The index of the ``[[logs]]`` entry the fleet replaces (``path``: the scene file's, for
    the messages; ``data``: its TOML data)."""
    logs = data.get("logs") or []
    names = [entry.get("name") for entry in logs]
    if not logs:
        raise SceneError(path, "logs", None, "a fleet replaces the file of one [[logs]] "
                         "entry, and this scene reads no log",
                         "add [[logs]] with name, file and time, and drive or measure from it")
    if log_name is None:
        if len(logs) == 1:
            return 0
        raise SceneError(path, "logs", None, f"a fleet replaces one log's file; the scene "
                         f"has {len(logs)} [[logs]]", "name it with --log-name"
                         + (f" ({', '.join(map(str, names))})" if names else ""))
    if log_name not in names:
        raise SceneError(path, "logs", "name", f'no [[logs]] entry "{log_name}"',
                         _suggest(log_name, names))
    return names.index(log_name)


def fleet_scene(path: str, pattern: str, log_name: str | None = None) -> Scene:
    """The scene a fleet runs, loaded from ``path``: as it is, or, when the file of the
    ``[[logs]]`` entry the fleet replaces does not exist, reading the glob's first log in its
    place (the fleet replaces it for every log: the scene's own file is not needed)."""
    from .scene import load_scene
    from .scene.parse import _Parser

    try:
        return load_scene(path)
    except SceneError as exc:
        if exc.key != "file" or not exc.table.startswith("logs"):
            raise
        text = pathlib.Path(path).read_text(encoding="utf-8")  # read and parsed already
        data = tomllib.loads(text)
        entry = log_entry(path, data, log_name)
        if exc.table != f'logs "{data["logs"][entry].get("name")}"':
            raise  # another log's file: the fleet does not replace it
        data["logs"][entry]["file"] = os.path.abspath(log_files(pattern)[0])
        return _Parser(data, text, path).parse()


def scene_for_log(scene: Scene, data: dict, entry: int, path: str) -> tuple[Scene, dict]:
    """The scene with its ``[[logs]]`` entry ``entry`` reading ``path`` (checked as a scene),
    and its TOML data."""
    from .scene.parse import _Parser

    trial = copy.deepcopy(data)
    trial["logs"][entry]["file"] = os.path.abspath(path)
    return _Parser(trial, scene.text, scene.path).parse(), trial


def run_log(job, path: str) -> dict:
    """The row of one log: ``run`` the scene over it (``job`` = (kind, scene, data, entry))."""
    kind, scene, data, entry = job
    try:
        one, one_data = scene_for_log(scene, data, entry, path)
        if kind == "fit":
            from .fit import fit

            return fit_row(fit(one, data=one_data))
        from .pipeline import solve

        return run_row(solve(one))
    except LinkpipeError as exc:  # this log cannot be taken: a row saying why
        return {"message": str(exc)}


def _reduce(f: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(peak |f|, RMS f) per column of f (S, n) over the ok steps (NaN where none)."""
    x = np.where(ok[:, None], f, np.nan)
    n = (~np.isnan(x)).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        peak = np.where(n > 0, np.abs(np.where(np.isnan(x), 0.0, x)).max(axis=0, initial=0.0), np.nan)
        rms = np.sqrt(np.where(np.isnan(x), 0.0, x * x).sum(axis=0) / n)
    return peak, np.where(n > 0, rms, np.nan)


def run_row(result) -> dict:
    ok = result.status == OK
    row = {"message": result.message, "n_steps": result.n_steps, "steps_ok": int(ok.sum()),
           "worst_status": int(result.status.max()) if result.n_steps else 0,
           "first_failed_step": int(np.flatnonzero(~ok)[0]) if (~ok).any() else -1}
    if result.forces and "input_force" in result.forces:
        row["peak_input_force"], row["rms_input_force"] = _reduce(result.forces["input_force"][1], ok)
    if result.measurements:
        row["measured_rms"] = np.asarray(result.measurements["rms"], float)
    return row


def fit_row(fr) -> dict:
    return {"message": str(fr.message), "n_steps": fr.after.n_steps, "fitted": np.asarray(fr.fitted, float),
            "standard_error": np.asarray(fr.standard_error, float),
            "rms_before": np.asarray(fr.before.measurements["rms"], float),
            "rms_after": np.asarray(fr.after.measurements["rms"], float),
            "evaluations": int(fr.n_evaluations),
            "reduced_chi_square": float(fr.reduced_chi_square),
            "warnings": "\n".join(fr.warnings)}


def run_fleet(kind: str, scene: Scene, pattern: str, log_name=None, executor="in_process",
              workers=None, scheduler=None, progress=None) -> tuple[list[str], list[dict]]:
    """Every log's row, in the order of the sorted log files: (paths, rows)."""
    from .executors import EXECUTORS

    paths = log_files(pattern)
    data = tomllib.loads(scene.text)
    entry = log_entry(scene.path, data, log_name)
    if kind == "fit":
        from .fit import parameters_of

        parameters_of(scene, data)  # a bad [fit] table is the scene's error, before any log
    rows: list = [None] * len(paths)
    job = (kind, scene, data, entry)
    for i, row in EXECUTORS[executor](run_log, job, [(p,) for p in paths], workers, scheduler):
        rows[i] = row
        if progress is not None:
            progress(i)
    return paths, rows


#: the columns of a fleet's rows: name -> (dimension after ``log``, fill, units key)
COLUMNS = {
    "run": {"n_steps": (None, -1, "1"), "steps_ok": (None, -1, "1"),
            "worst_status": (None, -1, "1"), "first_failed_step": (None, -2, "1"),
            "peak_input_force": ("driver", np.nan, "force"),
            "rms_input_force": ("driver", np.nan, "force"),
            "measured_rms": ("measurement", np.nan, "measurement")},
    "fit": {"fitted": ("parameter", np.nan, "parameter"),
            "standard_error": ("parameter", np.nan, "parameter"),
            "rms_before": ("measurement", np.nan, "measurement"),
            "rms_after": ("measurement", np.nan, "measurement"),
            "evaluations": (None, -1, "1"),
            "reduced_chi_square": (None, np.nan, "1")},
}


def log_labels(paths) -> list[str]:
    """Each log's label: its path from the folder all the logs share (``a.csv``,
    ``sub/a.csv``): unique, as the paths are, and short."""
    paths = [os.path.abspath(p) for p in paths]
    root = os.path.commonpath([os.path.dirname(p) for p in paths]) if paths else ""
    return [os.path.relpath(p, root) for p in paths]


def fleet_columns(kind: str, scene: Scene, paths, rows, params=()) -> tuple[dict, dict]:
    """``(labels {dimension: names}, columns {name: (dims, array)})`` of a fleet's rows: one
    row per log, a failed log's cells at their fill values (NaN, -1) and its message kept;
    ``params``: a fit's parameters."""
    labels = {"log": log_labels(paths),
              "driver": [d.name for d in scene.drivers],
              "measurement": [m.name for m in scene.measurements]}
    if kind == "fit":
        labels["parameter"] = [p.address for p in params]
    columns = {"message": (("log",), np.array([r.get("message", "") for r in rows], dtype=object)),
               "log_failed": (("log",), np.array([len(r) == 1 for r in rows], dtype=np.int8))}
    if kind == "fit":  # what each log's fit warned of ("" when nothing), one per line
        columns["warnings"] = (("log",), np.array([r.get("warnings", "") for r in rows],
                                                  dtype=object))
    for name, (dim, fill, _) in COLUMNS[kind].items():
        shape = (len(rows),) + ((len(labels[dim]),) if dim else ())
        if dim and not shape[1] or not any(name in r for r in rows):
            continue
        arr = np.full(shape, fill, dtype=float if isinstance(fill, float) else np.int64)
        for i, r in enumerate(rows):
            if name in r:
                arr[i] = r[name]
        columns[name] = (("log",) + ((dim,) if dim else ()), arr)
    return labels, columns


def fleet_table(kind: str, scene: Scene, labels: dict, columns: dict, entry_units: dict) -> str:
    """What ``run --logs`` / ``fit --logs`` print: one line per log, each figure with its unit
    (``entry_units`` {"force" | "measurement" | "parameter": each entry's unit})."""
    pu, fu, mu = ([f" {u}" if u else "" for u in entry_units.get(key, ())]
                  for key in ("parameter", "force", "measurement"))
    lines = [f"{scene.name}: {kind} over {len(labels['log'])} log(s)"]
    width = max(len(n) for n in labels["log"])
    for i, name in enumerate(labels["log"]):
        cells = []
        if kind == "fit" and "fitted" in columns:
            cells += [f"{p} {columns['fitted'][1][i, j]:.6g} ± "
                      f"{columns['standard_error'][1][i, j]:.3g}{pu[j]}"
                      for j, p in enumerate(labels["parameter"])]
            cells += [f"rms {m} {columns['rms_after'][1][i, k]:.4g}{mu[k]}"
                      for k, m in enumerate(labels["measurement"])]
        elif kind == "run":
            if "steps_ok" in columns and columns["steps_ok"][1][i] >= 0:
                cells.append(f"{columns['steps_ok'][1][i]}/{columns['n_steps'][1][i]} ok")
            if "peak_input_force" in columns:
                cells += [f"peak {d} {columns['peak_input_force'][1][i, j]:.6g}{fu[j]}"
                          for j, d in enumerate(labels["driver"])]
            if "measured_rms" in columns:
                cells += [f"rms {m} {columns['measured_rms'][1][i, k]:.4g}{mu[k]}"
                          for k, m in enumerate(labels["measurement"])]
        message = columns["message"][1][i]
        failed = columns["log_failed"][1][i]
        lines.append(f"  {name:<{width}}  " + (f"failed: {message}" if failed else ", ".join(cells)))
        if "warnings" in columns and not failed:
            lines += [f"  {'':<{width}}  warning: {w}" for w in
                      str(columns["warnings"][1][i]).splitlines()]
    return "\n".join(lines)


def write_fleet(kind: str, scene: Scene, pattern: str, paths, rows, out) -> tuple:
    """Write ``<name>_fleet.h5`` (``fit``: ``<name>_fleet_fit.h5``) into the folder ``out``;
    return (its path, the table to print)."""
    from .fit import parameters_of
    from .output_units import (common_unit, input_force_units, measured_units, parameter_units,
                               units_of)
    from .stores import fleet as fleet_store

    params = parameters_of(scene, tomllib.loads(scene.text)) if kind == "fit" else ()
    labels, columns = fleet_columns(kind, scene, paths, rows, params)
    # each entry's unit (an attribute beside a column whose entries may differ)
    entry_units = {"force": input_force_units(scene.drivers, units_of(scene)),
                   "measurement": measured_units(scene),
                   "parameter": parameter_units(scene, params)}
    attribute = {"force": "driver_units", "measurement": "measurement_units",
                 "parameter": "parameter_units"}
    units, attrs = {}, {}
    for name, (_, _, key) in COLUMNS[kind].items():
        if key in entry_units:
            units[name] = common_unit(entry_units[key]) if entry_units[key] else ""
            attrs[name] = {attribute[key]: ",".join(entry_units[key])}
        else:
            units[name] = key
    from .stores import output_folder

    out = output_folder(out)
    path = out / f"{scene.name}_fleet{'_fit' if kind == 'fit' else ''}.h5"
    fleet_store.write(path, {"scene_name": scene.name, "scene_toml": scene.text,
                             "logs_glob": pattern, "command": kind}, labels, columns, units, attrs)
    return path, fleet_table(kind, scene, labels, columns, entry_units)
