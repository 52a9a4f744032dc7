"""One model, many logs: ``fit SCENE --logs GLOB`` with ``[fit] per_log``.

One least-squares problem over every log the glob matches: the shared parameters (``[fit]
parameters`` not in ``per_log``) once, each ``per_log`` parameter once per log. The unknowns
are ``x = [shared (s), log 0's per-log values (q), log 1's (q), ...]`` (s + L q); the
residuals are each log's sigma-weighted residuals (:class:`linkpipe.fit.Problem`, the scene
with that log's file) one after the other. A log's residuals depend on the shared values and
its own per-log values only, so the Jacobian is block-sparse: forward differences over
groups of columns that share no rows (each shared column alone, the j-th per-log column of
every log together: :func:`groups_of`) give it in s + q evaluations of every log instead of
s + L q (50 logs, 3 + 2 parameters: 5 instead of 103), and a trial that moves only a
measurement's offset or scale solves nothing. The Jacobian goes to ``least_squares`` as a
sparse matrix, its trust-region steps solved by lsmr to 1e-12. (scipy's own ``jac_sparsity``
groups the columns too, but on the rig's logs of configs/logged its fit ended 3 mm from the
minimum that this grouping and a least squares written by hand on the closed form both find
(tests/test_real_logs.py); why was not found, so the grouping is done here.) Standard errors and the correlation matrix come from the joint
Jacobian at the solution (:func:`linkpipe.fit.covariance`), for the loss used.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from scipy.sparse import csr_matrix

from .errors import SceneError
from .fit import (FitOptions, Problem, _fit_warnings, blas_pool, correlation, covariance, fit_options,
                  fit_parameters, least_squares_options)
from .fleet import log_entry, log_files, log_labels, scene_for_log
from .scene import Scene


#: lsmr's tolerances for the trust-region step (its defaults, 1e-6, left the rig's joint fit
#: at 200 evaluations far from the minimum; 1e-12 reaches it in as many as the exact step)
LSMR_TOL = 1e-12


@dataclass
class JointFit:
    """Every figure of a joint fit: ``shared`` and ``per_log`` parameters (fit.Parameter),
    ``fitted``/``standard_error`` (s,) the shared values, ``fitted_per_log`` /
    ``standard_error_per_log`` (L, q), ``correlation`` (s + L q, s + L q) over ``names`` (the
    shared addresses, then ``<address>[<log label>]``), ``rms_before`` / ``rms_after`` (L, M)
    each log's measurements' RMS residual (their units)."""

    scene: Scene
    paths: list[str]
    labels: list[str]
    shared: list
    per_log: list
    fitted: np.ndarray
    standard_error: np.ndarray
    fitted_per_log: np.ndarray
    standard_error_per_log: np.ndarray
    initial: np.ndarray
    correlation: np.ndarray
    names: list[str]
    cost: list[float]
    rms_before: np.ndarray
    rms_after: np.ndarray
    options: FitOptions
    message: str = ""
    n_evaluations: int = 0
    solves: int = 0
    reduced_chi_square: float = math.nan
    warnings: tuple = ()
    seconds: float = 0.0
    #: the Jacobians computed, and the seconds spent reading every log's scene and solving it
    #: at the start values (before the least squares)
    n_jacobians: int = 0
    setup_seconds: float = 0.0
    extra: dict = field(default_factory=dict)


def layout(n_shared: int, n_per_log: int, n_logs: int) -> np.ndarray:
    """(L, s + q) int: each log's parameters' positions in the joint vector (shared first)."""
    shared = np.broadcast_to(np.arange(n_shared), (n_logs, n_shared))
    own = n_shared + np.arange(n_logs * n_per_log).reshape(n_logs, n_per_log)
    return np.concatenate([shared, own], axis=1)


def groups_of(index: np.ndarray, n_shared: int) -> list[np.ndarray]:
    """The Jacobian's columns differenced together: each shared column alone (every log's
    residuals depend on it), and the j-th per-log column of every log at once (each touches
    its own log's rows only): s + q groups for s + L q columns."""
    return ([np.array([k]) for k in range(n_shared)]
            + [index[:, j] for j in range(n_shared, index.shape[1])])


def grouped_jacobian(problems, index: np.ndarray, n_shared: int, sizes: list[int],
                     x: np.ndarray, f0: np.ndarray, lower, upper, diff_step: float) -> np.ndarray:
    """The joint Jacobian (N, s + L q) by forward differences over the groups of
    :func:`groups_of`: s + q evaluations of every log, each column's step ``diff_step x
    max(1, |x|)`` (backwards where a bound is near), as scipy's "2-point" takes it; the
    entries outside each log's block stay 0."""
    h = diff_step * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
    h = np.where((x + h > upper) | (x + h < lower), -h, h)
    h = (x + h) - x  # the step as represented
    starts = np.concatenate([[0], np.cumsum(sizes)])
    J = np.zeros((len(f0), len(x)))
    for group in groups_of(index, n_shared):
        xp = x.copy()
        xp[group] += h[group]
        for i, (pr, cols) in enumerate(zip(problems, index)):
            moved = np.intersect1d(cols, group)
            if not len(moved):
                continue
            rows = slice(starts[i], starts[i + 1])
            J[rows, moved[0]] = (pr.residuals(xp[cols]) - f0[rows]) / h[moved[0]]
    return J


def joint_fit(scene: Scene, pattern: str, log_name: str | None = None, progress=None,
              max_evaluations: int = 200, sparse: bool = True) -> JointFit:
    """Fit the scene to every log ``pattern`` matches as one problem (see the module doc).
    ``sparse`` False differences the Jacobian densely, every log solved at every evaluation
    (the benchmark's reference: a joint least squares that knows nothing of its structure)."""
    import time

    with blas_pool():
        return _joint_fit(scene, pattern, log_name, progress, max_evaluations, sparse,
                          time.perf_counter())


def _joint_fit(scene, pattern, log_name, progress, max_evaluations, sparse, t0) -> JointFit:
    import time

    data = tomllib.loads(scene.text)
    params = fit_parameters(scene, data)
    options = fit_options(scene, data)
    paths = log_files(pattern)
    entry = log_entry(scene.path, data, log_name)
    shared = [p for p in params if p.address not in options.per_log]
    per_log = [p for p in params if p.address in options.per_log]
    ordered = shared + per_log  # each log's Problem takes its parameters in this order
    labels = log_labels(paths)
    problems = []
    for path, label in zip(paths, labels):
        one, one_data = scene_for_log(scene, data, entry, path)
        try:
            problems.append(Problem(one, one_data, ordered, remember=sparse))
        except SceneError as exc:  # a joint fit needs every log: say which one failed
            raise SceneError(exc.file, exc.table, exc.key, f"log {label}: {exc.message}",
                             exc.hint) from None
    setup = time.perf_counter() - t0
    L, s, q = len(paths), len(shared), len(per_log)
    index = layout(s, q, L)
    x0 = np.concatenate([[p.initial for p in shared], np.tile([p.initial for p in per_log], L)])
    lower = np.concatenate([[p.bounds[0] for p in shared], np.tile([p.bounds[0] for p in per_log], L)])
    upper = np.concatenate([[p.bounds[1] for p in shared], np.tile([p.bounds[1] for p in per_log], L)])
    sizes = [pr.size for pr in problems]
    cost: list[float] = []
    evaluations = 0

    def residuals(x):
        nonlocal evaluations
        evaluations += 1
        out = np.concatenate([pr.residuals(x[cols]) for pr, cols in zip(problems, index)])
        if not cost:
            cost.append(float(out @ out))
        if progress is not None:
            progress(evaluations, float(out @ out))
        return out

    def per_iteration(intermediate_result):
        f = intermediate_result.fun
        cost.append(float(f @ f))

    settings = least_squares_options(options)
    if sparse:
        last = {}  # the point scipy asks the Jacobian at is the one it just evaluated

        def remember(x):
            last["x"], last["f"] = x.copy(), residuals(x)
            return last["f"]

        def jacobian(x):
            f0 = last["f"] if "x" in last and np.array_equal(last["x"], x) else residuals(x)
            return csr_matrix(grouped_jacobian(problems, index, s, sizes, x, f0, lower, upper,
                                               settings["diff_step"]))

        # a sparse Jacobian: the trust-region steps by lsmr (an SVD of the dense (N, s + L q)
        # matrix at every iteration cost 3 s at 50 logs x 2,000 rows), to tight tolerances
        fun, settings = remember, {**settings, "jac": jacobian, "tr_solver": "lsmr",
                                   "tr_options": {"atol": LSMR_TOL, "btol": LSMR_TOL}}
    else:
        fun = residuals
    sol = least_squares(fun, x0, bounds=(lower, upper), max_nfev=max_evaluations,
                        callback=per_iteration, **settings)
    sigma_given = all(pr.sigma_given for pr in problems)
    cov, identifiable = covariance(sol.jac, sol.fun, sigma_given)
    se = np.where(identifiable, np.sqrt(np.maximum(np.diag(cov), 0.0)), np.nan)
    penalties = np.concatenate([np.full(pr.size, pr.penalty) for pr in problems])
    chi2, warnings = _fit_warnings(sol.fun, penalties, len(x0), se, sigma_given, options)
    rms_after = np.stack([pr.after(sol.x[cols]).measurements["rms"]
                          for pr, cols in zip(problems, index)])
    rms_before = np.stack([pr.before.measurements["rms"] for pr in problems])
    names = [p.address for p in shared] + [f"{p.address}[{label}]" for label in labels
                                           for p in per_log]
    outliers = (int((np.abs(sol.fun) > 3.0 * options.f_scale).sum())
                if options.loss != "linear" else 0)
    return JointFit(scene, paths, labels, shared, per_log, sol.x[:s], se[:s],
                    sol.x[s:].reshape(L, q), se[s:].reshape(L, q), x0,
                    correlation(cov, identifiable), names, cost, rms_before, rms_after, options,
                    str(sol.message), int(sol.nfev), sum(pr.solves for pr in problems), chi2,
                    warnings, time.perf_counter() - t0, int(sol.njev or 0), setup,
                    {"outliers": outliers})


def joint_table(fit: JointFit, units: dict) -> str:
    """What ``fit --logs`` with ``per_log`` prints: the shared values, each log's own, the
    strongest correlations and each log's RMS residuals (``units``: {"parameter": [unit per
    parameter in [fit] order], "measurement": [...]})."""
    scene = fit.scene
    unit = dict(zip([p.address for p in fit.shared + fit.per_log], units["parameter"]))
    n = len(fit.labels)
    lines = [f"{scene.name}: joint fit of {len(fit.shared)} shared + {len(fit.per_log)} per-log "
             f"parameter(s) over {n} log(s) ({len(fit.shared) + n * len(fit.per_log)} unknowns, "
             f"loss {fit.options.loss}"
             + (f", f_scale {fit.options.f_scale:g}" if fit.options.loss != "linear" else "")
             + f"): {fit.message}",
             f"  {fit.n_evaluations} evaluations of every log ({fit.solves} solves), "
             f"{fit.seconds:.3g} s; reduced chi-square {fit.reduced_chi_square:.4g}"
             + (f" ({fit.extra['outliers']} residuals beyond 3 f_scale: outliers the "
                f"{fit.options.loss} loss weighs down)" if fit.extra.get("outliers") else "")]
    for p, v, e, v0 in zip(fit.shared, fit.fitted, fit.standard_error, fit.initial):
        lines.append(f"  {p.address}  {v0:.6g} -> {v:.6g} ± {e:.4g} {unit[p.address]}".rstrip())
    width = max(len(label) for label in fit.labels)
    for i, label in enumerate(fit.labels):
        cells = [f"{p.address} {fit.fitted_per_log[i, j]:.6g} ± "
                 f"{fit.standard_error_per_log[i, j]:.3g} {unit[p.address]}".rstrip()
                 for j, p in enumerate(fit.per_log)]
        cells += [f"rms {m.name} {fit.rms_after[i, k]:.4g} {u}".rstrip()
                  for k, (m, u) in enumerate(zip(scene.measurements, units["measurement"]))]
        lines.append(f"  {label:<{width}}  " + ", ".join(cells))
    corr = np.where(np.isfinite(fit.correlation), np.abs(fit.correlation), 0.0)
    np.fill_diagonal(corr, 0.0)
    if corr.size and corr.max() > 0:
        i, j = np.unravel_index(int(np.argmax(corr)), corr.shape)
        lines.append(f"  strongest correlation: {fit.names[i]} ~ {fit.names[j]} "
                     f"{fit.correlation[i, j]:+.3f}")
    lines += [f"  warning: {w}" for w in fit.warnings]
    return "\n".join(lines)


def write_joint(fit: JointFit, pattern: str, out) -> str:
    """Write ``<name>_fleet_fit.h5`` into the folder ``out``: ``fitted``, ``standard_error``
    (and ``initial``) on ``parameter`` (the shared values), ``fitted_per_log`` and
    ``standard_error_per_log`` on (log, per_log_parameter), ``correlation`` on
    (joint_parameter, joint_parameter_2), ``rms_before`` / ``rms_after`` on (log,
    measurement), ``cost`` on iteration; ``log`` names the files. Return its path."""
    from .output_units import common_unit, measured_units, parameter_units
    from .stores import fleet as fleet_store
    from .stores import output_folder

    scene = fit.scene
    shared_units = parameter_units(scene, fit.shared)
    own_units = parameter_units(scene, fit.per_log)
    m_units = measured_units(scene)
    labels = {"log": fit.labels, "parameter": [p.address for p in fit.shared],
              "per_log_parameter": [p.address for p in fit.per_log],
              "measurement": [m.name for m in scene.measurements],
              "joint_parameter": fit.names, "joint_parameter_2": fit.names,
              "iteration": list(map(str, range(len(fit.cost))))}
    columns = {
        "fitted": (("parameter",), np.asarray(fit.fitted, float)),
        "standard_error": (("parameter",), np.asarray(fit.standard_error, float)),
        "initial": (("parameter",), np.asarray(fit.initial[:len(fit.shared)], float)),
        "fitted_per_log": (("log", "per_log_parameter"), fit.fitted_per_log),
        "standard_error_per_log": (("log", "per_log_parameter"), fit.standard_error_per_log),
        "correlation": (("joint_parameter", "joint_parameter_2"), fit.correlation),
        "rms_before": (("log", "measurement"), fit.rms_before),
        "rms_after": (("log", "measurement"), fit.rms_after),
        "cost": (("iteration",), np.asarray(fit.cost, float)),
        "file": (("log",), np.array([str(p) for p in fit.paths], dtype=object)),
    }
    units = {"fitted": common_unit(shared_units) if shared_units else "",
             "standard_error": common_unit(shared_units) if shared_units else "",
             "initial": common_unit(shared_units) if shared_units else "",
             "fitted_per_log": common_unit(own_units) if own_units else "",
             "standard_error_per_log": common_unit(own_units) if own_units else "",
             "correlation": "1", "cost": "1",
             "rms_before": common_unit(m_units) if m_units else "",
             "rms_after": common_unit(m_units) if m_units else ""}
    attrs = {name: {"parameter_units": ",".join(shared_units)}
             for name in ("fitted", "standard_error", "initial")}
    attrs.update({name: {"per_log_parameter_units": ",".join(own_units)}
                  for name in ("fitted_per_log", "standard_error_per_log")})
    attrs.update({name: {"measurement_units": ",".join(m_units)}
                  for name in ("rms_before", "rms_after")})
    attrs["cost"] = {"long_name": "sum(((computed - measured) / sigma)^2) over every log: at the "
                     "start values (iteration 0), then at each iteration's point"}
    attrs["standard_error"]["long_name"] = (
        f"one standard error from the joint Jacobian (loss {fit.options.loss}); NaN where the "
        "data cannot identify it")
    out = output_folder(out)
    path = out / f"{scene.name}_fleet_fit.h5"
    fleet_store.write(path, {"scene_name": scene.name, "scene_toml": scene.text,
                             "logs_glob": pattern, "command": "fit", "joint": 1,
                             "loss": fit.options.loss, "f_scale": fit.options.f_scale,
                             "optimizer_message": fit.message,
                             "evaluations": fit.n_evaluations, "solves": fit.solves,
                             "reduced_chi_square": float(fit.reduced_chi_square),
                             "outliers": int(fit.extra.get("outliers", 0)),
                             "warnings": "\n".join(fit.warnings)},
                      labels, columns, units, attrs)
    return str(path)
