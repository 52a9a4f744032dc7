"""One variant of a study as its own scene, solved by its own run (the variant-by-variant path,
and the rows of the vectorised paths' variants that must be their own runs)."""
from __future__ import annotations

from ..errors import MemoryRefused, SceneError
from ..fit import scene_with
from ..pipeline import solve
from ..workers import DEFAULT_THREADS


def variant_scene(study, v: int):
    """The scene of variant ``v`` (parsed and checked as a scene file is; SceneError if not)."""
    return scene_with(study.scene, study.data, study.parameters, study.values[v])


def solve_variant(study, v: int, threads: int | None = DEFAULT_THREADS):
    """The Result of variant ``v``, or None where its scene cannot be built or assembled
    (``threads``: as :func:`linkpipe.solve`'s; None leaves the BLAS pool as it is)."""
    try:
        return solve(variant_scene(study, v), threads=threads)
    except MemoryRefused:
        raise  # the study's sweep is too long for this machine: not a row of data
    except SceneError:
        return None
