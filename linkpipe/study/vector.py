"""The vectorised path of a study: variants that differ only in force numbers share stage 1.

When every parameter is a number of a force table (``springs.<name>.k | free_length |
preload | damping``, a gas spring's ``force_extended | extended_length | dead_length |
gamma``, ``torsion_springs.<name>.k | free_angle``, ``masses.<link>.mass | inertia``, ``gravity.g.<i>``,
``loads.<name>.force.<i> | torque``) or a coordinate of an *anchor* (a fixed point that no
link, slider or driver uses: only springs and loads act there), every variant has the base
scene's kinematics. Stage 1 is solved once (per process); a batch of V variants is then one
force stage on a step axis of V x S rows (variant, step): the sweep tiled V times, each varied
number a column of per-row values (:class:`linkpipe.forces.constants.ForceConstants`), each
anchor's coordinate set in the tiled positions. The arithmetic per row is the one-by-one
run's (``tests/test_study.py`` checks every stored variable against one-by-one runs).

Before taking this path a study's extreme values of each parameter are parsed as a scene
(every check of a scene applies; the value must reach the scene unchanged); a moved anchor
gives each variant its own mechanism size (the length scale of its tolerances), as its own
scene would. A coordinate of a pivot (a fixed point the mechanism uses), a link's length
(``links.<name>.lengths.<first>-<second>``, the distance of its first two points), a side
length that places a further point of a plate (``links.<name>.lengths.<A>-<P>``) or a drawn
coordinate of a moving point takes the geometry path of :mod:`.pivots` (stage 1 too on all
variants at once, each variant's model constants as per-row values) where the scene and the
change allow it. Anything else runs variant by variant
(:func:`linkpipe.study.batch.solve_batch`), giving the same rows.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..forces.constants import ForceConstants
from ..model.build import mechanism_size
from ..pipeline import solve
from ..spine import finish

#: force tables and the keys of them the vectorised path varies: key -> ForceConstants field
FORCE_KEYS = {"springs": {"k": "spring_k", "free_length": "spring_free_length",
                          "preload": "spring_preload", "damping": "spring_damping",
                          "force_extended": "gas_force_extended",
                          "extended_length": "gas_extended_length",
                          "dead_length": "gas_dead_length", "gamma": "gas_gamma"},
              "torsion_springs": {"k": "torsion_k", "free_angle": "torsion_free_angle"},
              "masses": {"mass": "mass", "inertia": "inertia"},
              "gravity": {"g": "gravity"}, "loads": {"force": "load_force", "torque": "load_torque"}}
_BASE: dict = {}  # study fingerprint -> the base Result (stage 1 solved once per process)
#: the slots of the geometry path (:mod:`.pivots`): a pivot, a frame length, a plate's side
#: length, a drawn coordinate of a moving point
GEOMETRY = ("pivot", "length", "side", "drawn")
#: the slots whose variants' model rows are built again (:func:`linkpipe.model.rows.variant_rows`)
REBUILT = ("length", "side", "drawn")


def slot_of(scene, path: tuple):
    """``(field, index...)`` of a parameter's place in :class:`ForceConstants` (``("point",
    p, axis)`` for a point's coordinate (:func:`.paths.plan` tells anchors, pivots and moving points
    apart); ``("length", link)`` for the distance of a link's first two points, its frame;
    ``("side", link, key)`` for a side length that places a further point of a plate:
    :mod:`.pivots`), or None when it is not a force number."""
    table = path[0]
    if table == "points" and len(path) == 3 and path[2] in ("x", "y"):
        return ("point", scene.point_names.index(path[1]), "xy".index(path[2]))
    if table == "links" and len(path) == 4 and path[2] == "lengths":
        link = scene.links[path[1]]
        frame = {f"{link.points[0]}-{link.points[1]}", f"{link.points[1]}-{link.points[0]}"}
        if path[3] in frame:
            return ("length", link.name)
        if any(key == path[3] for key, _ in link.distances.values()):  # a plate's side length
            return ("side", link.name, path[3])
        return None
    keys = FORCE_KEYS.get(table, {})
    if table == "gravity" and len(path) == 3 and path[1] == "g":
        return ("gravity", path[2])
    if len(path) < 3 or path[2] not in keys:
        return None
    return (keys[path[2]],) + tuple(path[1:2]) + tuple(path[3:])


def base_result(study):
    """The base scene's Result, solved once per process (the kinematics every variant shares)."""
    if study.fingerprint not in _BASE:
        _BASE.clear()
        _BASE[study.fingerprint] = solve(study.scene)
    return _BASE[study.fingerprint]


def per_row_constants(study, model, slots, values: np.ndarray, S: int) -> dict:
    """{ForceConstants field: per-row values (V x S rows, ...)} of variants with parameter
    ``values`` (V, n_parameters): the scene's constants tiled, each varied number a column;
    a moved point (anchor or pivot) sets the rows' drawn positions and their own sizes."""
    V = values.shape[0]
    constants = ForceConstants.of(model)
    per_row = {f.name: np.array(np.broadcast_to(getattr(constants, f.name),
                                                (V * S,) + getattr(constants, f.name).shape))
               for f in dataclasses.fields(ForceConstants)
               if f.name not in ("size", "pivots", "model_rows")}
    for j, (field, *index) in enumerate(slots):
        if field in ("length", "side"):  # a constant of the model's rows (:mod:`.pivots`)
            continue
        if field == "point":  # an anchor: where it is drawn is where it is at the start
            per_row["start_assembled"][(slice(None),) + tuple(index)] = np.repeat(values[:, j], S)
        if field in ("point", "pivot", "drawn"):
            field = "start_position"
        per_row[field][(slice(None),) + tuple(index)] = np.repeat(values[:, j], S)
    if any(s[0] in ("point",) + GEOMETRY for s in slots):  # a moved point may widen the drawing
        per_row["size"] = np.repeat(mechanism_size(study.scene, per_row["start_position"][::S]), S)
    else:
        per_row["size"] = model.size
    return per_row


def variant_arrays(study, slots, lo: int, hi: int) -> tuple[np.ndarray, dict]:
    """``(status (V, S), {variable: (V, S, ...)})`` of variants ``lo .. hi - 1`` whose slots
    are force numbers and anchors: stage 1 tiled, the force stage on every row
    (:func:`linkpipe.spine.finish`)."""
    base = base_result(study)
    k, model = base.kinematics, base.model
    V, S = hi - lo, base.n_steps
    per_row = per_row_constants(study, model, slots, study.values[lo:hi], S)
    X = np.tile(k.sweep.position, (V, 1, 1))
    for field, p, axis in (s for s in slots if s[0] == "point"):
        X[:, p, axis] = per_row["start_position"][:, p, axis]
    result = finish(study.scene, model, k.tiled(V, X), ForceConstants(**per_row))
    out = {v.name: v.data.reshape((V, S) + v.data.shape[1:]) for v in result.variables()
           if v.dims[:1] == ("step",)}
    return out["status"], out
