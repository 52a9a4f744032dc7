"""Stream a study's rows into ``<name>_study.h5`` (netCDF-4 layout) batch by batch, resumably.

The file is laid out whole before the first batch (every variable at its full size, NaN /
fill values), under the fixed name ``.<name>_study.h5.partial`` beside its final place; each
finished batch writes its rows, is flushed, then marked in ``batch_done`` (dim ``batch``) and
flushed again. A study that is killed leaves the partial file: run again, the same study (same
``study_fingerprint``) skips the batches marked done. When every batch is done the file is
fsync'ed and renamed into place. The file holds no creation time: a resumed study writes the
same file as an uninterrupted one.
"""
from __future__ import annotations

import os
import pathlib

import h5py
import numpy as np

from . import check_space, remove_stale_temporaries
from .hdf5 import _set_attr, _write_coordinate, _write_variable


def partial_path(path) -> pathlib.Path:
    path = pathlib.Path(path)
    return path.with_name(f".{path.name}.partial")


class StudyFile:
    """The study file being written. ``coordinates``, ``variables``: ``result.Variable`` at
    full size (the variables' data are the fill values); ``fingerprint``: a resumed file must
    carry the same one, else it is started again."""

    def __init__(self, path, attributes: dict, coordinates, variables, fingerprint: str):
        self.path = pathlib.Path(path)
        self.partial = partial_path(self.path)
        remove_stale_temporaries(self.path.parent)
        self.file = self._resume(fingerprint)
        if self.file is None:
            check_space(self.path, sum(v.data.nbytes for v in variables))
            self.file = h5py.File(self.partial, "w", track_order=True)
            for key, value in {**attributes, "study_fingerprint": fingerprint}.items():
                _set_attr(self.file.attrs, key, value)
            scales = {c.name: _write_coordinate(self.file, c) for c in coordinates}
            for var in variables:
                _write_variable(self.file, var, scales)
            self.file.flush()

    def _resume(self, fingerprint: str):
        if not self.partial.exists():
            return None
        try:
            f = h5py.File(self.partial, "r+")
        except OSError:  # a file cut short by a kill: start again
            self.partial.unlink()
            return None
        if f.attrs.get("study_fingerprint") != fingerprint or "batch_done" not in f:
            f.close()
            self.partial.unlink()
            return None
        return f

    @property
    def done(self) -> np.ndarray:
        """(n_batches,) bool: the batches already in the file."""
        return self.file["batch_done"][()].astype(bool)

    def write_batch(self, batch: int, lo: int, rows: dict) -> None:
        """Write one batch's rows (variants ``lo ..``), then mark it done."""
        for name, data in rows.items():
            self.file[name][lo:lo + len(data)] = data
        self.file.flush()
        self.file["batch_done"][batch] = 1
        self.file.flush()

    def read(self, name: str) -> np.ndarray:
        return self.file[name][()]

    def finish(self) -> None:
        """Close, fsync and rename into place."""
        self.close()
        fd = os.open(self.partial, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(self.partial, self.path)

    def close(self) -> None:
        if self.file is not None and self.file.id.valid:
            self.file.close()


def read_done(path) -> np.ndarray | None:
    """``batch_done`` of a study's partial file, or None when there is none: a look at a study
    that may be running (no file lock taken; an OSError when caught mid-write)."""
    partial = partial_path(path)
    if not partial.exists():
        return None
    try:
        with h5py.File(partial, "r", locking=False) as f:
            return f["batch_done"][()].astype(bool)
    except (KeyError, ValueError) as exc:  # metadata half-written by the running study
        raise OSError(f"{partial}: caught mid-write ({exc})") from None


def read_arrays(path) -> dict[str, np.ndarray]:
    """Every dataset of a study file as a numpy array (strings as ``str``), and its root
    attributes under ``"attrs"``."""
    from .hdf5 import _decoded

    with h5py.File(path, "r") as f:
        out = {name: _decoded(ds[()]) for name, ds in f.items()}
        out["attrs"] = dict(f.attrs)
    return out
