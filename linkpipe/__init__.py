"""linkpipe: planar linkage analysis — kinematic sweeps, forces, HDF5 and Rerun outputs."""
from .version import __version__

from .errors import LinkpipeError, SceneError  # noqa: E402
from .scene import Scene, load_scene, parse_scene  # noqa: E402
from .pipeline import solve  # noqa: E402
from .result import Result  # noqa: E402

__all__ = ["LinkpipeError", "SceneError", "Scene", "load_scene", "parse_scene", "solve", "Result",
           "__version__"]


def read(path, form: str = "dataset"):
    """Read a run's ``.h5`` back: an xarray Dataset (``form="dataset"``) or a tidy DataFrame.

    The DataFrame has one row per step and columns like ``position.P.x``, ``input_force.crank``.
    """
    from .stores.hdf5 import read as _read

    return _read(path, form)


__all__.append("read")
