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

from ..errors import SceneError
from ..fit import scene_with
from ..forces import compute_forces
from ..forces.constants import ForceConstants
from ..model.build import mechanism_size
from ..pipeline import solve, status_of
from ..result import Motion
from ..output_units import units_of
from . import pivots

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


def slot_of(scene, path: tuple):
    """``(field, index...)`` of a parameter's place in :class:`ForceConstants` (``("point",
    p, axis)`` for a point's coordinate (:func:`plan` tells anchors, pivots and moving points
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


def _scene_value(scene, slot) -> float:
    """The parsed scene's number at ``slot`` (to check that a value reaches it unchanged)."""
    field, *index = slot
    if field == "length":
        return next(link.length for link in scene.links if link.name == index[0])
    if field == "side":
        link = next(link for link in scene.links if link.name == index[0])
        return next(d for key, d in link.distances.values() if key == index[1])
    if field in ("point", "pivot", "drawn"):
        p = scene.points[index[0]]
        return p.x if index[1] == 0 else p.y
    if field == "gravity":
        return scene.gravity[index[0]]
    table, key = next((t, k) for t, keys in FORCE_KEYS.items() for k, f in keys.items() if f == field)
    value = getattr(getattr(scene, table)[index[0]], key)
    return value[index[1]] if len(index) > 1 else value


def _anchor_reason(scene, point: int) -> str:
    name = scene.point_names[point]
    if not scene.points[point].fixed:
        return f"{name} moves"
    used = {p for l in scene.links for p in l.points}
    used |= {p for s in scene.sliders for p in (s.point, *(s.line_points or ()))}
    for d in scene.drivers:
        used |= set(d.points) | set(d.relative_to or ()) | ({d.input.point} if d.input else set())
    return f"{name} is a point of the mechanism" if name in used else ""


def plan(study) -> tuple[list | None, str]:
    """``(slots, "")`` when the study can take the vectorised path, else ``(None, why not)``."""
    scene = study.scene
    if scene.measurements or scene.time is not None:
        return None, "the scene has measurements or a [time] table"
    if scene.dynamics is not None:
        return None, "the scene has [dynamics]: each variant's motion is integrated on its own"
    slots = []
    for j, p in enumerate(study.parameters):
        slot = slot_of(scene, p.path)
        if slot is None:
            return None, (f"{p.address} is not one of the force numbers this path varies"
                          if p.path[0] in FORCE_KEYS else f"{p.address} changes the kinematics")
        why = _anchor_reason(scene, slot[1]) if slot[0] == "point" else ""
        if why.endswith("moves"):  # a drawn coordinate of a moving point
            slot, why = ("drawn",) + slot[1:], ""
        elif why:  # a pivot: the mechanism's own fixed point
            slot = ("pivot",) + slot[1:]
        for value in (study.values[:, j].min(), study.values[:, j].max()):
            try:
                trial = scene_with(scene, study.data, [p], [value])
            except SceneError as exc:
                if slot[0] in pivots.REBUILT and not pivots.passes_checks(study, slot, value):
                    continue  # the placement's own checks refuse it too: that variant's own run
                return None, f"{p.address} = {value:g} fails the scene's checks ({exc.message})"
            if _scene_value(trial, slot) != value:
                return None, f"{p.address}: the scene does not take the value as written"
            try:  # the trial's model has checks of its own (a far point beyond its frame)
                changed = pivots.changed_constants(study, trial) if why else ""
                unlike = (pivots.unlike_own_model(study, trial, slot, value)
                          if slot[0] in pivots.REBUILT else "")
            except SceneError as exc:
                if slot[0] in pivots.REBUILT and not pivots.passes_checks(study, slot, value):
                    continue  # variant_rows refuses it too: that variant's own run
                return None, f"{p.address} = {value:g} fails the model's checks ({exc.message})"
            if changed:
                return None, f"{p.address}: {why} and {changed}"
            if unlike:
                return None, f"{p.address}: {unlike}"
        slots.append(slot)
    moved = any(s[0] in pivots.GEOMETRY for s in slots)
    why = pivots.path_reason(study) if moved else "" if scene.effects else "the scene has no forces"
    return (None, why) if why else (slots, "")


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
    if any(s[0] in ("point",) + pivots.GEOMETRY for s in slots):  # a moved point may widen the drawing
        per_row["size"] = np.repeat(mechanism_size(study.scene, per_row["start_position"][::S]), S)
    else:
        per_row["size"] = model.size
    return per_row


def variant_arrays(study, slots, lo: int, hi: int) -> tuple[np.ndarray, dict]:
    """``(status (V, S), {variable: (V, S, ...)})`` of variants ``lo .. hi - 1``: every
    step-first variable a one-by-one run stores. Overflow and 0/0 are data here, as in a
    scene's own run (:func:`linkpipe.solve`): statuses, not warnings."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return _variant_arrays(study, slots, lo, hi)


def _variant_arrays(study, slots, lo: int, hi: int) -> tuple[np.ndarray, dict]:
    if any(s[0] in pivots.GEOMETRY for s in slots):
        return pivots.variant_arrays(study, slots, lo, hi)
    base = base_result(study)
    k, model = base.kinematics, base.model
    V, S = hi - lo, base.n_steps

    def rows(a):
        return None if a is None else np.tile(a, (V,) + (1,) * (a.ndim - 1))

    per_row = per_row_constants(study, model, slots, study.values[lo:hi], S)
    X = rows(k.sweep.position)
    for field, p, axis in (s for s in slots if s[0] == "point"):
        X[:, p, axis] = per_row["start_position"][:, p, axis]
    motion = Motion(s=rows(k.s), s_dot=rows(k.s_dot), s_ddot=rows(k.s_ddot), position=X,
                    velocity=rows(k.velocity), acceleration=rows(k.acceleration),
                    status=rows(k.der["status"]), influence=rows(k.der["influence"]),
                    link_angular_acceleration=rows(k.link_rates[1]), link_angle=rows(k.link_angle))
    forces = compute_forces(model, motion, units_of(study.scene), ForceConstants(**per_row))
    status = status_of(model, motion.status, rows(k.sweep.residual),
                       [X, rows(k.link_angle), motion.velocity, motion.acceleration,
                        rows(k.link_rates[0]), motion.link_angular_acceleration], forces,
                       per_row["size"])
    stored = {v.name: v.data for v in base.variables() if v.dims[:1] == ("step",)}
    out = {name: rows(data) for name, data in stored.items()}
    out.update({name: data for name, (dims, data, _) in forces.variables.items()
                if dims[:1] == ("step",)})
    out["position"], out["status"] = X, status
    shaped = {name: a.reshape((V, S) + a.shape[1:]) for name, a in out.items()}
    return shaped["status"], shaped
