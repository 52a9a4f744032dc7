"""``linkpipe fit``: adjust named scene values to the measurements by least squares.

``[fit] parameters`` address any numeric value of the scene file as ``table.entry.key[.index]``
(entries of ``[[...]]`` tables by their ``name``, ``[[masses]]`` by their ``link``, and
``masses.<link>.<n>.<key>`` the n-th (from 1, in the file's order) of several on one link;
``points.P.x``, ``links.coupler.lengths.A-B``, ``loads.tool.force.1``, ``gravity.g.1``).
Each trial value is written into the scene's TOML data and read back through the scene parser,
so every check of a scene applies to it. The objective is
``sum(((computed - measured) / sigma)^2)`` over every measurement and every step where both
exist at the initial values (a step that fails at a trial value, or a trial the scene refuses,
counts as 1000 sigma, or ten times the start's largest weighted residual where that is more:
the optimiser is pushed back, never handed a NaN). ``scipy.optimize.least_squares`` (trust-region
reflective, bounds from ``[fit] bounds``, ``[fit] loss`` and ``f_scale``: a robust loss on the
sigma-weighted residuals) minimises it. ``[fit] per_log`` matters with ``fit --logs`` only: one
joint fit over every log (:mod:`linkpipe.joint`), each log a :class:`Problem`.

When every parameter is a force parameter (``springs``, ``torsion_springs``, ``masses``,
``loads``, ``gravity``), stage 1 is solved once and reused for every trial (only the force
stage runs again). Standard errors come from the Jacobian at the solution: the covariance is
``inv(J^T J)`` with J of the sigma-weighted residuals, scaled by the residual variance
``cost / (N - p)`` when some measurement has no ``sigma`` (``cost``: the objective,
the sum of the squared weighted residuals; scipy's own is half of it). A parameter the data cannot
identify (a singular value of J below ``IDENTIFIABLE_RCOND`` of the largest, with the parameter
in the null direction) is reported as not identifiable, with no standard error. With a robust
loss J is scipy's loss-weighted Jacobian: the standard errors are those of the loss used. The
correlation matrix of the parameters comes from the same covariance.
"""
from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import diags

from .errors import MemoryRefused, SceneError
from .pipeline import solve
from .output_units import measured_units
from .scene import Scene
from .scene.keys import TABLES, _suggest

FORCE_TABLES = ("springs", "torsion_springs", "masses", "loads", "gravity", "friction")
#: a singular value of the weighted Jacobian below this part of the largest: not identifiable
IDENTIFIABLE_RCOND = 1e-8
#: a trial step that failed counts as this many sigma
FAILED_STEP_SIGMAS = 1e3
#: the solves a fit keeps, for trials that move only a measurement's offset or scale
RECENT_SOLVES = 8
#: ``[fit] loss``: scipy.optimize.least_squares' losses (all but "linear" robust to outliers)
LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")
FIT_KEYS = ("parameters", "bounds", "per_log", "loss", "f_scale")
#: keys a scene may leave out that a fit may still address: (table, key) -> their default
ABSENT_DEFAULTS = {("drivers", "offset"): 0.0, ("measurements", "offset"): 0.0,
                   ("logs", "lag"): 0.0}


@dataclass(frozen=True)
class Parameter:
    address: str
    path: tuple  # keys and indices into the scene's TOML data
    initial: float
    bounds: tuple[float, float] = (-math.inf, math.inf)

    @property
    def force_only(self) -> bool:
        """True when the number leaves stage 1 as it is: a force table's (a torsion spring's
        free angle too: its angle is the links' difference, whatever the free angle)."""
        return self.path[0] in FORCE_TABLES


@dataclass
class FitResult:
    """Every figure of a fit; standard errors NaN where not identifiable."""

    scene: Scene
    parameters: list[Parameter]
    fitted: np.ndarray
    standard_error: np.ndarray
    identifiable: np.ndarray
    cost: list[float]
    before: object  # the Result at the initial values
    after: object  # the Result at the fitted values
    fitted_data: dict
    stage1_solves: int
    message: str = ""
    #: the optimiser's evaluations (its ``max_nfev`` counts these; ``cost`` has one entry at the
    #: start and one per iteration), and every solve of the scene, the finite differences of
    #: the Jacobian (one per parameter per iteration) included
    n_evaluations: int = 0
    solves: int = 0
    extra: dict = field(default_factory=dict)
    #: the final objective over its degrees of freedom, cost / (N - p) (NaN when N <= p), and
    #: what the fit warns of (:func:`sigma_warnings`)
    reduced_chi_square: float = math.nan
    warnings: tuple = ()
    #: the parameters' correlation matrix (p, p) (NaN where not identifiable); the loss used
    correlation: np.ndarray | None = None
    loss: str = "linear"
    f_scale: float = 1.0

    @property
    def names(self) -> list[str]:
        return [p.address for p in self.parameters]


def parameters_of(scene: Scene, data: dict) -> list[Parameter]:
    """The ``[fit]`` table's parameters, located in ``data`` (scene errors name the key)."""
    raw = data.get("fit")
    where = f"{scene.path}"
    if not isinstance(raw, dict) or "parameters" not in raw:
        raise SceneError(where, "fit", "parameters", "missing: a fit needs [fit] parameters",
                         'add [fit] with parameters = ["springs.<name>.k", ...]')
    unknown = set(raw) - set(FIT_KEYS)
    if unknown:
        key = sorted(unknown)[0]
        raise SceneError(where, "fit", key, "unknown key", _suggest(key, FIT_KEYS))
    names = raw["parameters"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise SceneError(where, "fit", "parameters", "expected a non-empty array of strings",
                         'write e.g. parameters = ["springs.cable.k"]')
    if len(set(names)) != len(names):
        raise SceneError(where, "fit", "parameters", "a parameter is named twice", "name each once")
    bounds = raw.get("bounds", {})
    if not isinstance(bounds, dict):
        raise SceneError(where, "fit", "bounds", "expected a table", 'write bounds = { "springs.cable.k" = [0.0, 1e5] }')
    out = []
    for name in names:
        path, value = locate(scene, data, name)
        twin = next((q.address for q in out if q.path == path), None)
        if twin is not None:
            raise SceneError(where, "fit", "parameters", f'"{name}" is the same value as '
                             f'"{twin}" (two addresses of one number)', "name it once")
        acts(scene, name, path)
        lo, hi = _bounds_of(scene, bounds, name, value)
        out.append(Parameter(name, path, float(value), (lo, hi)))
    for name in bounds:
        if name not in names:
            raise SceneError(where, "fit.bounds", name, "is not one of [fit] parameters",
                             _suggest(name, names))
    return out


@dataclass(frozen=True)
class FitOptions:
    """``[fit] loss`` and ``f_scale`` (the residual, in sigmas, where a robust loss turns), and
    ``per_log``: the parameters a fit over several logs takes once per log."""

    loss: str = "linear"
    f_scale: float = 1.0
    per_log: tuple[str, ...] = ()


def fit_options(scene: Scene, data: dict) -> FitOptions:
    """The ``[fit]`` table's loss, f_scale and per_log, checked (after :func:`parameters_of`)."""
    raw = data.get("fit") or {}
    where = scene.path
    loss = raw.get("loss", "linear")
    if loss not in LOSSES:
        raise SceneError(where, "fit", "loss", f"unknown loss {loss!r}",
                         _suggest(str(loss), LOSSES) + " (linear: least squares; the others "
                         "weigh down residuals beyond f_scale sigmas)")
    f_scale = raw.get("f_scale", 1.0)
    if isinstance(f_scale, bool) or not isinstance(f_scale, (int, float)) or not (
            0 < f_scale < math.inf):
        raise SceneError(where, "fit", "f_scale", f"expected a positive number, got {f_scale!r}",
                         "the residual in sigmas where a robust loss turns, e.g. f_scale = 3.0")
    per_log = raw.get("per_log", [])
    names = raw.get("parameters", [])
    if not isinstance(per_log, list) or not all(isinstance(n, str) for n in per_log):
        raise SceneError(where, "fit", "per_log", "expected an array of parameter addresses",
                         'write e.g. per_log = ["drivers.crank.offset"]')
    for name in per_log:
        if name not in names:
            raise SceneError(where, "fit", "per_log", f'"{name}" is not one of [fit] parameters',
                             _suggest(name, names) + "; a per-log parameter is also listed in "
                             "parameters")
    if len(set(per_log)) != len(per_log):
        raise SceneError(where, "fit", "per_log", "a parameter is named twice", "name each once")
    return FitOptions(loss, float(f_scale), tuple(per_log))


def effects_moved_by(path: tuple) -> tuple[str, ...]:
    """The effects a force table's number acts through (any one of them on: it moves the
    computed forces), or () for a number of the geometry, the drivers, the logs or the
    measurements (it always may)."""
    table, key = path[0], next((k for k in path[2:] if isinstance(k, str)), "")
    if table in ("springs", "torsion_springs"):
        return ("damping",) if key == "damping" else ("springs",)
    if table == "masses":
        return ("inertia",) if key == "inertia" else ("gravity", "inertia")
    return (table,) if table in ("gravity", "loads", "friction") else ()


def acts(scene, name: str, path: tuple, where=None) -> None:
    """A parameter of an effect the scene leaves off changes nothing: fitted, it would come
    back "not identifiable" with no word of why (a study's or a search's variants would all be
    the same); one message instead. ``where``: (file, table, key), as :func:`locate`'s."""
    effects = effects_moved_by(path)
    if effects and not set(effects) & set(scene.effects):
        either = " or ".join(f'"{e}"' for e in effects)
        raise SceneError(*(where or (scene.path, "fit", "parameters")),
                         f'"{name}" acts through the effect {either}, which [analysis] effects '
                         f"leaves off: it changes nothing that is computed",
                         f"add {either.split(' or ')[0]} to [analysis] effects, or leave the "
                         f"parameter out")


def _bounds_of(scene, bounds, name, value):
    if name not in bounds:
        return -math.inf, math.inf
    b = bounds[name]
    if (not isinstance(b, list) or len(b) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in b)
            or not b[0] < b[1] or not b[0] <= value <= b[1]):
        raise SceneError(scene.path, "fit.bounds", name,
                         f"expected [low, high] with low < high around the value {value:g}, got {b!r}",
                         f'write e.g. "{name}" = [{value / 10 if value > 0 else value - 1:g}, '
                         f"{value * 10 if value > 0 else value + 1:g}]")
    return float(b[0]), float(b[1])


def locate(scene: Scene, data: dict, address: str, where=None):
    """Return (path, value) of a numeric value addressed ``table.entry.key[.index]``.

    ``where``: (file, table, key) a mistake is reported at (default: the scene's ``[fit]
    parameters``; a study names its own file and ``[study.parameters]``)."""
    parts = address.split(".")
    where = where or (scene.path, "fit", "parameters")

    def fail(message, hint=""):
        return SceneError(*where, f'"{address}": {message}', hint)

    table = parts[0]
    if table not in TABLES or table not in data:
        raise fail(f'no table "{table}" in the scene', _suggest(table, [t for t in TABLES if t in data]))
    node, path, rest = data[table], [table], parts[1:]
    if TABLES[table] == "array":
        if not rest:
            raise fail(f"name an entry of [[{table}]]", f'write "{table}.<name>.<key>"')
        field_name = "link" if table == "masses" else "name"
        matches = [i for i, e in enumerate(node) if e.get(field_name) == rest[0]]
        if not matches:
            raise fail(f'no [[{table}]] entry with {field_name} = "{rest[0]}"',
                       _suggest(rest[0], [e.get(field_name) for e in node]))
        rest = rest[1:]
        if table == "masses" and rest and rest[0].isdigit():  # masses.<link>.<n>: the n-th on it
            n = int(rest[0])
            if not 1 <= n <= len(matches):
                raise fail(f'link "{parts[1]}" has {len(matches)} [[masses]] entr'
                           f'{"y" if len(matches) == 1 else "ies"}, not {n}',
                           f"number them from 1 in the file's order, up to {len(matches)}")
            matches, rest = [matches[n - 1]], rest[1:]
        if len(matches) > 1:  # (names are unique elsewhere: only masses share their link)
            raise fail(f'{len(matches)} [[masses]] entries are on link "{parts[1]}", and the '
                       "address does not say which",
                       f'number them from 1 in the file\'s order: "masses.{parts[1]}.1.'
                       f'{".".join(rest) or "mass"}" .. "masses.{parts[1]}.{len(matches)}.'
                       f'{".".join(rest) or "mass"}"')
        node, path = node[matches[0]], path + [matches[0]]
    for i, part in enumerate(rest):
        if isinstance(node, dict) and part in node:
            node, path = node[part], path + [part]
        elif (isinstance(node, dict) and i == len(rest) - 1 and len(path) == 2
              and (table, part) in ABSENT_DEFAULTS):  # a key left at its default
            node, path = ABSENT_DEFAULTS[table, part], path + [part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node, path = node[int(part)], path + [int(part)]
        else:
            choices = list(node) if isinstance(node, dict) else [str(i) for i in range(len(node))] \
                if isinstance(node, list) else []
            raise fail(f'no "{part}" there', _suggest(part, choices) if choices else "")
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise fail(f"is not a number ({type(node).__name__})", "address a numeric value, "
                   "e.g. an index of an array: loads.tool.force.1")
    return tuple(path), node


def _set(data: dict, path: tuple, value: float) -> None:
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = float(value)


def scene_with(scene: Scene, data: dict, params, x) -> Scene:
    """The scene with the parameters at ``x``, parsed (and checked) as a scene file is."""
    from .scene.parse import _Parser

    trial = copy.deepcopy(data)
    for p, v in zip(params, x):
        _set(trial, p.path, v)
    trial.pop("fit", None)
    return _Parser(trial, scene.text, scene.path).parse()


def fit_parameters(scene: Scene, data: dict | None = None) -> list[Parameter]:
    """``scene``'s ``[fit]`` parameters, with every check a fit makes before its first
    trial (the addresses, the bounds around each initial value, measurements to fit to and
    their sigmas where their units differ): what ``check`` runs on a scene with ``[fit]``.
    ``data``: as :func:`fit`."""
    data = tomllib.loads(scene.text) if data is None else data
    params = parameters_of(scene, data)
    fit_options(scene, data)  # loss, f_scale, per_log
    if not scene.measurements:
        raise SceneError(scene.path, "fit", "parameters", "nothing to fit to: the scene has no "
                         "[[measurements]]", "add [[measurements]] with log, of and sigma")
    units = measured_units(scene)
    if len(set(units)) > 1:  # residuals in different units are added only once weighed
        for m, unit in zip(scene.measurements, units):
            if m.sigma is None:
                others = sorted(set(units) - {unit})
                raise SceneError(scene.path, f'measurements "{m.name}"', "sigma",
                                 f"missing: this measurement is in {unit}, others in "
                                 f"{', '.join(others)}; a fit adds their residuals squared, "
                                 "which needs each divided by its own standard deviation",
                                 f"add sigma = <its standard deviation, in {unit}> to every "
                                 "measurement")
    return params


def declared_fit_parameters(scene: Scene) -> list[Parameter]:
    """:func:`fit_parameters` of a scene that has ``[fit]`` (what ``check`` describes); []
    without one."""
    data = tomllib.loads(scene.text)
    return fit_parameters(scene, data) if "fit" in data else []


def _nothing_to_fit(scene: Scene, before, k: int, m) -> SceneError:
    """The error for measurement ``k`` (``m``) with no step where both its measured and its
    computed value are finite at the start values (``before``, their Result): it names the
    side that is missing, and for failed steps what the run's summary says of them."""
    measured = np.isfinite(before.measurements["measured"][:, k])
    if not measured.any():
        return SceneError(scene.path, f'measurements "{m.name}"', "log",
                          f'the log column "{m.log}.{m.column}" has no number at any step',
                          "check that the column holds numbers over the sweep's time span")
    totals = before.totals
    why = "; ".join(totals.non_finite_causes)
    return SceneError(scene.path, "fit", "parameters",
                      f'with the start values, no step where "{m.log}.{m.column}" has a value '
                      f'computes "{m.address}" ({totals.message}'
                      + (f"; {why}" if why else "") + ")",
                      "start the fit from values at which the scene solves: run the scene "
                      "(python -m linkpipe run) to see its steps' statuses")


class Problem:
    """One scene's sigma-weighted residuals as a function of its fit parameters' values:
    solved once at the start values (``before``), which fixes the residuals counted
    (``mask``: steps where measured and computed are both finite), the ``sigma`` per
    measurement and the ``penalty`` a failed step or a refused trial counts as. ``solves`` and
    ``stage1`` count the solves of the scene. ``remember``: trials that move only measurements'
    offsets or scales reuse a recent solve (False: every trial solves, a reference)."""

    def __init__(self, scene: Scene, data: dict, params: list, remember: bool = True):
        self.scene, self.data, self.params = scene, data, params
        self.wanted = frozenset(m.of[0] for m in scene.measurements)  # trials read nothing else
        self.stage1 = self.solves = 0
        self.before = self.solve_at(np.array([p.initial for p in params]), None)
        self.reuse = self.before.kinematics if all(p.force_only for p in params) else None
        self.mask = np.isfinite(self.before.measurements["residual"])
        for k, m in enumerate(scene.measurements):
            if not self.mask[:, k].any():  # nothing to fit to: not a success with the start values
                raise _nothing_to_fit(scene, self.before, k, m)
        self.sigma = np.array([m.sigma if m.sigma is not None else 1.0
                               for m in scene.measurements])
        self.sigma_given = all(m.sigma is not None for m in scene.measurements)
        # a failed step, or a trial the scene cannot take, counts as FAILED_STEP_SIGMAS, or as
        # ten times the start's largest weighted residual where that is larger: never a way down
        start = np.abs(self.before.measurements["residual"] / self.sigma)[self.mask]
        self.penalty = max(FAILED_STEP_SIGMAS, 10.0 * float(start.max()) if start.size else 0.0)

        # a measurement's offset or scale moves the measured values alone: trials that change
        # nothing else reuse the computed series of the last solve (no solve)
        self.reading = [k for k, p in enumerate(params) if remember and p.path[0] ==
                        "measurements" and len(p.path) > 2 and p.path[2] in ("offset", "scale")]
        self.solving = [k for k in range(len(params)) if k not in self.reading]
        self.recent: dict = {}  # the solving parameters' values -> computed (S, M), last few

    @property
    def size(self) -> int:
        """The number of residuals (measured steps over every measurement)."""
        return int(self.mask.sum())

    def solve_at(self, x, reuse):
        self.stage1 += reuse is None
        self.solves += 1
        # threads None: the BLAS pool is set once around the whole fit (blas_pool)
        return solve(scene_with(self.scene, self.data, self.params, x), kinematics=reuse,
                     wanted=self.wanted, threads=None)

    def measured(self, x, measurements) -> np.ndarray:
        """The measured values (S, M) at ``x``: each of ``measurements``' (the trial scene's)
        ``parts @ scales + offset`` with the fitted offsets and scales in place."""
        out = []
        for i, m in enumerate(measurements):
            scales, offset = list(m.scales), m.offset
            for k in self.reading:
                path = self.params[k].path
                if path[1] != i:
                    continue
                if path[2] == "offset":
                    offset = x[k]
                elif len(path) == 4:
                    scales[path[3]] = x[k]
                else:
                    scales = [x[k]] * len(scales)
            out.append(m.parts @ np.asarray(scales, float) + offset)
        return np.stack(out, axis=1)

    def residuals(self, x) -> np.ndarray:
        """The weighted residuals (size,) at ``x``: ``(computed - measured) / sigma`` over the
        mask, ``penalty`` where a step fails or the scene refuses the values."""
        key = tuple(np.asarray(x, float)[self.solving])
        if key in self.recent:
            computed, measurements = self.recent[key]
        else:
            try:
                r = self.solve_at(x, self.reuse)
            except MemoryRefused:
                raise  # the scene's size, not this trial's values
            except SceneError:  # a trial the scene cannot take (e.g. a triangle that cannot close)
                return np.full(self.size, self.penalty)
            computed = r.measurements["measured"] + r.measurements["residual"]
            measurements = r.scene.measurements  # (a lag moves a second logger's parts)
            if self.reading:  # a Jacobian's columns go back to the point differenced
                self.recent[key] = computed, measurements
                while len(self.recent) > RECENT_SOLVES:
                    self.recent.pop(next(iter(self.recent)))
        weighted = (computed - self.measured(x, measurements)) / self.sigma
        return np.where(np.isfinite(weighted), weighted, self.penalty)[self.mask]

    def after(self, x):
        """The Result at the fitted values ``x``; a SceneError naming them if the scene refuses."""
        try:
            return self.solve_at(x, self.reuse)
        except SceneError as exc:  # the optimiser stopped where the scene cannot go
            values = ", ".join(f"{p.address} = {v:.6g}" for p, v in zip(self.params, x))
            raise SceneError(self.scene.path, "fit", "bounds", f"the fit ended at {values}, "
                             f"which the scene refuses ([{exc.table}] {exc.key}: {exc.message})",
                             "give [fit] bounds that keep each parameter where the scene is "
                             f'valid, e.g. bounds = {{ "{self.params[0].address}" = [low, high] }}'
                             ) from None


def blas_pool():
    """The BLAS thread pool a fit's solves run in, set once for the whole fit (setting it per
    solve costs milliseconds: threadpoolctl finds the libraries each time)."""
    from threadpoolctl import threadpool_limits

    from .workers import DEFAULT_THREADS

    return threadpool_limits(limits=DEFAULT_THREADS, user_api="blas")


def least_squares_options(options: FitOptions) -> dict:
    """The settings every fit passes to scipy.optimize.least_squares (trust-region
    reflective; forward differences of relative step 1e-7; the loss)."""
    return dict(method="trf", x_scale="jac", diff_step=1e-7, xtol=1e-12, ftol=1e-12,
                gtol=1e-12, loss=options.loss, f_scale=options.f_scale)


def fit(scene: Scene, progress=None, max_evaluations: int = 200, data: dict | None = None) -> FitResult:
    """Fit ``scene``'s ``[fit] parameters`` to its measurements; see the module doc.
    ``data``: the scene's TOML data when it differs from its text (a fleet's log file)."""
    data = tomllib.loads(scene.text) if data is None else data
    params = fit_parameters(scene, data)
    options = fit_options(scene, data)
    x0 = np.array([p.initial for p in params])
    with blas_pool():
        return _fit(scene, data, params, options, x0, progress, max_evaluations)


def _fit(scene, data, params, options, x0, progress, max_evaluations) -> FitResult:
    problem = Problem(scene, data, params)
    cost: list[float] = []  # the objective at the start, then at each iteration's point

    def residuals(x):
        out = problem.residuals(x)
        objective = float(out @ out)  # sum(((computed - measured) / sigma)^2)
        if not cost:  # the optimiser's first evaluation is at the start values
            cost.append(objective)
        if progress is not None:
            progress(problem.solves, objective)
        return out

    def per_iteration(intermediate_result):  # scipy's iterate after each iteration (the name
        f = intermediate_result.fun           # asks for the OptimizeResult; its f, not 1/2 f.f)
        cost.append(float(f @ f))

    lower, upper = zip(*(p.bounds for p in params))
    sol = least_squares(residuals, x0, bounds=(lower, upper), max_nfev=max_evaluations,
                        callback=per_iteration, **least_squares_options(options))
    cov, identifiable = covariance(sol.jac, sol.fun, problem.sigma_given)
    se = np.where(identifiable, np.sqrt(np.maximum(np.diag(cov), 0.0)), np.nan)
    chi2, warnings = _fit_warnings(sol.fun, problem.penalty, len(params), se,
                                   problem.sigma_given, options)
    after = problem.after(sol.x)
    fitted_data = copy.deepcopy(data)
    for p, v in zip(params, sol.x):
        _set(fitted_data, p.path, v)
    return FitResult(scene, params, sol.x, se, identifiable, cost, problem.before, after,
                     fitted_data, problem.stage1, sol.message, sol.nfev, solves=problem.solves,
                     reduced_chi_square=chi2, warnings=warnings,
                     correlation=correlation(cov, identifiable), loss=options.loss,
                     f_scale=options.f_scale)


def _fit_warnings(fun: np.ndarray, penalty, n_params: int, se: np.ndarray,
                  sigma_given: bool, options: FitOptions) -> tuple[float, tuple]:
    """(reduced chi-square over the steps that do not fail, what the fit warns of);
    ``penalty`` a number, or one per residual (a joint fit: each log's)."""
    failing = fun == penalty  # steps that fail at the fitted values (counted as penalty)
    penalty = float(np.max(penalty))
    real = fun[~failing]
    dof = real.size - n_params
    chi2 = float(real @ real) / dof if dof > 0 else math.nan
    warnings = ((f"{int(failing.sum())} of the {failing.size} measured steps fail at the fitted "
                 f"values (each counted as {penalty:.4g} sigma in the cost; "
                 "reduced_chi_square leaves them out): the fit ended beside a region the "
                 "scene cannot reach; give [fit] bounds that keep it out",) if failing.any()
                else ())
    if sigma_given and options.loss == "linear":  # a robust loss expects outliers beyond sigma
        warnings += sigma_warnings(float(real @ real), dof, se)
    return chi2, warnings


#: a fit whose final cost is this improbable under the sigmas (either tail of chi-square with
#: N - p degrees of freedom) and whose residuals are off the sigmas by more than SIGMA_FACTOR
#: (the standard errors as far off: a long log makes a few percent improbable, not wrong) says
#: so: the sigmas, a measurement's scale or the model is off
SIGMA_TAIL = 1e-6
SIGMA_FACTOR = 1.5


def sigma_warnings(cost: float, dof: int, se: np.ndarray) -> tuple[str, ...]:
    """What a fit with every ``sigma`` given warns of: a final ``cost`` (the sum of squared
    sigma-weighted residuals) that chi-square with ``dof`` degrees of freedom puts beyond
    :data:`SIGMA_TAIL` on either side, where the residuals are off the sigmas by more than
    :data:`SIGMA_FACTOR`. The standard errors ``se`` (NaN: not identifiable) take the sigmas
    as true; the warning gives them scaled by the residuals, as a fit without sigma would."""
    if dof <= 0:
        return ()
    from scipy.special import chdtr, chdtrc  # chi-square's cdf and sf (scipy.stats: 1 s to import)

    ratio = cost / dof
    if chdtrc(dof, cost) < SIGMA_TAIL and ratio > SIGMA_FACTOR ** 2:
        scaled = ", ".join(f"{v:.4g}" if np.isfinite(v) else "not identifiable"
                           for v in se * math.sqrt(ratio))
        return (f"the residuals are {math.sqrt(ratio):.3g} times what the sigmas allow (cost / "
                f"(N - p) = {ratio:.4g} over {dof} degrees of freedom, where about 1 is "
                "expected): a sigma, a measurement's scale or the model is off, and the standard "
                "errors, which take the sigmas as true, are too small; scaled by the residuals "
                f"they would be {scaled}",)
    if chdtr(dof, cost) < SIGMA_TAIL and ratio < SIGMA_FACTOR ** -2:
        return (f"the residuals are {math.sqrt(ratio):.3g} times the sigmas (cost / (N - p) = "
                f"{ratio:.4g} over {dof} degrees of freedom, where about 1 is expected): the "
                "sigmas overstate the noise, and the standard errors with them",)
    return ()


def covariance(J, residual: np.ndarray, sigma_given: bool):
    """Return (covariance (p, p), identifiable (p,) bool) of the parameters from the weighted
    Jacobian ``J`` (n, p; dense, or scipy.sparse: then from the eigenvectors of J^T J with
    J's columns scaled to unit length, which keeps the singular values to about 1e-8 of the
    largest) at the solution: ``pinv(J^T J)`` over the identifiable directions, times
    ``cost / (N - p)`` when no sigma is given. With a robust
    loss ``J`` is scipy's loss-weighted Jacobian (``J^T J`` the Gauss-Newton Hessian of the
    robust cost): the standard errors are those of the loss used."""
    n, p = J.shape
    if hasattr(J, "toarray"):  # sparse (a joint fit's): from J^T J of unit columns, (p, p)
        norms = np.sqrt(np.asarray(J.multiply(J).sum(axis=0)).ravel())
        scale = np.where(norms > 0, norms, 1.0)
        unit = J @ diags(1.0 / scale)
        eig, V = np.linalg.eigh((unit.T @ unit).toarray())
        order = np.argsort(eig)[::-1]
        sv, Vt = np.sqrt(np.maximum(eig[order], 0.0)), V[:, order].T
        small = sv < IDENTIFIABLE_RCOND * (sv[0] if len(sv) and sv[0] > 0 else 1.0)
        identifiable = np.ones(p, dtype=bool)
        for k in np.flatnonzero(small):
            identifiable &= ~(np.abs(Vt[k]) > 0.1)
        inv_sv2 = np.where(small, 0.0, 1.0 / np.where(small, 1.0, sv) ** 2)
        cov = ((Vt.T * inv_sv2) @ Vt) / np.outer(scale, scale)
        if not sigma_given:
            cov = cov * (float(residual @ residual) / max(n - p, 1))
        return cov, identifiable & (norms > 0)
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    small = sv < IDENTIFIABLE_RCOND * (sv[0] if len(sv) and sv[0] > 0 else 1.0)
    identifiable = np.ones(p, dtype=bool)
    for k in np.flatnonzero(small):  # parameters in a direction the data do not see
        identifiable &= ~(np.abs(Vt[k]) > 0.1)
    inv_sv2 = np.where(small, 0.0, 1.0 / np.where(small, 1.0, sv) ** 2)
    cov = (Vt.T * inv_sv2) @ Vt
    if not sigma_given:
        dof = max(n - p, 1)
        cov = cov * (float(residual @ residual) / dof)
    return cov, identifiable


def correlation(cov: np.ndarray, identifiable: np.ndarray) -> np.ndarray:
    """The parameters' correlation matrix (p, p) from their covariance; NaN in the rows and
    columns of a parameter that is not identifiable."""
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = cov / np.outer(se, se)
    ok = identifiable & (se > 0)
    out[~ok, :] = np.nan
    out[:, ~ok] = np.nan
    return out


def standard_errors(J: np.ndarray, residual: np.ndarray, sigma_given: bool):
    """Return (standard errors (p,), identifiable (p,) bool) from the weighted Jacobian."""
    cov, identifiable = covariance(J, residual, sigma_given)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return np.where(identifiable, se, np.nan), identifiable
