"""A log that is still being written, read as it grows: the rows that are complete.

:class:`CsvTail` reads a delimited text log from the byte where it stopped: a last line
without its end of line waits for it (the logger is mid-write), every complete line is one
row. :class:`ParquetTail` reads Parquet files that a logger closes one after another (a glob:
``rig/run_*.parquet``, taken in name order) and a file rewritten with more row groups (the
new groups). Both return the new rows as arrays (the time column in seconds, each wanted
column as floats, NaN where empty) and check what a live source can do wrong, each one
:class:`LogFault` naming the file and row: the file truncated or replaced under the reader (a
rotation), a time that does not increase, a row with fewer fields than the header (a column
that disappeared), text in a number's place. No maths here; :mod:`linkpipe.follow.run` solves.
"""
from __future__ import annotations

import glob as globbing
import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import LinkpipeError

#: a plain decimal number (no exponent, no quotes): read without pandas
_PLAIN = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")


class LogFault(LinkpipeError):
    """The live log did something the rows stored so far cannot follow (exit status 1: the
    source failed, not the scene)."""

    exit_code = 1


@dataclass
class Rows:
    """New complete rows: ``t`` (n,) seconds, ``columns`` {name: (n,) float}; ``fault``: the
    :class:`LogFault` met after these rows (the rows before it are good), or None."""

    t: np.ndarray
    columns: dict
    fault: LogFault | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class TailState:
    """What the reader has read: rows so far, the last time, the partial last line's bytes."""

    rows: int = 0
    last_t: float = -np.inf
    partial: bytes = b""
    waiting_since: float | None = field(default=None)


def _line_of(path: Path, row: int, skipped: int) -> str:
    """Row ``row`` (0-based, over every file read) as a user finds it."""
    if path.suffix.lower() == ".parquet":
        return f"row {row + 1}"
    return f"row {row + 1} (line {row + 2 + skipped} of the file)"


class CsvTail:
    """Delimited text read as it grows (``poll()`` returns the new complete rows).

    ``time`` the time column (times ``time_scale`` seconds), ``wanted`` the data columns to
    return, ``delimiter`` the field separator, ``skip_rows`` rows under the header that are not
    samples. The file is held open: a file whose inode changes under its path (a rotation), or
    that becomes shorter than what was read (truncated), is a fault after the rows read."""

    def __init__(self, path, time: str, wanted, time_scale: float = 1.0, delimiter: str = ",",
                 skip_rows: int = 0):
        self.path = Path(path)
        self.time, self.wanted, self.time_scale = time, tuple(wanted), time_scale
        self.delimiter, self.skip_rows = delimiter, skip_rows
        self.state = TailState()
        self._file = None
        self._offset = 0
        self.header: list[str] | None = None
        self._to_skip = skip_rows

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def _open(self) -> bool:
        if self._file is not None:
            return True
        try:
            self._file = open(self.path, "rb")
        except FileNotFoundError:
            return False
        self._ino = os.fstat(self._file.fileno()).st_ino
        return True

    def _replaced(self) -> str:
        """Why the file under the path is no longer the one read ("" when it is)."""
        try:
            now = os.stat(self.path)
        except FileNotFoundError:
            return "was removed (rotated away)"
        if now.st_ino != self._ino:
            return "was replaced by another file (a rotation)"
        if now.st_size < self._offset:
            return f"was truncated to {now.st_size:,} bytes (after {self._offset:,} read)"
        return ""

    def poll(self) -> Rows:
        """The complete rows written since the last poll (none: an empty :class:`Rows`)."""
        empty = Rows(np.empty(0), {c: np.empty(0) for c in self.wanted})
        if not self._open():
            return empty
        why = self._replaced()
        if why:
            empty.fault = LogFault(f'{self.path}: the log {why}; the {self.state.rows:,} rows '
                                   "read before are kept")
            return empty
        self._file.seek(self._offset)
        new = self._file.read()
        if not new:
            return empty
        self._offset += len(new)
        data = self.state.partial + new
        end = data.rfind(b"\n")
        if end < 0:
            self.state.partial = data
            return empty
        lines, self.state.partial = data[:end + 1], data[end + 1:]
        if self.header is None:
            first = lines.find(b"\n")
            self.header = self._fields(lines[:first].decode("utf-8").rstrip("\r"))
            missing = [c for c in (self.time, *self.wanted) if c not in self.header]
            if missing:
                empty.fault = LogFault(f'{self.path}: the header has no column "{missing[0]}" '
                                       f"(it has {', '.join(self.header)})")
                self.header = None
                return empty
            lines = lines[first + 1:]
        while self._to_skip and lines:
            cut = lines.find(b"\n")
            lines, self._to_skip = lines[cut + 1:], self._to_skip - 1
        if not lines.strip():
            return empty
        return self._rows(lines)

    def _fields(self, line: str) -> list[str]:
        if self.delimiter == " ":
            return line.split()
        return [f.strip() for f in line.split(self.delimiter)]

    def _rows(self, lines: bytes) -> Rows:
        """Parse complete ``lines``; the first bad one ends them with its fault."""
        import pandas as pd

        text = lines.decode("utf-8", errors="replace")
        raw = text.splitlines()
        keep = [line for line in raw if line.strip()]
        first_row = self.state.rows
        fault = None
        n_fields = len(self.header)
        sep = r"\s+" if self.delimiter == " " else self.delimiter
        counts = np.array([len(self._fields(line)) if self.delimiter == " "
                           else line.count(self.delimiter) + 1 for line in keep])
        short = np.flatnonzero(counts < n_fields)
        if len(short):
            i = int(short[0])
            row = first_row + i
            fault = LogFault(f"{self.path}: {_line_of(self.path, row, self.skip_rows)} has "
                             f"{counts[i]} fields, the header {n_fields}: a column disappeared "
                             f"(the last, \"{self.header[-1]}\", or one before it); the "
                             f"{row:,} rows before it are kept")
            keep = keep[:i]
        if not keep:
            return Rows(np.empty(0), {c: np.empty(0) for c in self.wanted}, fault)
        quick = self._plain(keep) if (counts[:len(keep)] == n_fields).all() else None
        if quick is not None:
            t = quick.pop(self.time) * self.time_scale
            return self._checked(t, quick, len(keep), fault)
        try:
            frame = pd.read_csv(io.StringIO("\n".join(keep)), header=None, names=self.header,
                                sep=sep, skipinitialspace=True, usecols=[self.time, *self.wanted],
                                index_col=False)
        except Exception as exc:  # noqa: BLE001 (more fields than the header, quotes, ...)
            text = " ".join(str(exc).split())
            raise LogFault(f"{self.path}: cannot read rows {first_row + 1:,} .. "
                           f"{first_row + len(keep):,}: {text}") from None
        columns, bad = {}, len(keep)
        for name in (self.time, *self.wanted):
            values = pd.to_numeric(frame[name], errors="coerce").to_numpy(dtype=float)
            text_there = np.flatnonzero(np.isnan(values) & frame[name].notna().to_numpy()
                                        & (frame[name].astype(str).str.strip() != "").to_numpy())
            if len(text_there) and text_there[0] < bad:
                bad = int(text_there[0])
                fault = LogFault(f'{self.path}: {_line_of(self.path, first_row + bad, self.skip_rows)}, '
                                 f'column "{name}": {str(frame[name].iloc[bad])!r} is not a number; '
                                 f"the {first_row + bad:,} rows before it are kept")
            columns[name] = values
        t = columns.pop(self.time) * self.time_scale
        return self._checked(t, columns, bad, fault)

    def _plain(self, keep: list[str]) -> dict | None:
        """{name: (n,) float} of ``keep``'s lines when every field read is a plain decimal of
        at most 15 digits (``-12.345``), else None (pandas reads them). The same floats as
        pandas' reader (the log's batch reader): its converter gathers the digits into an
        exact integer (< 2^53) and takes one multiplication or division by an exact power of
        ten, a correctly rounded result, as Python's ``float`` is. No pandas call: a poll
        brings a few rows (1 kHz, 5 ms), where pandas costs ~2 ms CPU (docs/follow.md)."""
        if self.delimiter == " ":
            fields = [line.split() for line in keep]
        else:
            fields = [line.split(self.delimiter) for line in keep]
        out = {}
        for name in (self.time, *self.wanted):
            i = self.header.index(name)
            texts = [row[i].strip() for row in fields]
            for text in texts:
                if not _PLAIN.fullmatch(text) or sum(c.isdigit() for c in text) > 15:
                    return None
            out[name] = np.array([float(text) for text in texts])
            if (out[name] == 0).any():  # "-0": pandas reads an integer 0 (its sign lost)
                return None
        return out

    def _checked(self, t, columns, bad: int, fault) -> Rows:
        """Rows up to ``bad`` whose time is finite and increasing (the first that is not ends
        them with its fault); the reader's state moves past the rows returned."""
        first_row = self.state.rows
        prev = np.r_[self.state.last_t, t[:-1]]
        wrong = np.flatnonzero(~(t > prev))  # NaN compares False: a missing stamp too
        if len(wrong) and wrong[0] < bad:
            bad = int(wrong[0])
            row = first_row + bad
            now, before = float(t[bad]), float(prev[bad])
            what = ("has no time stamp" if np.isnan(now) else
                    f"time {now!r} s goes backwards (the row before has {before!r} s)"
                    if now < before else f"time {now!r} s repeats the row before's")
            fault = LogFault(f"{self.path}: {_line_of(self.path, row, self.skip_rows)}: {what}; "
                             f"the {row:,} rows before it are kept")
        t = t[:bad]
        columns = {k: v[:bad] for k, v in columns.items()}
        if len(t):
            self.state.rows += len(t)
            self.state.last_t = float(t[-1])
        return Rows(t, columns, fault)


class ParquetTail(CsvTail):
    """Parquet files matching ``pattern`` (one file, or a glob), in name order: each file's
    row groups as they appear (a file is read once its footer is written; a file rewritten
    with more row groups gives the new ones). A file that disappears or shrinks below the
    groups read is a fault, as a rotated CSV."""

    def __init__(self, pattern, time: str, wanted, time_scale: float = 1.0):
        super().__init__(pattern, time, wanted, time_scale)
        self.pattern = str(pattern)
        self._groups: dict[str, int] = {}  # file -> row groups read

    def close(self) -> None:
        pass

    def poll(self) -> Rows:
        import pyarrow.parquet as pq

        ts, cols, fault = [], {c: [] for c in self.wanted}, None
        files = sorted(globbing.glob(self.pattern)) if globbing.has_magic(self.pattern) else (
            [self.pattern] if os.path.exists(self.pattern) else [])
        for name in self._groups:
            if name not in files:
                fault = LogFault(f"{name}: the log file was removed (rotated away); the "
                                 f"{self.state.rows:,} rows read before are kept")
        done_files = [f for f in self._groups]
        if fault is None and done_files and files and files[0] < done_files[-1] and \
                any(f not in self._groups and f < done_files[-1] for f in files):
            late = next(f for f in files if f not in self._groups and f < done_files[-1])
            fault = LogFault(f"{late}: a new log file sorts before {done_files[-1]}, which was "
                             f"read: its rows would come out of order; the {self.state.rows:,} "
                             "rows read are kept")
        for name in files if fault is None else ():
            try:
                pf = pq.ParquetFile(name)
            except Exception:  # noqa: BLE001 (no footer yet: the logger is writing it)
                break
            have = self._groups.get(name, 0)
            if pf.num_row_groups < have:
                fault = LogFault(f"{name}: the log file now has {pf.num_row_groups} row groups, "
                                 f"{have} were read (it was replaced); the rows read are kept")
                break
            missing = [c for c in (self.time, *self.wanted) if c not in pf.schema_arrow.names]
            if missing:
                fault = LogFault(f'{name}: no column "{missing[0]}" (a column disappeared); the '
                                 f"{self.state.rows:,} rows read before are kept")
                break
            for g in range(have, pf.num_row_groups):
                table = pf.read_row_group(g, columns=[self.time, *self.wanted])
                t = table.column(self.time).to_numpy(zero_copy_only=False).astype(float)
                got = {c: table.column(c).to_numpy(zero_copy_only=False).astype(float)
                       for c in self.wanted}
                rows = self._checked(t * self.time_scale, got, len(t), None)
                ts.append(rows.t)
                for c in self.wanted:
                    cols[c].append(rows.columns[c])
                self._groups[name] = g + 1
                if rows.fault is not None:
                    fault = LogFault(f"{name}: {rows.fault}")
                    break
            if fault is not None:
                break
            self._groups.setdefault(name, pf.num_row_groups)
        t = np.concatenate(ts) if ts else np.empty(0)
        return Rows(t, {c: (np.concatenate(v) if v else np.empty(0)) for c, v in cols.items()},
                    fault)
