"""Reading ``[[logs]]`` files with pandas (.csv, .parquet) and checking what a scene takes from
them: a time column that is finite and strictly increasing, numeric driver columns, the
columns a driver names. Every problem is one :class:`SceneError` naming the file, the table,
the key, the row and column where it applies, and what to do."""
from __future__ import annotations

import difflib
import json
import math
import re
from pathlib import Path

import numpy as np

from .keys import _Table, _show

#: the formats a log may be (``[[logs]] format``; default from the suffix: .parquet, else csv)
LOG_FORMATS = ("csv", "parquet")
#: delimiters worth suggesting when the one given leaves a single column (as written in TOML)
COMMON_DELIMITERS = {"\t": '"\\t"', ",": '","', ";": '";"', "|": '"|"', " ": '" "'}
#: the logs kept read, up to this many bytes (a joint fit re-reads each of its logs' scenes at
#: every trial; the newest is always kept)
MAX_FRAME_BYTES = 256 * 2 ** 20


def format_of(path: Path, fmt: str | None) -> str:
    """The log's format: ``fmt`` as given, else "parquet" for a .parquet file, else "csv"
    (delimited text of any name)."""
    if fmt is not None:
        return fmt
    return "parquet" if path.suffix.lower() == ".parquet" else "csv"


def resolve(scene_path: str, file: str) -> Path:
    """The log file ``file`` relative to the scene file's folder (absolute paths stay)."""
    base = Path(scene_path).parent if scene_path != "<string>" else Path.cwd()
    return (base / file) if not Path(file).is_absolute() else Path(file)


def _first_long_line(path: Path, sep: str, skip_rows: int) -> tuple[int, int, int]:
    """(line, its fields, the header's fields) of the first line with more fields than the
    header (a plain split: on the error path only); (0, 0, 0) if none is found."""
    def split(line: str) -> list:
        return line.split() if sep == r"\s+" else line.split(sep)

    with open(path, encoding="utf-8", errors="replace") as f:
        header = len(split(f.readline().rstrip("\r\n")))
        for number, line in enumerate(f, start=2):
            if number <= 1 + skip_rows or not line.strip():
                continue
            n = len(split(line.rstrip("\r\n")))
            if n > header:
                return number, n, header
    return 0, 0, 0


def read_frame(table: _Table, path: Path, skip_rows: int = 0, fmt: str | None = None,
               delimiter: str = ","):
    """The log's table (a pandas DataFrame): one SceneError when the file is missing or
    unreadable, naming the file, line and column where it can. ``fmt``: "csv" (delimited text,
    any file name) or "parquet" (default: :func:`format_of`); ``delimiter`` a csv's field
    separator (" ": runs of spaces), read by pandas' C parser. ``skip_rows``: a CSV's rows
    right after its header that are not samples (a units row), left out (the frame's
    ``attrs["skipped_rows"]``). The header is taken as written (a leading ``%`` or ``#`` is
    part of the first name); a header with more fields than the rows gives the extra names
    empty columns; a row with more fields than the header is an error naming its line."""
    import warnings

    import pandas as pd

    fmt = format_of(path, fmt)
    if not path.is_file():
        raise table.error("file", f'no such log file "{path}"',
                          "check the path (a relative path is read from the scene file's folder)")
    if skip_rows and fmt != "csv":
        raise table.error("skip_rows", f"skip_rows = {skip_rows} is for a CSV's rows under its "
                          f'header; "{path}" is Parquet, whose rows are all samples',
                          "remove skip_rows")
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size, skip_rows, fmt, delimiter)
    if key in _FRAMES:  # the same file, unchanged: a fit reads its scene again at every trial
        return _FRAMES[key]
    sep = r"\s+" if delimiter == " " else delimiter
    try:
        if fmt == "csv":
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                frame = pd.read_csv(path, sep=sep, skipinitialspace=sep != r"\s+",
                                    skiprows=range(1, 1 + skip_rows), index_col=False,
                                    engine="c")
            if any("Length of header" in str(w.message) for w in caught):
                line, saw, want = _first_long_line(path, sep, skip_rows)
                raise ValueError(f"Expected {want} fields in line {line}, saw {saw}")
        else:
            frame = pd.read_parquet(path)
    except Exception as exc:  # pandas raises many kinds (parser, arrow, empty, encoding)
        text = " ".join(str(exc).split())  # one line, whatever the library wrote
        ragged = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", text)
        if ragged:
            want, line, saw = ragged.groups()
            raise table.error("file", f'cannot read "{path}": line {line} has {saw} fields, '
                              f"the header {want}", "give every row the header's columns (a "
                              + {",": "comma", "\t": "tab", ";": "semicolon", " ": "space"}.get(
                                  delimiter, f"delimiter {json.dumps(delimiter)}")
                              + " inside a value needs quotes)") from None
        raise table.error("file", f'cannot read "{path}" as {fmt}: {type(exc).__name__}: {text}',
                          "write the log as delimited text with a header row (format = "
                          '"csv" and its delimiter), or as Parquet (format = "parquet")') from None
    if fmt == "csv" and len(frame.columns) == 1:
        header = str(frame.columns[0])
        found = [shown for d, shown in COMMON_DELIMITERS.items() if d != delimiter and d in header]
        raise table.error("delimiter", f'"{path}" line 1: delimiter {json.dumps(delimiter)} leaves '
                          f"the header {_show(header)} one column",
                          (f"the header holds {found[0]}: write delimiter = {found[0]}" if found
                           else 'give the delimiter the file uses ("\\t" for tabs, " " for runs '
                           "of spaces)"))
    frame.attrs["skipped_rows"] = skip_rows
    frame.attrs["format"] = fmt
    _FRAMES[key] = frame
    while len(_FRAMES) > 1 and sum(int(f.memory_usage(deep=False).sum())
                                   for f in _FRAMES.values()) > MAX_FRAME_BYTES:
        _FRAMES.pop(next(iter(_FRAMES)))  # bounded: the oldest read goes
    return frame


#: the last log read, by (path, modification time, size): read-only after reading
_FRAMES: dict = {}


def row_label(path: Path, i: int, skipped: int = 0) -> str:
    """Data row ``i`` (0-based) as a user finds it: 1-based, and the text file's line (header
    = 1, then ``skipped`` rows that are not samples; a Parquet file has rows only)."""
    if path.suffix.lower() != ".parquet":
        return f"row {i + 1} (line {i + 2 + skipped} of the file)"
    return f"row {i + 1}"


def skipped_rows(frame) -> int:
    """The rows under a CSV's header that :func:`read_frame` left out (0: none)."""
    return int(frame.attrs.get("skipped_rows", 0))


def nearest_columns(name: str, names) -> str:
    """A hint listing the columns nearest to ``name`` (difflib), or all of them when few."""
    names = [str(n) for n in names]
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.4)
    same = [n for n in names if n.lower() == name.lower()]
    near = list(dict.fromkeys(same + close))
    listed = ", ".join(f'"{n}"' for n in (near or names[:12]))
    return (f"nearest columns: {listed}" if near else f"the columns are: {listed}"
            + (", ..." if len(names) > 12 else ""))


def numeric_column(frame, column: str, path: Path, table: _Table, key: str) -> np.ndarray:
    """The column as floats (NaN where the log has no value: empty, NaN, NA); text or an
    infinite value is a SceneError naming its row and column."""
    import pandas as pd

    raw = frame[column]
    if raw.dtype.kind in "fiu":
        values = raw.to_numpy(dtype=float)
    else:
        text = raw.astype("string").str.strip()
        blank = raw.isna() | (text == "")
        values = pd.to_numeric(raw.where(~blank), errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~blank.to_numpy() & np.isnan(values))
        if len(bad):
            i = int(bad[0])
            units_row = i == 0 and frame.attrs.get("format") == "csv" and not skipped_rows(frame)
            raise table.error(key, f'"{path}" {row_label(path, i, skipped_rows(frame))}, column "{column}": '
                              f"{_show(str(raw.iloc[i]))} is not a number",
                              "fix that value (leave the cell empty where a sample is missing)"
                              + ("; if it is a row of units under the header, skip_rows = 1 "
                                 "in its [[logs]] entry leaves it out" if units_row else ""))
    bad = np.flatnonzero(np.isinf(values))
    if len(bad):
        i = int(bad[0])
        raise table.error(key, f'"{path}" {row_label(path, i, skipped_rows(frame))}, column "{column}": '
                          f"{values[i]} is not a finite number",
                          "fix that value (leave the cell empty where a sample is missing)")
    return values


def _seconds_from_first(raw) -> np.ndarray:
    """A time column of dates (datetime64) or durations (timedelta64), as seconds from its first
    row (NaN where a stamp is missing)."""
    values = raw.to_numpy(dtype="timedelta64[ns]" if raw.dtype.kind == "m" else "datetime64[ns]")
    finite = ~np.isnat(values)  # (a time zone is dropped: UTC, the same offsets)
    origin = values[finite][0] if finite.any() else values[0]
    seconds = (values - origin) / np.timedelta64(1, "ns") * 1e-9
    return np.where(finite, seconds, np.nan).astype(float)


def _stamps(raw, column: str, path: Path, table: _Table, skipped: int = 0):
    """A text time column as dates (ISO 8601, "2024-05-01 10:00:00.250", offsets taken to UTC)
    or durations ("00:01:02.5") where its first value is one, else as it is (numbers, whose
    own check names a bad row). A column that starts with dates has dates in every row: the
    first that is not one is a SceneError naming its row."""
    import pandas as pd

    text = raw.astype("string").str.strip()
    filled = text[~(raw.isna() | (text == ""))]
    if not len(filled) or not pd.isna(pd.to_numeric(filled.iloc[:1], errors="coerce")).all():
        return raw  # numbers (or nothing): numeric_column reads them
    for kind, parse in (("date", lambda v: pd.to_datetime(v, format="ISO8601", utc=True,
                                                          errors="coerce")),
                        ("duration", lambda v: pd.to_timedelta(v, errors="coerce"))):
        try:
            first = parse(filled.iloc[:1])
        except (ValueError, TypeError):
            continue
        if pd.isna(first).all():
            continue
        if kind == "date":  # an offset on some stamps and not on others: which zone is meant?
            zoned = filled.str.contains(r"(?:Z|[+-]\d\d:?\d\d)$", regex=True).to_numpy()
            if zoned.any() and not zoned.all():
                i = int(np.flatnonzero(zoned != zoned[0])[0])  # among the filled rows
                row = int(np.flatnonzero(raw.index == filled.index[i])[0])
                raise table.error("time", f'"{path}" {row_label(path, row, skipped)}, column '
                                  f'"{column}": {_show(str(filled.iloc[i]))} '
                                  + ("has no UTC offset" if zoned[0] else "has a UTC offset")
                                  + f" and the first row's {_show(str(filled.iloc[0]))} "
                                  + ("has one" if zoned[0] else "has none"),
                                  "give every stamp an offset (e.g. +02:00, or Z for UTC), or none")
        values = parse(text.where(text != ""))
        bad = np.flatnonzero(pd.isna(values).to_numpy() & ~(raw.isna() | (text == "")).to_numpy())
        if len(bad):
            i = int(bad[0])
            raise table.error("time", f'"{path}" {row_label(path, i, skipped)}, column "{column}": '
                              f"{_show(str(raw.iloc[i]))} is not a {kind} like the first row's "
                              f"{_show(str(filled.iloc[0]))}",
                              f"write every time stamp as a {kind} (ISO 8601, e.g. "
                              + ('"2024-05-01 10:00:00.250"' if kind == "date" else '"00:01:02.5"')
                              + "), or all of them as seconds")
        return pd.Series(values, index=raw.index)
    return raw


def time_column(frame, column: str, path: Path, table: _Table, scale: float = 1.0) -> np.ndarray:
    """The time column: numbers, finite and strictly increasing (a SceneError names the file
    and the first bad row otherwise). Dates or durations (a Parquet timestamp column, or a
    CSV's ISO 8601 dates or "hh:mm:ss.f" durations) are seconds from the first row; numbers
    are times ``scale`` seconds (the ``[[logs]]`` entry's ``time_scale``: 0.001 for ms)."""
    if column not in frame.columns:
        raise table.error("time", f'"{path}" has no column "{column}"',
                          nearest_columns(column, frame.columns))
    raw = frame[column]
    if raw.dtype.kind not in "mMfiu":  # text: numbers, or a CSV's dates or durations
        raw = _stamps(raw, column, path, table, skipped_rows(frame))
    if raw.dtype.kind in "mM" and scale != 1.0:
        raise table.error("time_scale", f'time_scale = {scale:g}, but the time column "{column}" '
                          "holds dates or durations, which are read as seconds",
                          "remove time_scale (it scales a column of numbers)")
    t = (_seconds_from_first(raw) if raw.dtype.kind in "mM"
         else numeric_column(frame, column, path, table, "time") * scale)
    if len(t) < 2:
        raise table.error("time", f'"{path}" has {len(t)} row(s): a log needs at least two '
                          "samples", "give the log its samples, one row each")
    missing = np.flatnonzero(np.isnan(t))
    if len(missing):
        raise table.error("time", f'"{path}" {row_label(path, int(missing[0]), skipped_rows(frame))}: the time '
                          f'column "{column}" is empty there', "give every row its time stamp "
                          "(a missing sample is an empty value in its data column)")
    step = np.diff(t)
    bad = np.flatnonzero(~(step > 0))
    if len(bad):
        i = int(bad[0]) + 1
        raise table.error("time", f'"{path}" {row_label(path, i, skipped_rows(frame))}: time {float(t[i])!r} does '
                          f"not increase (the row before has {float(t[i - 1])!r}); the time "
                          "column must be strictly increasing", "sort the log by time and remove repeated "
                          "time stamps")
    return t


def check_spans(log, instants: np.ndarray, table: _Table, key: str) -> None:
    """A sweep asking for instants outside the log's time column is an error, never an
    extrapolation."""
    lo, hi = float(log.t[0]), float(log.t[-1])
    first, last = float(instants[0]), float(instants[-1])
    tiny = 1e-12 * max(1.0, abs(lo), abs(hi))
    if first < lo - tiny or last > hi + tiny:
        lag = getattr(log, "lag", 0.0)
        shifted = f" (its stamps less lag = {lag:g} s)" if lag else ""
        raise table.error(key, f'[time] runs from {first:g} s to {last:g} s but log '
                          f'"{log.name}" ("{log.path}") covers only {lo:g} s to {hi:g} s'
                          + shifted, (f"a lag of at most {lag - max(lo - first, last - hi):g} s "
                                      "keeps it on [time], or " if lag else "")
                          + f"shorten [time] to lie within {lo:g} .. {hi:g} s, or use "
                          f'[time] log = "{log.name}" (the log\'s own rows); a log is never '
                          "extrapolated")


def finite_values(values: np.ndarray) -> tuple[float, float]:
    """The smallest and largest finite value (NaN, NaN when there is none)."""
    finite = values[np.isfinite(values)]
    return (float(finite.min()), float(finite.max())) if len(finite) else (math.nan, math.nan)
