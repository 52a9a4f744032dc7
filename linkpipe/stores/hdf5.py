"""Write a :class:`~linkpipe.result.Result` as a netCDF-4 style HDF5 file, and read it back.

Layout (``docs/output-format.md``): one HDF5 dataset per coordinate and data variable at
the root, named as in ``Result.coordinates()`` / ``Result.variables()``. Coordinate variables
are HDF5 dimension scales and every data variable has them attached, so h5py, xarray
(``engine="h5netcdf"``), MATLAB and HDFView all see labelled dimensions.
"""
from __future__ import annotations

import os
from typing import Any

import h5py
import numpy as np

from . import atomic_path

STR = h5py.string_dtype("utf-8")
#: the netCDF-4 marker for a dimension that has no coordinate variable
_PHANTOM = "This is a netCDF dimension but not a netCDF variable."


def write(result, path: str | os.PathLike) -> None:
    """Write ``result`` to ``path`` atomically (temporary file, then ``os.replace``)."""
    variables = result.variables()
    write_layout(path, result.attributes(), result.coordinates(), variables,
                 n_bytes=sum(v.data.nbytes for v in variables))


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


def _write_variable(f: h5py.File, var, scales: dict[str, h5py.Dataset]) -> h5py.Dataset:
    data = _array(var.data)
    if data.ndim != len(var.dims):
        raise ValueError(f"variable {var.name!r}: {data.ndim}-d data for dims {var.dims}")
    ds = f.create_dataset(var.name, data=data)
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
    (the variable name, then its non-step coordinate labels, joined by dots). Needs only h5py
    and pandas.
    """
    if form == "dataframe":
        return _read_dataframe(path)
    if form != "dataset":
        raise ValueError(f"form must be 'dataset' or 'dataframe', not {form!r}")
    try:
        import xarray as xr
    except ImportError:
        with h5py.File(path, "r") as f:
            return {name: _decoded(ds[()]) for name, ds in f.items()}
    with xr.open_dataset(path, engine="h5netcdf", decode_timedelta=False) as ds:
        return ds.load()


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
    with h5py.File(path, "r") as f:
        step = f["step"][()]
        labels = {name: _decoded(ds[()]) for name, ds in f.items()
                  if ds.is_scale and ds.ndim == 1 and name != "step"}
        for name, ds in f.items():
            dims = dimensions(ds)
            if ds.is_scale or not dims or dims[0] != "step":
                continue
            data = ds[()]
            if data.ndim == 1:
                columns[name] = data
                continue
            rest = [labels.get(d, np.arange(n).astype(str)) for d, n in zip(dims[1:], data.shape[1:])]
            flat = data.reshape(len(step), -1)
            for j, idx in enumerate(np.ndindex(*data.shape[1:])):
                key = ".".join([name, *(str(rest[k][i]) for k, i in enumerate(idx))])
                columns[key] = flat[:, j]
    return pd.DataFrame(columns, index=pd.Index(step, name="step"))
