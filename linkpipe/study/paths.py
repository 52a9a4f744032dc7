"""Which path a study's variants take: the one place it is decided (:func:`plan`), and the
vectorised paths' entry (:func:`variant_arrays`).

A study whose parameters are force numbers or anchors takes :mod:`.vector` (stage 1 once, the
force stage on every variant's rows); one that moves pivots, changes link or side lengths or
draws moving points elsewhere takes :mod:`.pivots` where the scene and the change allow it
(the checks here: the model's rows as the variant's own scene builds them, the base on the
closed-form dyads, ...); anything else runs variant by variant (:mod:`.variants`), giving the
same rows. :mod:`.batch` asks this module.
"""
from __future__ import annotations

import numpy as np

from .. import kinematics as kin
from ..errors import SceneError
from ..fit import scene_with
from ..forces.applied import center_frame
from ..model.build import build_model
from ..model.rows import variant_rows
from . import pivots, vector
from .vector import FORCE_KEYS, GEOMETRY, REBUILT, slot_of


def variant_arrays(study, slots, lo: int, hi: int) -> tuple[np.ndarray, dict]:
    """``(status (V, S), {variable: (V, S, ...)})`` of variants ``lo .. hi - 1`` on the
    vectorised path :func:`plan` chose: every step-first variable a one-by-one run stores.
    Overflow and 0/0 are data here, as in a scene's own run (:func:`linkpipe.solve`):
    statuses, not warnings."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if any(s[0] in GEOMETRY for s in slots):
            return pivots.variant_arrays(study, slots, lo, hi)
        return vector.variant_arrays(study, slots, lo, hi)


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
                if slot[0] in REBUILT and not passes_checks(study, slot, value):
                    continue  # the placement's own checks refuse it too: that variant's own run
                return None, f"{p.address} = {value:g} fails the scene's checks ({exc.message})"
            if _scene_value(trial, slot) != value:
                return None, f"{p.address}: the scene does not take the value as written"
            try:  # the trial's model has checks of its own (a far point beyond its frame)
                changed = changed_constants(study, trial) if why else ""
                unlike = (unlike_own_model(study, trial, slot, value)
                          if slot[0] in REBUILT else "")
            except SceneError as exc:
                if slot[0] in REBUILT and not passes_checks(study, slot, value):
                    continue  # variant_rows refuses it too: that variant's own run
                return None, f"{p.address} = {value:g} fails the model's checks ({exc.message})"
            if changed:
                return None, f"{p.address}: {why} and {changed}"
            if unlike:
                return None, f"{p.address}: {unlike}"
        slots.append(slot)
    moved = any(s[0] in GEOMETRY for s in slots)
    why = path_reason(study) if moved else "" if scene.effects else "the scene has no forces"
    return (None, why) if why else (slots, "")


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


def passes_checks(study, slot, value: float) -> bool:
    """Whether the variant with one parameter (``slot``) at ``value`` passes the model's and
    the placement's checks as :func:`variant_rows` tells them (a study's extreme value that
    its own scene refuses must be refused here too, its variants then being their own runs)."""
    base = build_model(study.scene)
    _, ok = variant_rows(base, *pivots.rows_inputs(base, [slot], np.array([[float(value)]])))
    return bool(ok[0])


def unlike_own_model(study, trial, slot, value: float) -> str:
    """What of the model a trial scene (one parameter, ``slot``, at ``value``: a frame length,
    a side length or a drawn coordinate) builds otherwise than :func:`variant_rows` builds it
    for that value ("": nothing, the vectorised path applies)."""
    base, own = build_model(study.scene), build_model(trial)
    rows, _ = variant_rows(base, *pivots.rows_inputs(base, [slot], np.array([[float(value)]])))
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
    if (not kin.METHODS[scene.solver.method].branch_checked
            or scene.solver.derivatives == "finite_difference"):
        return 'pivots move: the vectorised path needs [solver] method = "auto" and analytic derivatives'
    base = vector.base_result(study)
    if base.solver_method_used != "dyads":
        return "pivots move and the base scene does not take the closed-form dyads"
    if base.reach_note:  # the variants' own runs start where each one's reach begins
        return "pivots move and the base scene's first steps are out of its drawing's reach"
    if any(st.ambiguous for st in pivots.base_chain(study).steps):
        return "pivots move and a dyad starts on its singular shape"
    if any(sp.kind != "gas" and sp.free_length is None for sp in scene.springs):
        return ("pivots move and a spring's start length (its preload's, or its free length) "
                "is each variant's own assembled drawing")
    return ""
