"""The references errors are measured against: closed forms where the scene is a four-bar or
slider-crank, else the tightest setting with extended checks (refined by one more Newton step)."""
from __future__ import annotations

import dataclasses as dc
import math
from dataclasses import dataclass

import numpy as np

from .. import closed_forms
from .. import kinematics as kin
from ..pipeline import solve
from ..status import OK
from ..scene import Scene
from .knobs import EXACT_SIGN_SCALE, REFERENCE_SOLVER, _all_orders, _with_solver, _with_steps
from .rows import BRANCH_FRACTION, QUANTITIES, Row


@dataclass
class Reference:
    """Reference values at one sweep's driver values (arrays step axis first, NaN = none)."""

    values: dict  # quantity -> array or None
    size: float


def _extended(scene: Scene, steps: int, base_steps: int):
    """Return the extended-checks reference Result at ``steps`` steps, and refinement info.

    Coarser sweeps than the scene's are solved on a grid ``k`` times finer (so continuation is
    as safe as the scene's own) and sampled at every k-th step.
    """
    k = max(1, math.ceil((base_steps - 1) / max(steps - 1, 1))) if steps > 1 else 1
    fine = _with_steps(scene, (steps - 1) * k + 1) if steps > 1 else scene
    ref = solve(_with_solver(_all_orders(fine), **REFERENCE_SOLVER))
    moved = math.nan
    # refinement: one more Newton step everywhere, kept where it lowers the residual
    model = ref.model
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    ok = ref.status == OK
    if ok.any():
        q = model.q_of(ref.position[ok])
        q2, res2, _, _ = kin.newton(model, q, s[ok], 0.0, 1, "analytic")
        better = res2 <= ref.residual[ok]
        q2 = np.where(better[:, None], q2, q)
        moved = float(np.abs(q2 - q).max()) if q.size else 0.0
        X = ref.position.copy()
        X[ok] = model.positions(q2)
        X[:, model.fixed] = model.start_position[model.fixed]
        der = kin.dense_derivatives(model, np.where(np.isfinite(X), X, 0.0), s, s_dot, s_ddot,
                              ref.status, True)
        good = (der["status"] == OK)[:, None, None]
        ref = dc.replace(ref, position=X,
                         velocity=np.where(good, der["velocity"], np.nan),
                         acceleration=np.where(good, der["acceleration"], np.nan))
    if k > 1:
        n_fine = ref.n_steps
        pick = np.arange(0, n_fine, k)

        def sample(a):
            return a[pick] if isinstance(a, np.ndarray) and a.ndim and a.shape[0] == n_fine else a

        sampled = {name: sample(getattr(ref, name))
                   for name in ("position", "velocity", "acceleration", "driver_value", "status")}
        if ref.forces:
            sampled["forces"] = {n: (d, sample(a), u) for n, (d, a, u) in ref.forces.items()}
        ref = dc.replace(ref, **sampled)
    return ref, moved


def _input_force(result):
    if not result.forces or "input_force" not in result.forces:
        return None
    return result.forces["input_force"][1]


class References:
    """Reference values per step count (closed form where the scene has one, else extended)."""

    def __init__(self, scene: Scene):
        self.scene = _all_orders(scene)
        self.base_steps = scene.n_steps
        self.has_forces = bool(scene.effects)
        self._cache: dict[int, Reference] = {}
        self.checks: dict[str, float] = {}
        ext, moved = _extended(self.scene, self.base_steps, self.base_steps)
        self.checks["refinement_moved"] = moved
        self.size = float(ext.model.size)
        self.form = closed_forms.detect(self.scene, ext.position[0]) if (
            ext.status[0] == OK) else None
        self.kind = "extended checks (tol 1e-15, analytic Jacobian, linear derivatives, " \
                    "second-order predictor, one Newton refinement step)"
        if self.form is not None:
            X, V, A = self._closed(self.scene)
            ok = ext.status == OK
            dev = {}
            for name, cf, ex in (("position", X, ext.position), ("velocity", V, ext.velocity),
                                 ("acceleration", A, ext.acceleration)):
                scale = self.size if name == "position" else max(
                    np.nanmax(np.linalg.norm(cf[ok], axis=-1)), np.finfo(float).tiny)
                dev[name] = float(np.nanmax(np.linalg.norm(cf[ok] - ex[ok], axis=-1)) / scale)
                self.checks[f"extended_vs_closed_form_{name}"] = dev[name]
            if not max(dev.values()) < 1e-9:  # not the mechanism the formulas describe
                self.checks["closed_form_rejected"] = 1.0
                self.form = None
        if self.form is not None:
            forces = " (input force: extended checks)" if self.has_forces else ""
            self.kind = self.form.description + forces
        self._cache[self.base_steps] = self._build(self.scene, ext)

    def _closed(self, scene: Scene):
        from ..model import build_model

        _, s, s_dot, s_ddot = kin.driver_motion(build_model(scene))
        return closed_forms.evaluate(self.form, scene, s[:, 0], s_dot[:, 0], s_ddot[:, 0])

    def _build(self, scene: Scene, ext) -> Reference:
        values = {"position": ext.position, "velocity": ext.velocity,
                  "acceleration": ext.acceleration,
                  "input_force": _input_force(ext) if self.has_forces else None,
                  "friction_speed": _friction_speed(ext)}
        if self.form is not None:
            X, V, A = self._closed(scene)
            values.update(position=X, velocity=V, acceleration=A)
        ok = ext.status == OK
        for name in ("position", "velocity", "acceleration"):
            values[name] = np.where(ok[:, None, None], values[name], np.nan)
        return Reference(values, self.size)

    def exact_sign(self, steps: int) -> Reference:
        """The reference at ``steps`` steps with friction's exact sign law (the regularisation
        scale at :data:`.knobs.EXACT_SIGN_SCALE`): what ``friction_velocity_scale`` rows are
        measured against."""
        key = ("exact_sign", steps)
        if key not in self._cache:
            variant = _with_solver(_with_steps(self.scene, steps),
                                   friction_velocity_scale=EXACT_SIGN_SCALE)
            ext, _ = _extended(variant, steps, self.base_steps)
            self._cache[key] = self._build(variant, ext)
        return self._cache[key]

    def at(self, steps: int) -> Reference:
        if steps not in self._cache:
            variant = _with_steps(self.scene, steps)
            ext, _ = _extended(variant, steps, self.base_steps)
            self._cache[steps] = self._build(variant, ext)
        return self._cache[steps]


def _scales(ref: Reference, force_units: list[str] | None = None) -> dict:
    """The scale each quantity's relative error divides by: the mechanism's size for
    positions, the largest reference magnitude over the sweep for the others (1 where that
    is 0; NaN where nothing is measured).

    The input force is scaled by unit: each driver by the largest reference magnitude among
    the drivers of its own unit (``force_units``, each driver's: :func:`input_force_units`;
    None: one unit), in ``input_force_per_driver`` (nd,). With one unit that is the one
    ``input_force`` scale, as before; where the units differ (a crank's torque beside a
    cylinder's force) ``input_force`` is NaN: no one number scales them both."""
    out: dict = {"position": ref.size}
    for q in ("velocity", "acceleration", "input_force"):
        v = ref.values.get(q)
        if v is None or not np.isfinite(v).any():
            out[q] = math.nan
            continue
        if q == "input_force":
            out.update(_force_scales(np.abs(v), force_units))
            continue
        m = float(np.nanmax(np.linalg.norm(v, axis=-1)))
        out[q] = m if m > 0 else 1.0
    return out


def _force_scales(magnitude: np.ndarray, units: list[str] | None) -> dict:
    """``input_force`` and ``input_force_per_driver`` of :func:`_scales` from the reference's
    |input force| (S, nd)."""
    nd = magnitude.shape[1]
    units = list(units) if units is not None else [""] * nd
    largest = np.where(np.isfinite(magnitude), magnitude, -np.inf).max(axis=0)  # (nd,)
    per_driver = np.full(nd, math.nan)
    for unit in set(units):
        group = [j for j in range(nd) if units[j] == unit]
        m = float(largest[group].max())
        if np.isfinite(m):
            per_driver[group] = m if m > 0 else 1.0
    one = len(set(units)) == 1
    return {"input_force": float(np.nanmax(per_driver)) if one else math.nan,
            "input_force_per_driver": per_driver}


def _measure_errors(row: Row, result, ref: Reference, scales: dict[str, float]) -> None:
    """Fill ``row``'s errors, failed steps and branch flag from ``result`` against ``ref``."""
    got = {"position": result.position, "velocity": result.velocity,
           "acceleration": result.acceleration, "input_force": _input_force(result)}
    failed = np.zeros(result.n_steps, dtype=bool)
    pos_ref = ref.values["position"]
    both = np.isfinite(pos_ref).all(axis=(1, 2)) & np.isfinite(result.position).all(axis=(1, 2))
    if both.any():
        per_step = np.linalg.norm(result.position[both] - pos_ref[both], axis=-1).max(axis=1)
        row.branch_kept = bool((per_step < BRANCH_FRACTION * ref.size).all())
    for q in QUANTITIES:
        a, b = got[q], ref.values.get(q)
        if b is None:
            continue
        want = np.isfinite(b).reshape(b.shape[0], -1).all(axis=1)
        if a is None:
            continue
        have = np.isfinite(a).reshape(a.shape[0], -1).all(axis=1)
        failed |= want & ~have
        both = want & have  # whole steps only: a failed step's fixed points say nothing
        if not both.any():
            continue
        if q == "input_force":  # each driver against its own unit's scale (_scales)
            per_driver = np.abs(a - b)[both].max(axis=0)  # (nd,)
            relative = per_driver / scales["input_force_per_driver"]
            row.error[q] = float(per_driver.max()) if np.isfinite(scales[q]) else math.nan
            row.relative_error[q] = (float(np.nanmax(relative)) if np.isfinite(relative).any()
                                     else math.nan)
            continue
        err = float(np.linalg.norm(a - b, axis=-1)[both].max())
        row.error[q] = err
        row.relative_error[q] = err / scales[q] if np.isfinite(scales[q]) else math.nan
    row.steps_failed = int(failed.sum())


def _friction_speed(result):
    """(S, n_friction) each friction's relative speed |power| / force (0 where it has no
    force: at rest), or None without friction."""
    forces = result.forces or {}
    if "friction_force" not in forces:
        return None
    force, power = forces["friction_force"][1], forces["friction_power"][1]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(force > 0, np.abs(power) / force, 0.0)


#: a step is near rest where some friction's relative speed is below this part of its largest
#: over the sweep (the reference's: the exact sign law's), else away from rest; below
#: AT_REST (rounding) it is at rest, where the exact law has no value: not compared
NEAR_REST, AT_REST = 1e-2, 1e-12


def friction_errors(row: Row, result, ref: Reference, scales: dict[str, float]) -> None:
    """A ``friction_velocity_scale`` row's input-force error against the exact sign law split
    in two: ``relative_error_away`` at steps away from rest, ``relative_error_near`` at steps
    near it (:data:`NEAR_REST`; each relative to the largest reference input force), also said
    in its note; the row's own input force error then leaves out the steps at rest, where the
    exact law has no value (static friction may be anything up to its limit there)."""
    speed = ref.values.get("friction_speed")
    a, b = _input_force(result), ref.values.get("input_force")
    if speed is None or a is None or b is None:
        return
    top = np.nanmax(speed, axis=0, initial=0.0)
    rest = (speed <= AT_REST * top).any(axis=1)
    near = (speed < NEAR_REST * top).any(axis=1) & ~rest
    scale = scales["input_force_per_driver"]
    for name, steps in (("away", ~near & ~rest), ("near", near)):
        both = steps & np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        if both.any():
            setattr(row, f"relative_error_{name}", float(np.nanmax(
                np.abs(a - b)[both].max(axis=0) / scale)))
    compared = ~rest & np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    if compared.any():  # the row's input force error: over the steps the exact law defines
        per_driver = np.abs(a - b)[compared].max(axis=0)
        row.error["input_force"] = float(per_driver.max())
        row.relative_error["input_force"] = float(np.nanmax(per_driver / scale))
    row.note = "; ".join(x for x in (row.note, f"vs exact sign: {row.relative_error_away:.1e} "
                                     f"away from rest, {row.relative_error_near:.1e} near it "
                                     f"({int(near.sum())} steps; {int(rest.sum())} at rest "
                                     "not compared)") if x)
