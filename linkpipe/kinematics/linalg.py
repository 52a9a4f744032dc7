"""Dense linear algebra of the constraint Jacobian: the one condition estimate, the singular
test and its named thresholds, solves and (pseudo-)inverses of stacks of Jacobians.

The sparse whole-sweep counterpart, with the same condition measure, is :mod:`.sparse`."""
from __future__ import annotations

import numpy as np


#: steps per chunk of whole-sweep work (the dyad chain, batched Newton, block solves, the force
#: stage's multipliers): about the largest that keeps each chunk's working set in cache
CHUNK = 8192

#: a step's condition c against the scene's ``singular_rcond`` r: ``c r >= SINGULAR_AT`` is
#: singular (its derivatives and forces are undetermined); ``c r >= POLISH_FROM`` is iterated to
#: rounding level before that is decided (a double root is approached only linearly);
#: ``c r < MODE_SETTLED_BELOW`` is well clear of any limit (its assembly mode is settled)
SINGULAR_AT, POLISH_FROM, MODE_SETTLED_BELOW = 1.0, 1e-3, 1e-4


def is_singular(condition, rcond: float, margin: float = SINGULAR_AT):
    """Whether condition(s) ``c`` reach ``margin / rcond`` (NaN counts as singular)."""
    return ~(np.asarray(condition) * rcond < margin)


def condition(J: np.ndarray) -> np.ndarray:
    """Return the condition (S,) of Jacobians (S, m, n), the one measure every path uses.

    Square: the 1-norm condition ``|J|_1 |J^-1|_1`` (inf when exactly singular); more rows than
    columns (known redundancy): ``sigma_1 / sigma_n``, the rank deficiency beyond the redundancy.
    """
    if J.shape[1] == J.shape[2]:
        return np.linalg.cond(J, 1)
    return pseudo_inverse(J)[1]


def condition_and_inverse(J: np.ndarray):
    """Return (condition (S,), inverse (S, n, m)) of Jacobians (S, m, n): the inverse and the
    1-norm condition where square and regular, else the pseudo-inverse and sigma_1/sigma_n."""
    if J.shape[1] == J.shape[2]:
        try:
            inv = np.linalg.inv(J)
            return np.abs(J).sum(axis=1).max(axis=1) * np.abs(inv).sum(axis=1).max(axis=1), inv
        except np.linalg.LinAlgError:
            pass
    inv, cond = pseudo_inverse(J)
    return cond, inv


def condition_and_inverse_one(J: np.ndarray):
    """:func:`condition_and_inverse` of one square Jacobian (n, n): (condition, inverse or
    None where exactly singular); the continuation's per-step form."""
    try:
        inv = np.linalg.inv(J)
    except np.linalg.LinAlgError:
        return (np.nan if np.isnan(J).any() else np.inf), None
    c = float(np.abs(J).sum(axis=0).max() * np.abs(inv).sum(axis=0).max())
    if c != c and not np.isnan(J).any():
        c = np.inf
    return c, inv


def lin_solve(J, b):
    """Solve J x = b for stacks (S, m, n), (S, m) in the least-squares, minimum-norm sense."""
    S, m, n = J.shape
    if m == n:
        try:
            return np.linalg.solve(J, b[..., None])[..., 0]
        except np.linalg.LinAlgError:
            pass
    return np.einsum("sij,sj->si", np.linalg.pinv(J, rcond=1e-13), b)


def pseudo_inverse(J):
    """Return the pseudo-inverse and the condition sigma_1/sigma_n of stacks (S, m, n)."""
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    n = J.shape[2]
    cond = sv[:, 0] / np.where(sv[:, n - 1] > 0, sv[:, n - 1], np.finfo(float).tiny)
    cut = sv > (1e-13 * sv[:, :1])
    inv_sv = np.where(cut, 1.0 / np.where(cut, sv, 1.0), 0.0)
    inv = np.einsum("sji,sj,skj->sik", Vt, inv_sv, U)
    return inv, cond


#: a Jacobian with more unknowns than this gets its condition estimated from a few solves
#: (:func:`estimate_inverse_norm1`) instead of forming the inverse, when nothing else needs
#: the inverse (no force stage): n block solves per step cost more than ~7 from about here
ESTIMATE_FROM = 16


def estimate_inverse_norm1(solve, solve_transpose, n: int, S: int, iterations: int = 3):
    """Return a lower bound (S,) of ``|J^-1|_1`` at every step, from a few solves: Hager's
    method as refined by Higham (LAPACK's ``xLACON``, Higham 1988), vectorised over steps, run
    from two starting vectors (the uniform one and Higham's alternating one), the larger kept.

    ``solve(x)`` and ``solve_transpose(x)`` solve ``J y = x`` and ``J^T y = x`` for x (n, S)
    (an array, coordinates first; iterating it gives the n rows) and return (n, S) or a list
    of n arrays (S,). Each iterate ``|J^-1 x|_1`` with ``|x|_1 = 1`` is a
    lower bound; the largest is kept. One start alone can stop at a vertex several times below
    the norm (measured: 5.7x on a 36-unknown chain); with two starts the worst measured was
    3.1x there, and 3x on the random families of tests/test_condition.py. ``derivatives`` takes
    the exact value wherever the estimate comes within 1e-3 of the singular threshold, so a
    step's status would need an estimate 1000x low to change."""
    i = np.arange(n)
    alt = np.where(i % 2, -1.0, 1.0) * (1.0 + i / max(n - 1, 1))  # (-1)^i (1 + i / (n - 1))
    starts = (np.full(n, 1.0 / n), alt / np.abs(alt).sum())
    best = np.zeros(S)
    finite = np.ones(S, dtype=bool)
    with np.errstate(invalid="ignore", over="ignore"):
        for start in starts:
            x = np.repeat(start[:, None], S, axis=1)  # (n, S)
            for _ in range(iterations):
                y = _rows_array(solve(x))  # (n, S)
                finite &= np.isfinite(y).all(axis=0)
                best = np.fmax(best, np.abs(y).sum(axis=0))
                sign = np.where(y >= 0, 1.0, -1.0)
                z = np.abs(_rows_array(solve_transpose(sign)))
                j = np.argmax(z, axis=0)  # the next unit vector: the steepest direction
                x = (np.arange(n)[:, None] == j[None, :]).astype(float)
    return np.where(finite, best, np.inf)


#: an estimated condition is replaced by the exact one where it comes within EXACT_WITHIN of the
#: singular threshold (no status rests on an estimate), or within the caller's ``within`` of
#: the threshold it decides at: POLISH_WITHIN for the polish threshold (the estimate, a lower
#: bound, was measured within 3.1x of the exact value: tests/test_condition.py)
EXACT_WITHIN, POLISH_WITHIN = 1e3, 10.0


def estimated_condition(norm1, solve, solve_transpose, exact, n: int, S: int, rcond: float,
                        threshold: float = SINGULAR_AT, within: float = EXACT_WITHIN):
    """Return the condition ``|J|_1 |J^-1|_1`` (S,) from ``norm1`` (S,) = |J|_1 and the
    estimate of |J^-1|_1 (:func:`estimate_inverse_norm1` on ``solve``, ``solve_transpose``),
    inf where a solve is not finite; ``exact(near)`` gives the exact condition at the steps
    ``near`` (bool (S,)) where the estimate times ``within`` reaches ``threshold / rcond``, or
    times EXACT_WITHIN the singular threshold."""
    est = estimate_inverse_norm1(solve, solve_transpose, n, S)
    with np.errstate(invalid="ignore"):
        cond = np.where(np.isfinite(est), norm1 * est, np.inf)
    near = is_singular(cond * within, rcond, threshold) | is_singular(cond * EXACT_WITHIN, rcond)
    if near.any():
        cond[near] = exact(near)
    return cond


def _rows_array(y) -> np.ndarray:
    """(n, S) from a list of n arrays (S,) or an (n, S) array (not copied)."""
    return y if isinstance(y, np.ndarray) else np.stack(y)
