"""The result of one scene's run, and the one table of output names, dims and units.

``Result.variables()`` is the single place where the contract's variable names
(``docs/output-format.md``) meet the arrays; both stores write from it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .model import Mobility, Model
from .scene import Scene
from .status import (FLAG_MEANINGS, NON_FINITE, OK, code_counts, counts, finite_rows,
                     named_counts, not_finite_at)
from .status import message as status_message
from .output_units import (common_unit, driver_units_of, friction_units, input_force_units,
                           units_of)
from .stroke import names as stroke_names
from .stroke import units as stroke_units



def stride_of(n_steps: int, max_steps: int | None) -> int:
    """The uniform stride of steps that keeps at most ``max_steps`` of ``n_steps`` (1: every
    step; ``max_steps`` 0/None: no cap): a recording's rows of a long sweep."""
    if not max_steps or n_steps <= max_steps:
        return 1
    return -(-n_steps // max_steps)


@dataclass(frozen=True)
class Variable:
    """One output variable: contract name, dimension names, data, units and extra attributes."""

    name: str
    dims: tuple[str, ...]
    data: np.ndarray
    units: str
    attrs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Motion:
    """The solved sweep the force stage works on, step axis first.

    ``s``, ``s_dot``, ``s_ddot`` (S, n_drivers) driver values and rates in internal units
    (rad, length); ``position`` (S, n_points, 2) with NaN at failed steps; ``velocity`` and
    ``acceleration`` (S, n_points, 2) or None where the scene needs none; ``status`` (S,) the
    kinematic status; ``influence`` (S, n_q, n_drivers) the influence coefficients dq/ds, NaN
    where the step is not ok;
    ``link_angular_acceleration`` (S, n_links) rad/s^2 or None; ``link_angle`` (S, n_links)
    unwrapped along the whole sweep (a torsion spring's angle is its links' difference).
    """

    s: np.ndarray
    s_dot: np.ndarray
    s_ddot: np.ndarray
    position: np.ndarray
    velocity: np.ndarray | None
    acceleration: np.ndarray | None
    status: np.ndarray
    influence: np.ndarray
    link_angular_acceleration: np.ndarray | None
    link_angle: np.ndarray | None = None

    def rows(self, steps: slice) -> "Motion":
        """The same motion at a slice of its steps (views, no copies)."""
        return Motion(*(None if a is None else a[steps] for a in (
            self.s, self.s_dot, self.s_ddot, self.position, self.velocity, self.acceleration,
            self.status, self.influence, self.link_angular_acceleration, self.link_angle)))


@dataclass(frozen=True)
class Forces:
    """What the force stage returns: ``variables`` {name: (dims, data, units)} in the
    contract's names, ``coords`` {dimension: labels} for the dimensions it adds (joint, effect,
    slider, fixed_point), and ``status`` (S,) with no_leverage where an input has none."""

    variables: dict[str, tuple[tuple[str, ...], np.ndarray, str]]
    coords: dict[str, list[str]]
    status: np.ndarray
    #: {variable: (n_columns,) bool} columns the scene does not define (NaN at every step by
    #: construction: the force in a link between two fixed points), left out of status checks
    undefined: dict[str, np.ndarray] = field(default_factory=dict)

    def defined_arrays(self) -> list[np.ndarray]:
        """Every step-first variable, (S, n_defined_columns), without its undefined columns."""
        out = []
        for name, (dims, data, _) in self.variables.items():
            if dims[:1] != ("step",):
                continue
            columns = data.reshape(data.shape[0], -1)
            out.append(columns[:, ~self.undefined[name]] if name in self.undefined else columns)
        return out


def _nanmax(a) -> float:
    """The largest finite value of ``a`` (NaN where there is none)."""
    a = np.asarray(a)
    fin = a[np.isfinite(a)]
    return float(fin.max()) if fin.size else np.nan


@dataclass(frozen=True)
class Totals:
    """What a run's summary and the HDF5 root attributes say of the whole sweep, kept apart from
    the arrays so that a sweep solved in segments (:mod:`linkpipe.segments`) sums them as it
    goes: :meth:`of` one Result (or segment), :meth:`merged` two in step order.

    ``status_counts`` (n_flags,) steps per status code; residual maxima NaN where no step has a
    finite one (``max_residual_solved``: over steps whose positions are finite); the linear
    equations' residual maxima None where the run solved no such equation; ``input_force_min``
    / ``_max`` (n_drivers,) over finite values, NaN where none (None without forces)."""

    n_steps: int
    status_counts: tuple
    max_residual: float
    max_residual_solved: float
    iterations_sum: int
    iterations_max: int
    max_velocity_residual: float | None = None
    max_acceleration_residual: float | None = None
    input_force_min: np.ndarray | None = None
    input_force_max: np.ndarray | None = None
    #: the first non_finite step (-1: none), the causes linkpipe names there and what is not
    #: finite there (``spring_force[strut]``): :func:`not_finite_at`
    first_non_finite: int = -1
    non_finite_causes: tuple = ()
    non_finite_there: tuple = ()

    @classmethod
    def of(cls, result: "Result") -> "Totals":
        found = code_counts(result.status)
        solved = finite_rows([result.position], result.n_steps)
        lo = hi = None
        if result.forces and "input_force" in result.forces:
            f = result.forces["input_force"][1]
            with np.errstate(invalid="ignore"):
                lo = np.where(np.isfinite(f), f, np.inf).min(axis=0, initial=np.inf)
                hi = np.where(np.isfinite(f), f, -np.inf).max(axis=0, initial=-np.inf)
            lo, hi = np.where(np.isinf(lo), np.nan, lo), np.where(np.isinf(hi), np.nan, hi)
        vres, ares = result.velocity_residual, result.acceleration_residual
        first, causes, there = -1, (), ()
        if found[NON_FINITE]:
            first = int(np.argmax(result.status == NON_FINITE))
            causes, there = not_finite_at(result, first)
        return cls(result.n_steps, found, _nanmax(result.residual),
                   _nanmax(result.residual[solved]), int(result.iterations.sum()),
                   int(result.iterations.max()) if result.n_steps else 0,
                   None if vres is None else _nanmax(vres), None if ares is None else _nanmax(ares),
                   lo, hi, first, causes, there)

    def merged(self, later: "Totals") -> "Totals":
        """The totals of this run's steps followed by ``later``'s."""
        def biggest(a, b):
            if a is None or b is None:
                return a if b is None else b
            return np.fmax(a, b)

        def smallest(a, b):
            return a if b is None else b if a is None else np.fmin(a, b)

        return Totals(self.n_steps + later.n_steps,
                      tuple(a + b for a, b in zip(self.status_counts, later.status_counts)),
                      float(biggest(self.max_residual, later.max_residual)),
                      float(biggest(self.max_residual_solved, later.max_residual_solved)),
                      self.iterations_sum + later.iterations_sum,
                      max(self.iterations_max, later.iterations_max),
                      biggest(self.max_velocity_residual, later.max_velocity_residual),
                      biggest(self.max_acceleration_residual, later.max_acceleration_residual),
                      smallest(self.input_force_min, later.input_force_min),
                      biggest(self.input_force_max, later.input_force_max),
                      *self._first_non_finite(later))

    def _first_non_finite(self, later: "Totals") -> tuple:
        """(step, causes, entries) of the first non_finite step of this run then ``later``'s
        (its step counted from this run's first)."""
        if self.first_non_finite >= 0 or later.first_non_finite < 0:
            return self.first_non_finite, self.non_finite_causes, self.non_finite_there
        return (later.first_non_finite + self.n_steps, later.non_finite_causes,
                later.non_finite_there)

    @property
    def n_ok(self) -> int:
        return self.status_counts[OK]

    def counts(self) -> dict[str, int]:
        """``{name: number of steps}`` for the codes that occur, in code order."""
        return named_counts(self.status_counts)

    @property
    def message(self) -> str:
        """One line: how many steps are ok, and what the others are."""
        return status_message(self.status_counts)


@dataclass(frozen=True)
class Result:
    """Everything one run produced, step axis first (like scipy's ``OdeResult``).

    Kinematic arrays: ``driver_value`` (S, n_drivers), ``time`` (S,) or None,
    ``driver_velocity``/``driver_acceleration`` (S, n_drivers) (a v1 sweep's constant rate and
    acceleration at every step; a [time] sweep's from its laws and logs), ``position``
    (S, n_points, 2), ``velocity``/``acceleration`` (S, n_points, 2) or None, ``link_angle``
    (S, n_links) rad unwrapped, ``link_angular_velocity``/``_acceleration`` (S, n_links) or
    None, ``status`` (S,) int8, ``residual`` (S,), ``iterations`` (S,), ``condition`` (S,).
    ``forces``: name -> (dims, array, units) from stage 2 (None when no effect is on);
    ``force_coords``: the labels of the dimensions stage 2 adds.
    ``seconds``: stage name -> wall seconds, only for stages that ran.
    """

    scene: Scene
    model: Model
    mobility: Mobility
    driver_value: np.ndarray
    time: np.ndarray | None
    position: np.ndarray
    link_angle: np.ndarray
    status: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    condition: np.ndarray
    velocity: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    driver_velocity: np.ndarray | None = None
    driver_acceleration: np.ndarray | None = None
    link_angular_velocity: np.ndarray | None = None
    link_angular_acceleration: np.ndarray | None = None
    velocity_residual: np.ndarray | None = None
    acceleration_residual: np.ndarray | None = None
    forces: dict[str, tuple[tuple[str, ...], np.ndarray, str]] | None = None
    force_coords: dict[str, list[str]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    message: str = ""
    solver_method_used: str = ""  # "dyads" (closed form) or "newton" (general path)
    solver_note: str = ""  # the dyad chain, or why method = "auto" chose Newton
    linear_algebra_used: str = ""  # general path: the one-step solves' dense or sparse LU, and why
    time_note: str = ""  # why there is no time axis although every driver has a rate
    #: why the sweep's first steps are no_assembly (its first driver value out of reach), or ""
    reach_note: str = ""
    measurements: dict | None = None  # linkpipe.measure.compare: measured against computed
    kinematics: Any = field(default=None, repr=False, compare=False)  # stage1.Kinematics
    step_numbers: np.ndarray | None = None  # the sweep's step of each row (None: 0, 1, ...)
    #: the whole sweep's Totals where this Result holds some of its rows (a sweep streamed in
    #: segments: the rows its recording keeps); None: this Result's own rows are the sweep
    sweep_totals: Totals | None = None
    #: (stride, why) where the rows were taken at a uniform stride of the sweep's steps
    sampled: tuple | None = None
    #: (S, n_strokes) each actuator's and gas spring's distance to its stroke's nearer end
    #: (negative outside: linkpipe.stroke), None where the scene gives no stroke
    stroke_margin: np.ndarray | None = None

    @property
    def totals(self) -> Totals:
        """The whole sweep's :class:`Totals` (what the summary and the HDF5 attributes say)."""
        return self.sweep_totals if self.sweep_totals is not None else Totals.of(self)

    #: the fields that hold one row per step (step axis first)
    PER_STEP = ("driver_value", "time", "position", "link_angle", "status", "residual",
                "iterations", "condition", "velocity", "acceleration", "driver_velocity",
                "driver_acceleration", "link_angular_velocity", "link_angular_acceleration",
                "velocity_residual", "acceleration_residual", "stroke_margin")

    def strided(self, rows: np.ndarray) -> "Result":
        """The result at the steps ``rows`` only (the recording's view of a long sweep), each
        row remembering its step number; the force and measurement arrays likewise."""
        changes = {name: getattr(self, name)[rows] for name in self.PER_STEP
                   if getattr(self, name) is not None}
        if self.forces:
            changes["forces"] = {name: (dims, data[rows] if dims[:1] == ("step",) else data, unit)
                                 for name, (dims, data, unit) in self.forces.items()}
        if self.measurements:
            changes["measurements"] = {k: (v[rows] if k in ("measured", "residual") else v)
                                       for k, v in self.measurements.items()}
        steps = self.step_numbers if self.step_numbers is not None else np.arange(self.n_steps)
        return replace(self, **changes, kinematics=None, step_numbers=steps[rows])

    # ------------------------------------------------------------------ summaries
    @property
    def n_steps(self) -> int:
        return self.position.shape[0]

    @property
    def n_ok(self) -> int:
        return int((self.status == OK).sum())

    @property
    def point_names(self) -> tuple[str, ...]:
        return self.scene.point_names

    @property
    def link_names(self) -> tuple[str, ...]:
        return tuple(l.name for l in self.scene.links)

    @property
    def driver_names(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.scene.drivers)

    @property
    def spring_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.scene.springs) if "springs" in self.scene.effects else ()

    def forces_not_unique(self) -> list[str]:
        """Return the link and slider forces that redundant constraints leave undetermined.

        Their values are the minimum-norm choice (HDF5 ``link_force_unique`` /
        ``slider_force_unique`` = 0 for them).
        """
        out = []
        for var, names in (("link_force_unique", self.link_names),
                           ("slider_force_unique", tuple(s.name for s in self.scene.sliders))):
            if self.forces and var in self.forces:
                out += [f"{var.split('_')[0]} {n}" for n, u in zip(names, self.forces[var][1]) if not u]
        return out

    def status_counts(self) -> dict[str, int]:
        return counts(self.status)

    # ------------------------------------------------------------------ the output table
    @property
    def warnings(self) -> tuple[str, ...]:
        """What is legal but probably not meant: the scene's (parsing) and the drawing's (a
        drawn pose far from an assembled one: :func:`linkpipe.kinematics.start.drawing_warnings`)."""
        from .kinematics.start import scene_warnings

        return scene_warnings(self.model)

    def units(self) -> dict[str, str]:
        """Unit strings from the scene (free text), with neutral defaults."""
        return units_of(self.scene)

    def driver_units(self) -> list[str]:
        return driver_units_of(self.scene)

    def coordinates(self) -> list[Variable]:
        """Coordinate variables (dimension scales)."""
        coords = [
            Variable("step", ("step",), np.arange(self.n_steps, dtype=np.int64), "1"),
            Variable("point", ("point",), np.array(self.point_names, dtype=object), ""),
            Variable("xy", ("xy",), np.array(["x", "y"], dtype=object), ""),
            Variable("link", ("link",), np.array(self.link_names, dtype=object), ""),
            Variable("driver", ("driver",), np.array(self.driver_names, dtype=object), ""),
        ]
        if self.spring_names:
            coords.append(Variable("spring", ("spring",), np.array(self.spring_names, dtype=object), ""))
        for name, values in self.force_coords.items():
            coords.append(Variable(name, (name,), np.array(values, dtype=object), ""))
        if self.stroke_margin is not None:
            coords.append(Variable("stroke", ("stroke",), np.array(stroke_names(self.scene),
                                                                   dtype=object), ""))
        if self.measurements:
            coords.append(Variable("measurement", ("measurement",),
                                   np.array(self.measurements["names"], dtype=object), ""))
        return coords

    def variables(self) -> list[Variable]:
        """Data variables, each with dims and units; only what this run computed."""
        u = self.units()
        L, T = u["length"], u["time"]
        dunits = self.driver_units()
        out = [
            Variable("driver_value", ("step", "driver"), self.driver_value,
                     common_unit(dunits),
                     {"driver_units": ",".join(dunits)}),
        ]
        if self.time is not None:
            out.append(Variable("time", ("step",), self.time, "s" if T in ("s", "") else T))
        for name, data, per in (("driver_velocity", self.driver_velocity, T),
                                ("driver_acceleration", self.driver_acceleration, f"{T}^2")):
            if data is not None:
                units = [f"{d}/{per}" for d in dunits]
                out.append(Variable(name, ("step", "driver"), data,
                                    common_unit(units),
                                    {"driver_units": ",".join(units)}))
        out.append(Variable("position", ("step", "point", "xy"), self.position, L))
        if self.velocity is not None:
            out.append(Variable("velocity", ("step", "point", "xy"), self.velocity, f"{L}/{T}"))
        if self.acceleration is not None:
            out.append(Variable("acceleration", ("step", "point", "xy"), self.acceleration, f"{L}/{T}^2"))
        out.append(Variable("link_angle", ("step", "link"), self.link_angle, "rad"))
        if self.link_angular_velocity is not None:
            out.append(Variable("link_angular_velocity", ("step", "link"), self.link_angular_velocity, f"rad/{T}"))
        if self.link_angular_acceleration is not None:
            out.append(Variable("link_angular_acceleration", ("step", "link"),
                                self.link_angular_acceleration, f"rad/{T}^2"))
        if self.forces:
            per_driver = {"driver_units": ",".join(input_force_units(self.scene.drivers, u))}
            per_friction = {"friction_units": ",".join(friction_units(self.scene, u))}
            for name, (dims, data, units) in self.forces.items():
                out.append(Variable(name, dims, data, units,
                                    dict(per_driver) if dims[1:2] == ("driver",) else
                                    dict(per_friction) if name == "friction_force" else {}))
        if self.stroke_margin is not None:
            each = stroke_units(self.scene, L)
            out.append(Variable("stroke_margin", ("step", "stroke"), self.stroke_margin,
                                common_unit(each), {"stroke_units": ",".join(each),
                                                    "long_name": "distance to the stroke's nearer "
                                                                 "end, negative outside"}))
        if self.measurements:
            m = self.measurements
            units = common_unit(m["units"])
            per = {"measurement_units": ",".join(m["units"])}
            out.append(Variable("measured", ("step", "measurement"), m["measured"], units, per))
            out.append(Variable("measured_residual", ("step", "measurement"), m["residual"], units,
                                {**per, "rms": m["rms"], "max_abs": m["max_abs"],
                                 "long_name": "computed - measured"}))
        out.append(Variable("status", ("step",), self.status.astype(np.int8), "1", {
            "flag_values": np.arange(len(FLAG_MEANINGS), dtype=np.int8),
            "flag_meanings": " ".join(FLAG_MEANINGS),
        }))
        out.append(Variable("residual", ("step",), self.residual, L,
                            {"long_name": "max abs constraint residual after the position solve"}))
        out.append(Variable("iterations", ("step",), self.iterations.astype(np.int32), "1",
                            {"long_name": "Newton iterations"}))
        out.append(Variable("condition", ("step",), self.condition, "1",
                            {"long_name": "1-norm condition estimate of the constraint Jacobian "
                                          "(sigma_1/sigma_n when redundant)"}))
        if self.velocity_residual is not None:
            out.append(Variable("velocity_residual", ("step",), self.velocity_residual, f"{L}/{T}",
                                {"long_name": "max abs residual of Phi_q qd = -Phi_t"}))
        if self.acceleration_residual is not None:
            out.append(Variable("acceleration_residual", ("step",), self.acceleration_residual,
                                f"{L}/{T}^2", {"long_name": "max abs residual of Phi_q qdd = gamma"}))
        return out


def combine_flags(into: dict, part: dict) -> None:
    """Fold the per-sweep flags of one chunk (or segment) of steps, ``part`` {name: (dims, data,
    units)}, into ``into``: each variable without a step axis (the ``*_unique`` flags: no
    self-stress reaches that force at any ok step) is the minimum over the chunks."""
    for name, (dims, data, unit) in part.items():
        if dims[:1] == ("step",):
            continue
        if name in into:
            np.minimum(into[name][1], data, out=into[name][1])
        else:
            into[name] = (dims, data.copy(), unit)
