"""``[optimize]``: read and check an optimisation problem over a study's variants.

``[optimize]`` sits in a scene (beside its own ``[study]`` with ``[study.metrics]``) or in a
study file (beside ``[study] base`` and ``[study.metrics]``)::

    [optimize]
    minimize = "peak_handle"            # a [study.metrics] name, or two: a Pareto set
    parameters = { "springs.left.k" = [0.0, 5000.0], "points.S1.y" = [-1.0, 0.5] }
    tie = { "springs.right.k" = "springs.left.k" }
    constraints = ["hold_open <= 0", "margin"]   # "<metric> <= | >= <number>", or a bare
    seed = 1                                     #   metric name: it must be >= 0 (a margin)

``[optimize] parameters`` are what the search varies (``[study.parameters]``, where present, are
the study's and play no part). The problem is a :class:`linkpipe.study.spec.Study` whose
parameters are the bounded ones (kind ``"bound"``, spec (low, high)) and the tied ones (kind
``"tie"``): every generation of the search is that study's variants at other values, solved
by the study's own batch (:func:`linkpipe.study.batch.solve_batch`). Every mistake is one
:class:`SceneError` naming the file, ``[optimize]`` (or ``[study.metrics]``) and the key.
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import re
import tomllib
import os
import stat
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..fit import acts, locate
from ..scene.keys import KEYS, _is_number, _suggest
from ..version import __version__
from . import paths, spec
from .reductions import compile_metric
from .spec import Metric, Study, StudyParameter

#: the hidden metric every evaluation carries: its steps that are not ok
FAILED = "_failed_steps"
_CONSTRAINT = re.compile(r"^\s*(?P<a>[^<>=]+?)\s*(?P<op><=|>=|<|>)\s*(?P<b>[^<>=]+?)\s*$")


@dataclass(frozen=True)
class Constraint:
    """``metric op limit`` (``op`` "<=" or ">="; a strict sign reads as its closed form)."""

    text: str
    metric: str
    op: str
    limit: float

    def excess(self, value: np.ndarray) -> np.ndarray:
        """How far past its limit each value is (<= 0 where it holds; +inf where NaN)."""
        g = value - self.limit if self.op == "<=" else self.limit - value
        return np.where(np.isnan(g), np.inf, g)


@dataclass(frozen=True)
class Problem:
    """A checked ``[optimize]``: ``study`` (its parameters: the bounded ones, then the tied;
    ``values``: the bounds' two corners), ``objectives`` (one or two metric names),
    ``constraints``, ``lower``/``upper`` (n_free,) bounds of the bounded parameters, and the
    search's settings."""

    study: Study
    objectives: tuple[str, ...]
    constraints: tuple[Constraint, ...]
    lower: np.ndarray
    upper: np.ndarray
    seed: int
    population: int
    generations: int
    tol: float

    @property
    def n_free(self) -> int:
        return len(self.lower)

    def values(self, free: np.ndarray) -> np.ndarray:
        """(n, n_parameters): every parameter's value (ties set) at the bounded ones' ``free``
        (n, n_free)."""
        free = np.atleast_2d(free)
        out = np.empty((free.shape[0], len(self.study.parameters)))
        out[:, :self.n_free] = free
        return spec.with_ties(self.study.parameters, out)


def has_optimize(path) -> bool:
    """Whether the TOML file at ``path`` holds an ``[optimize]`` table (False if unreadable;
    a path that is no regular file is never opened here: a FIFO would block, the scene reader
    explains it)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return False
    except OSError:
        return False
    try:
        return isinstance(spec._read(str(path))[1].get("optimize"), dict)
    except SceneError:
        return False


def load_problem(path, catalog_of=None) -> Problem:
    """Read and check the ``[optimize]`` of the study file or scene at ``path``."""
    path = str(path)
    text, data = spec._read(path)
    raw = data.get("optimize")
    if not isinstance(raw, dict):
        raise SceneError(path, "optimize", None, "no [optimize] table" if raw is None else
                         "expected a table [optimize]",
                         'add [optimize] with minimize = "<a [study.metrics] name>" and '
                         'parameters = { "<address>" = [low, high] }')
    unknown = sorted(set(raw) - set(KEYS["optimize"]))
    if unknown:
        raise SceneError(path, "optimize", unknown[0], "unknown key",
                         _suggest(unknown[0], KEYS["optimize"]))
    study_raw = data.get("study", {})
    if not isinstance(study_raw, dict):
        raise SceneError(path, "study", None, "expected a table [study]",
                         "write [study.metrics] with the metrics [optimize] names")
    bad = sorted(set(study_raw) - set(KEYS["study"]))
    if bad:
        raise SceneError(path, "study", bad[0], "unknown key", _suggest(bad[0], KEYS["study"]))
    scene, name = spec._base_scene(path, data, study_raw)
    base = {k: v for k, v in tomllib.loads(scene.text).items()
            if k not in ("study", "fit", "optimize")}
    catalog = (catalog_of or spec._catalog)(scene)
    metrics = spec._metrics(path, study_raw, catalog, scene.n_steps)
    objectives = _objectives(path, raw, metrics)
    constraints = _constraints(path, raw, metrics)
    bounded = _bounded(path, raw, scene, base)
    params = tuple(bounded) + spec.tied(path, "optimize", raw.get("tie"), scene, base, bounded)
    lower = np.array([p.spec[0] for p in bounded])
    upper = np.array([p.spec[1] for p in bounded])
    seed = _whole(path, raw, "seed", 0, 0)
    population = _whole(path, raw, "population", max(40, 20 * len(bounded)), 5)
    generations = _whole(path, raw, "generations", 1000, 1)
    tol = raw.get("tol", 1e-4)
    if not _is_number(tol) or not 0 < tol < 1:
        raise SceneError(path, "optimize", "tol", f"expected a number in (0, 1), got {tol!r}",
                         "write e.g. tol = 1e-4 (the objective's spread in the population, over "
                         "the first generation's, where the search hands over to the polish)")
    failed = Metric(FAILED, "count_failed()", compile_metric(path, FAILED, "count_failed()", catalog))
    corners = spec.with_ties(params, np.concatenate(
        [np.stack([lower, upper]), np.zeros((2, len(params) - len(bounded)))], axis=1))
    digest = hashlib.sha256("\0".join([__version__, text, scene.text]).encode()).hexdigest()
    batch = spec.default_batch_size(population, scene.n_steps)
    study = Study(path, name, text, scene, base, params, corners, metrics + (failed,), catalog,
                  1, seed, batch, digest)
    slots, why = paths.plan(study)
    note = (f"variant by variant: {why}" if slots is None else
            "vectorised: each generation one batch of variants")
    study = dataclasses.replace(study, slots=None if slots is None else tuple(slots),
                                path_note=note)
    return Problem(study, objectives, constraints, lower, upper, seed, population, generations,
                   float(tol))


def _names(metrics) -> list[str]:
    return [m.name for m in metrics]


def _objectives(path, raw, metrics) -> tuple[str, ...]:
    names = _names(metrics)
    hint = ('name a metric of [study.metrics], or add one there' if names else
            'add [study.metrics] with e.g. peak = "max(abs(input_force.<driver>))" and name it')
    value = raw.get("minimize")
    if value is None:
        raise SceneError(path, "optimize", "minimize", "missing: what to minimise", hint)
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not 1 <= len(items) <= 2 or \
            not all(isinstance(v, str) for v in items):
        raise SceneError(path, "optimize", "minimize", f"expected a metric name or a list of "
                         f"two, got {value!r}", hint)
    for item in items:
        if item not in names:
            raise SceneError(path, "optimize", "minimize", f'"{item}" names no metric'
                             + (f" ({_suggest(item, names)})" if names else
                                " (there is no [study.metrics])"), hint)
    if len(items) == 2 and items[0] == items[1]:
        raise SceneError(path, "optimize", "minimize", "the same metric twice", "name two metrics, or one")
    return tuple(items)


def _constraints(path, raw, metrics) -> tuple[Constraint, ...]:
    names = _names(metrics)
    value = raw.get("constraints", [])
    hint = ('write constraints = ["hold_open <= 0", "margin"] (a metric against a number, or a '
            "metric alone: it must be >= 0)")
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise SceneError(path, "optimize", "constraints", f"expected a list of strings, got {value!r}", hint)
    out = []
    for text in value:
        m = _CONSTRAINT.match(text)
        if m is None:
            if text.strip() in names:
                out.append(Constraint(text, text.strip(), ">=", 0.0))
                continue
            a, op, b = text.strip(), None, None
        else:
            a, op, b = m["a"], m["op"], m["b"]
        flip = {"<=": ">=", ">=": "<=", "<": ">=", ">": "<="}
        if op is not None and a in names and _float(b) is not None:
            out.append(Constraint(text, a, op.rstrip("=") + "=", _float(b)))
        elif op is not None and b in names and _float(a) is not None:
            out.append(Constraint(text, b, flip[op], _float(a)))
        else:
            unknown = [w for w in (a, b) if w is not None and _float(w) is None and w not in names]
            raise SceneError(path, "optimize", "constraints",
                             f'"{text}": ' + (f'"{unknown[0]}" names no metric ({_suggest(unknown[0], names)})'
                                              if unknown else "not a metric against a number"), hint)
    return tuple(out)


def _float(text):
    try:
        value = float(text)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _bounded(path, raw, scene, base) -> list[StudyParameter]:
    table = raw.get("parameters")
    hint = 'write parameters = { "springs.left.k" = [0.0, 5000.0] } (each value\'s low and high bound)'
    if not isinstance(table, dict) or not table:
        raise SceneError(path, "optimize", "parameters", "missing or empty: the search varies at "
                         "least one value", hint)
    out = []
    for address, bounds in table.items():
        where = (path, "optimize.parameters", address)
        p_path, value = locate(scene, base, address, where)
        acts(scene, address, p_path, where)
        if p_path[0] == "time" or p_path[-1] in spec._STEP_KEYS or spec._moves_step_count(base, p_path):
            raise SceneError(*where, "would change the steps; the variants share one sweep of "
                             "steps", "optimise another value")
        if not (isinstance(bounds, list) and len(bounds) == 2 and all(map(_is_number, bounds))
                and all(map(math.isfinite, bounds))):
            raise SceneError(*where, f"expected [low, high] (two finite numbers), got {bounds!r}", hint)
        lo, hi = map(float, bounds)
        if not lo < hi:
            raise SceneError(*where, f"the bounds are empty: low {lo:g} >= high {hi:g}",
                             "give low < high")
        twin = next((q.address for q in out if q.path == p_path), None)
        if twin is not None:
            raise SceneError(*where, f'is the same value as "{twin}" (two addresses of one '
                             "number)", "name it once")
        out.append(StudyParameter(address, p_path, float(value), "bound", (lo, hi)))
    return out


def _whole(path, raw, key, default, low) -> int:
    value = raw.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise SceneError(path, "optimize", key, f"expected a whole number >= {low}, got {value!r}",
                         f"write e.g. {key} = {KEYS['optimize'][key]}")
    return value
