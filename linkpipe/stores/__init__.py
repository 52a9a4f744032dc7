"""Writers (and a reader) for the output contract, ``docs/output-format.md``.

The only modules that import h5py (:mod:`.hdf5`) and rerun (:mod:`.rrd`); import them
explicitly, so that writing one format never pays for importing the other.
"""
from __future__ import annotations

import contextlib
import os
import pathlib
import uuid
from collections.abc import Iterator


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[pathlib.Path]:
    """Yield a temporary path beside ``path``; rename it into place only if the block succeeds.

    On any exception the temporary file is removed and ``path`` keeps its previous content.
    """
    path = pathlib.Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
