"""Write a :class:`~linkpipe.result.Result` as a netCDF-4 style HDF5 file, and read it back.

Layout (``docs/output-format.md``): one HDF5 dataset per coordinate and data variable at
the root, named as in ``Result.coordinates()`` / ``Result.variables()``. Coordinate variables
are HDF5 dimension scales and every data variable has them attached, so h5py, xarray
(``engine="h5netcdf"``), MATLAB and HDFView all see labelled dimensions.
"""
from __future__ import annotations

import functools
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import h5py
import numpy as np

from ..errors import LinkpipeError
from ..result import combine_flags
from ..result import Variable
from ..workers import held_interrupts
from ..version import __version__
from . import atomic_path

STR = h5py.string_dtype("utf-8")
#: the netCDF-4 marker for a dimension that has no coordinate variable
_PHANTOM = "This is a netCDF dimension but not a netCDF variable."


def write(result, path: str | os.PathLike) -> None:
    """Write ``result`` to ``path`` atomically (temporary file, then ``os.replace``)."""
    with SweepWriter(path, result.n_steps) as writer:
        writer.add(result)
        writer.finish(result)


def _clean_failures(method):
    """Re-raise an OSError from h5py (a full disk) as a new one that holds no h5py frames: a
    traceback that keeps a dataset of a file that then fails to close alive was seen to crash
    the garbage collector later. The caller (``atomic_path``) turns ENOSPC into OutputError."""
    @functools.wraps(method)
    def wrapper(*args, **kwargs):
        failure = None
        try:
            return method(*args, **kwargs)
        except OSError as exc:
            failure = OSError(exc.errno, str(exc).splitlines()[0] if str(exc) else "write failed")
        raise failure

    return wrapper


class SweepWriter:
    """Write one run's file from its rows as they come, step-first variables into datasets of
    the whole sweep's length, each part's rows written in place (a sweep solved in segments:
    :mod:`linkpipe.segments`; a whole Result is one part). A context manager: the file is
    written to a temporary name and renamed into place only when :meth:`finish` was called
    with every step written and nothing failed.

    ``add(part)``: a Result of the sweep's next consecutive steps (``part.step_numbers``, or all
    of them): the first part creates the file's layout; each writes its rows, and the variables
    without a step axis (the ``*_unique`` flags, which a part without an ok step does not
    give) are the minimum over the parts that give them, as the force stage takes them over
    its chunks. ``restart()``: the parts come again from the first step. ``finish(result)``:
    the flags and the root attributes (:func:`root_attributes`: the whole sweep's totals).

    A full disk must fail cleanly, one part written or many: the datasets are contiguous (a
    failed write into a chunked one was measured to crash the process when the file closes:
    HDF5 2.0 through h5py 3.16) and HDF5's sieve buffer is off (with it, a write that failed
    between two parts left dirty data that crashed the close likewise;
    ``tests/faults/test_writes.py`` streams several parts onto a full disk)."""

    stage = "hdf5"

    def __init__(self, path: str | os.PathLike, n_steps: int):
        self.path, self.n_steps = path, n_steps
        self._atomic = self._file = None
        self._flags: dict = {}  # name -> (dims, data, units) of a per-sweep flag, so far
        self._datasets: dict = {}
        self._scales: dict = {}
        self._next = 0  # the first step the next part must hold
        self._finished = False
        self._thread: ThreadPoolExecutor | None = None  # writes a part's rows while the next solves
        self._pending: Future | None = None
        self._fd: int | None = None  # the temporary file's descriptor (each part synced)
        self._syncer: ThreadPoolExecutor | None = None  # syncs the parts while the next is written
        self._syncing: Future | None = None

    def __enter__(self) -> "SweepWriter":
        return self

    def __exit__(self, *exc) -> None:
        raised = None
        try:
            self._wait()
        except BaseException as error:  # noqa: BLE001 (a part that failed to write, or Ctrl-C
            raised = error              # while waiting: the file is not kept)
        stop = self._end_thread()  # every write has ended before the file closes
        raised = raised or stop
        self._datasets.clear()  # no dataset outlives its file (h5py objects of a file that
        self._scales.clear()    # failed to close were seen to crash the garbage collector)
        try:
            if self._file is not None:
                self._file.close()  # h5py flushes here: a full disk may show now
        except BaseException as error:  # noqa: BLE001 (any failure to close loses the file;
            raised = error              # a Ctrl-C here still removes the temporary below)
        finally:
            self._file = None
        if self._atomic is None:
            if raised is not None and exc[0] is None:
                raise raised
            return
        if exc[0] is None and raised is not None:
            exc = (type(raised), raised, raised.__traceback__)
        elif exc[0] is None and not self._finished:  # left early: nothing is kept
            exc = (RuntimeError, RuntimeError("the writer was not finished"), None)
            raised = None
        else:
            raised = None
        # the temporary file is removed on an exception (a full disk becomes OutputError)
        self._atomic.__exit__(*exc)
        if raised is not None:
            raise raised

    @_clean_failures
    def _open(self, part) -> None:
        variables = part.variables()
        per_step = sum(v.data.nbytes for v in variables if v.dims[:1] == ("step",))
        n_bytes = per_step * self.n_steps // max(1, part.n_steps) + sum(
            v.data.nbytes for v in variables if v.dims[:1] != ("step",))
        self._atomic = atomic_path(self.path, n_bytes)
        tmp = self._atomic.__enter__()
        f = self._file = _new_file(tmp)
        try:
            self._fd = f.id.get_vfd_handle()
        except Exception:  # noqa: BLE001 (a driver without a descriptor: the final fsync only)
            self._fd = None
        for c in part.coordinates():
            if c.name == "step":
                ds = f.create_dataset("step", shape=(self.n_steps,), dtype=np.int64)
                ds.make_scale("step")
                ds.attrs["units"] = c.units
                self._scales["step"] = self._datasets["step"] = ds
            else:
                self._scales[c.name] = _write_coordinate(f, c)
        timed = any(v.name == "time" and v.dims == ("step",) for v in variables)
        for var in variables:
            shape = ((self.n_steps,) + var.data.shape[1:] if var.dims[:1] == ("step",)
                     else None)
            if timed and shape is not None and var.name != "time":
                var = time_coordinate(var)
            self._datasets[var.name] = _write_variable(f, var, self._scales, shape)

    def add(self, part) -> None:
        """Take the sweep's next part: its rows are written on the writer's thread while the
        caller solves the next one (h5py's writes release the GIL); this waits for the part
        before it (whose failure, a full disk, is raised here)."""
        steps = (part.step_numbers if part.step_numbers is not None
                 else np.arange(part.n_steps))
        self._wait()
        if not len(steps) or steps[0] != self._next or steps[-1] - steps[0] + 1 != len(steps):
            raise ValueError(f"a part must hold the next consecutive steps from {self._next}")
        if self._file is None:
            self._open(part)
        rows = slice(int(steps[0]), int(steps[-1]) + 1)
        combine_flags(self._flags, part.forces or {})  # the force stage's rule over its chunks
        self._next = rows.stop
        if self._thread is None:
            self._thread = ThreadPoolExecutor(1, thread_name_prefix="linkpipe-hdf5")
        self._pending = self._thread.submit(self._write_rows, part, rows, steps)

    @_clean_failures
    def _write_rows(self, part, rows: slice, steps: np.ndarray) -> None:
        """Write ``part``'s rows (the writer's thread), then, but for the sweep's last part,
        start them to the disk (``fdatasync`` on a thread of its own, :meth:`_sync_behind`)
        while the next part is written and the caller solves the one after: the disk works
        alongside both, and the final fsync (``atomic_path``) has only the last parts and
        HDF5's metadata left to wait for. Measured on the 360k-step
        crank-rocker (134 MB, 22 parts, 2026-11-25): a run 0.84 -> 0.68 s (median of 6),
        the final fsync 0.17 -> 0.00 s; starting the writeback alone
        (``posix_fadvise(DONTNEED)``) had left 0.17 s. A Ctrl-C meanwhile waits for the sync in
        flight (the parts written since the last one: milliseconds on a local disk)."""
        self._datasets["step"][rows] = steps
        for var in part.variables():
            if var.dims[:1] == ("step",):
                self._datasets[var.name][rows] = _array(var.data)
        if self._fd is not None and rows.stop < self.n_steps:
            self._sync_behind()

    def _sync_behind(self) -> None:
        """Start the parts written so far to the disk (``fdatasync``) on a thread of its own,
        unless a sync is still running (the next part's, or the final fsync, covers these);
        a failed sync (a full disk found at writeback) is raised here, at the next part."""
        if self._syncing is not None:
            if not self._syncing.done():
                return
            self._syncing.result()
        if self._syncer is None:
            self._syncer = ThreadPoolExecutor(1, thread_name_prefix="linkpipe-hdf5-sync")
        self._syncing = self._syncer.submit(_sync_data, self._fd)

    def _wait(self) -> None:
        """Wait for the part being written; raise its failure."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def _end_thread(self) -> BaseException | None:
        """Wait for the writer's thread, then the syncing one, to end, whatever happened (no
        write or sync outlives the file: a part's copy takes milliseconds, so a Ctrl-C
        meanwhile is held until then and returned, for the caller to raise once the file is
        closed and removed)."""
        held = None
        for name in ("_thread", "_syncer"):
            pool = getattr(self, name)
            if pool is not None:
                held = held_interrupts(lambda: pool.shutdown(wait=True, cancel_futures=True)) or held
                setattr(self, name, None)
        return held

    def restart(self) -> None:
        self._wait()
        self._flags, self._next = {}, 0

    @_clean_failures
    def finish(self, result) -> None:
        self._wait()
        if self._syncing is not None:  # the parts' last sync: its failure is the file's
            self._syncing.result()
        if self._next != self.n_steps:
            raise ValueError(f"the file holds steps 0 .. {self._next - 1} of {self.n_steps}")
        for name, (dims, data, units) in self._flags.items():
            if name in self._datasets:
                self._datasets[name][...] = data
            else:  # a flag the first part did not give (no ok step in it)
                self._datasets[name] = _write_variable(self._file, Variable(name, dims, data, units),
                                                       self._scales)
        for key, value in root_attributes(result).items():
            _set_attr(self._file.attrs, key, value)
        self._finished = True


def _sync_data(fd: int) -> None:
    """The file's data on the disk: ``fdatasync`` (``fsync`` where the platform has none)."""
    getattr(os, "fdatasync", os.fsync)(fd)


def _new_file(path) -> h5py.File:
    """A new HDF5 file at ``path`` as ``h5py.File(path, "w", track_order=True)`` makes it, with
    HDF5's sieve buffer off (:class:`SweepWriter` says why)."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_sieve_buf_size(0)
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    order = h5py.h5p.CRT_ORDER_TRACKED | h5py.h5p.CRT_ORDER_INDEXED
    fcpl.set_link_creation_order(order)
    fcpl.set_attr_creation_order(order)
    return h5py.File(h5py.h5f.create(os.fsencode(path), h5py.h5f.ACC_TRUNC, fapl=fapl,
                                     fcpl=fcpl))


def write_layout(path: str | os.PathLike, attributes: dict, coordinates, variables,
                 n_bytes: int = 0) -> None:
    """Write root attributes, coordinate variables and data variables (``result.Variable``)
    to ``path`` atomically, in the netCDF-4 layout described above (``n_bytes``: the estimated
    size, checked against the free space before writing)."""
    with atomic_path(path, n_bytes) as tmp:
        with h5py.File(tmp, "w", track_order=True) as f:
            for key, value in attributes.items():
                _set_attr(f.attrs, key, value)
            scales = {c.name: _write_coordinate(f, c) for c in coordinates}
            for var in variables:
                _write_variable(f, var, scales)


def time_coordinate(var):
    """``var`` (step first) with the netCDF/CF attribute ``coordinates = "time"``: xarray and
    other CF readers open ``time`` as a coordinate of ``step`` beside it (not a data variable)."""
    import dataclasses

    return dataclasses.replace(var, attrs={**var.attrs, "coordinates": "time"})


def _array(data) -> np.ndarray:
    """Return ``data`` as an array h5py stores natively (strings as variable-length UTF-8)."""
    arr = np.asarray(data)
    if arr.dtype.kind in "OUS":
        return np.array([str(x) for x in arr.ravel()], dtype=STR).reshape(arr.shape)
    return arr


def _set_attr(attrs, key: str, value: Any) -> None:
    """Set one attribute; lists of strings become string arrays (empty ones too)."""
    if value is None:
        return
    if isinstance(value, str):
        attrs[key] = value  # h5py: scalar variable-length UTF-8
    elif isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        attrs.create(key, np.array(value, dtype=STR), dtype=STR)
    elif isinstance(value, bool):
        attrs[key] = np.int8(value)
    else:
        attrs[key] = value


def _write_coordinate(f: h5py.File, coord) -> h5py.Dataset:
    ds = f.create_dataset(coord.name, data=_array(coord.data))
    ds.make_scale(coord.name)
    ds.attrs["units"] = coord.units  # "" for name labels: every variable carries units
    for key, value in coord.attrs.items():
        _set_attr(ds.attrs, key, value)
    return ds


def _write_variable(f: h5py.File, var, scales: dict[str, h5py.Dataset],
                    shape: tuple | None = None) -> h5py.Dataset:
    """Create ``var``'s dataset with its attributes and dimension scales: with its data, or
    (``shape``: the whole sweep's, step axis first) empty, for the caller to fill."""
    data = _array(var.data)
    if data.ndim != len(var.dims):
        raise ValueError(f"variable {var.name!r}: {data.ndim}-d data for dims {var.dims}")
    if shape is None:
        ds = f.create_dataset(var.name, data=data)
    else:
        ds = f.create_dataset(var.name, shape=shape, dtype=data.dtype)
        data = ds  # the shape the scales below read
    ds.attrs["units"] = var.units
    for key, value in var.attrs.items():
        _set_attr(ds.attrs, key, value)
    for axis, dim in enumerate(var.dims):
        if dim not in scales:  # a dimension without a coordinate variable
            scale = f.create_dataset(dim, data=np.arange(data.shape[axis], dtype=np.int64))
            scale.make_scale(_PHANTOM)
            scales[dim] = scale
        ds.dims[axis].attach_scale(scales[dim])
    return ds


# ---------------------------------------------------------------------------------- reading
def read(path: str | os.PathLike, form: str = "dataset"):
    """Read a file written by :func:`write`.

    ``form="dataset"``: an ``xarray.Dataset`` (loaded into memory, file closed; values as
    stored, no time decoding). xarray is an
    optional (test) dependency; without it this returns a plain ``dict`` of numpy arrays,
    name -> array, coordinates included (strings as ``str`` arrays; no attributes — open the
    file with h5py for those).

    ``form="dataframe"``: a tidy ``pandas.DataFrame`` indexed by ``step`` with one column per
    scalar series: ``position.P.x``, ``link_angle.crank``, ``input_force.crank``, ``status``...
    (the variable name, then its non-step coordinate labels, joined by dots). Each column's
    unit is in ``df.attrs["units"]`` ({column: unit}, an entry's own unit where a variable's
    entries differ: ``driver_units``, ``measurement_units``). Needs only h5py and pandas.
    """
    if form == "dataframe":
        return _read_dataframe(path)
    if form != "dataset":
        raise ValueError(f"form must be 'dataset' or 'dataframe', not {form!r}")
    try:
        import xarray as xr
    except ImportError:
        with _open(path) as f:
            return {name: _decoded(ds[()]) for name, ds in f.items()}
    try:
        with xr.open_dataset(path, engine="h5netcdf", decode_timedelta=False) as ds:
            return ds.load()
    except OSError:  # a file ``follow`` is writing (HDF5 SWMR): read as a SWMR reader
        pass
    for attempt in range(50):
        with _open(path) as f:
            try:
                with xr.open_dataset(f, engine="h5netcdf", decode_timedelta=False) as ds:
                    return ds.load()
            except ValueError:  # a variable longer than step by the block being written
                if attempt == 49:
                    raise
        time.sleep(0.02)


def _open(path) -> h5py.File:
    """``path`` read-only; a file that ``follow`` is growing (HDF5 SWMR, still open for
    writing) as a SWMR reader."""
    try:
        return h5py.File(path, "r")
    except OSError:
        return h5py.File(path, "r", swmr=True)


def _decoded(arr: np.ndarray) -> np.ndarray:
    if arr.dtype.kind in "OS":
        return np.array([x.decode() if isinstance(x, bytes) else str(x) for x in arr.ravel()],
                        dtype=str).reshape(arr.shape)
    return arr


def dimensions(ds: h5py.Dataset) -> tuple[str, ...]:
    """Return the dimension names of a dataset (the names of its attached scales)."""
    return tuple(d[0].name.lstrip("/") if len(d) else "" for d in ds.dims)


def _read_dataframe(path):
    import pandas as pd

    columns: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    with _open(path) as f:
        step = f["step"][()]
        labels = {name: _decoded(ds[()]) for name, ds in f.items()
                  if ds.is_scale and ds.ndim == 1 and name != "step"}
        for name, ds in f.items():
            dims = dimensions(ds)
            if ds.is_scale or not dims or dims[0] != "step":
                continue
            data = ds[:len(step)]  # (a growing file's variables may hold a block more)
            unit = _text(ds.attrs.get("units", ""))
            if data.ndim == 1:
                columns[name], units[name] = data, unit
                continue
            rest = [labels.get(d, np.arange(n).astype(str)) for d, n in zip(dims[1:], data.shape[1:])]
            per = _text(ds.attrs.get(f"{dims[1]}_units", ""))  # each entry's own unit
            per = per.split(",") if per else []
            flat = data.reshape(len(step), -1)
            for j, idx in enumerate(np.ndindex(*data.shape[1:])):
                key = ".".join([name, *(str(rest[k][i]) for k, i in enumerate(idx))])
                columns[key] = flat[:, j]
                units[key] = per[idx[0]] if len(per) == data.shape[1] else unit
    frame = pd.DataFrame(columns, index=pd.Index(step, name="step"))
    frame.attrs["units"] = units
    return frame


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def root_attributes(result) -> dict[str, Any]:
    """The root attributes of a Result's HDF5 file (docs/output-format.md): the scene, the
    solver's settings and what it used, and the whole sweep's totals."""
    import datetime

    sc, totals = result.scene, result.totals
    attrs: dict[str, Any] = {
        "linkpipe_version": __version__,
        "scene_name": sc.name,
        "scene_toml": sc.text,
        "scene_path": str(sc.path),
        "effects": list(sc.effects),
        "present_but_off": list(sc.present_but_off),
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "solver_tol": sc.solver.tol,
        "solver_max_iter": sc.solver.max_iter,
        "solver_method": sc.solver.method,
        "solver_method_used": result.solver_method_used,
        "solver_note": result.solver_note,
        "solver_linear_algebra": sc.solver.linear_algebra,
        "solver_linear_algebra_used": result.linear_algebra_used,
        "solver_jacobian": sc.solver.jacobian,
        "solver_derivatives": sc.solver.derivatives,
        "solver_predictor": sc.solver.predictor,
        "solver_singular_rcond": sc.solver.singular_rcond,
        "solver_rate_residuals": sc.solver.rate_residuals,
        "degrees_of_freedom": result.mobility.dof,
        "redundant_constraints": result.mobility.redundant,
        "forces_not_unique": result.forces_not_unique(),
        "steps_ok": totals.n_ok,
        "steps_failed": totals.n_steps - totals.n_ok,
        "max_residual": totals.max_residual,
        "newton_iterations_mean": (totals.iterations_sum / totals.n_steps
                                   if totals.n_steps else 0.0),
        "newton_iterations_max": totals.iterations_max,
    }
    for key in ("max_velocity_residual", "max_acceleration_residual"):
        value = getattr(totals, key)
        if value is not None and np.isfinite(value):
            attrs[key] = value
    if result.time_note:
        attrs["time_note"] = result.time_note
    if result.reach_note:
        attrs["reach_note"] = result.reach_note
    attrs["warnings"] = list(result.warnings)  # legal but probably not meant
    for key, val in result.units().items():
        attrs[f"units_{key}"] = val
    for stage, sec in result.seconds.items():
        attrs[f"seconds_{stage}"] = float(sec)
    return attrs


def read_plain(path: str | os.PathLike) -> tuple[dict, dict]:
    """Read any linkpipe ``.h5`` (a run's, a study's) with h5py alone: ``(root attributes,
    {name: {"dims": (dimension names), "data": array, "attrs": {...}}})``, strings decoded,
    every variable and coordinate loaded (the HTML report's input: :mod:`linkpipe.html_report`)."""
    def plain(value):
        if isinstance(value, bytes):
            return value.decode()
        if isinstance(value, np.ndarray) and value.dtype.kind in "OS":
            return _decoded(value)
        return value

    if not h5py.is_hdf5(path):
        raise LinkpipeError(f"{path}: not an HDF5 file; report takes a .h5 that run, study or "
                            "optimize wrote")
    with h5py.File(path, "r") as f:
        root = {k: plain(v) for k, v in f.attrs.items()}
        variables = {}
        for name, ds in f.items():
            if not isinstance(ds, h5py.Dataset):
                continue
            dims = tuple((d[0].name.rsplit("/", 1)[-1] if len(d) else "") for d in ds.dims)
            attrs = {k: plain(v) for k, v in ds.attrs.items()
                     if k not in ("DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME",
                                  "_Netcdf4Dimid", "_Netcdf4Coordinates")}
            variables[name] = {"dims": dims, "data": _decoded(ds[()]), "attrs": attrs}
    return root, variables
