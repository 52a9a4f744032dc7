"""Measure what accuracy costs in time: one scene over a ladder of solver settings.

``python -m linkpipe accuracy configs/x.toml`` (issue 6). Each *row* of the ladder is the scene
with one ``[solver]`` knob (or the sweep's step count) changed, built with
``dataclasses.replace`` on the loaded :class:`~linkpipe.scene.Scene`. Per row:

* wall time, the median of ``repeats`` runs in this one process (so ratios between rows mean
  something): of the stage the knob acts on (``seconds``: positions, derivatives, or the whole
  kinematics for step counts) and of the whole :func:`~linkpipe.pipeline.solve`;
* the max error of position, velocity, acceleration and input force (when the scene has
  effects) against a reference at the same driver values, absolute (scene units) and relative
  (to the mechanism's size for positions, to the largest reference value otherwise);
* Newton iterations (mean, max), failed steps, and whether the assembly branch was kept.

The reference is a closed form (:mod:`linkpipe.closed_forms`) where the scene is a four-bar or
slider-crank, else the tightest setting with extended checks: tolerance 1e-15, analytic
Jacobian, linear derivatives, second-order predictor, then one more Newton step (refinement)
at every step. The input force always comes from that extended run (no closed form for
forces). Every row asks for velocities and accelerations, so all three kinematic orders are
measured even where the scene itself would not compute them.

The knobs ``tol``, ``max_iter``, ``jacobian``, ``derivatives`` and ``predictor`` are varied on
the general Newton path (``method = "newton"``): the closed-form dyads that ``method = "auto"``
takes where the scene decomposes do not iterate. The ``method`` rows compare the paths from the
scene's own settings; a ``dyads`` row the build cannot run says "not available". The Pareto
front (:meth:`Ladder.front`) is found among rows at the scene's own step count, over all paths
and over the Newton path alone.

numpy only: the files are written by :mod:`linkpipe.stores.accuracy`.
"""
from __future__ import annotations

import dataclasses as dc
import datetime
import gc
import math
import os
import pathlib
import platform
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import closed_forms
from . import kinematics as kin
from .pipeline import solve
from .errors import LinkpipeError
from .status import OK
from .result import Variable
from .scene import Scene, load_scene

QUANTITIES = ("position", "velocity", "acceleration", "input_force")
#: a step whose position is off by more than this fraction of the mechanism's size is on
#: another assembly branch (loose tolerances stay orders of magnitude below it)
BRANCH_FRACTION = 0.1
#: relative errors below this are reported as this (the floor of the log plots)
ERROR_FLOOR = 1e-17
#: the noise band of the Pareto front: times within 10 %, errors within a factor 2 are equal
TIME_NOISE, ERROR_NOISE = 0.10, 2.0

# The ladder. Step counts are multiples of the scene's own number of intervals.
FULL = dict(
    tol=(1e-2, 1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14),
    max_iter=(1, 2, 3, 5, 25),
    fd_steps=(0.25, 0.5, 1, 2, 4),
    predictor_steps=(1 / 16, 0.25, 1, 4),
)
QUICK = dict(
    tol=(1e-2, 1e-4, 1e-8, 1e-12, 1e-14),
    max_iter=(2, 25),
    fd_steps=(1, 2),
    predictor_steps=(0.25, 1),
)
#: the reference's settings (extended checks add one Newton refinement step)
REFERENCE_SOLVER = dict(tol=1e-15, max_iter=50, jacobian="analytic", derivatives="linear",
                        predictor="second", method="newton")


@dataclass
class Row:
    """One setting of the ladder and what it measured (errors NaN when not computed)."""

    knob: str
    value: str
    steps: int
    stage: str  # the stage ``seconds`` times: positions / derivatives / kinematics
    solver: dict
    available: bool = True
    note: str = ""
    failure: str = ""  # the exception that stopped this rung ("Type: message"); "" if none
    seconds: float = math.nan
    seconds_positions: float = math.nan
    seconds_derivatives: float = math.nan
    seconds_solve: float = math.nan
    error: dict = field(default_factory=lambda: {q: math.nan for q in QUANTITIES})
    relative_error: dict = field(default_factory=lambda: {q: math.nan for q in QUANTITIES})
    iterations_mean: float = math.nan
    iterations_max: int = -1
    steps_failed: int = 0
    branch_kept: bool = True
    #: finite-difference rows: log(e_prev / e) / log(h_prev / h) against the next coarser
    #: finite-difference row (h: the step in driver value), per quantity; NaN elsewhere
    observed_order: dict = field(default_factory=lambda: {q: math.nan for q in QUANTITIES})
    path: str = ""  # the path the solve took: "dyads" (closed form) or "newton"
    base: bool = False  # the scene's own settings
    newton_base: bool = False  # the scene's own settings on the general path (method newton)
    front: bool = False  # on the Pareto front (whole-solve time vs worst relative error)
    newton_front: bool = False  # on the front among the rows solved by the general path

    @property
    def label(self) -> str:
        if self.knob in ("tol", "max_iter", "jacobian", "method"):
            return f"{self.knob}={self.value}"
        return f"{self.knob}={self.value},steps={self.steps}"

    @property
    def worst_relative_error(self) -> float:
        vals = [v for v in self.relative_error.values() if np.isfinite(v)]
        return max(vals) if vals else math.nan

    @property
    def valid(self) -> bool:
        """Measured, every step solved, on the reference's branch: a usable setting."""
        return self.available and self.steps_failed == 0 and self.branch_kept and np.isfinite(
            self.seconds_solve)


@dataclass
class Ladder:
    """The rows of one scene's ladder and how they were measured."""

    scene: Scene
    rows: list[Row]
    reference: str
    quantities: tuple[str, ...]
    units: dict[str, str]
    scales: dict[str, float]
    checks: dict[str, float]
    repeats: int
    quick: bool
    created: str
    machine: str

    def front(self, quantity: str | None = None, path: str | None = None) -> list[Row]:
        """Return the rows on the Pareto front of whole-solve time against error.

        ``quantity`` None: the worst relative error over the measured quantities. Only valid
        rows (every step solved, branch kept) at the scene's own step count (the same output)
        compete, and with ``path`` only those solved by it ("newton": the general path, which
        scenes that do not decompose into dyads take); times within :attr:`time_noise` and
        errors within a factor 2 count as equal (the noise of the measurement).
        """
        def err(r):
            e = r.worst_relative_error if quantity is None else r.relative_error[quantity]
            return max(e, ERROR_FLOOR) if np.isfinite(e) else math.inf

        rows = [r for r in self.rows if r.valid and r.steps == self.scene.n_steps
                and (path is None or r.path == path)]
        noise = self.time_noise

        def dominates(a, b):
            t_le = a.seconds_solve <= b.seconds_solve * (1 + noise)
            e_le = err(a) <= err(b) * ERROR_NOISE
            t_lt = a.seconds_solve < b.seconds_solve * (1 - noise)
            e_lt = err(a) * ERROR_NOISE < err(b)
            return t_le and e_le and (t_lt or e_lt)

        return [r for r in rows if not any(dominates(o, r) for o in rows if o is not r)]

    @property
    def time_noise(self) -> float:
        """Return the relative timing noise: the spread of rows that repeat the same work.

        Several knobs' rows repeat one setting (on the general path: tol 1e-12, max_iter 25,
        analytic, linear, first; the scene's own settings for the method rows): the same work
        timed again. The largest (max - min) / min within such a group, and at least 10 %, is
        the band within which two times count as equal.
        """
        groups: dict = {}
        for r in self.rows:
            if r.available and np.isfinite(r.seconds_solve):
                key = (tuple(sorted(r.solver.items())), r.steps)
                groups.setdefault(key, []).append(r.seconds_solve)
        spread = max([(max(g) - min(g)) / min(g) for g in groups.values() if len(g) >= 2],
                     default=0.0)
        return max(TIME_NOISE, float(spread))

    def attributes(self) -> dict:
        from . import __version__

        attrs = {
            "linkpipe_version": __version__,
            "scene_name": self.scene.name,
            "scene_path": str(self.scene.path),
            "scene_toml": self.scene.text,
            "reference": self.reference,
            "repeats": self.repeats,
            "ladder": "quick" if self.quick else "full",
            "created": self.created,
            "machine": self.machine,
            "quantities": list(self.quantities),
            "timing": (f"median of {self.repeats} runs in one process; seconds: the stage the "
                       "knob acts on; seconds_solve: the whole solve"),
            "relative_error": ("position: max error / mechanism size; others: max error / "
                               "max |reference|"),
            "branch_fraction": BRANCH_FRACTION,
            "time_noise": self.time_noise,
        }
        for q, s in self.scales.items():
            attrs[f"scale_{q}"] = s
        for q, u in self.units.items():
            attrs[f"units_{q}"] = u
        for k, v in self.checks.items():
            attrs[f"check_{k}"] = v
        return attrs

    def variables(self) -> tuple[list[Variable], list[Variable]]:
        """Return (coordinates, data variables) in the netCDF layout: dims ``row``, ``quantity``."""
        rows = self.rows
        coords = [
            Variable("row", ("row",), np.array([r.label for r in rows], dtype=object), ""),
            Variable("quantity", ("quantity",), np.array(self.quantities, dtype=object), ""),
        ]

        def col(name, values, units="", **attrs):
            return Variable(name, ("row",), np.asarray(values), units, attrs)

        def strings(name, values, **attrs):
            return Variable(name, ("row",), np.array(values, dtype=object), "", attrs)

        flag = dict(flag_values=np.array([0, 1], dtype=np.int8), flag_meanings="false true")
        data = [
            strings("knob", [r.knob for r in rows], long_name="the setting varied in this row"),
            strings("value", [r.value for r in rows]),
            col("steps", [r.steps for r in rows], "1", long_name="sweep steps"),
            strings("stage", [r.stage for r in rows], long_name="the stage `seconds` times"),
        ]
        for key in ("tol", "max_iter"):
            data.append(col(f"solver_{key}", [r.solver[key] for r in rows], "1"))
        for key in ("jacobian", "derivatives", "predictor", "method"):
            data.append(strings(f"solver_{key}", [r.solver[key] for r in rows]))
        data += [
            col("available", np.array([r.available for r in rows], dtype=np.int8), "1", **flag),
            strings("note", [r.note for r in rows]),
            strings("failure", [r.failure for r in rows]),
            col("seconds", [r.seconds for r in rows], "s",
                long_name=f"median wall time of the knob's stage over {self.repeats} runs"),
            col("seconds_positions", [r.seconds_positions for r in rows], "s"),
            col("seconds_derivatives", [r.seconds_derivatives for r in rows], "s"),
            col("seconds_solve", [r.seconds_solve for r in rows], "s",
                long_name=f"median wall time of the whole solve over {self.repeats} runs"),
            Variable("error", ("row", "quantity"),
                     np.array([[r.error[q] for q in self.quantities] for r in rows], float).reshape(
                         len(rows), len(self.quantities)),
                     ",".join(self.units[q] for q in self.quantities),
                     {"long_name": "max abs error against the reference (units per quantity)",
                      "quantity_units": [self.units[q] for q in self.quantities]}),
            Variable("relative_error", ("row", "quantity"),
                     np.array([[r.relative_error[q] for q in self.quantities] for r in rows],
                              float).reshape(len(rows), len(self.quantities)), "1",
                     {"long_name": "error / scale (position: mechanism size; others: max |ref|)"}),
            Variable("observed_order", ("row", "quantity"),
                     np.array([[r.observed_order[q] for q in self.quantities] for r in rows],
                              float).reshape(len(rows), len(self.quantities)), "1",
                     {"long_name": "finite-difference rows: order of convergence against the "
                                   "next coarser finite-difference row"}),
            col("iterations_mean", [r.iterations_mean for r in rows], "1",
                long_name="Newton iterations per step, mean"),
            col("iterations_max", np.array([r.iterations_max for r in rows], dtype=np.int32), "1"),
            col("steps_failed", np.array([r.steps_failed for r in rows], dtype=np.int32), "1",
                long_name="steps the reference solves that this row does not"),
            col("branch_kept", np.array([r.branch_kept for r in rows], dtype=np.int8), "1", **flag),
            strings("path", [r.path for r in rows],
                    long_name="the path the solve took: dyads (closed form) or newton"),
            col("base", np.array([r.base for r in rows], dtype=np.int8), "1",
                long_name="the scene's own solver settings", **flag),
            col("newton_base", np.array([r.newton_base for r in rows], dtype=np.int8), "1",
                long_name="the scene's own solver settings with method = newton", **flag),
            col("pareto_front", np.array([r.front for r in rows], dtype=np.int8), "1",
                long_name="on the Pareto front of seconds_solve vs worst relative error", **flag),
            col("newton_pareto_front", np.array([r.newton_front for r in rows], dtype=np.int8),
                "1", long_name="on the Pareto front among the rows solved by the Newton path",
                **flag),
        ]
        return coords, data


# ----------------------------------------------------------------------------- the ladder
def _with_solver(scene: Scene, **changes) -> Scene:
    return dc.replace(scene, solver=dc.replace(scene.solver, **changes))


def _with_steps(scene: Scene, steps: int) -> Scene:
    """Return ``scene`` swept over the same range with ``steps`` steps."""
    drivers = []
    for d in scene.drivers:
        to = d.to_value if d.step is None else d.from_value + (d.steps - 1) * d.step
        drivers.append(dc.replace(d, steps=steps, step=None, to_value=to))
    return dc.replace(scene, drivers=tuple(drivers))


def _all_orders(scene: Scene) -> Scene:
    """Return ``scene`` asking for velocities and accelerations (so every order is measured)."""
    return dc.replace(scene, outputs=dc.replace(scene.outputs,
                                                kinematics=("velocity", "acceleration")))


KNOBS = ("tol", "max_iter", "jacobian", "derivatives", "predictor", "method")


def settings(scene: Scene, quick: bool = False, knobs=KNOBS) -> list[tuple[str, str, Scene, str]]:
    """Return the ladder's rows as (knob, value, scene variant, timed stage).

    ``knobs``: which of :data:`KNOBS` to include (all by default).
    """
    unknown = set(knobs) - set(KNOBS)
    if unknown:
        raise ValueError(f"unknown knob(s) {sorted(unknown)}; choose from {KNOBS}")
    ladder = QUICK if quick else FULL
    base = _all_orders(scene)
    # the Newton knobs measure the general path (method = "auto" may take closed-form dyads,
    # which have no tolerance, iterations, Jacobian or predictor)
    newton = _with_solver(base, method="newton")
    out = []
    if "tol" in knobs:
        for tol in ladder["tol"]:
            out.append(("tol", f"{tol:.0e}", _with_solver(newton, tol=tol), "positions"))
    if "max_iter" in knobs:
        for n in ladder["max_iter"]:
            out.append(("max_iter", str(n), _with_solver(newton, max_iter=n), "positions"))
    if "jacobian" in knobs:
        for jac in ("analytic", "finite_difference"):
            out.append(("jacobian", jac, _with_solver(newton, jacobian=jac), "positions"))
    m = scene.n_steps - 1
    if m >= 2 and "derivatives" in knobs:
        out.append(("derivatives", "linear", _with_solver(newton, derivatives="linear"),
                    "derivatives"))
        fd = _with_solver(newton, derivatives="finite_difference")
        for n in _intervals(m, ladder["fd_steps"]):
            out.append(("derivatives", "finite_difference", _with_steps(fd, n + 1),
                        "derivatives"))
    if m >= 2 and "predictor" in knobs:
        for n in _intervals(m, ladder["predictor_steps"]):
            for pred in ("none", "first", "second"):
                out.append(("predictor", pred, _with_steps(_with_solver(newton, predictor=pred),
                                                           n + 1), "kinematics"))
    if "method" in knobs:
        for method in ("auto", "newton", "dyads"):
            out.append(("method", method, _with_solver(base, method=method), "kinematics"))
    return out


def _intervals(m: int, factors) -> list[int]:
    """Return the distinct interval counts ``round(m * f)`` (at least 2), in order."""
    seen = []
    for f in factors:
        n = max(2, int(round(m * f)))
        if n not in seen:
            seen.append(n)
    return seen


# ----------------------------------------------------------------------------- timing
def _timed(fn, repeats: int):
    """Return (last value, median seconds) of ``repeats`` calls, garbage collector paused."""
    times = []
    value = None
    for _ in range(max(1, repeats)):
        gc.collect()
        was = gc.isenabled()
        gc.disable()
        try:
            t0 = time.perf_counter()
            value = fn()
            times.append(time.perf_counter() - t0)
        finally:
            if was:
                gc.enable()
    return value, float(np.median(times))


_NOT_KINEMATIC = {"model", "positions", "forces", "hdf5", "rrd", "fd_derivatives"}


def _stage_seconds(med: dict, finite_difference: bool) -> tuple[float, float]:
    """Return (positions, derivatives) seconds from the pipeline's per-stage medians.

    Derivatives: the linear solves' stage(s) (``jacobian``...), or for finite differences
    along the sweep the ``fd_derivatives`` stage alone (the pipeline still runs the linear
    stage for the step status and the force stage's inverse: that is not the shortcut's cost).
    On the dyad path the closed-form derivatives are part of ``positions``.
    """
    pos = med.get("positions", math.nan)
    if finite_difference and "fd_derivatives" in med:
        return pos, med["fd_derivatives"]
    return pos, sum(v for k, v in med.items() if k not in _NOT_KINEMATIC)


# ----------------------------------------------------------------------------- references
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
        from .model import build_model

        _, s, s_dot, s_ddot = kin.driver_motion(build_model(scene))
        return closed_forms.evaluate(self.form, scene, s[:, 0], s_dot[:, 0], s_ddot[:, 0])

    def _build(self, scene: Scene, ext) -> Reference:
        values = {"position": ext.position, "velocity": ext.velocity,
                  "acceleration": ext.acceleration,
                  "input_force": _input_force(ext) if self.has_forces else None}
        if self.form is not None:
            X, V, A = self._closed(scene)
            values.update(position=X, velocity=V, acceleration=A)
        ok = ext.status == OK
        for name in ("position", "velocity", "acceleration"):
            values[name] = np.where(ok[:, None, None], values[name], np.nan)
        return Reference(values, self.size)

    def at(self, steps: int) -> Reference:
        if steps not in self._cache:
            variant = _with_steps(self.scene, steps)
            ext, _ = _extended(variant, steps, self.base_steps)
            self._cache[steps] = self._build(variant, ext)
        return self._cache[steps]


def _scales(ref: Reference) -> dict[str, float]:
    out = {"position": ref.size}
    for q in ("velocity", "acceleration", "input_force"):
        v = ref.values.get(q)
        if v is None or not np.isfinite(v).any():
            out[q] = math.nan
            continue
        mag = np.abs(v) if q == "input_force" else np.linalg.norm(v, axis=-1)
        m = float(np.nanmax(mag))
        out[q] = m if m > 0 else 1.0
    return out


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
        diff = np.abs(a - b) if q == "input_force" else np.linalg.norm(a - b, axis=-1)
        err = float(diff[both].max())
        row.error[q] = err
        row.relative_error[q] = err / scales[q] if np.isfinite(scales[q]) else math.nan
    row.steps_failed = int(failed.sum())


# ----------------------------------------------------------------------------- fast path probe
def method_available(result, method: str) -> tuple[bool, str]:
    """Return whether ``result`` was solved by ``method``, and a note on the path it took.

    ``result.solver_method_used`` says which path ran ("dyads" or "newton"); a build without
    it has no fast path, so ``dyads`` is not available there.
    """
    used = str(getattr(result, "solver_method_used", "") or "")
    if method == "dyads" and used != "dyads":
        return False, ("not available: " + (f"solved by {used}" if used
                                            else "no dyads fast path in this build"))
    if method == "auto" and used:
        return True, f"auto took {used}"
    return True, ""


# ----------------------------------------------------------------------------- measuring
def _machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (f"{cpu}, {cores} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, numpy {np.__version__}")


def measure(scene: Scene | str, quick: bool = False, repeats: int = 5, echo=None,
            knobs=KNOBS) -> Ladder:
    """Run ``scene`` over the ladder and return the measured :class:`Ladder`.

    The repeats go round-robin over the rows (run 1 of every row, then run 2, ...), so that a
    burst of background load on the machine spreads over all rows instead of skewing one.
    ``echo``: optional callable given a short progress line now and then. ``knobs``: a subset
    of :data:`KNOBS` to measure (all by default).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    tell = echo if callable(echo) else (lambda line: None)
    repeats = max(1, int(repeats))
    with np.errstate(invalid="ignore", divide="ignore"):  # loose rows fail steps on purpose
        return _measure(scene, quick, repeats, tell, tuple(knobs))


def _measure(scene: Scene, quick: bool, repeats: int, tell, knobs) -> Ladder:
    refs = References(scene)
    scales = _scales(refs.at(scene.n_steps))
    quantities = ("position", "velocity", "acceleration") + (
        ("input_force",) if refs.has_forces else ())
    base_solver = dc.asdict(scene.solver)
    newton_solver = dict(base_solver, method="newton")
    rows: list[Row] = []
    runs = []  # (row, variant, [wall seconds], [stage seconds dicts], [last result])
    for knob, value, variant, stage in settings(scene, quick, knobs):
        row = Row(knob, value, variant.n_steps, stage, dc.asdict(variant.solver))
        same_steps = variant.n_steps == scene.n_steps
        row.base = row.solver == base_solver and same_steps
        row.newton_base = row.solver == newton_solver and same_steps
        rows.append(row)
        try:  # the first run: does the knob run at all (and warms up its code paths)
            result, first = _timed(lambda: solve(variant), 1)
        except LinkpipeError as exc:  # the scene cannot take this setting: a row that says so
            row.available, row.base = False, False
            row.note = f"not available: {exc}"[:200]
            tell(f"  {row.label}: {row.note}")
            continue
        except Exception as exc:  # noqa: BLE001 - a crashed rung: a row with its error, and
            row.available, row.base = False, False  # the command's exit status says so
            row.failure = f"{type(exc).__name__}: {exc}"[:300]
            row.note = f"FAILED: {row.failure}"
            tell(f"  {row.label}: {row.note}")
            continue
        row.path = str(getattr(result, "solver_method_used", "") or "newton")
        if knob == "method":
            row.available, row.note = method_available(result, value)
            if not row.available:
                row.base = row.newton_base = False
                tell(f"  {row.label}: {row.note}")
                continue
        # the full ladder discards the first run as a warm-up; the quick one counts it
        runs.append((row, variant, [] if not quick else [first],
                     [] if not quick else [dict(result.seconds)], [result]))
    tell(f"  {len(runs)} settings x {repeats} runs, round-robin")
    for _ in range(repeats - 1 if quick else repeats):
        for row, variant, walls, stages, last in runs:
            result, wall = _timed(lambda: solve(variant), 1)
            walls.append(wall)
            stages.append(dict(result.seconds))
            last[0] = result
    for row, variant, walls, stages, last in runs:
        result = last[0]
        row.seconds_solve = float(np.median(walls))
        keys = set().union(*stages)
        med = {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in keys}
        row.seconds_positions, row.seconds_derivatives = _stage_seconds(
            med, row.solver["derivatives"] == "finite_difference")
        row.seconds = {"positions": row.seconds_positions,
                       "derivatives": row.seconds_derivatives,
                       "kinematics": row.seconds_positions + row.seconds_derivatives}[row.stage]
        it = np.asarray(result.iterations)
        row.iterations_mean = float(it.mean()) if it.size else 0.0
        row.iterations_max = int(it.max()) if it.size else 0
        _measure_errors(row, result, refs.at(variant.n_steps), scales)
        if result.n_ok < result.n_steps:
            row.note = "; ".join(x for x in (row.note, result.message) if x)
    ladder = Ladder(scene=scene, rows=rows, reference=refs.kind, quantities=quantities,
                    units=_units(scene), scales=scales, checks=refs.checks, repeats=repeats,
                    quick=quick,
                    created=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                    machine=_machine())
    for r in ladder.front():
        r.front = True
    for r in ladder.front(path="newton"):
        r.newton_front = True
    _observed_orders(rows)
    return ladder


def _observed_orders(rows: list[Row]) -> None:
    """Set each finite-difference row's order of convergence against the next coarser one."""
    fd = sorted((r for r in rows if r.knob == "derivatives" and r.value == "finite_difference"
                 and r.available and r.steps > 2), key=lambda r: r.steps)
    for coarse, fine in zip(fd, fd[1:]):
        ratio = (coarse.steps - 1) / (fine.steps - 1)  # h_fine / h_coarse
        for q in ("velocity", "acceleration", "input_force"):  # positions are not differenced
            e1, e2 = coarse.error[q], fine.error[q]
            if np.isfinite(e1) and np.isfinite(e2) and e1 > 0 and e2 > 0:
                fine.observed_order[q] = float(np.log(e1 / e2) / -np.log(ratio))


def orders_line(ladder: Ladder) -> str:
    """Return one line with the observed orders of the finite-difference derivatives."""
    fd = [r for r in ladder.rows if np.isfinite(r.observed_order["velocity"])]
    if not fd:
        return ""
    parts = []
    for q in ("velocity", "acceleration"):
        vals = [f"{r.observed_order[q]:.2f}" for r in fd if np.isfinite(r.observed_order[q])]
        if vals:
            parts.append(f"{q} {', '.join(vals)}")
    everything = sorted((r for r in ladder.rows if r.knob == "derivatives"
                         and r.value == "finite_difference" and r.available),
                        key=lambda r: r.steps)
    steps = " -> ".join(str(r.steps) for r in everything)
    return (f"  finite differences along the sweep, observed order of convergence (steps "
            f"{steps}): " + "; ".join(parts))


def _units(scene: Scene) -> dict[str, str]:
    u = dict(scene.units)
    L, T, F = u.get("length", "length"), u.get("time", "s"), u.get("force", "force")
    kinds = {d.kind for d in scene.drivers}
    if any(d.input is not None for d in scene.drivers) or kinds == {"coordinate"}:
        force = F
    elif kinds == {"angle"}:
        force = f"{F}*{L}"
    else:
        force = "mixed"
    return {"position": L, "velocity": f"{L}/{T}", "acceleration": f"{L}/{T}^2",
            "input_force": force}


# ----------------------------------------------------------------------------- reporting
def _fmt_err(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{max(v, 0.0):.1e}" if v >= ERROR_FLOOR or v == 0 else f"<{ERROR_FLOOR:.0e}"


def _fmt_ms(v: float) -> str:
    if not np.isfinite(v):
        return "-"
    return f"{v * 1e3:.3g}"


def _front(r: Row) -> str:
    return ("*" if r.front else "") + ("n" if r.newton_front else "")


def table(ladder: Ladder, markdown: bool = False, compact: bool = False) -> str:
    """Return the ladder as a text table (or a Markdown table): one line per row.

    Errors are relative (see :func:`header`); a row whose knob cannot run says why instead.
    ``compact``: only knob, value, steps, solve time, worst error, failed steps and the front.
    Value marks: "(base)" the scene's own settings, "(newton base)" the same on the general
    path. Front: "*" on the Pareto front of all rows, "n" on the front of the Newton-path rows.
    """
    short = {"position": "pos", "velocity": "vel", "acceleration": "acc", "input_force": "force"}
    if compact:
        head = ["knob", "value", "path", "steps", "solve ms", "worst err", "failed", "front"]
    else:
        head = (["knob", "value", "path", "steps", "stage", "stage ms", "solve ms",
                 "iter mean/max",
                 "failed", "branch"] + [f"{short[q]} err" for q in ladder.quantities]
                + ["front", "note"])
    lines = []
    for r in ladder.rows:
        mark = " (base)" if r.base else " (newton base)" if r.newton_base else ""
        cells = [r.knob, r.value + mark, r.path, str(r.steps)]
        if not compact:
            cells.append(r.stage)
        if not r.available:
            lines.append((cells, r.note))
            continue
        if compact:
            cells += [_fmt_ms(r.seconds_solve), _fmt_err(r.worst_relative_error),
                      str(r.steps_failed), _front(r)]
            lines.append((cells, None))
            continue
        cells += [_fmt_ms(r.seconds), _fmt_ms(r.seconds_solve),
                  f"{r.iterations_mean:.2f}/{r.iterations_max}", str(r.steps_failed),
                  "kept" if r.branch_kept else "LOST"]
        cells += [_fmt_err(r.relative_error[q]) for q in ladder.quantities]
        cells += [_front(r), r.note]
        lines.append((cells, None))
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
        for cells, unavailable in lines:
            if unavailable:
                cells = cells + [unavailable] + [""] * (len(head) - len(cells) - 1)
            out.append("| " + " | ".join(cells) + " |")
        return "\n".join(out)
    widths = [max([len(h)] + [len(c[i]) for c, u in lines if u is None]) for i, h in enumerate(head)]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths)).rstrip(),
           "  ".join("-" * w for w in widths)]
    for cells, unavailable in lines:
        text = "  ".join(c.ljust(w) for c, w in zip(cells, widths))
        out.append((text + "  " + unavailable) if unavailable else text.rstrip())
    return "\n".join(out)


def header(ladder: Ladder, markdown: bool = False) -> str:
    """Return the lines that say what the table's numbers are."""
    sc = ladder.scene
    scales = ", ".join(
        f"{q} {ladder.scales[q]:.4g} {ladder.units[q]}" for q in ladder.quantities)
    first = (f"{sc.name}: what accuracy costs ({'quick' if ladder.quick else 'full'} ladder, "
             f"{sc.n_steps} steps, median of {ladder.repeats} runs)")
    rest = [
        f"reference: {ladder.reference}",
        f"errors: max error / scale, with scales {scales} (position: the mechanism's size)",
        "tol, max_iter, jacobian, derivatives and predictor act on the general Newton path "
        "(method = newton); method compares the paths (auto takes closed-form dyads where "
        "the scene decomposes)",
        "stage ms: the stage the knob acts on; solve ms: the whole solve; front: * on the "
        "Pareto front of solve time vs worst error among rows at the scene's step count, n "
        "on that front among the Newton-path rows (times within "
        f"{100 * ladder.time_noise:.0f} %, the spread of rows that repeat one setting, and "
        "errors within 2x count as equal)",
        f"machine: {ladder.machine}; {ladder.created}",
    ]
    if markdown:
        return "\n".join([f"**{first}**", ""] + [f"- {line}" for line in rest])
    return "\n".join([first] + [f"  {line}" for line in rest])


def run_accuracy(path, out: pathlib.Path = pathlib.Path("outputs"), quick: bool = False,
                 repeats: int = 5) -> int:
    """Measure ``path``'s ladder, print the table, write the .h5 and .rrd; return exit status."""
    scene = load_scene(path)
    if quick:
        repeats = min(repeats, 3)
    ladder = measure(scene, quick=quick, repeats=repeats,
                     echo=lambda line: print(line, file=sys.stderr, flush=True))
    print(header(ladder))
    print(table(ladder))
    if orders_line(ladder):
        print(orders_line(ladder))
    for name, front in (("Pareto front", ladder.front()),
                        ("Pareto front of the Newton path", ladder.front(path="newton"))):
        if front:
            print(f"  {name}: " + ", ".join(
                r.label for r in sorted(front, key=lambda r: r.seconds_solve)))
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from .stores import accuracy as store

    h5 = out / f"{scene.name}_accuracy.h5"
    rrd = out / f"{scene.name}_accuracy.rrd"
    store.write_h5(ladder, h5)
    store.write_rrd(ladder, rrd, table_markdown=header(ladder, True) + "\n\n" + table(ladder, True, compact=True))
    print(f"  wrote {h5}, {rrd}")
    failed = [r.label for r in ladder.rows if r.failure]
    if failed:
        print(f"error: {len(failed)} setting(s) failed: {', '.join(failed)} (see their rows)",
              file=sys.stderr)
    return 1 if failed else 0
