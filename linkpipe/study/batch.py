"""Solve one batch of a study's variants and reduce it to the study file's rows.

Two paths give the same rows: the vectorised ones (:mod:`.paths` decides which: :mod:`.vector`,
variants that differ in force numbers only, all at once; :mod:`.pivots`, the geometry too)
and variant by variant (each variant's scene parsed and solved by :func:`linkpipe.solve`:
:mod:`.variants`).

:func:`solve_batch` is the one task every executor runs (in-process, or on Dask workers): it
takes the study and a range of variants and returns their rows {variable: (V, ...)}. A
variant whose scene cannot be built or assembled (a triangle that cannot close, a start that
does not assemble) is a row with status no_assembly at every step, never an error of the
study.
"""
from __future__ import annotations

import numpy as np
from threadpoolctl import ThreadpoolController

from ..workers import DEFAULT_THREADS
from ..status import NO_ASSEMBLY
from .metrics import BatchArrays, batch_metrics, transmission_pins
from .paths import variant_arrays
from .reductions import references
from .variants import solve_variant


def wanted_series(study) -> list[tuple[str, tuple]]:
    """Every (variable, index) the named metrics read."""
    return sorted({r for m in study.metrics for r in references(m.tree)})


_POOLS: list = []  # one ThreadpoolController per process: building one scans the loaded
# libraries (4 ms, most of a small batch's time: an optimiser's polish solves many)


def _blas_limit():
    if not _POOLS:
        _POOLS.append(ThreadpoolController())
    return _POOLS[0].limit(limits=DEFAULT_THREADS, user_api="blas")


def solve_batch(study, lo: int, hi: int) -> dict[str, np.ndarray]:
    """Rows ``{variable: (hi - lo, ...)}`` of variants ``lo .. hi - 1``: all at once on the
    vectorised paths (:mod:`.paths`) where the study allows it, else variant by variant. The
    BLAS pool is set once for the batch (as :func:`linkpipe.solve` sets it for a scene)."""
    with _blas_limit():
        if study.slots is not None:
            status, arrays = variant_arrays(study, study.slots, lo, hi)
            batch = BatchArrays(status, arrays.get("input_force"), arrays["position"],
                                {(name, index): arrays[name][(slice(None), slice(None)) + index]
                                 for name, index in wanted_series(study)})
        else:
            batch = stack(study, [solve_variant(study, v, None) for v in range(lo, hi)])
        return batch_metrics(study, batch, transmission_pins(study.scene))


def stack(study, results) -> BatchArrays:
    """The arrays of solved variants with a leading variant axis (NaN and no_assembly for a
    variant that is None)."""
    scene = study.scene
    V, S, P = len(results), scene.n_steps, len(scene.points)
    status = np.full((V, S), NO_ASSEMBLY, dtype=np.int8)
    position = np.full((V, S, P, 2), np.nan)
    has_forces = "input_force" in study.catalog
    force = np.full((V, S, len(scene.drivers)), np.nan) if has_forces else None
    series = {key: np.full((V, S), np.nan) for key in wanted_series(study)}
    for k, r in enumerate(results):
        if r is None:
            continue
        status[k], position[k] = r.status, r.position
        stored = {var.name: var.data for var in r.variables()}
        if has_forces:
            force[k] = stored["input_force"]
        for (name, index), arr in series.items():
            arr[k] = stored[name][(slice(None),) + index]
    return BatchArrays(status, force, position, series)
