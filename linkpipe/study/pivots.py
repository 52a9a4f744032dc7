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
(:func:`linkpipe.study.batch.solve_variant`) and its rows put in place: every row is its own
run's (``tests/test_study_pivots.py``, ``tests/test_study_lengths.py``).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .. import kinematics as kin
from ..forces import compute_forces
from ..forces.applied import center_frame
from ..forces.constants import ForceConstants
from ..kinematics.decompose import bodies_of, chain_at
from ..model.build import build_model
from ..model.rows import variant_rows
from .. import stroke
from ..pipeline import Stages, result_of, status_of
from ..stage1 import Kinematics
from ..result import Motion
from ..output_units import units_of
from ..status import NO_ASSEMBLY
from . import vector

_CHAIN: dict = {}  # study fingerprint -> the base scene's dyad chain with its branches


def changed_constants(study, trial) -> str:
    """What of the model a trial scene (a pivot moved) changes beyond its fixed points ("":
    nothing, the vectorised path applies)."""
    base, model = build_model(study.scene), build_model(trial)
    for family in ("dist", "local", "sfix", "smov", "drivers"):
        if getattr(model.rows, family) != getattr(base.rows, family):
            return (f"the model's {family} rows change with it (a length or local coordinate "
                    "taken from the drawing)")
    for m in study.scene.masses:
        if center_frame(model, m.link, m.center) != center_frame(base, m.link, m.center):
            return f"the mass centre of {m.link} is taken from the drawing"
    return ""


#: the slots of the geometry path: a pivot, a frame length, a plate's side length, a drawn
#: coordinate of a moving point
GEOMETRY = ("pivot", "length", "side", "drawn")
#: the slots whose variants' model rows are built again (:func:`variant_rows`)
REBUILT = ("length", "side", "drawn")


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


def passes_checks(study, slot, value: float) -> bool:
    """Whether the variant with one parameter (``slot``) at ``value`` passes the model's and
    the placement's checks as :func:`variant_rows` tells them (a study's extreme value that
    its own scene refuses must be refused here too, its variants then being their own runs)."""
    base = build_model(study.scene)
    _, ok = variant_rows(base, *rows_inputs(base, [slot], np.array([[float(value)]])))
    return bool(ok[0])


def unlike_own_model(study, trial, slot, value: float) -> str:
    """What of the model a trial scene (one parameter, ``slot``, at ``value``: a frame length,
    a side length or a drawn coordinate) builds otherwise than :func:`variant_rows` builds it
    for that value ("": nothing, the vectorised path applies)."""
    base, own = build_model(study.scene), build_model(trial)
    rows, _ = variant_rows(base, *rows_inputs(base, [slot], np.array([[float(value)]])))
    rows = rows.take(0)  # the one variant's numbers
    for family in rows.FAMILIES:
        if getattr(rows, family) != getattr(own.rows, family):
            return f"the model's {family} rows are not the variant's own"
    for m in study.scene.masses:
        if center_frame(base, m.link, m.center, rows) != center_frame(own, m.link, m.center):
            return f"the mass centre frame of {m.link} is not the variant's own"
    return ""


def path_reason(study) -> str:
    """Why a study that moves pivots cannot take the vectorised path ("" when it can)."""
    scene = study.scene
    if scene.solver.method != "auto" or scene.solver.derivatives == "finite_difference":
        return 'pivots move: the vectorised path needs [solver] method = "auto" and analytic derivatives'
    base = vector.base_result(study)
    if base.solver_method_used != "dyads":
        return "pivots move and the base scene does not take the closed-form dyads"
    if base.reach_note:  # the variants' own runs start where each one's reach begins
        return "pivots move and the base scene's first steps are out of its drawing's reach"
    if any(st.ambiguous for st in base_chain(study).steps):
        return "pivots move and a dyad starts on its singular shape"
    if any(sp.kind != "gas" and sp.free_length is None for sp in scene.springs):
        return ("pivots move and a spring's start length (its preload's, or its free length) "
                "is each variant's own assembled drawing")
    return ""


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
    order = 2 if stages.acceleration else 1 if stages.velocity else 0
    chain, rows, alike = variant_model(study, slots, study.values[lo:hi])
    usable, a = kin.solve_pivot_variants(model, chain, per_row["start_position"][::S],
                                         per_row["size"][::S],
                                         k.s, k.s_dot, k.s_ddot, order, stages.forces, rows)
    usable &= alike
    der = a["der"]
    forces = None
    if stages.forces:
        motion = Motion(s=a["s"], s_dot=a["s_dot"], s_ddot=a["s_ddot"], position=a["position"],
                        velocity=a["velocity"], acceleration=a["acceleration"],
                        status=der["status"], influence=der["influence"],
                        link_angular_acceleration=a["link_rates"][1], link_angle=a["link_angle"])
        forces = compute_forces(model, motion, units_of(scene),
                                ForceConstants(**per_row, pivots=True, model_rows=a["rows"]))
    stored = [a["position"], a["link_angle"], a["velocity"], a["acceleration"], *a["link_rates"]]
    status = status_of(model, der["status"], a["residual"], stored, forces, per_row["size"],
                       stroke_margin=stroke.margins(scene, np.tile(k.drive.value, (V, 1)),
                                                    a["position"],
                                                    per_row.get("gas_extended_length")))
    drive = dataclasses.replace(k.drive, **{f.name: np.tile(v, (V,) + (1,) * (v.ndim - 1))
                                            for f in dataclasses.fields(k.drive)
                                            for v in [getattr(k.drive, f.name)] if v is not None})
    sweep = kin.Sweep(a["position"], a["residual"], np.zeros(V * S, dtype=np.int32), a["status"],
                      "dyads", k.sweep.note, a["velocity"], a["acceleration"])
    rows = Kinematics(k.mobility, drive, a["s"], a["s_dot"], a["s_ddot"], sweep, a["link_angle"],
                      der, a["velocity"], a["acceleration"], a["link_rates"])
    result = result_of(scene, model, rows, forces, status, {})
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
    from .batch import solve_variant  # batch imports vector, which imports this module

    r = solve_variant(study, variant, None)
    stored = {} if r is None else {v.name: v.data for v in r.variables()}
    for name, arr in out.items():
        if name in stored:
            arr[row] = stored[name]
        elif name == "status":
            arr[row] = NO_ASSEMBLY
        else:
            arr[row] = np.nan if arr.dtype.kind == "f" else 0
