"""The status of a step: the codes, their names, and the one rule that combines them.

Every stage reports a status per step (shape ``(S,)``, int8); the pipeline combines them with
:func:`worst`, which is the only place where one stage's verdict overrides another's.
Codes are the HDF5 ``status`` variable's CF ``flag_values``; names its ``flag_meanings``.
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np


class Status(IntEnum):
    """What a step holds (docs/output-format.md, "Results at steps that fail")."""

    OK = 0  # solved; everything stored is finite and met its tolerance
    NO_ASSEMBLY = 1  # the constraints have no solution there: NaN for every moving quantity
    SINGULAR = 2  # positions solved, Jacobian rank-deficient: NaN derivatives and forces
    NOT_CONVERGED = 3  # a root exists but the iteration cap stopped short: NaN as no_assembly
    NO_LEVERAGE = 4  # the input point does not move with its driver: NaN input force


OK, NO_ASSEMBLY, SINGULAR, NOT_CONVERGED, NO_LEVERAGE = (int(s) for s in Status)

#: the HDF5 ``flag_meanings``, in code order
FLAG_MEANINGS = tuple(s.name.lower() for s in Status)

#: severity of each code (index = code): a step keeps the most severe verdict any stage gave
_SEVERITY = np.array([0, 4, 2, 3, 1], dtype=np.int8)
_BY_SEVERITY = np.argsort(_SEVERITY).astype(np.int8)


def worst(*statuses: np.ndarray) -> np.ndarray:
    """Return, step by step, the most severe of the stages' statuses ``(S,)`` int8.

    Severity, least to most: ok < no_leverage < singular < not_converged < no_assembly
    (a step that did not assemble cannot be singular; a singular step has no leverage to test).
    """
    rank = np.maximum.reduce([_SEVERITY[np.asarray(s, dtype=np.intp)] for s in statuses])
    return _BY_SEVERITY[rank]


def counts(status: np.ndarray) -> dict[str, int]:
    """Return ``{name: number of steps}`` for the codes that occur, in code order."""
    found = np.bincount(np.asarray(status, dtype=np.intp), minlength=len(Status))
    return {FLAG_MEANINGS[c]: int(n) for c, n in enumerate(found) if n}
