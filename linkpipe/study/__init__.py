"""Design studies: many variants of one scene, each reduced to a row of metrics.

:mod:`.spec` reads ``[study]`` (parameters addressed as ``[fit]`` addresses them, grids and
distributions, named reductions) and lays out the variants; :mod:`.reductions` parses the
named reductions (never ``eval``); :mod:`.batch` solves a batch of variants and
:mod:`.metrics` reduces it; :mod:`.run` runs the batches on an executor (in-process or Dask)
and streams the rows into ``<name>_study.h5`` (:mod:`linkpipe.stores.study`), resumably.
"""
from .run import run_study
from .spec import Study, load_study

__all__ = ["Study", "load_study", "run_study"]
