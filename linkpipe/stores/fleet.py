"""Write a fleet's rows (:mod:`linkpipe.fleet`) as ``<name>_fleet.h5`` / ``<name>_fleet_fit.h5``:
netCDF-4 layout, dimension ``log`` (the log files' names) and, per column, ``driver``,
``measurement`` or ``parameter``; root attributes name the scene and the glob."""
from __future__ import annotations

import numpy as np

from . import hdf5
from ..result import Variable


def write(path, attributes: dict, labels: dict, columns: dict, units: dict,
          attrs: dict | None = None) -> None:
    """``labels`` {dimension: names}; ``columns`` {name: (dims, array)}; ``units`` {name: unit};
    ``attrs`` {name: {attribute: value}} beside the units (each entry's own unit)."""
    coords = [Variable(dim, (dim,), np.array(names, dtype=object), "")
              for dim, names in labels.items() if names]
    attrs = attrs or {}
    variables = [Variable(name, dims, data, units.get(name, ""), attrs.get(name, {}))
                 for name, (dims, data) in columns.items()]
    hdf5.write_layout(path, attributes, coords, variables,
                      n_bytes=sum(np.asarray(d).nbytes for _, d in columns.values()))
