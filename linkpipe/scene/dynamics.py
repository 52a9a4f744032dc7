"""Reading ``[dynamics]`` and the forward-dynamics keys of ``[[drivers]]`` (``start_rate``,
``force``, ``force_law``, ``force_log``). Parsing only: the motion is integrated in
:mod:`linkpipe.dynamics`."""
from __future__ import annotations

import math

import numpy as np

from . import logs as logfiles
from .keys import _Table, _show, _suggest
from .tables import DYNAMICS_METHODS, LAWS, Dynamics, ForceLaw

#: the driver keys that only a [dynamics] scene gives a meaning
DYNAMICS_ONLY_KEYS = ("start_rate", "force", "force_law", "force_log")
#: the ways a driver's actuator force is given (at most one; none: a free degree of freedom)
FORCE_KEYS = ("force", "force_law", "force_log")
#: driver keys that prescribe a motion, which [dynamics] computes instead
PRESCRIBING_KEYS = ("to", "steps", "step", "rate", "acceleration", "law", "log", "smoothing")
#: the tightest and loosest integrator tolerance (scipy raises rtol below 100 eps itself)
MIN_RTOL, MAX_RTOL = 1e-13, 1e-2
#: the most output instants of one run
MAX_INSTANTS = 1e8


class DynamicsTables:
    """The ``[dynamics]`` and dynamic-driver readers of :class:`~.parse._Parser`."""

    def dynamics_table(self) -> Dynamics | None:
        if self.top("dynamics") is None:
            return None
        table = self.table("dynamics")
        if self.top("time") is not None:
            raise table.error(None, "[dynamics] and [time] together: [time] prescribes the "
                              "drivers' motion over time, [dynamics] computes it from the forces",
                              "remove [time] (the instants are [dynamics] output_step), or "
                              "remove [dynamics] to prescribe the motion")
        to = table.number("to")
        if not to > 0:
            raise table.error("to", f"must be positive (seconds from 0), got {to:g}",
                              f"write e.g. {table.example('to')}")
        step = table.number("output_step")
        if not step > 0:
            raise table.error("output_step", f"must be positive (seconds), got {step:g}",
                              f"write e.g. {table.example('output_step')}")
        if step > to:
            raise table.error("output_step", f"output_step = {step:g} s is longer than to = "
                              f"{to:g} s: only the start would be stored",
                              f"use an output_step of at most {to:g} s, e.g. {to / 100:g}")
        count = to / step + 1e-9
        if not count < MAX_INSTANTS:
            raise table.error("output_step", f"gives {count:.3g} output instants, more than "
                              f"{MAX_INSTANTS:.0e}", "use a larger output_step")
        rtol = table.number("rtol", 1e-9)
        if not MIN_RTOL <= rtol <= MAX_RTOL:
            raise table.error("rtol", f"must be between {MIN_RTOL:g} and {MAX_RTOL:g} (the "
                              f"integrator's relative error per step), got {rtol:g}",
                              f"write e.g. {table.example('rtol')}")
        method = table.string("method", DYNAMICS_METHODS[0])
        if method not in DYNAMICS_METHODS:
            raise table.error("method", f"unknown integrator {_show(method)}",
                              _suggest(method, DYNAMICS_METHODS))
        n = math.floor(count) + 1
        return Dynamics(to, step, rtol, method, np.minimum(np.arange(n, dtype=float) * step, to))

    def dynamic_driver(self, table: _Table, kind: str, dynamics: Dynamics) -> dict:
        """The Driver fields of a driver of a [dynamics] scene: a degree of freedom from
        ``from`` at ``start_rate``, pushed by its force (or free)."""
        given = [k for k in FORCE_KEYS if table.has(k)]
        for key in PRESCRIBING_KEYS:
            if not table.has(key):
                continue
            if key in ("law", "log") and given:
                raise table.error(key, f"a driver with both {given[0]} and {key}: with "
                                  f"[dynamics], {key} would prescribe the motion that "
                                  f"{given[0]} computes", f"remove {key} (a force that follows a "
                                  f"law is force_law, one from a log is force_log)")
            raise table.error(key, f"with [dynamics] the driver's motion is computed from its "
                              f"force and the scene's effects: {key} would prescribe it",
                              f"remove {key}; give from, start_rate and force (or force_law, "
                              "force_log, or none: free)")
        if len(given) > 1:
            raise table.error(given[1], f"give one of force, force_law or force_log, not both "
                              f"{given[0]} and {given[1]}",
                              f"keep one of {' or '.join(table.as_given(k) for k in given)}")
        for key in ("scale", "offset"):
            if table.has(key) and "force_log" not in given:
                raise table.error(key, f"{key} belongs to a force_log",
                                  f'remove {key}, or give force_log = "<log>.<column>"')
        start = table.number("from")
        fields = dict(from_value=start, to_value=start, steps=len(dynamics.instants), step=None,
                      start_rate=self.rate(table, "start_rate", kind, 1))
        if "force" in given:
            fields["force"] = table.number("force")
        elif "force_law" in given:
            fields["force_law"] = self.force_law(table, dynamics)
        elif "force_log" in given:
            (fields["force_log"], fields["scale"], fields["offset"],
             fields["unit_factor"]) = self.force_log(table, dynamics)
        return fields

    def force_law(self, table: _Table, dynamics: Dynamics) -> ForceLaw:
        sub = table.sub("force_law")
        law = sub.string("law")
        if law not in LAWS:
            raise sub.error("law", f"unknown law {_show(law)}", _suggest(law, LAWS))
        duration = sub.number("duration", dynamics.to)
        if not duration > 0:
            raise sub.error("duration", f"must be positive (seconds), got {duration:g}",
                            f"write e.g. {sub.example('duration')}")
        return ForceLaw(law, sub.number("from"), sub.number("to"), duration)

    def force_log(self, table: _Table, dynamics: Dynamics) -> tuple[tuple[str, str], float,
                                                                    float, float]:
        """force_log = "<log>.<column>": ``((log, column), scale, offset, unit_factor)``, the
        force being ``column x unit_factor x scale + offset``. ``unit_factor`` takes a column
        with ``[[logs]] units`` to the scene's force (a force unit) or force per length^2 (a
        pressure: ``scale`` is then the area it acts on); ``offset`` is in the scene's force
        units. Read and checked now; its time column (less the log's ``lag``) must cover
        0 .. [dynamics] to."""
        text = table.string("force_log")
        log_name, dot, column = text.partition(".")
        if not dot or not column:
            raise table.error("force_log", f"{_show(text)} is not <log>.<column>",
                              'write e.g. force_log = "run3.p_cap"')
        log = self.log_named(table, "force_log", log_name, self.logs)
        frame = self.frames[log.name]
        if column == log.time or column not in frame.columns:
            raise table.error("force_log", f'log "{log.name}" ("{log.path}") has no data '
                              f'column "{column}"', logfiles.nearest_columns(column, log.names))
        if column not in log.columns:
            log.columns[column] = logfiles.numeric_column(frame, column,
                                                          logfiles.Path(log.path), table,
                                                          "force_log")
        values = log.columns[column]
        if int(np.isfinite(values).sum()) < 2:
            raise table.error("force_log", f'column "{column}" of "{log.path}" has fewer than '
                              "2 values", "give the log more samples")
        if not (log.t[0] <= 0.0 and log.t[-1] >= dynamics.to):
            raise table.error("force_log", f'log "{log.name}" runs from {log.t[0]:g} s to '
                              f"{log.t[-1]:g} s; [dynamics] needs its force from 0 to "
                              f"{dynamics.to:g} s", "use a log that covers the run, or a "
                              "shorter [dynamics] to")
        factor = 1.0
        if column in log.units:
            quantity, order, _ = log.units[column]
            if quantity not in ("force", "pressure") or order:
                raise table.error("force_log", f'column "{column}" of log "{log.name}" is in '
                                  f'"{self.data_units(log, column)}", not a force or a pressure',
                                  "push the driver by a column of forces (N, kN, lbf) or "
                                  "pressures (bar, MPa, psi: scale = the area they act on), or "
                                  "correct [[logs]] units")
            factor = self.unit_factor(table, "force_log", log, column)
        scale = table.number("scale", 1.0)
        return (log.name, column), scale, table.number("offset", 0.0), factor


def check_not_dynamic(table: _Table) -> None:
    """Outside a [dynamics] scene the forward-dynamics keys of a driver are an error."""
    for key in DYNAMICS_ONLY_KEYS:
        if table.has(key):
            raise table.error(key, f"{key} needs a [dynamics] table: only forward dynamics "
                              "computes a motion from a force",
                              "add [dynamics] with to and output_step, or remove " + key)
