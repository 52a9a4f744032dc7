"""Reading ``[time]``, ``[[logs]]`` and the time keys of ``[[drivers]]`` (``law``, ``log``,
``scale``, ``smoothing``, ``rate`` as a function of time). The log files are read here (with
pandas, :mod:`.logs`) so that every problem in them is a scene error before any work; the
motion itself (laws, splines) is computed in :mod:`linkpipe.model.drive`."""
from __future__ import annotations

import json

import numpy as np

from . import logs as logfiles
from . import units
from .keys import _Table, _show, _suggest
from ..log_splines import log_spline, missing_at
from .tables import LAWS, LogData, Measurement, TimeSweep

#: the keys that say how a driver of a [time] scene moves (exactly one of them)
TIMED_KEYS = ("log", "law", "rate")
#: the driver keys that only a [time] scene gives a meaning
TIME_ONLY_KEYS = ("law", "log", "scale", "smoothing", "offset")
#: a rate driver's ``to``, when given, must be its value at the last instant within this
#: part of the motion (relative)
TO_AGREES = 1e-9
#: the fewest finite samples a smoothing spline takes (scipy's make_smoothing_spline)
MIN_SMOOTHING_SAMPLES = 5


class TimeTables:
    """The ``[[logs]]``, ``[time]`` and timed-driver readers of :class:`~.parse._Parser`."""

    def log_tables(self) -> dict[str, LogData]:
        self.frames = {}
        logs = {}
        for table in self.entries("logs"):
            name = table.data["name"]
            file = table.string("file")
            path = logfiles.resolve(self.path, file)
            skip = table.integer("skip_rows", 0)
            if skip < 0:
                raise table.error("skip_rows", f"must be >= 0, got {skip}",
                                  "the rows right under the header that are not samples, e.g. "
                                  "skip_rows = 1 for a units row")
            fmt = table.string("format", None)
            if fmt is not None and fmt not in logfiles.LOG_FORMATS:
                raise table.error("format", f"unknown format {_show(fmt)}",
                                  'write format = "csv" (delimited text, any file name) or '
                                  'format = "parquet"')
            delimiter = table.string("delimiter", ",")
            if not delimiter or delimiter in ('"', "\n", "\r"):
                raise table.error("delimiter", f"{json.dumps(delimiter)} cannot separate fields",
                                  'write the character between fields: "," ";" "\\t" or " " '
                                  "(runs of spaces)")
            if table.has("delimiter") and logfiles.format_of(path, fmt) != "csv":
                raise table.error("delimiter", "a Parquet log has no delimiter",
                                  'remove delimiter, or say format = "csv"')
            frame = logfiles.read_frame(table, path, skip, fmt, delimiter)
            column = table.string("time")
            time_scale = table.number("time_scale", 1.0)
            if not (time_scale > 0 and np.isfinite(time_scale)):
                raise table.error("time_scale", f"must be positive, got {time_scale:g}",
                                  "seconds per unit of the time column: 0.001 for ms, 60 for min")
            if column not in frame.columns:  # the time column first: its message names it
                logfiles.time_column(frame, column, path, table)
            column_units = self.column_units(table, frame, path)
            if column in column_units:
                quantity, order, si = column_units[column]
                if (quantity, order) != ("time", 0):
                    raise table.error("units", f'the time column "{column}" is in '
                                      f'"{table.data["units"][column]}", not a time',
                                      'give it a time unit ("s", "ms", "min") or none (seconds)')
                time_scale *= si
            lag = table.number("lag", 0.0)
            if not np.isfinite(lag):
                raise table.error("lag", f"must be finite, got {lag:g}",
                                  "the seconds the log's stamps are late by (negative: early)")
            t = logfiles.time_column(frame, column, path, table, time_scale) - lag
            self.frames[name] = frame
            logs[name] = LogData(name, file, str(path), column, t, {},
                                 tuple(str(c) for c in frame.columns), lag, column_units)
        return logs

    def column_units(self, table: _Table, frame, path) -> dict:
        """``[[logs]] units`` = {column: unit}: each column's (quantity, order, SI value),
        checked against the file's columns and the scene's ``[scene].units`` it converts to."""
        if not table.has("units"):
            return {}
        given = table.data["units"]
        if not isinstance(given, dict):
            raise table.wrong_type("units", "a table of column = unit")
        out = {}
        for column, unit in given.items():
            if column not in frame.columns:
                raise table.error("units", f'"{path}" has no column "{column}"',
                                  logfiles.nearest_columns(column, frame.columns))
            if not isinstance(unit, str):
                raise table.error("units", f'column "{column}": expected a unit string, got '
                                  f"{_show(unit)}", f'write e.g. {column} = "mm"')
            try:
                out[column] = units.column_unit(unit)
                quantity, order, _ = out[column]
                if quantity != "angle":  # angles convert to degrees or radians: always known
                    units.scene_unit_si(quantity, order, self.units)
            except ValueError as exc:
                raise table.error("units", f'column "{column}": {exc}',
                                  "give the column a unit linkpipe knows, and [scene].units "
                                  '(e.g. units = { length = "m", mass = "kg", time = "s", '
                                  'force = "N" }) for it to convert to') from None
        return out

    def unit_factor(self, table: _Table, key: str, log: LogData, column: str,
                    angle: str = "deg", expect: str | None = None) -> float:
        """The factor taking ``column`` of ``log`` to the scene's units (1 when it has no
        unit); ``expect`` a quantity it must be ("angle", "length": a driver's)."""
        if column not in log.units:
            return 1.0
        quantity, order, si = log.units[column]
        if expect is not None and (quantity, order) != (expect, 0):
            raise table.error(key, f'column "{column}" of log "{log.name}" is in '
                              f'"{self.data_units(log, column)}", not {"an" if expect[0] in "aeiou" else "a"} {expect}',
                              f"drive it by a column of {expect}s, or correct [[logs]] units")
        return si / units.scene_unit_si(quantity, order, self.units, angle)

    def data_units(self, log: LogData, column: str) -> str:
        entry = next(t for t in self.entries("logs") if t.data.get("name") == log.name)
        return str(entry.data["units"][column])

    def time_table(self, logs: dict[str, LogData]) -> TimeSweep | None:
        if self.top("time") is None:
            return None
        table = self.table("time")
        if table.has("log"):
            for key in ("from", "to", "steps", "step"):
                if table.has(key):
                    raise table.error(key, "with log the instants are the log's own rows",
                                      f"remove {key}, or remove log and keep from, to, steps")
            log = self.log_named(table, "log", table.string("log"), logs)
            return TimeSweep(float(log.t[0]), float(log.t[-1]), len(log.t), None, log.name,
                             log.t)
        if not any(table.has(k) for k in ("from", "to", "steps", "step")):
            raise table.error("from", "missing: [time] needs from, to and steps (or step), "
                              "or log", 'add from = 0.0, to = 4.0, steps = 4001, or log = "run3"')
        start, stop = table.number("from"), table.number("to")
        if stop < start:
            raise table.error("to", f"to = {stop:g} is before from = {start:g}",
                              "time runs forward: give to > from (to = from with steps = 1 "
                              "for a single instant)")
        steps, step = self.driver_steps(table, start, stop, "instant")
        i = np.arange(steps, dtype=float)
        if step is not None:
            instants = start + i * step
        else:  # steps = 1: the single instant from = to
            instants = start + i * ((stop - start) / max(steps - 1, 1))
        return TimeSweep(start, stop, steps, step, None, instants)

    def log_named(self, table: _Table, key: str, name: str, logs: dict[str, LogData]) -> LogData:
        if name not in logs:
            raise table.error(key, f'no [[logs]] entry named {_show(name)}',
                              (_suggest(name, logs) if logs else "")
                              + f' — add [[logs]] with name = "{name}", file and time')
        return logs[name]

    def timed_driver(self, table: _Table, kind: str, time: TimeSweep, logs) -> dict:
        """The Driver fields of a driver in a [time] scene: how it moves and its value range."""
        for key in ("steps", "step"):
            if table.has(key):
                raise table.error(key, "with [time] the steps are its instants, not the "
                                  "driver's", f"remove {key} (the sweep is set by [time])")
        how = table.exactly_one(TIMED_KEYS)
        if how != "log":
            for key in ("scale", "smoothing", "offset"):
                if table.has(key):
                    raise table.error(key, f"{key} belongs to a log driver",
                                      f'remove {key}, or drive by log = "<log>.<column>"')
        fields = dict(steps=time.steps, step=None, timed=how)
        if how == "law" and time.to_value == time.from_value:
            raise table.error("law", "a law moves from its from to its to over [time]'s span, "
                              "and a single instant has none",
                              "drive it by rate (rate = 0.0 holds it at from) or by log, or "
                              "give [time] a span (to > from, steps >= 2)")
        if how == "law":
            if table.has("rate") or table.has("acceleration"):
                key = "rate" if table.has("rate") else "acceleration"
                raise table.error(key, "a law sets the rates itself",
                                  f"remove {key}, or drive by rate instead of law")
            law = table.string("law")
            if law not in LAWS:
                raise table.error("law", f"unknown law {_show(law)}", _suggest(law, LAWS))
            fields.update(law=law, from_value=table.number("from"), to_value=table.number("to"))
        elif how == "rate":
            fields.update(self.rate_of_time(table, time, kind))
        else:
            fields.update(self.log_driver(table, kind, time, logs))
        return fields

    def rate_of_time(self, table: _Table, time: TimeSweep, kind: str) -> dict:
        """from + rate t + acceleration t^2/2 (t from [time].from); ``to`` optional, checked;
        rate and acceleration may carry a unit (:meth:`MotionTables.rate`)."""
        start = table.number("from")
        if not table.has("rate"):
            table.number("rate")  # the missing-key message
        rate, acc = self.rate(table, "rate", kind, 1), self.rate(table, "acceleration", kind, 2)
        span = float(time.instants[-1] - time.from_value)
        end = start + rate * span + 0.5 * acc * span * span
        if table.has("to"):
            stop = table.number("to")
            motion = abs(end - start) + abs(stop - start)
            if abs(stop - end) > TO_AGREES * max(motion, abs(start), 1e-300):
                raise table.error("to", f"to = {stop:g} but from + rate t + acceleration t^2/2 "
                                  f"reaches {end:.12g} at the last instant ({span:g} s)",
                                  f"remove to (rate and [time] set it), or write to = {end:.12g}")
        return dict(from_value=start, to_value=end, rate=rate, acceleration=acc)

    def log_driver(self, table: _Table, kind: str, time: TimeSweep, logs) -> dict:
        """log = "<log>.<column>", scale, smoothing: the column read and checked now."""
        for key in ("from", "to", "rate", "acceleration"):
            if table.has(key):
                raise table.error(key, "a log driver takes its values from the log",
                                  f"remove {key} (use scale for units)")
        text = table.string("log")
        log_name, dot, column = text.partition(".")
        if not dot or not column:
            raise table.error("log", f"{_show(text)} is not <log>.<column>",
                              'write e.g. log = "run3.boom_len"')
        log = self.log_named(table, "log", log_name, logs)
        if column == log.time:
            raise table.error("log", f'"{column}" is the time column of log "{log.name}"',
                              "name a data column of the log")
        frame = self.frames[log.name]
        path = logfiles.Path(log.path)
        if column not in frame.columns:
            raise table.error("log", f'log "{log.name}" ("{log.path}") has no column '
                              f'"{column}"', logfiles.nearest_columns(column, log.names))
        if column not in log.columns:
            log.columns[column] = logfiles.numeric_column(frame, column, path, table, "log")
        scale = table.number("scale", 1.0)
        if scale == 0:
            raise table.error("scale", "is 0: every value would be 0",
                              "write the factor from the column's unit, e.g. scale = 0.001")
        offset = table.number("offset", 0.0)
        factor = self.unit_factor(table, "log", log, column,
                                  expect="angle" if kind == "angle" else "length")
        smoothing = table.number("smoothing", 0.0)
        if smoothing < 0:
            raise table.error("smoothing", f"must be >= 0, got {smoothing:g}",
                              "0 interpolates the samples; > 0 smooths noisy data")
        values = log.columns[column]
        finite = int(np.isfinite(values).sum())
        need = MIN_SMOOTHING_SAMPLES if smoothing > 0 else 2
        if finite < need:
            why = (f"a smoothing spline (smoothing = {smoothing:g}) needs at least {need}; "
                   "the interpolating one (smoothing = 0) needs 2" if smoothing > 0 else
                   f"the spline needs at least {need}")
            raise table.error("log", f'column "{column}" of "{log.path}" has {finite} value(s): '
                              + why, "give the log more samples"
                              + (", or set smoothing = 0" if smoothing > 0 and finite >= 2 else ""))
        logfiles.check_spans(log, time.instants, self.table("time"),
                             "log" if time.log else "to")
        driven = values * (factor * scale) + offset
        low, high = logfiles.finite_values(driven)
        if kind == "distance" and not low > 0:
            i = int(np.flatnonzero(np.isfinite(values) & ~(driven > 0))[0])
            raise table.error("log", f'"{log.path}" {logfiles.row_label(path, i, logfiles.skipped_rows(frame))}, column '
                              f'"{column}": a cylinder length of {driven[i]:g}',
                              "a cylinder's length must be positive: check the column, its "
                              "units, scale and offset")
        return dict(log=(log.name, column), scale=scale, smoothing=smoothing,
                    from_value=low, to_value=high, offset=offset, unit_factor=factor)


def check_not_timed(table: _Table) -> None:
    """Outside a [time] scene the time keys of a driver are an error naming the key."""
    for key in TIME_ONLY_KEYS:
        if table.has(key):
            raise table.error(key, f"{key} needs a [time] table: the steps must be instants",
                              "add [time] with from, to and steps (or log), or remove " + key)



#: what ``of`` may address: variable -> the scene names it is labelled by, and whether it has xy
MEASURABLE = {
    "position": ("points", True), "velocity": ("points", True), "acceleration": ("points", True),
    "driver_value": ("drivers", False), "driver_velocity": ("drivers", False),
    "driver_acceleration": ("drivers", False), "input_force": ("drivers", False),
    "input_force_lagrange": ("drivers", False), "link_angle": ("links", False),
    "link_angular_velocity": ("links", False), "link_angular_acceleration": ("links", False),
    "link_force": ("links", False), "spring_force": ("springs", False),
    "spring_length": ("springs", False), "spring_extension": ("springs", False),
    "spring_energy": ("springs", False), "slider_force": ("sliders", False),
    "torsion_spring_angle": ("torsion_springs", False),
    "torsion_spring_torque": ("torsion_springs", False),
    "torsion_spring_energy": ("torsion_springs", False), "joint_force": ("joints", True),
    "ground_reaction": ("fixed_points", True),
    "friction_force": ("friction", False), "friction_power": ("friction", False),
}


#: what computes a measurable variable beyond the positions: "velocity" / "acceleration" (a
#: measurement calls for them: :meth:`linkpipe.spine.Stages.of`), "forces" (the force
#: stage, which runs only with effects), "springs" (that effect); absent: always computed
MEASURED_NEEDS = {
    "velocity": "velocity", "link_angular_velocity": "velocity",
    "acceleration": "acceleration", "link_angular_acceleration": "acceleration",
    **dict.fromkeys(("input_force", "input_force_lagrange", "link_force", "slider_force",
                     "joint_force", "ground_reaction"), "forces"),
    **dict.fromkeys(("spring_force", "spring_length", "spring_extension", "spring_energy",
                     "torsion_spring_angle", "torsion_spring_torque",
                     "torsion_spring_energy"), "springs"),
    **dict.fromkeys(("friction_force", "friction_power"), "friction"),
}


def entry_unit_is_radians(variable: str) -> bool:
    """Whether a measured variable is stored in radians (link and torsion-spring angles and
    their rates), where a column in angle units converts to radians (degrees elsewhere)."""
    return variable.startswith(("link_angle", "link_angular", "torsion_spring_angle"))


class MeasurementTables:
    """The ``[[measurements]]`` reader of :class:`~.parse._Parser` (after logs and [time])."""

    def measurement_tables(self, drivers, springs, torsion_springs, sliders, effects=(),
                           friction=()) -> tuple:
        out = []
        for table in self.entries("measurements"):
            if self.time is None or self.time.log is None:
                raise table.error("log", "a measurement needs [time] log = <its log>: the "
                                  "steps are then the log's rows, where it was measured",
                                  'add [time] with log = "<the log\'s name>"')
            of = self.measured_of(table, drivers, springs, torsion_springs, sliders, friction)
            columns, scales, values, parts = self.measured_columns(table, of)
            offset = table.number("offset", 0.0)
            values = values + offset
            sigma = table.number("sigma", None)
            if sigma is not None and not sigma > 0:
                raise table.error("sigma", f"must be positive, got {sigma:g}",
                                  "the measurement's standard deviation, in its scaled unit")
            alarm = table.number("alarm", None)
            if alarm is not None and not (alarm > 0 and sigma is not None):
                raise table.error("alarm", f"alarm = {alarm:g} is a number of sigmas: it needs "
                                  "a positive value and the measurement's sigma",
                                  "give sigma (the measurement's standard deviation) and alarm > 0")
            need = MEASURED_NEEDS.get(of[0])
            effect = need in ("springs", "friction")  # computed by that effect alone
            if need == "forces" and not effects or effect and need not in effects:
                what = (f'"{need}" in [analysis] effects' if effect else
                        "the force stage, which runs only with [analysis] effects")
                raise table.error("of", f'"{of[0]}" is computed by {what}; this scene has '
                                  + (f"effects {list(effects)}" if effects else "none"),
                                  f'add it, e.g. [analysis] effects = ["{need}"]' if effect
                                  else 'add the effects the machine has, e.g. '
                                  '[analysis] effects = ["gravity"]')
            (log, column), scale = columns[0], scales[0]
            out.append(Measurement(table.data["name"], log, column, scale, of, sigma, values,
                                   columns, scales, offset, parts, alarm))
        return tuple(out)

    def measured_columns(self, table: _Table, of: tuple) -> tuple:
        """``log`` = "<log>.<column>" or a list of them, ``scale`` a number or a list as long:
        ((log, column), ...), (scale, ...), the measured values (S,) at the steps,
        ``sum(part_i x scale_i)``, and the parts (S, n): each column in the scene's units at
        the steps (a log other than [time]'s through its cubic spline at the instants; NaN
        where a sample is missing)."""
        raw = table.data.get("log")
        many = isinstance(raw, list)
        texts = [table.string("log")] if not many else raw
        if many and (not texts or not all(isinstance(x, str) for x in texts)):
            raise table.error("log", f"expected a string or a non-empty array of strings, got "
                              f"{_show(raw)}", 'write log = ["run3.p_cap", "run3.p_rod"]')
        if isinstance(table.data.get("scale"), list):
            scales = table.data["scale"]
            if (len(scales) != len(texts) or not all(isinstance(v, (int, float)) and not
                                                     isinstance(v, bool) for v in scales)):
                raise table.error("scale", f"expected {len(texts)} number(s), one per column "
                                  f"of log, got {_show(scales)}",
                                  f"give one factor per column: scale = [{', '.join(['1.0'] * len(texts))}]")
            scales = [float(v) for v in scales]
        else:
            scales = [table.number("scale", 1.0)] * len(texts)
        angle = "rad" if entry_unit_is_radians(of[0]) else "deg"
        instants = self.time.instants
        columns, parts, total = [], [], np.zeros(len(instants))
        for text, scale in zip(texts, scales):
            log_name, dot, column = text.partition(".")
            if not dot or not column:
                raise table.error("log", f"{_show(text)} is not <log>.<column>",
                                  'write e.g. log = "run3.p_force"')
            log = self.log_named(table, "log", log_name, self.logs)
            frame = self.frames[log.name]
            if column not in frame.columns or column == log.time:
                raise table.error("log", f'log "{log.name}" ("{log.path}") has no data column '
                                  f'"{column}"', logfiles.nearest_columns(column, log.names))
            if column not in log.columns:
                log.columns[column] = logfiles.numeric_column(frame, column, logfiles.Path(log.path),
                                                              table, "log")
            y = log.columns[column] * self.unit_factor(table, "log", log, column, angle)
            if log.name != self.time.log:  # another logger: read at [time]'s instants
                logfiles.check_spans(log, instants, table, "log")
                if int(np.isfinite(y).sum()) < 2:
                    raise table.error("log", f'column "{column}" of "{log.path}" has fewer '
                                      "than two values", "give the log its samples")
                y = np.where(missing_at(log.t, y, instants), np.nan,
                             log_spline(log.t, y, 0.0)(instants))
            columns.append((log.name, column))
            parts.append(y)
            total = total + y * scale
        return tuple(columns), tuple(scales), total, np.stack(parts, axis=1)

    def measured_of(self, table, drivers, springs, torsion_springs, sliders,
                    friction=()) -> tuple:
        """``of = "<variable>.<name>[.x|.y]"`` checked against the scene's names."""
        text = table.string("of")
        variable, _, rest = text.partition(".")
        if variable not in MEASURABLE:
            raise table.error("of", f'"{variable}" is not a stored variable that can be measured',
                              _suggest(variable, MEASURABLE))
        kind, xy = MEASURABLE[variable]
        axis = None
        if xy:
            rest, dot, last = rest.rpartition(".")
            if not dot or last not in ("x", "y"):
                raise table.error("of", f'{_show(text)}: "{variable}" has x and y',
                                  f'write e.g. of = "{variable}.<name>.y"')
            axis = "xy".index(last)
        names = {"points": list(self.points), "drivers": [d.name for d in drivers],
                 "links": list(self.links), "springs": [s.name for s in springs],
                 "torsion_springs": [t.name for t in torsion_springs],
                 "sliders": [s.name for s in sliders],
                 "joints": [f"{p}@{n}" for n, ln in self.links.items() for p in ln.points],
                 "fixed_points": [n for n, p in self.points.items() if p.fixed],
                 "friction": [f.name for f in friction]}[kind]
        if rest not in names:
            raise table.error("of", f'{_show(text)}: no {"friction entry" if kind == "friction" else kind[:-1].replace("_", " ")} named '
                              f'{_show(rest)}', _suggest(rest, names) if names else "")
        return variable, rest, axis
