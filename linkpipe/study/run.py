"""Run a study: batches on an executor, rows streamed into ``<name>_study.h5`` as they finish.

Executors (:data:`linkpipe.executors.EXECUTORS`): ``in_process`` (the default: one batch
after another here), ``dask`` (a ``LocalCluster`` of ``workers`` processes, or the cluster
whose scheduler is at ``scheduler``). Every executor runs the same task,
:func:`linkpipe.study.batch.solve_batch`, and yields the rows of each batch in the order
batches finish; the store writes them where they belong, so the file does not depend on the
executor or on the order. A study run again after a kill resumes from its finished
batches (:mod:`linkpipe.stores.study`).
"""
from __future__ import annotations

import pathlib

import numpy as np

from ..executors import EXECUTORS
from ..result import Variable
from ..output_units import common_unit, input_force_units, units_of
from ..version import __version__
from .batch import solve_batch


def layout(study) -> tuple[dict, list, list]:
    """(attributes, coordinates, variables at full size with their fill values)."""
    V, D, B = study.n_variants, len(study.driver_names), len(study.batches())
    # each driver's input force unit (a torque for an angle driver without an input point)
    by_driver = input_force_units(study.scene.drivers, units_of(study.scene))
    force = common_unit(by_driver)
    p_units, m_units = study.parameter_units(), study.metric_units()
    coords = [Variable("variant", ("variant",), np.arange(V, dtype=np.int64), "1"),
              Variable("parameter", ("parameter",), np.array(study.names, dtype=object), "",
                       {"kind": [p.kind for p in study.parameters]}),
              Variable("driver", ("driver",), np.array(study.driver_names, dtype=object), ""),
              Variable("batch", ("batch",), np.arange(B, dtype=np.int64), "1")]
    nan = np.full((V, D), np.nan)
    per_driver = {"long_name": "over the variant's ok steps", "driver_units": ",".join(by_driver)}
    variables = [
        Variable("parameter_value", ("variant", "parameter"), study.values, common_unit(p_units),
                 {"initial": [p.initial for p in study.parameters],
                  "parameter_units": ",".join(p_units)}),
        Variable("peak_input_force", ("variant", "driver"), nan, force,
                 {**per_driver, "long_name": "max |input_force| over the variant's ok steps"}),
        Variable("rms_input_force", ("variant", "driver"), nan, force, per_driver),
        Variable("input_force_range", ("variant", "driver"), nan, force,
                 {**per_driver,
                  "long_name": "max - min of input_force over the variant's ok steps"}),
        Variable("min_transmission_angle", ("variant",), np.full(V, np.nan), "degree",
                 {"long_name": "smallest min(mu, 180 - mu) at the pins between two moving "
                               "links no angle driver turns, over the ok steps"}),
        Variable("worst_status", ("variant",), np.full(V, -1, np.int8), "1",
                 {"long_name": "the highest status code met (codes of the scene's status)"}),
        Variable("first_failed_step", ("variant",), np.full(V, -2, np.int32), "1",
                 {"long_name": "first step that is not ok; -1 if none"}),
        *[Variable(m.name, ("variant",), np.full(V, np.nan), m_units[m.name],
                   {"reduction": m.text}) for m in study.metrics],
        Variable("batch_done", ("batch",), np.zeros(B, np.int8), "1",
                 {"long_name": "1 where the batch's rows are written"}),
    ]
    attrs = {"linkpipe_version": __version__, "scene_name": study.name,
             "study_path": study.path, "study_toml": study.text,
             "base_scene_path": study.scene.path, "base_scene_toml": study.scene.text,
             "samples": study.samples, "seed": study.seed, "batch_size": study.batch_size,
             "n_steps": study.scene.n_steps, "solved": study.path_note}
    return attrs, coords, variables


def run_study(study, out, executor: str = "in_process", workers=None, scheduler=None,
              progress: bool = False, after_batch=None) -> pathlib.Path:
    """Solve every batch not yet in ``out/<name>_study.h5`` and return that file's path.

    ``after_batch(n_written)``: called after each batch is written (a test stops a study
    half-way by raising there)."""
    from ..stores import output_folder, output_lock

    out = output_folder(out)
    # a second run of the same study into the same folder waits for the first (it would
    # otherwise take the first one's unfinished file for one cut short by a kill)
    with output_lock(out, f"{study.name}_study"):
        return _run_locked(study, out, executor, workers, scheduler, progress, after_batch)


def _run_locked(study, out: pathlib.Path, executor, workers, scheduler, progress, after_batch):
    from ..stores.study import StudyFile

    path = out / f"{study.name}_study.h5"
    store = StudyFile(path, *layout(study), study.fingerprint)
    try:
        done = store.done
        todo = [t for t in study.batches() if not done[t[0]]]
        bar = _bar(study, progress, sum(hi - lo for b, lo, hi in study.batches() if done[b]))
        tasks = [(lo, hi) for b, lo, hi in todo]
        finished = EXECUTORS[executor](solve_batch, study, tasks, workers, scheduler)
        for n, (i, rows) in enumerate(finished, 1):
            store.write_batch(todo[i][0], todo[i][1], rows)
            if bar is not None:
                bar.update(len(rows["worst_status"]))
            if after_batch is not None:
                after_batch(n)
        if bar is not None:
            bar.close()
    finally:
        store.close()
    store.finish()
    return path


def _bar(study, progress: bool, initial: int):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=study.n_variants, initial=initial, desc=f"study {study.name}",
                unit=" variants", leave=False, disable=None)
