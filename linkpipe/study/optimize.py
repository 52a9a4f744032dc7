"""``linkpipe optimize``: the best design within bounds that meets the constraints.

A global search, then a local polish, both over the study's vectorised variants
(:class:`.problem.Problem`):

- **search**: :func:`scipy.optimize.differential_evolution` with ``vectorized=True`` and
  deferred updating, so each generation is one batch of variants (split over the workers on
  Dask); the constraints and the failed steps are scipy's constraint rows (Lampinen's
  feasibility rules: a feasible variant beats an infeasible one; two infeasible ones compare
  by their excesses), the objective is asked only of feasible variants. It hands over to the
  polish when the population has gathered (its spread is below ``HANDOVER`` of each bound's
  width), or its best has improved by less than ``STALL_GAIN`` of itself plus ``tol`` x the
  first generation's spread of the objective in ``STALL`` generations (with no feasible
  member: its least violation by less than ``STALL_GAIN`` of itself), or after
  ``generations``. The search's box reaches ``MARGIN`` beyond the bounds, a value there
  evaluated at the bound (see ``MARGIN``).
- **polish**: CMA-ES (:mod:`cma`, ask/tell: each iteration's population one batch, ranked
  by the same feasibility rules; CMA-ES needs only the ranks, and its covariance follows a
  curved valley and the kinks of a peak ``max(abs(..))``, where a gradient method stops
  short) in the bounds scaled to [0, 1], from the search's best. Values within
  ``BOUND_TRY`` of a bound are tried on it, the nearest first, one at a time (one CMA-ES run
  over the others): where that face
  holds a better best they stay there (an optimum on a bound is reached exactly, and a
  valley that runs into a bound is not crawled down); then a coarse pass (to ``STEP_MIDDLE``
  of each bound's width) and a fine one (to ``STEP_END``), each face reached on the way
  tried the same way. A pass that stops short of its tolerance starts again from its best
  (``CMA_RUNS`` runs of ``CMA_ITERATIONS``); one whose best has not improved in
  ``CMA_STALL`` iterations ends.

Every evaluated variant is kept (:class:`Outcome`): values, metrics, failed steps, which
generation (-1: the polish). Two objectives: the search runs once per weight of a
Chebyshev scalarisation of the two (normalised on the first run's spread; weights 1, 3/4,
1/2, 1/4, 0), each polished; the Pareto set is every feasible evaluation no other beats in
both; the best is the Pareto member lowest in the first objective.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import NonlinearConstraint, differential_evolution

from ..errors import LinkpipeError
from .batch import solve_batch
from .problem import FAILED, Problem

#: the search hands over when every parameter's spread in the population is below this
#: fraction of its bound's width
HANDOVER = 1e-3
#: the polish's first step, where a coarse pass ends and where the fine one ends (fractions
#: of each bound's width)
STEP_START, STEP_MIDDLE, STEP_END = 1e-2, 1e-4, 1e-9
#: CMA-ES runs a polish pass may start (each from the last one's best) and their iterations
CMA_RUNS, CMA_ITERATIONS = 6, 100
#: iterations without a better best after which a CMA-ES pass ends (values the objective does
#: not depend on, where it sits, never reach the step tolerance)
CMA_STALL = 50
#: the search's box reaches this far (a fraction of each bound's width) beyond the bounds;
#: a value there is evaluated at the bound: scipy puts a trial outside its box anywhere in
#: it at random, which keeps a population from settling on a bound; here the bound is a
#: plateau it can settle on
MARGIN = 0.1
#: differential evolution's crossover probability: high, as the variables of a design are
#: seldom separable (a spring's rate against its anchor's place is a curved valley)
RECOMBINATION = 0.9
#: generations without a better best (or less violation) after which the search hands over
STALL, STALL_GAIN = 30, 1e-3
#: the polish tries the values this close to a bound (a fraction of its width) on the bound,
#: and keeps them there where that face holds a better best
BOUND_TRY = 0.2
#: a constraint within this fraction of its metric's spread over the evaluations is active;
#: a parameter within this fraction of its bound's width of a bound sits on it
ACTIVE, ON_BOUND = 1e-6, 1e-7
#: the weights of the first objective in a two-objective search's runs
WEIGHTS = (1.0, 0.75, 0.5, 0.25, 0.0)


class Infeasible(LinkpipeError):
    """No evaluated variant meets the constraints (exit 1; the message names the closest)."""

    exit_code = 1


@dataclass
class Outcome:
    """Every evaluation ``(E, ...)`` of a search and what it found. ``values`` (E,
    n_parameters); ``metrics`` {name: (E,)} (each named metric and ``_failed_steps``);
    ``generation`` (E,) (-1: the polish); ``feasible`` (E,); ``violation`` (E,) the summed
    excesses (each over its metric's spread) plus the failed steps' fraction; ``best`` the
    evaluation reported; ``pareto`` the Pareto set's evaluations (two objectives; else
    empty), by the first objective; ``population_best`` (G,) the lowest feasible first
    objective after each generation (NaN before a feasible one); ``active`` the constraints
    that hold with equality at the best; ``on_bound`` [(parameter, "lower" | "upper")]."""

    problem: Problem
    values: np.ndarray
    metrics: dict
    generation: np.ndarray
    feasible: np.ndarray
    violation: np.ndarray
    best: int
    pareto: np.ndarray
    population_best: np.ndarray
    active: list
    on_bound: list
    seconds: float
    messages: list

    @property
    def objective(self) -> np.ndarray:
        """(E,) the first objective of every evaluation."""
        return self.metrics[self.problem.objectives[0]]

    @property
    def best_values(self) -> np.ndarray:
        return self.values[self.best]


def _solve_rows(study, values):
    """The study's rows at ``values`` (n, n_parameters): one batch."""
    return solve_batch(dataclasses.replace(study, values=values), 0, len(values))


class Evaluator:
    """Evaluate variants once each, a whole set as one round of batches; keep every one."""

    def __init__(self, problem: Problem, pool):
        self.problem, self.pool = problem, pool
        self.shared = pool.share(problem.study)
        self.names = [m.name for m in problem.study.metrics]
        self.index: dict[bytes, int] = {}
        self.values: list[np.ndarray] = []
        self.rows: dict[str, list] = {name: [] for name in self.names}
        self.generations: list[np.ndarray] = []
        self.generation = 0
        self.n = 0
        self._columns: dict[str, tuple] = {}

    def __call__(self, free: np.ndarray) -> np.ndarray:
        """(n,) evaluation indices of the variants at the bounded parameters' ``free`` (n,
        n_free)."""
        free = np.ascontiguousarray(np.atleast_2d(free), dtype=float)
        keys = [row.tobytes() for row in free]
        new = list(dict.fromkeys(k for k in keys if k not in self.index))
        if new:
            X = self.problem.values(np.array([np.frombuffer(k) for k in new]))
            size = self.problem.study.batch_size
            n_tasks = max(self.pool.n_workers, -(-len(X) // size))
            edges = np.linspace(0, len(X), min(n_tasks, len(X)) + 1).astype(int)
            parts = self.pool.map(_solve_rows, self.shared,
                                  [(X[a:b],) for a, b in zip(edges[:-1], edges[1:]) if b > a])
            for name in self.names:
                self.rows[name].append(np.concatenate([p[name] for p in parts]))
            self.values.append(X)
            self.generations.append(np.full(len(X), self.generation))
            for k in new:
                self.index[k] = self.n
                self.n += 1
        return np.array([self.index[k] for k in keys], dtype=np.intp)

    def column(self, name: str) -> np.ndarray:
        """(E,) one metric of every evaluation so far."""
        if self._columns.get(name, (None, -1))[1] != self.n:
            rows = self.rows[name]
            self._columns[name] = (np.concatenate(rows) if rows else np.zeros(0), self.n)
        return self._columns[name][0]

    def arrays(self) -> tuple[np.ndarray, dict, np.ndarray]:
        """(values (E, P), {metric: (E,)}, generation (E,)) of every evaluation so far."""
        P = len(self.problem.study.parameters)
        values = np.concatenate(self.values) if self.values else np.zeros((0, P))
        metrics = {name: np.concatenate(rows) if rows else np.zeros(0)
                   for name, rows in self.rows.items()}
        gen = np.concatenate(self.generations) if self.generations else np.zeros(0, int)
        return values, metrics, gen


class _Judge:
    """Feasibility, excesses and violations of evaluations, from the evaluator's rows."""

    def __init__(self, problem: Problem, ev: Evaluator):
        self.problem, self.ev = problem, ev

    def metric(self, name: str, idx) -> np.ndarray:
        return self.ev.column(name)[idx]

    def rows(self, idx) -> np.ndarray:
        """(n, n_constraints + 1): each constraint's excess (<= 0: holds; +inf: NaN), then
        the failed steps (+1 where an objective is not finite): scipy's constraint rows."""
        objectives = np.stack([self.metric(o, idx) for o in self.problem.objectives], axis=1)
        failed = self.metric(FAILED, idx) + (~np.isfinite(objectives).all(axis=1))
        return np.column_stack([c.excess(self.metric(c.metric, idx))
                                for c in self.problem.constraints] + [failed])

    def scales(self) -> np.ndarray:
        """(n_constraints,) each constraint metric's spread over the evaluations (its limit's
        size where it has none): what an excess is measured in."""
        out = []
        for c in self.problem.constraints:
            x = self.metric(c.metric, slice(None))
            x = x[np.isfinite(x)]
            spread = float(np.ptp(x)) if len(x) else 0.0
            out.append(spread or abs(c.limit) or 1.0)
        return np.array(out)

    def violation(self, idx) -> np.ndarray:
        """(n,) summed excesses over their scales plus the failed steps' fraction (0: feasible)."""
        g = self.rows(idx)
        S = self.problem.study.scene.n_steps
        excess = np.maximum(g[:, :-1], 0.0) / self.scales()
        return excess.sum(axis=1) + g[:, -1] / S


def optimize(problem: Problem, pool, progress=None) -> Outcome:
    """Search ``problem`` (:mod:`module doc <.optimize>`) with the executor ``pool``
    (:class:`linkpipe.executors.Pool`); ``progress(generation, best)`` after each generation.
    Raises :class:`Infeasible` when no evaluated variant meets the constraints."""
    t0 = time.perf_counter()
    ev = Evaluator(problem, pool)
    judge = _Judge(problem, ev)
    rng = np.random.default_rng(problem.seed)
    messages = []
    if len(problem.objectives) == 1:
        merit = _objective(judge, problem.objectives[0])
        x, message = _search(problem, ev, judge, merit, problem.seed, progress)
        _polish(problem, ev, judge, merit, x, rng)
        messages.append(message)
    else:
        a, b = problem.objectives
        for k, w in enumerate(WEIGHTS):
            merit = _objective(judge, a) if w == 1.0 else _chebyshev(judge, a, b, w)
            x, message = _search(problem, ev, judge, merit, problem.seed + k, progress)
            _polish(problem, ev, judge, merit, x, rng)
            messages.append(f"weight {w:g}: {message}")
    return _outcome(problem, ev, judge, messages, time.perf_counter() - t0)


def _objective(judge: _Judge, name: str):
    """merit(idx) -> (n,): the metric itself."""
    return lambda idx: judge.metric(name, idx)


def _chebyshev(judge: _Judge, a: str, b: str, w: float):
    """merit(idx) -> (n,): max(w fa, (1 - w) fb) + 0.001 (w fa + (1 - w) fb), each objective
    measured from one spread below its lowest feasible value so far, in that spread."""
    idx = np.arange(judge.ev.n)
    ok = judge.violation(idx) == 0
    ref = []
    for name in (a, b):
        x = judge.metric(name, idx)[ok]
        x = x[np.isfinite(x)]
        lo, spread = (float(x.min()), float(np.ptp(x))) if len(x) else (0.0, 1.0)
        spread = spread or abs(lo) or 1.0
        ref.append((lo - spread, spread))

    def merit(i):
        fa = (judge.metric(a, i) - ref[0][0]) / ref[0][1]
        fb = (judge.metric(b, i) - ref[1][0]) / ref[1][1]
        return np.maximum(w * fa, (1 - w) * fb) + 1e-3 * (w * fa + (1 - w) * fb)

    return merit


def _search(problem: Problem, ev: Evaluator, judge: _Judge, merit, seed: int, progress):
    """One differential evolution over the bounds; returns (the best free values, scipy's
    message)."""
    lo, width = problem.lower, problem.upper - problem.lower
    first_spread, history = [], []

    def evaluate(uT):  # (F, S) or (F,) scaled, beyond the bounds by MARGIN: clipped to them
        u = np.atleast_2d(np.asarray(uT).T) if np.ndim(uT) > 1 else np.asarray(uT)[None]
        return ev(lo + np.clip(u, 0.0, 1.0) * width)

    def constraints(uT):  # (F, S) or (F,) -> (M, S) or (M,)
        g = judge.rows(evaluate(uT))
        return g[0] if np.ndim(uT) == 1 else g.T

    def objective(uT):  # asked only of feasible variants (already evaluated)
        f = merit(evaluate(uT))
        f = np.where(np.isfinite(f), f, np.inf)
        return f[0] if np.ndim(uT) == 1 else f

    def gathered(intermediate_result) -> bool:
        result = intermediate_result
        ev.generation += 1
        energies = np.asarray(result.population_energies)
        finite = energies[np.isfinite(energies)]
        if progress is not None:
            progress(ev.generation, float(finite.min()) if len(finite) else float("nan"))
        if not first_spread:
            first_spread.append(float(np.std(finite)) if len(finite) else 0.0)
        spread = np.ptp(np.clip(result.population, 0.0, 1.0), axis=0)
        if spread.max() < HANDOVER:  # gathered (on the closest variant, if none is feasible)
            return True
        # stalled: the best (or, with no feasible one, the least violation) better by less
        # than STALL_GAIN of itself (plus tol x the first generation's spread) in STALL
        # generations
        scale = problem.tol * first_spread[0]
        best = (0, float(finite.min())) if len(finite) else \
            (1, float(judge.violation(np.arange(ev.n)).min()))
        history.append(best)
        if len(history) > STALL and history[-1 - STALL][0] == best[0]:
            then = history[-1 - STALL][1]
            if not best[1] < then - STALL_GAIN * abs(then) - (scale if best[0] == 0 else 0.0):
                return True
        return False

    n = problem.n_free
    result = differential_evolution(
        objective, [(-MARGIN, 1.0 + MARGIN)] * n,
        constraints=[NonlinearConstraint(constraints, -np.inf, 0.0)],
        popsize=max(1, -(-problem.population // n)), maxiter=problem.generations, tol=0.0,
        atol=0.0, polish=False, vectorized=True, updating="deferred", rng=seed,
        recombination=RECOMBINATION, init="latinhypercube",
        callback=gathered)
    ev.generation += 1  # the next run's (or the polish's) evaluations start a new generation
    return lo + np.clip(result.x, 0.0, 1.0) * width, str(result.message)


def _key(judge: _Judge, merit, idx) -> np.ndarray:
    """(n, 2) sort keys by the feasibility rules: (0, merit) feasible, (1, violation) not."""
    v = judge.violation(idx)
    ok = v == 0
    f = merit(idx)
    return np.column_stack([~ok, np.where(ok, np.where(np.isfinite(f), f, np.inf), v)]).astype(float)


def _polish(problem: Problem, ev: Evaluator, judge: _Judge, merit, x0, rng) -> None:
    """From ``x0`` (free values): see the module doc. Its evaluations are generation -1."""
    lo, width = problem.lower, problem.upper - problem.lower
    keep, ev.generation = ev.generation, -1
    every = np.arange
    u = np.clip((np.asarray(x0) - lo) / width, 0.0, 1.0)
    ev(lo + u * width)
    free = np.ones(problem.n_free, dtype=bool)
    tried = np.zeros(problem.n_free, dtype=bool)
    fine = False

    def best_u():
        b = _best_of(judge, merit, every(ev.n))
        return b, (ev.arrays()[0][b, :problem.n_free] - lo) / width

    while True:  # each face tried once; a face that holds a better best is kept
        distance = np.minimum(u, 1 - u)
        near = free & ~tried & (distance < BOUND_TRY)
        if near.any():  # the nearest bound first, one value at a time
            j = int(np.flatnonzero(near)[np.argmin(distance[near])])
            before = _key(judge, merit, np.array([best_u()[0]]))[0]
            face = u.copy()
            face[j] = np.round(u[j])
            rest = free.copy()
            rest[j] = False
            ev(lo + face * width)
            if rest.any():
                _cma(problem, ev, judge, merit, face, rest, rng, STEP_START, STEP_MIDDLE,
                     runs=1)
            b, ub = best_u()
            tried[j] = True
            if tuple(_key(judge, merit, np.array([b]))[0]) < tuple(before) and ub[j] == face[j]:
                u, free, fine = ub, rest, False
            continue
        if not free.any():
            break
        _cma(problem, ev, judge, merit, u, free, rng, STEP_MIDDLE * 10 if fine else STEP_START,
             STEP_END if fine else STEP_MIDDLE)
        u = best_u()[1]
        new = (free & ~tried & ((u < BOUND_TRY) | (u > 1 - BOUND_TRY))).any()
        if fine and not new:
            break
        fine = fine or not new
    ev.generation = keep


def _cma(problem: Problem, ev: Evaluator, judge: _Judge, merit, u0, free, rng, sigma, tolx,
         runs: int = CMA_RUNS) -> None:
    """CMA-ES over the parameters ``free`` (a mask) from ``u0`` (scaled to the bounds' [0,
    1]), the others held; each iteration's population one batch, ranked by the feasibility
    rules (CMA-ES needs only the ranks)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # cma's note that matplotlib is not installed
        import cma

    lo, width = problem.lower, problem.upper - problem.lower
    n = int(free.sum())
    u = np.array(u0, dtype=float)
    for _ in range(runs):  # a run that stops short of tolx starts again from its best
        options = {"bounds": [0.0, 1.0], "tolx": tolx, "tolfun": 0.0, "tolfunhist": 0.0,
                   "tolflatfitness": 20, "tolupsigma": 1e300, "maxiter": CMA_ITERATIONS,
                   "popsize": max(16, 8 * n), "seed": int(rng.integers(1, 2**31 - 1)),
                   "verbose": -9}
        es = cma.CMAEvolutionStrategy(list(u[free]), sigma, options)
        best, since = (np.inf, np.inf), 0
        while not es.stop() and since < CMA_STALL:
            trial = np.clip(np.array(es.ask()), 0.0, 1.0)
            full = np.tile(u, (len(trial), 1))
            full[:, free] = trial
            keys = _key(judge, merit, ev(lo + full * width))
            order = np.lexsort((keys[:, 1], keys[:, 0]))
            since += 1
            if tuple(keys[order[0]]) < best:
                best, top, since = tuple(keys[order[0]]), full[order[0]], 0
            rank = np.empty(len(keys))
            rank[order] = np.arange(len(keys))
            es.tell(list(trial), list(rank))
        if best < (np.inf, np.inf):
            u = top
        if "tolx" in es.stop() or since >= CMA_STALL:  # converged, or no better in CMA_STALL
            return


def _best_of(judge: _Judge, merit, idx) -> int:
    keys = _key(judge, merit, idx)
    return int(idx[np.lexsort((keys[:, 1], keys[:, 0]))[0]])


def _outcome(problem: Problem, ev: Evaluator, judge: _Judge, messages, seconds) -> Outcome:
    values, metrics, generation = ev.arrays()
    idx = np.arange(ev.n)
    violation = judge.violation(idx)
    feasible = violation == 0
    first = metrics[problem.objectives[0]]
    if not feasible.any():
        raise Infeasible(_closest(problem, judge, values, metrics, violation))
    pareto = np.zeros(0, dtype=np.intp)
    if len(problem.objectives) == 2:
        from .view import pareto_set

        pool = np.flatnonzero(feasible)
        pareto = pool[pareto_set(first[pool], metrics[problem.objectives[1]][pool])]
        best = int(pareto[0])
    else:
        f = np.where(feasible & np.isfinite(first), first, np.inf)
        best = len(f) - 1 - int(np.argmin(f[::-1]))  # the last of equals: a bound snapped to
    G = int(generation.max()) + 1 if len(generation) else 0
    population_best = np.full(G, np.nan)
    for g in range(G):
        sel = feasible & (generation >= 0) & (generation <= g)
        if sel.any():
            population_best[g] = first[sel].min()
    scales = judge.scales()
    active = [c.text for c, s in zip(problem.constraints, scales)
              if abs(c.excess(metrics[c.metric][best:best + 1])[0]) <= ACTIVE * s]
    u = (values[best, :problem.n_free] - problem.lower) / (problem.upper - problem.lower)
    on_bound = [(p.address, "lower" if u[j] <= ON_BOUND else "upper")
                for j, p in enumerate(problem.study.parameters[:problem.n_free])
                if u[j] <= ON_BOUND or u[j] >= 1 - ON_BOUND]
    return Outcome(problem, values, metrics, generation, feasible, violation, best, pareto,
                   population_best, active, on_bound, seconds, messages)


def _closest(problem: Problem, judge: _Judge, values, metrics, violation) -> str:
    """The message for a problem no evaluated variant meets: the one closest to meeting it."""
    v = int(np.argmin(violation))
    units = problem.study.parameter_units()
    where = ", ".join(f"{p.address} = {values[v, j]:.6g}" + (f" {units[j]}" if units[j] else "")
                      for j, p in enumerate(problem.study.parameters))
    m_units = problem.study.metric_units()
    broken = [f"{c.metric} = {metrics[c.metric][v]:.6g}"
              + (f" {m_units[c.metric]}" if m_units.get(c.metric) else "")
              + f" (must be {c.op} {c.limit:g})"
              for c in problem.constraints if c.excess(metrics[c.metric][v:v + 1])[0] > 0]
    failed = int(metrics[FAILED][v])
    if failed:
        broken.append(f"{failed} of {problem.study.scene.n_steps} steps failed")
    return (f"{problem.study.path}: [optimize] constraints: no variant meets the constraints "
            f"({len(violation):,} evaluated, a variant with a failed step fails); the closest, "
            f"{where}, has " + "; ".join(broken or ["a metric that is not a number"])
            + " — widen the bounds, or relax the constraints")
