"""``<name>.h5`` growing along ``step`` while ``follow`` runs: HDF5 SWMR (single writer,
multiple readers), readable by other processes at any moment, resumable after any stop.

The layout is :mod:`.hdf5`'s (the same names, dims, units and dimension scales as ``run``
writes), with every step-first dataset chunked and extendible. The root attribute
``complete`` is 0 while the file grows and 1 once it has ended (then the root attributes hold
the whole file's totals, as ``run``'s). Readers: ``h5py.File(path, "r", swmr=True)`` (the
lengths and values they see are consistent at every flush: each block's rows are written to
every variable, then ``step`` is extended last, then flushed: ``step``'s length is the rows
stored, and other variables may be longer by the block being written).

A stop of any kind leaves the rows of every flushed block: a clean end (idle, Ctrl-C,
SIGTERM) reopens the file to finish its attributes; a killed writer leaves it marked open
(HDF5 then refuses other than SWMR reads), and the next :class:`GrowingWriter` on it copies
its stored rows into a new file and goes on.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np

from ..result import Result, Totals, Variable, combine_flags
from .hdf5 import (_PHANTOM, _array, _set_attr, _write_coordinate, _write_variable,
                   root_attributes)

#: seconds the end waits for readers that hold the file to let it go (then: without the lock)
LOCK_WAIT = 5.0
#: rows read at a time where the whole file is read back (totals, RMS, a copy)
READ_ROWS = 1 << 20
#: bytes of chunk cache per dataset: the rows go in order, so the chunk being filled is all a
#: dataset needs (HDF5's default 1 MiB each, over ~40 datasets, held ~40 MB more)
CHUNK_CACHE = 1 << 18


@dataclass(frozen=True)
class Stored:
    """What a file of an earlier ``follow`` holds: ``rows`` stored, the ``time`` of the last
    one (NaN: none), its ``link_angle`` (n_links,), whether it was ``complete``, whether its
    writer was killed (``open``: HDF5's flags say it is still open for writing), the scene's
    TOML it was made from, the per-sweep flags so far, and whether ``follow`` wrote it
    (``followed``: a ``run``'s file has fixed-size datasets, which cannot grow)."""

    rows: int
    time: float
    link_angle: np.ndarray | None
    complete: bool
    killed: bool
    scene_toml: str
    flags: dict
    followed: bool = True
    #: the log's first row as it was read when the file was made ({"t": seconds, "columns":
    #: {name: value}}; None in a file without it): a log replaced by another with other rows
    first_row: dict | None = None


def stored(path) -> Stored | None:
    """The rows in ``path`` (None: no such file)."""
    path = Path(path)
    if not path.exists():
        return None
    killed = False
    try:
        f = h5py.File(path, "r")
    except OSError:
        f = h5py.File(path, "r", swmr=True)  # a killed writer's file: SWMR reads only
        killed = True
    with f:
        n = int(f["step"].shape[0]) if "step" in f else 0
        t = float(f["time"][n - 1]) if n and "time" in f else float("nan")
        ang = f["link_angle"][n - 1] if n and "link_angle" in f else None
        toml = f.attrs.get("scene_toml", "")
        flags = {}
        for name, ds in f.items():
            if name.endswith("_unique") and not ds.is_scale:
                from .hdf5 import dimensions

                flags[name] = (dimensions(ds), ds[()], ds.attrs.get("units", ""))
        first = f.attrs.get("follow_first_row")
        first = json.loads(first.decode() if isinstance(first, bytes) else first) \
            if first is not None else None
        return Stored(n, t, ang, bool(f.attrs.get("complete", 1)), killed,
                      toml.decode() if isinstance(toml, bytes) else str(toml), flags,
                      "complete" in f.attrs, first)


class GrowingWriter:
    """Append blocks of rows (Results with ``step_numbers``) to ``path``; ``finish`` marks it
    complete. ``template``: a Result of the scene (a few rows: the layout's variables,
    coordinates and first attributes); ``resume``: the :class:`Stored` of the file already
    there (its rows kept). The file is open (and readable) from here on."""

    stage = "hdf5"

    def __init__(self, path, template: Result, resume: Stored | None = None,
                 first_row: dict | None = None):
        self.path = Path(path)
        self.resume = resume
        # the log's first row, kept in the file (a resumed file keeps its own)
        self.first_row = (resume.first_row if resume is not None and resume.first_row
                          else first_row)
        self.rows = resume.rows if resume else 0
        self.flags: dict = dict(resume.flags) if resume else {}
        self._file: h5py.File | None = None
        self._data: dict[str, h5py.Dataset] = {}
        self.template: Result = template
        self._open(template)

    # ----------------------------------------------------------------------- opening
    def _create(self, target: Path, part: Result) -> h5py.File:
        f = h5py.File(target, "w", libver="latest", track_order=True,
                      rdcc_nbytes=CHUNK_CACHE)
        per_row = sum(v.data[:1].nbytes for v in part.variables() if v.dims[:1] == ("step",))
        chunk = int(max(256, min(8192, (256 << 10) // max(per_row, 1))))
        scales = {}
        step = f.create_dataset("step", shape=(0,), maxshape=(None,), chunks=(chunk,),
                                dtype=np.int64)
        step.make_scale("step")
        step.attrs["units"] = "1"
        scales["step"] = step
        for c in part.coordinates():
            if c.name != "step":
                scales[c.name] = _write_coordinate(f, c)
        for var in part.variables():
            data = _array(var.data)
            if var.dims[:1] == ("step",):
                ds = f.create_dataset(var.name, shape=(0,) + data.shape[1:],
                                      maxshape=(None,) + data.shape[1:],
                                      chunks=(chunk,) + data.shape[1:], dtype=data.dtype)
            else:
                ds = f.create_dataset(var.name, data=data)
            ds.attrs["units"] = var.units
            for key, value in var.attrs.items():
                if key not in ("rms", "max_abs"):  # the whole file's: set when it ends
                    _set_attr(ds.attrs, key, value)
            for axis, dim in enumerate(var.dims):
                if dim not in scales:
                    scale = f.create_dataset(dim, data=np.arange(data.shape[axis], dtype=np.int64))
                    scale.make_scale(_PHANTOM)
                    scales[dim] = scale
                ds.dims[axis].attach_scale(scales[dim])
        for key, value in root_attributes(part).items():
            _set_attr(f.attrs, key, value)
        f.attrs["complete"] = np.int8(0)
        if self.first_row is not None:  # exact: json writes each float's shortest repr
            f.attrs["follow_first_row"] = json.dumps(self.first_row)
        return f

    def _open(self, part: Result) -> None:
        """Open the file for the first block: a new one, the one there (ended cleanly), or a
        copy of a killed writer's rows in a new file."""
        if self.resume is None or self.resume.rows == 0:
            tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
            self._file = self._create(tmp, part)
            self._datasets()
            os.replace(tmp, self.path)
        elif not self.resume.killed:
            self._file = _writable(self.path, libver="latest", rdcc_nbytes=CHUNK_CACHE)
            self._file.attrs["complete"] = np.int8(0)
            self._datasets()
        else:
            tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
            self._file = self._create(tmp, part)
            self._datasets()
            self._copy_rows(self.path, self.resume.rows)
            os.replace(tmp, self.path)
        self._file.swmr_mode = True

    def _datasets(self) -> None:
        self._data = {name: ds for name, ds in self._file.items()
                      if not ds.is_scale and ds.dims[0] and len(ds.dims[0])
                      and ds.dims[0][0].name == "/step"}
        self._data["step"] = self._file["step"]

    def _copy_rows(self, old_path: Path, n: int) -> None:
        """The first ``n`` rows of every step variable of ``old_path`` (a killed writer's)."""
        with h5py.File(old_path, "r", swmr=True) as old:
            missing = [k for k in self._data if k not in old]
            if missing:
                raise OSError(f"{old_path}: no variable {missing[0]!r}: it was not written "
                              "from this scene")
            for lo in range(0, n, READ_ROWS):
                hi = min(n, lo + READ_ROWS)
                for name, ds in self._data.items():
                    ds.resize((hi,) + ds.shape[1:])
                    ds[lo:hi] = old[name][lo:hi]

    # ----------------------------------------------------------------------- writing
    def add(self, part: Result) -> None:
        """Append ``part``'s rows (its ``step_numbers`` must continue the file)."""
        steps = np.asarray(part.step_numbers)
        if steps[0] != self.rows:
            raise ValueError(f"rows from {steps[0]} given, the file holds {self.rows}")
        lo, hi = self.rows, self.rows + len(steps)
        for var in part.variables():
            ds = self._data.get(var.name)
            if ds is not None and var.dims[:1] == ("step",):
                ds.resize((hi,) + ds.shape[1:])
                ds[lo:hi] = _array(var.data)
        before = {k: v[1].copy() for k, v in self.flags.items()}
        combine_flags(self.flags, part.forces or {})
        for name, (dims, data, units) in self.flags.items():
            if name in self._file and (name not in before or (before[name] != data).any()):
                self._file[name][...] = data
        # the variables on disk before ``step`` grows: HDF5's metadata cache may write a
        # dataset's new shape in any order at a flush, and a reader takes ``step`` as the rows
        # it may read (blocks come faster than a flush's order could be left to chance)
        self._file.flush()
        step = self._data["step"]
        step.resize((hi,))
        step[lo:hi] = steps
        self._file.flush()
        self.rows = hi

    def close(self) -> None:
        """Close the file as it is (``complete`` stays 0: a crash's state, for tests)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def finish(self, seconds: dict | None = None, extra: dict | None = None) -> None:
        """Close the SWMR file and reopen it to write the whole file's attributes (the root's
        as ``run`` writes them: totals, RMS of the measurements) and ``complete`` = 1."""
        self.close()
        if not self.path.exists():
            return
        with _writable(self.path) as f:
            self._finish(f, seconds, extra)

    def _finish(self, f: h5py.File, seconds, extra) -> None:
        n = int(f["step"].shape[0])
        template = self.template
        totals, sums = None, None
        names = [v.name for v in template.variables() if v.dims[:1] == ("step",)]
        for lo in range(0, n, READ_ROWS):
            hi = min(n, lo + READ_ROWS)
            part = _rows_of(template, {k: f[k][lo:hi] for k in names if k in f}, lo)
            t = Totals.of(part)
            totals = t if totals is None else totals.merged(t)
            if "measured_residual" in f:
                r = f["measured_residual"][lo:hi]
                fin = np.isfinite(r)
                s = (np.where(fin, r, 0.0) ** 2).sum(axis=0), fin.sum(axis=0), np.where(
                    fin, np.abs(r), 0.0).max(axis=0, initial=0.0)
                sums = s if sums is None else (sums[0] + s[0], sums[1] + s[1],
                                               np.maximum(sums[2], s[2]))
        if totals is None:  # no row stored
            totals = Totals.of(template.strided(np.arange(0)))
        if sums is not None:
            with np.errstate(invalid="ignore"):
                count = np.maximum(sums[1], 1)
                rms = np.where(sums[1] > 0, np.sqrt(sums[0] / count), np.nan)
                top = np.where(sums[1] > 0, sums[2], np.nan)
            f["measured_residual"].attrs["rms"] = rms
            f["measured_residual"].attrs["max_abs"] = top
        forces = dict(template.forces or {})
        forces.update(self.flags)
        scales = {name: ds for name, ds in f.items() if ds.is_scale}
        for name, (dims, data, units) in self.flags.items():
            if name in f:
                f[name][...] = data
            else:  # a flag no block gave before (no ok step in it)
                _write_variable(f, Variable(name, dims, data, units), scales)
        summary = replace(template, sweep_totals=totals, forces=forces or None,
                          seconds=dict(seconds or {}))
        for key, value in root_attributes(summary).items():
            _set_attr(f.attrs, key, value)
        for key, value in (extra or {}).items():
            _set_attr(f.attrs, key, value)
        f.attrs["complete"] = np.int8(1)


def _writable(path: Path, **options) -> h5py.File:
    """``path`` opened to write outside SWMR (its end, or a clean file resumed). HDF5's lock
    keeps readers out meanwhile (one that opens then is refused, and tries again: a reader
    of a file changing under it outside SWMR was seen to loop for ever); a reader that holds
    the file already makes the lock fail: tried again for :data:`LOCK_WAIT` seconds, then
    opened without the lock (the file must end complete; the reader holding it reads what
    it had)."""
    end = time.monotonic() + LOCK_WAIT
    while True:
        try:
            return h5py.File(path, "r+", **options)
        except OSError as exc:
            if "lock" not in str(exc):
                raise
        if time.monotonic() > end:
            return h5py.File(path, "r+", locking=False, **options)
        time.sleep(0.05)


def _rows_of(template: Result, arrays: dict, first: int) -> Result:
    """A Result of rows read back from a file (``arrays``: name -> rows), for its totals."""
    fields = {name: arrays[name] for name in Result.PER_STEP if name in arrays}
    n = len(arrays["status"])
    for name in Result.PER_STEP:
        if name not in fields and getattr(template, name) is not None:
            fields[name] = None
    forces = None
    if template.forces:
        forces = {k: (dims, arrays[k] if dims[:1] == ("step",) else data, u)
                  for k, (dims, data, u) in template.forces.items()
                  if dims[:1] != ("step",) or k in arrays}
    return replace(template, **fields, forces=forces, measurements=None, kinematics=None,
                   step_numbers=np.arange(first, first + n), sweep_totals=None)
