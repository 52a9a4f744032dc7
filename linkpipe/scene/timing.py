"""Reading ``[time]``, ``[[logs]]`` and the time keys of ``[[drivers]]`` (``law``, ``log``,
``scale``, ``smoothing``, ``rate`` as a function of time). The log files are read here (with
pandas, :mod:`.logs`) so that every problem in them is a scene error before any work; the
motion itself (laws, splines) is computed in :mod:`linkpipe.model.drive`."""
from __future__ import annotations

import numpy as np

from . import logs as logfiles
from .keys import _Table, _show, _suggest
from .tables import LAWS, LogData, Measurement, TimeSweep

#: the keys that say how a driver of a [time] scene moves (exactly one of them)
TIMED_KEYS = ("log", "law", "rate")
#: the driver keys that only a [time] scene gives a meaning
TIME_ONLY_KEYS = ("law", "log", "scale", "smoothing")
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
            frame = logfiles.read_frame(table, path, skip)
            column = table.string("time")
            time_scale = table.number("time_scale", 1.0)
            if not (time_scale > 0 and np.isfinite(time_scale)):
                raise table.error("time_scale", f"must be positive, got {time_scale:g}",
                                  "seconds per unit of the time column: 0.001 for ms, 60 for min")
            t = logfiles.time_column(frame, column, path, table, time_scale)
            self.frames[name] = frame
            logs[name] = LogData(name, file, str(path), column, t, {},
                                 tuple(str(c) for c in frame.columns))
        return logs

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
            for key in ("scale", "smoothing"):
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
        low, high = logfiles.finite_values(values * scale)
        if kind == "distance" and not low > 0:
            i = int(np.flatnonzero(np.isfinite(values) & ~(values * scale > 0))[0])
            raise table.error("log", f'"{log.path}" {logfiles.row_label(path, i, logfiles.skipped_rows(frame))}, column '
                              f'"{column}": a cylinder length of {values[i] * scale:g}',
                              "a cylinder's length must be positive: check the column and scale")
        return dict(log=(log.name, column), scale=scale, smoothing=smoothing,
                    from_value=low, to_value=high)


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
}


#: what computes a measurable variable beyond the positions: "velocity" / "acceleration" (a
#: measurement calls for them: :meth:`linkpipe.pipeline.Stages.of`), "forces" (the force
#: stage, which runs only with effects), "springs" (that effect); absent: always computed
MEASURED_NEEDS = {
    "velocity": "velocity", "link_angular_velocity": "velocity",
    "acceleration": "acceleration", "link_angular_acceleration": "acceleration",
    **dict.fromkeys(("input_force", "input_force_lagrange", "link_force", "slider_force",
                     "joint_force", "ground_reaction"), "forces"),
    **dict.fromkeys(("spring_force", "spring_length", "spring_extension", "spring_energy",
                     "torsion_spring_angle", "torsion_spring_torque",
                     "torsion_spring_energy"), "springs"),
}


class MeasurementTables:
    """The ``[[measurements]]`` reader of :class:`~.parse._Parser` (after logs and [time])."""

    def measurement_tables(self, drivers, springs, torsion_springs, sliders, effects=()) -> tuple:
        out = []
        for table in self.entries("measurements"):
            if self.time is None or self.time.log is None:
                raise table.error("log", "a measurement needs [time] log = <its log>: the "
                                  "steps are then the log's rows, where it was measured",
                                  'add [time] with log = "<the log\'s name>"')
            text = table.string("log")
            log_name, dot, column = text.partition(".")
            if not dot or not column:
                raise table.error("log", f"{_show(text)} is not <log>.<column>",
                                  'write e.g. log = "run3.p_force"')
            log = self.log_named(table, "log", log_name, self.logs)
            if log.name != self.time.log:
                raise table.error("log", f'log "{log.name}" is not [time]\'s log '
                                  f'"{self.time.log}": its rows are not the steps',
                                  f'measure from "{self.time.log}", or make [time] log = "{log.name}"')
            frame = self.frames[log.name]
            if column not in frame.columns or column == log.time:
                raise table.error("log", f'log "{log.name}" ("{log.path}") has no data column '
                                  f'"{column}"', logfiles.nearest_columns(column, log.names))
            if column not in log.columns:
                log.columns[column] = logfiles.numeric_column(frame, column, logfiles.Path(log.path),
                                                              table, "log")
            scale = table.number("scale", 1.0)
            sigma = table.number("sigma", None)
            if sigma is not None and not sigma > 0:
                raise table.error("sigma", f"must be positive, got {sigma:g}",
                                  "the measurement's standard deviation, in its scaled unit")
            alarm = table.number("alarm", None)
            if alarm is not None and not (alarm > 0 and sigma is not None):
                raise table.error("alarm", f"alarm = {alarm:g} is a number of sigmas: it needs "
                                  "a positive value and the measurement's sigma",
                                  "give sigma (the measurement's standard deviation) and alarm > 0")
            of = self.measured_of(table, drivers, springs, torsion_springs, sliders)
            need = MEASURED_NEEDS.get(of[0])
            if need == "forces" and not effects or need == "springs" and "springs" not in effects:
                what = ('"springs" in [analysis] effects' if need == "springs" else
                        "the force stage, which runs only with [analysis] effects")
                raise table.error("of", f'"{of[0]}" is computed by {what}; this scene has '
                                  + (f"effects {list(effects)}" if effects else "none"),
                                  'add it, e.g. [analysis] effects = ["springs"]' if need ==
                                  "springs" else 'add the effects the machine has, e.g. '
                                  '[analysis] effects = ["gravity"]')
            out.append(Measurement(table.data["name"], log.name, column, scale, of, sigma,
                                   log.columns[column] * scale, alarm))
        return tuple(out)

    def measured_of(self, table, drivers, springs, torsion_springs, sliders) -> tuple:
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
                 "fixed_points": [n for n, p in self.points.items() if p.fixed]}[kind]
        if rest not in names:
            raise table.error("of", f'{_show(text)}: no {kind[:-1].replace("_", " ")} named '
                              f'{_show(rest)}', _suggest(rest, names) if names else "")
        return variable, rest, axis
