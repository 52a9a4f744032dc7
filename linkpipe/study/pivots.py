"""The vectorised path of a study whose variants move the mechanism's fixed points (pivots),
change its links' lengths or a plate's side lengths, or draw its moving points elsewhere.

A parameter ``points.<P>.x | y`` of a fixed point that links, sliders or drivers use changes
the kinematics, but on a scene that takes the closed-form dyads (``[solver] method`` auto) it
changes nothing else of the model where the scene gives the lengths and local coordinates of
the links at that point (checked at both ends of each parameter's range: the model's rows and
mass-centre frames must equal the base scene's). A parameter ``links.<name>.lengths.A-B`` (the
distance of a link's first two points) changes the model's constants: each variant's are
built by the model's own code at once for the batch (:func:`linkpipe.model.rows.variant_rows`:
the rows with (V,) arrays where they differ; the dyads' constants from them by
:func:`linkpipe.kinematics.decompose.chain_at`), checked at both ends of each parameter's range
against the model the variant's own scene builds (rows and mass-centre frames equal to the
bit). A side length that places a further point of a plate (``links.<name>.lengths.A-P``)
and a moving point's drawn coordinate (``points.<P>.x | y``: its start guess, and the lengths,
local coordinates and plate sides the scene takes from the drawing) are built the same way:
:func:`variant_rows` places each variant's plates again with the code that placed the
scene's at load (:func:`linkpipe.scene.sides.placement` on (V,) arrays) and builds its rows
from its own drawing; the placement's and the model's checks are (V,) masks, a variant that
fails them being its own run (its scene refuses it: no_assembly rows). All variants of a batch then run as one stage 1 on V x S rows (variant, step) with the
pivots as per-row columns and the constants as per-row values
(:func:`linkpipe.kinematics.pivots.solve_pivot_variants`), then one force stage on the same
rows, force parameters of the study and the model's constants as per-row constants
(:mod:`.vector`, :class:`linkpipe.forces.constants.ForceConstants`). A variant whose own
run would take another path or other branches (or not assemble), or whose own scene would
decompose into other dyads or fail the model's checks, is solved by its own run
(:func:`linkpipe.study.variants.solve_variant`) and its rows put in place: every row is its own
run's (``tests/test_study_pivots.py``, ``tests/test_study_lengths.py``).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .. import kinematics as kin
from ..forces.constants import ForceConstants
from ..kinematics.decompose import bodies_of, chain_at
from ..model.rows import variant_rows
from ..spine import Stages, finish
from ..stage1 import Kinematics
from ..status import NO_ASSEMBLY
from . import vector
from .variants import solve_variant

_CHAIN: dict = {}  # study fingerprint -> the base scene's dyad chain with its branches


def rows_inputs(model, slots, values: np.ndarray) -> tuple[dict, dict, np.ndarray | None]:
    """``(lengths, distances, drawn)`` of :func:`variant_rows` for variants with parameter
    ``values`` (V, n_parameters): frame lengths {link: (V,)}, side lengths {(link, key): (V,)}
    and, where a pivot or a moving point's drawn coordinate varies, every variant's drawing
    (V, n_points, 2) with each varied coordinate (of any point) set (the side a plate's point
    is drawn on, lengths taken from the drawing: each variant's own); else None."""
    lengths = {slot[1]: values[:, j] for j, slot in enumerate(slots) if slot[0] == "length"}
    distances = {(slot[1], slot[2]): values[:, j] for j, slot in enumerate(slots)
                 if slot[0] == "side"}
    drawn = None
    if any(slot[0] in ("pivot", "drawn") for slot in slots):
        drawn = np.repeat(model.start_position[None], values.shape[0], axis=0)
        for j, slot in enumerate(slots):
            if slot[0] in ("point", "pivot", "drawn"):
                drawn[:, slot[1], slot[2]] = values[:, j]
    return lengths, distances, drawn


def base_chain(study):
    """The base scene's dyads with the branches its own run takes (once per process)."""
    if study.fingerprint not in _CHAIN:
        _CHAIN.clear()
        base = vector.base_result(study)
        chain = kin.decompose(base.model)
        kin.start_branches(base.model, chain, base.kinematics.s)
        _CHAIN[study.fingerprint] = chain
    return _CHAIN[study.fingerprint]


def variant_arrays(study, slots, lo: int, hi: int) -> tuple[np.ndarray, dict]:
    """``(status (V, S), {variable: (V, S, ...)})`` of variants ``lo .. hi - 1`` (as
    :func:`.vector.variant_arrays`): the usable ones at once, the others by their own runs."""
    base = vector.base_result(study)
    scene, model, k = study.scene, base.model, base.kinematics
    V, S = hi - lo, base.n_steps
    per_row = vector.per_row_constants(study, model, slots, study.values[lo:hi], S)
    stages = Stages.of(scene)
    order = stages.order
    chain, rows, alike = variant_model(study, slots, study.values[lo:hi])
    usable, a = kin.solve_pivot_variants(model, chain, per_row["start_position"][::S],
                                         per_row["size"][::S],
                                         k.s, k.s_dot, k.s_ddot, order, stages.forces, rows)
    usable &= alike
    drive = dataclasses.replace(k.drive, **{f.name: np.tile(v, (V,) + (1,) * (v.ndim - 1))
                                            for f in dataclasses.fields(k.drive)
                                            for v in [getattr(k.drive, f.name)] if v is not None})
    sweep = kin.Sweep(a["position"], a["residual"], np.zeros(V * S, dtype=np.int32), a["status"],
                      "dyads", k.sweep.note)
    motion = Kinematics(k.mobility, drive, a["s"], a["s_dot"], a["s_ddot"], sweep,
                        a["link_angle"], a["der"], a["velocity"], a["acceleration"],
                        a["link_rates"])
    result = finish(scene, model, motion,
                    ForceConstants(**per_row, pivots=True, model_rows=a["rows"]))
    out = {v.name: v.data.reshape((V, S) + v.data.shape[1:]) for v in result.variables()
           if v.dims[:1] == ("step",)}
    for v in np.flatnonzero(~usable):
        _own_run(study, lo + int(v), out, v)
    return out["status"], out


def variant_model(study, slots, values: np.ndarray):
    """``(chain, rows, alike (V,))`` of variants with parameter ``values`` (V, n_parameters):
    the base scene's dyads (branches set) with the variants' constants, the model's rows with
    (V,) arrays where frame lengths, side lengths or drawn coordinates of moving points vary
    (None where none does: pivots only), and where each variant's own scene passes the
    placement's and the model's checks and decomposes into these dyads (all True without
    them)."""
    model = vector.base_result(study).model
    lengths, distances, drawn = rows_inputs(model, slots, values)
    if not lengths and not distances and drawn is None:
        return base_chain(study), None, np.ones(values.shape[0], dtype=bool)
    rows, checked = variant_rows(model, lengths, distances, drawn)
    chain, alike = chain_at(base_chain(study), bodies_of(model, rows))
    return chain, rows, checked & alike


def _own_run(study, variant: int, out: dict, row: int) -> None:
    """Put variant ``variant``'s own run into row ``row`` of every array of ``out`` (NaN and
    no_assembly where its scene cannot be built or assembled)."""
    r = solve_variant(study, variant, None)
    stored = {} if r is None else {v.name: v.data for v in r.variables()}
    for name, arr in out.items():
        if name in stored:
            arr[row] = stored[name]
        elif name == "status":
            arr[row] = NO_ASSEMBLY
        else:
            arr[row] = np.nan if arr.dtype.kind == "f" else 0
