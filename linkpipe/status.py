"""The status of a step: the codes, their names, and the one rule that combines them.

Every stage reports a status per step (shape ``(S,)``, int8); the pipeline combines them with
:func:`worst`, which is the only place where one stage's verdict overrides another's.
Codes are the HDF5 ``status`` variable's CF ``flag_values``; names its ``flag_meanings``.
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np

from .workers import for_chunks


class Status(IntEnum):
    """What a step holds (docs/output-format.md, "Results at steps that fail")."""

    OK = 0  # solved; everything stored is finite and met its tolerance
    NO_ASSEMBLY = 1  # the constraints have no solution there: NaN for every moving quantity
    SINGULAR = 2  # positions solved, Jacobian rank-deficient: NaN derivatives and forces
    NOT_CONVERGED = 3  # a root exists but did not reach tol (iteration cap): NaN as no_assembly
    NO_INPUT = 4  # a logged driver value is missing at this step (format v2): NaN as no_assembly
    NO_LEVERAGE = 5  # the input point does not move with its driver: NaN input force
    NON_FINITE = 6  # solved, but a stored quantity overflowed (inf or NaN): not to be trusted
    OUT_OF_STROKE = 7  # solved, but an actuator or gas spring is outside its stroke (v3): values kept


(OK, NO_ASSEMBLY, SINGULAR, NOT_CONVERGED, NO_INPUT, NO_LEVERAGE, NON_FINITE,
 OUT_OF_STROKE) = (int(s) for s in Status)

#: the HDF5 ``flag_meanings``, in code order
FLAG_MEANINGS = tuple(s.name.lower() for s in Status)

#: severity of each code (index = code): a step keeps the most severe verdict any stage gave
_SEVERITY = np.array([0, 7, 4, 5, 6, 1, 2, 3], dtype=np.int8)
_BY_SEVERITY = np.argsort(_SEVERITY).astype(np.int8)


def worst(*statuses: np.ndarray) -> np.ndarray:
    """Return, step by step, the most severe of the stages' statuses ``(S,)`` int8.

    Severity, least to most: ok < no_leverage < non_finite < out_of_stroke < singular <
    not_converged < no_input < no_assembly (a step that did not assemble cannot be singular; a
    singular step has no leverage to test; a step the machine cannot reach as built is that
    before any lack of leverage or overflow there).
    """
    rank = np.maximum.reduce([_SEVERITY[np.asarray(s, dtype=np.intp)] for s in statuses])
    return _BY_SEVERITY[rank]


def counts(status: np.ndarray) -> dict[str, int]:
    """Return ``{name: number of steps}`` for the codes that occur, in code order."""
    return named_counts(code_counts(status))


def code_counts(status: np.ndarray) -> tuple[int, ...]:
    """The number of steps of each code (n_codes,), in code order."""
    return tuple(int(n) for n in np.bincount(np.asarray(status, dtype=np.intp),
                                             minlength=len(Status)))


def named_counts(found) -> dict[str, int]:
    """``{name: number of steps}`` of the codes that occur, from :func:`code_counts`."""
    return {FLAG_MEANINGS[c]: int(n) for c, n in enumerate(found) if n}


def message(found) -> str:
    """One line from :func:`code_counts`: how many steps are ok, and what the others are."""
    n_steps, n_ok = sum(found), found[OK]
    if n_ok == n_steps:
        return f"all {n_steps} steps ok"
    return f"{n_ok}/{n_steps} steps ok; " + ", ".join(
        f"{n} {k}" for k, n in named_counts(found).items() if k != "ok")


def assign(stage_statuses, residual: np.ndarray, tol_abs: float, stored,
           finite: np.ndarray | None = None) -> np.ndarray:
    """The one place a step's final status is decided (int8, (S,)).

    The most severe verdict of the stages (:func:`worst`); then an ok step whose position
    residual is above the tolerance that was asked for (``tol_abs``, a length) is
    not_converged; then an ok step where anything ``stored`` (arrays, step axis first) is not
    finite, or ``finite`` (S,) is False (rows of arrays checked before), is non_finite
    (:func:`ok_only_if_finite`)."""
    status = worst(*stage_statuses)
    with np.errstate(invalid="ignore"):
        loose = (status == OK) & ~(np.asarray(residual) <= tol_abs)
    status = np.where(loose, NOT_CONVERGED, status).astype(np.int8)
    return ok_only_if_finite(status, stored, finite)


def finite_rows(arrays, n_steps: int) -> np.ndarray:
    """(S,) True where every float array of ``arrays`` (step axis first) is finite (in chunks
    of steps on the workers' threads: :func:`linkpipe.workers.for_chunks`)."""
    ok = np.ones(n_steps, dtype=bool)
    arrays = [a.reshape(a.shape[0], -1) for a in map(np.asarray, arrays) if a.dtype.kind == "f"]

    def work(lo: int, hi: int) -> None:
        for a in arrays:
            # the rows' total is finite only if every entry is (an inf or NaN anywhere makes
            # it inf or NaN): one vectorised sum clears the usual all-finite chunk at once
            if np.isfinite(np.sum(a[lo:hi])):
                continue
            # a row's sum (one BLAS product) is finite if and only if its entries are, but for
            # finite entries whose sum overflows: the rows whose sum is not are looked at entry
            # by entry (3x faster than isfinite(a).all(axis=1) when every row is finite)
            summed = a[lo:hi] @ np.ones(a.shape[1])
            doubt = np.flatnonzero(~np.isfinite(summed))
            if len(doubt):
                ok[lo + doubt] &= np.isfinite(a[lo + doubt]).all(axis=1)

    with np.errstate(invalid="ignore", over="ignore"):
        for_chunks(work, n_steps, FINITE_CHUNK)
    return ok


#: steps per chunk of :func:`finite_rows`
FINITE_CHUNK = 32768


def ok_only_if_finite(status: np.ndarray, arrays, finite: np.ndarray | None = None) -> np.ndarray:
    """Return ``status`` with NON_FINITE at every ok step where one of ``arrays`` (each with the
    step axis first) holds an inf or NaN, or ``finite`` is False: a step is ok only if
    everything stored at it is finite."""
    status = np.asarray(status)
    ok = finite_rows(arrays, len(status)) if (status == OK).any() else np.ones(len(status), bool)
    if finite is not None:
        ok &= finite
    return np.where((status == OK) & ~ok, NON_FINITE, status).astype(np.int8)


def not_finite_at(result, step: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Why a solved step is non_finite, as (causes, entries): the causes linkpipe can name, as
    text (a gas spring at or below its dead length), and what ``result`` stores that is not
    finite at ``step`` (an index into its rows), each as ``variable[entry]``
    (``spring_force[strut]``, ``joint_force[A@crank]``), in the order of
    :meth:`linkpipe.result.Result.variables`."""
    labels = {c.name: [str(x) for x in c.data] for c in result.coordinates()}
    out = []
    for v in result.variables():
        if not v.dims or v.dims[0] != "step" or v.data.dtype.kind != "f":
            continue
        row = np.asarray(v.data[step])
        bad = ~np.isfinite(row)
        if not bad.any():
            continue
        if row.ndim == 0:
            out.append(v.name)
            continue
        entries = np.flatnonzero(bad.reshape(bad.shape[0], -1).any(axis=1))
        names = labels.get(v.dims[1], [])
        out.extend(f"{v.name}[{names[e] if e < len(names) else e}]" for e in entries)
    return _gas_springs_dead(result, step), tuple(out)


def _gas_springs_dead(result, step: int) -> tuple[str, ...]:
    """Why a gas spring's force is not finite at ``step``: its length at or below its
    dead_length (the gas volume is gone), as text naming the spring, or ()."""
    length = (result.forces or {}).get("spring_length")
    if length is None:
        return ()
    unit = result.units()["length"]
    return tuple(f"gas spring {sp.name}: length {length[1][step, j]:.4g} {unit} at or below its "
                 f"dead_length {sp.dead_length:.4g} {unit}"
                 for j, sp in enumerate(result.scene.springs)
                 if sp.kind == "gas" and length[1][step, j] <= sp.dead_length)
