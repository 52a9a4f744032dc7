"""The ladder's rows and the ladder: what each setting measured, the Pareto fronts, and the
variables the accuracy store writes."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..result import Variable
from ..output_units import common_unit, input_force_units, units_of
from ..scene import Scene


QUANTITIES = ("position", "velocity", "acceleration", "input_force")


#: a step whose position is off by more than this fraction of the mechanism's size is on
#: another assembly branch (loose tolerances stay orders of magnitude below it)
BRANCH_FRACTION = 0.1


#: relative errors below this are reported as this (the floor of the log plots)
ERROR_FLOOR = 1e-17


#: the noise band of the Pareto front: times within 10 %, errors within a factor 2 are equal
TIME_NOISE, ERROR_NOISE = 0.10, 2.0


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
    #: friction_velocity_scale rows: the input force's relative error against the exact sign
    #: law at steps away from rest and near it (:func:`.references.friction_errors`)
    relative_error_away: float = math.nan
    relative_error_near: float = math.nan
    path: str = ""  # the path the solve took: "dyads" (closed form) or "newton"
    linear_algebra: str = ""  # newton: its one-step solves' "dense ..." or "sparse LU ..." and why
    base: bool = False  # the scene's own settings
    newton_base: bool = False  # the scene's own settings on the general path (method newton)
    front: bool = False  # on the Pareto front (whole-solve time vs worst relative error)
    newton_front: bool = False  # on the front among the rows solved by the general path

    @property
    def label(self) -> str:
        if self.knob in ("tol", "max_iter", "jacobian", "linear_algebra", "method"):
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

    @property
    def force_units(self) -> list[str]:
        """Each driver's input-force unit (the per-unit scales' units)."""
        return driver_force_units(self.scene)

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
        from ..version import __version__

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
                               "max |reference|; input force: each driver's error / max "
                               "|reference| over the drivers of its unit"),
            "branch_fraction": BRANCH_FRACTION,
            "time_noise": self.time_noise,
        }
        for q, s in self.scales.items():
            attrs[f"scale_{q}"] = s
        for q, u in self.units.items():
            attrs[f"units_{q}"] = u
        if "input_force_per_driver" in self.scales:  # beside scale_input_force_per_driver
            attrs["units_input_force_per_driver"] = ",".join(
                self.force_units)
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
            col("relative_error_away_from_rest", [r.relative_error_away for r in rows], "1",
                long_name="friction_velocity_scale rows: input force error against the exact "
                          "sign law at steps away from rest, relative"),
            col("relative_error_near_rest", [r.relative_error_near for r in rows], "1",
                long_name="the same at steps near rest (a friction's speed below 1 % of its "
                          "largest)"),
            col("iterations_mean", [r.iterations_mean for r in rows], "1",
                long_name="Newton iterations per step, mean"),
            col("iterations_max", np.array([r.iterations_max for r in rows], dtype=np.int32), "1"),
            col("steps_failed", np.array([r.steps_failed for r in rows], dtype=np.int32), "1",
                long_name="steps the reference solves that this row does not"),
            col("branch_kept", np.array([r.branch_kept for r in rows], dtype=np.int8), "1", **flag),
            strings("path", [r.path for r in rows],
                    long_name="the path the solve took: dyads (closed form) or newton"),
            strings("linear_algebra", [r.linear_algebra for r in rows],
                    long_name="newton: the one-step solves' linear algebra (dense or sparse "
                              "LU) and why; empty on the dyads path"),
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


def driver_force_units(scene: Scene) -> list[str]:
    """Each driver's input-force unit in ``scene``'s units."""
    return input_force_units(scene.drivers, units_of(scene))


def _units(scene: Scene) -> dict[str, str]:
    """The unit of each quantity the ladder measures (the input force's: the drivers' shared
    unit, else "mixed", as the run's own file)."""
    u = units_of(scene)
    L, T = u["length"], u["time"]
    return {"position": L, "velocity": f"{L}/{T}", "acceleration": f"{L}/{T}^2",
            "input_force": common_unit(driver_force_units(scene))}
