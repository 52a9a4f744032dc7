"""A self-contained HTML page of a run's or a study's ``.h5``: what a design review reads.

``python -m linkpipe report NAME.h5`` (or ``run --report``) writes ``NAME.html`` beside it:
one file, no script, no link to anything outside it (the plots are inline SVG drawn by
matplotlib), that opens in any browser and can be mailed on. A run's page holds its status
summary and key numbers, the mechanism at a few poses, the input force against the driver
(against time for a timed or logged scene), the springs' forces, and each measurement beside
its computed value; a study's page its variants' peak input force against each parameter and
its best variants. The numbers are read back from the ``.h5`` (``stores.hdf5.read_plain``),
so a page says what the file holds.
"""
from __future__ import annotations

import html
import io
import os
import pathlib
import tomllib

import numpy as np

from .errors import LinkpipeError

#: poses of the mechanism drawn (evenly spread over the steps that assembled)
POSES = 4
#: the page's figures, inches at 100 dpi (SVG scales with the page)
WIDE, TALL = (9.0, 3.6), (9.0, 5.0)
#: each pose's colour, early to late (viridis, a reading order)
POSE_CMAP = "viridis"


def write_report(h5_path, out_path=None) -> pathlib.Path:
    """Write the page of the ``.h5`` at ``h5_path`` to ``out_path`` (default: beside it, with
    ``.html``); return its path. The file is written whole, then renamed into place."""
    from .stores.hdf5 import read_plain

    h5_path = pathlib.Path(h5_path)
    out = pathlib.Path(out_path) if out_path else h5_path.with_suffix(".html")
    root, variables = read_plain(h5_path)
    draw = next((draw for marker, draw in (("evaluation", _optimize_page),
                                           ("variant", _study_page), ("status", _run_page))
                 if marker in variables), None)  # the file's kind: the variable only it has
    if draw is None:
        what = ("a fit's file (its figures are the table `fit` printed and the fitted scene "
                "beside it)" if "fitted" in variables else
                "an accuracy ladder's file (its recording shows the trade)" if "knob" in variables
                else "not a file that run, study or optimize wrote")
        raise LinkpipeError(f"{h5_path}: {what}; report takes a .h5 that run, study or "
                            "optimize wrote")
    page = draw(h5_path, root, variables)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, out)
    return out


# -- the page ------------------------------------------------------------------------------

STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 960px; color: #1d232a; line-height: 1.4; }
h1 { font-size: 1.6em; margin-bottom: 0.1em; } h2 { font-size: 1.2em; margin-top: 1.6em;
     border-bottom: 1px solid #d6dbe0; padding-bottom: 0.2em; }
.headline { font-size: 1.15em; padding: 0.5em 0.8em; border-radius: 6px; margin: 0.8em 0; }
.ok { background: #e3f4e6; } .failed { background: #fdecea; } .slip { background: #fff4d6; }
table { border-collapse: collapse; margin: 0.5em 0; } td, th { padding: 0.2em 0.9em 0.2em 0;
     text-align: left; vertical-align: top; } th { color: #56606b; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.small { color: #56606b; font-size: 0.9em; } figure { margin: 0.6em 0; } svg { max-width: 100%;
     height: auto; }
"""


def _html(title: str, body: list[str]) -> str:
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def _table(rows, header=None) -> str:
    """A table; numbers right-aligned in a table with a header (columns of numbers), else
    written beside their names."""
    out = ["<table>"]
    if header:
        out.append("<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in header) + "</tr>")
    for row in rows:
        cells = []
        for c in row:
            num = isinstance(c, (int, float, np.integer, np.floating)) and header is not None
            text = _num(c) if isinstance(c, (int, float, np.integer, np.floating)) else str(c)
            cells.append(f"<td class=\"num\">{html.escape(text)}</td>" if num else
                         f"<td>{html.escape(text)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "\n".join(out + ["</table>"])


def _num(x) -> str:
    x = float(x)
    if not np.isfinite(x):
        return "—"
    return f"{x:,.0f}" if x == round(x) and abs(x) < 1e12 else f"{x:,.6g}"


def _svg(fig) -> str:
    """The figure as inline SVG (no external reference), and the figure closed."""
    import matplotlib.pyplot as plt

    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight")
    plt.close(fig)
    text = buf.getvalue()
    return "<figure>" + text[text.index("<svg"):] + "</figure>"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.fonttype": "none", "font.size": 9, "axes.grid": True,
                         "grid.alpha": 0.3, "axes.spines.top": False, "axes.spines.right": False})
    return plt


def _labels(variables, dim: str) -> list[str]:
    return [str(x) for x in variables[dim]["data"]] if dim in variables else []


def _unit(variables, name: str) -> str:
    return str(variables[name]["attrs"].get("units", "")) if name in variables else ""


def _status_counts(variables) -> tuple[list[tuple[str, int]], int, int]:
    status = np.asarray(variables["status"]["data"])
    attrs = variables["status"]["attrs"]
    meanings = str(attrs.get("flag_meanings", "")).split()
    values = list(np.asarray(attrs.get("flag_values", range(len(meanings)))).tolist())
    counts = [(meanings[values.index(v)] if v in values else str(v), int((status == v).sum()))
              for v in np.unique(status)]
    return counts, int((status == 0).sum()), len(status)


def _headline(counts, n_ok: int, n: int) -> str:
    if n_ok == n:
        return f"all {n:,} steps ok"
    failed = "; ".join(f"{c:,} {name}" for name, c in counts if name != "ok")
    return f"{n_ok:,}/{n:,} steps ok; {failed}"


def _axis(variables, scene: dict, root: dict):
    """(x (S,), its label): time for a timed or forward-dynamics scene (``[time]``,
    ``[dynamics]``), else the first driver's value, else step."""
    if ("time" in scene or "dynamics" in scene) and "time" in variables:
        return np.asarray(variables["time"]["data"], float), f"time [{_unit(variables, 'time')}]"
    if "driver_value" in variables:
        names = _labels(variables, "driver")
        return (np.asarray(variables["driver_value"]["data"], float)[:, 0],
                f"{names[0]} [{_unit(variables, 'driver_value').split(',')[0]}]")
    return np.arange(len(variables["status"]["data"]), dtype=float), "step"


def _run_page(h5_path, root, variables) -> str:
    plt = _pyplot()
    scene = tomllib.loads(str(root.get("scene_toml", "")))
    info = scene.get("scene", {})
    name = str(root.get("scene_name") or info.get("name") or h5_path.stem)
    counts, n_ok, n = _status_counts(variables)
    head = _headline(counts, n_ok, n)
    warnings = [str(w) for w in np.atleast_1d(root.get("warnings", [])) if str(w)]
    slip = [w for w in warnings if "the drawing is not an assembled pose" in w]
    body = [f"<h1>{html.escape(name)}</h1>"]
    if info.get("description"):
        body.append(f"<p>{html.escape(str(info['description']))}</p>")
    kind = "ok" if n_ok == n and not slip else ("slip" if n_ok == n else "failed")
    body.append(f"<div class=\"headline {kind}\">{html.escape(head)}"
                + (" — but the drawing is far from its assembly (below)" if slip else "")
                + "</div>")
    body.append(f"<p class=\"small\">{html.escape(str(h5_path.name))}, written "
                f"{html.escape(str(root.get('created', '')))} by linkpipe "
                f"{html.escape(str(root.get('linkpipe_version', '')))}</p>")
    body.append("<h2>Status and key numbers</h2>")
    body.append(_table(_key_numbers(root, variables, scene, counts, n)))
    if warnings:
        body.append("<p><b>Warnings</b></p><ul>" + "".join(
            f"<li>{html.escape(w)}</li>" for w in warnings) + "</ul>")
    x, xlabel = _axis(variables, scene, root)
    if "position" in variables:
        body.append("<h2>The mechanism</h2>")
        body.append(_svg(_poses(plt, variables, scene, root)))
    free = ("input_force" in variables
            and not np.nanmax(np.abs(variables["input_force"]["data"]), initial=0.0))
    if free:   # a [dynamics] driver with no force: a plot of the Lagrange check's rounding
        body.append("<h2>Input force</h2><p>None: every driver moves freely (an input force "
                    "of 0 at every step).</p>")
    elif "input_force" in variables:
        body.append("<h2>Input force</h2>")
        body.append(_svg(_lines(plt, x, xlabel, variables, "input_force", "driver",
                                "input force", lagrange=True, names=_input_names(scene))))
    if "spring_force" in variables:
        body.append("<h2>Springs</h2>")
        body.append(_svg(_lines(plt, x, xlabel, variables, "spring_force", "spring",
                                "spring force (tension > 0)")))
    if "dynamics" in scene and "driver_value" in variables:
        body.append("<h2>Motion</h2>")
        body.append(_svg(_lines(plt, x, xlabel, variables, "driver_value", "driver",
                                "driver's value")))
        if "energy_error" in variables:
            body.append(_svg(_single(plt, x, xlabel, variables, "energy_error",
                                     "energy error (energy − initial − work)")))
    if "friction_force" in variables:
        body.append("<h2>Friction</h2>")
        body.append(_svg(_lines(plt, x, xlabel, variables, "friction_force", "friction",
                                "friction force")))
    if "stroke_margin" in variables:
        body.append("<h2>Stroke margin</h2>")
        body.append(_svg(_lines(plt, x, xlabel, variables, "stroke_margin", "stroke",
                                "stroke margin (< 0: out of stroke)")))
    if "measured" in variables:
        body.append("<h2>Measured against computed</h2>")
        body.append(_svg(_measured(plt, x, xlabel, variables)))
    return _html(f"{name}: linkpipe report", body)


def _key_numbers(root, variables, scene, counts, n) -> list:
    units = {k[6:]: str(v) for k, v in root.items() if k.startswith("units_")}
    rows = [("steps", n)]
    rows += [(f"  {name}", c) for name, c in counts]
    status = np.asarray(variables["status"]["data"])
    if (status != 0).any():
        rows.append(("first failed step", int(np.argmax(status != 0))))
    rows.append(("max residual (solved steps)",
                 f"{float(root.get('max_residual', np.nan)):.3g} {units.get('length', '')}"))
    rows.append(("degrees of freedom", int(root.get("degrees_of_freedom", 0))))
    rows.append(("points, links", f"{len(_labels(variables, 'point'))}, "
                                  f"{len(_labels(variables, 'link'))}"))
    effects = [str(e) for e in np.atleast_1d(root.get("effects", [])) if str(e)]
    rows.append(("effects", ", ".join(effects) or "none (kinematics only)"))
    rows.append(("units", ", ".join(f"{k} {v}" for k, v in units.items())))
    if "driver_value" in variables:
        dv = np.asarray(variables["driver_value"]["data"], float)
        dunits = _unit(variables, "driver_value").split(",")
        for j, d in enumerate(_labels(variables, "driver")):
            u = dunits[j] if j < len(dunits) else dunits[0]
            rows.append((f"driver {d}", f"{_num(np.nanmin(dv[:, j]))} .. "
                                        f"{_num(np.nanmax(dv[:, j]))} {u}"))
    if "input_force" in variables:
        F = np.asarray(variables["input_force"]["data"], float)
        funits = (variables["input_force"]["attrs"].get("driver_units") or
                  _unit(variables, "input_force"))
        funits = str(funits).split(",")
        dv = (np.asarray(variables["driver_value"]["data"], float)
              if "driver_value" in variables else None)
        for j, d in enumerate(_labels(variables, "driver")):
            col = F[:, j]
            if not np.isfinite(col).any():
                continue
            k = int(np.nanargmax(np.abs(col)))
            u = funits[j] if j < len(funits) else funits[0]
            at = (f" at {d} = {_num(dv[k, j])}" if dv is not None else f" at step {k}")
            rows.append((f"input force {d}", f"{_num(np.nanmin(col))} .. {_num(np.nanmax(col))} "
                                             f"{u}; peak |F| {_num(abs(col[k]))}{at}"))
    if "spring_force" in variables:
        T = np.asarray(variables["spring_force"]["data"], float)
        for j, s in enumerate(_labels(variables, "spring")):
            if np.isfinite(T[:, j]).any():
                rows.append((f"spring {s}", f"{_num(np.nanmin(T[:, j]))} .. "
                                            f"{_num(np.nanmax(T[:, j]))} "
                                            f"{_unit(variables, 'spring_force')}"))
    if "measured_residual" in variables:
        attrs = variables["measured_residual"]["attrs"]
        rms = np.atleast_1d(attrs.get("rms", []))
        for j, m in enumerate(_labels(variables, "measurement")):
            if j < len(rms):
                rows.append((f"measurement {m}", f"computed − measured rms {_num(rms[j])}"))
    return rows


def _poses(plt, variables, scene, root):
    X = np.asarray(variables["position"]["data"], float)       # (S, P, 2)
    names = _labels(variables, "point")
    idx = {p: i for i, p in enumerate(names)}
    ok = np.isfinite(X).all(axis=(1, 2))
    steps = np.flatnonzero(ok)
    picks = (np.unique(steps[np.linspace(0, len(steps) - 1, min(POSES, len(steps))).round()
                             .astype(int)]) if len(steps) else [])
    fig, ax = plt.subplots(figsize=TALL)
    cmap = plt.get_cmap(POSE_CMAP)
    fixed = [p for p, v in scene.get("points", {}).items() if isinstance(v, dict) and v.get("fixed")]
    links = [(ln.get("name", ""), [p for p in ln.get("points", []) if p in idx])
             for ln in scene.get("links", [])]
    for p in scene.get("outputs", {}).get("trace", []):
        if p in idx:
            ax.plot(X[:, idx[p], 0], X[:, idx[p], 1], color="0.6", lw=0.8, ls="--", zorder=1)
    cylinders = [[idx[p] for p in d["distance"] if p in idx] for d in scene.get("drivers", [])
                 if isinstance(d.get("distance"), list)]
    for n_pose, k in enumerate(picks):
        colour = cmap(0.85 * n_pose / max(len(picks) - 1, 1))
        for _, pts in links:
            if len(pts) < 2:
                continue
            xy = _outline(X[k, [idx[p] for p in pts]])
            ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=2.0, alpha=0.9, zorder=2,
                    solid_capstyle="round")
        for ends in cylinders:   # a linear actuator: a wide grey bar between its pins
            if len(ends) == 2:
                ax.plot(X[k, ends, 0], X[k, ends, 1], color="0.55", lw=4.5, alpha=0.6, zorder=1,
                        solid_capstyle="butt")
        ax.plot([], [], color=colour, lw=2, label=f"step {int(k)}")
    if len(picks):
        k = picks[0]
        for p, i in idx.items():
            ax.annotate(p, X[k, i], textcoords="offset points", xytext=(4, 4), fontsize=8,
                        color="0.25")
    for p in fixed:
        if p in idx:
            xy = X[picks[0] if len(picks) else 0, idx[p]]
            ax.plot(*xy, marker="^", color="0.3", ms=9, zorder=3)
    ax.set_aspect("equal", adjustable="datalim")
    length = str(root.get("units_length", ""))
    ax.set_xlabel(f"x [{length}]")
    ax.set_ylabel(f"y [{length}]")
    ax.set_title(f"{len(picks)} poses (points labelled at the first; ▲ fixed)")
    if len(picks):
        ax.legend(loc="best", fontsize=8)
    return fig


def _input_names(scene: dict) -> dict[str, str]:
    """What each driver's input force is (as the recording names it): a force at the input's
    point, a torque of an angle driver, a cylinder's axial force."""
    out = {}
    for d in scene.get("drivers", []):
        name = str(d.get("name", ""))
        if isinstance(d.get("input"), dict) and d["input"].get("point"):
            out[name] = f"force at {d['input']['point']} ({name})"
        elif "angle" in d:
            out[name] = f"torque of {name}"
        elif "distance" in d:
            out[name] = f"{name} axial force"
        else:
            out[name] = f"force of {name}"
    return out


def _outline(xy: np.ndarray) -> np.ndarray:
    """A bar's two points, or a plate's points in turn about their centre, closed (a plate
    drawn in the scene's listing order may cross itself)."""
    if len(xy) <= 2:
        return xy
    c = xy.mean(axis=0)
    order = np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]), kind="stable")
    return xy[np.r_[order, order[0]]]


def _lines(plt, x, xlabel, variables, name, dim, title, lagrange=False, names=None):
    """One curve per column of ``name`` against ``x``; columns in different units (a slider's
    friction force in N beside a hinge's torque in N*m) each on an axis of their own, one above
    the other; coinciding columns one curve, said so in its legend entry."""
    Y = np.asarray(variables[name]["data"], float)
    labels = [(names or {}).get(label, label) for label in _labels(variables, dim)]
    units = str(variables[name]["attrs"].get(f"{dim}_units") or _unit(variables, name)).split(",")
    units = [units[j] if j < len(units) else units[0] for j in range(len(labels))]
    groups = list(dict.fromkeys(units))
    fig, axes = plt.subplots(len(groups), 1, figsize=(WIDE[0], WIDE[1] * len(groups)),
                             squeeze=False)
    for ax, unit in zip(axes[:, 0], groups):
        drawn, lines = [], []
        for j, label in enumerate(labels):
            if units[j] != unit:
                continue
            same = [k for k in drawn if np.allclose(Y[:, k], Y[:, j], equal_nan=True,
                                                      rtol=1e-6, atol=1e-12)]
            if same:  # one curve, said once
                line = lines[drawn.index(same[0])]
                line.set_label(f"{line.get_label()} = {label} (coincide)")
                continue
            (line,) = ax.plot(x, Y[:, j], lw=1.6, label=label)
            drawn.append(j)
            lines.append(line)
        if lagrange and f"{name}_lagrange" in variables:
            L = np.asarray(variables[f"{name}_lagrange"]["data"], float)
            for j in drawn:
                ax.plot(x, L[:, j], ls=":", color="k", lw=1.0,
                        label="Lagrange multipliers (check)" if j == drawn[0] else None)
        ax.set_ylabel(f"{title} [{unit}]")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(xlabel)
    return fig


def _single(plt, x, xlabel, variables, name, title):
    fig, ax = plt.subplots(figsize=WIDE)
    ax.plot(x, np.asarray(variables[name]["data"], float), lw=1.4)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{title} [{_unit(variables, name)}]")
    ax.axhline(0.0, color="0.5", lw=0.6)
    return fig


def _measured(plt, x, xlabel, variables):
    M = np.asarray(variables["measured"]["data"], float)
    R = np.asarray(variables["measured_residual"]["data"], float)
    names = _labels(variables, "measurement")
    units = str(variables["measured"]["attrs"].get("measurement_units")
                or _unit(variables, "measured")).split(",")
    fig, axes = plt.subplots(len(names), 1, figsize=(WIDE[0], WIDE[1] * len(names)), squeeze=False)
    for j, (ax, name) in enumerate(zip(axes[:, 0], names)):
        ax.plot(x, M[:, j], ".", ms=2.5, color="tab:orange", label="measured")
        ax.plot(x, M[:, j] + R[:, j], lw=1.6, color="tab:blue", label="computed")
        ax.set_ylabel(f"{name} [{units[j] if j < len(units) else units[0]}]")
        ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel(xlabel)
    return fig


def _study_page(h5_path, root, variables) -> str:
    plt = _pyplot()
    name = str(root.get("study_name") or root.get("scene_name") or h5_path.stem)
    params = _labels(variables, "parameter")
    P = np.asarray(variables["parameter_value"]["data"], float)          # (V, n_par)
    peak = np.asarray(variables["peak_input_force"]["data"], float)      # (V, n_drv)
    drivers = _labels(variables, "driver")
    worst = np.asarray(variables["worst_status"]["data"]) if "worst_status" in variables else None
    V = P.shape[0]
    n_ok = int((worst == 0).sum()) if worst is not None else V
    body = [f"<h1>{html.escape(name)}: design study</h1>",
            f"<div class=\"headline {'ok' if n_ok == V else 'failed'}\">{V:,} variants, "
            f"{n_ok:,} all ok, {V - n_ok:,} with failed steps</div>",
            f"<p class=\"small\">{html.escape(h5_path.name)}"
            + (f", written {html.escape(str(root['created']))}" if root.get("created") else "")
            + "</p>"]
    funit = _unit(variables, "peak_input_force")
    rows = [("variants", V), ("parameters", ", ".join(params))]
    for j, p in enumerate(params):
        rows.append((f"  {p}", f"{_num(np.nanmin(P[:, j]))} .. {_num(np.nanmax(P[:, j]))}"))
    for j, d in enumerate(drivers):
        col = peak[:, j]
        if np.isfinite(col).any():
            rows.append((f"peak input force {d}", f"{_num(np.nanmin(col))} .. "
                                                  f"{_num(np.nanmax(col))} {funit}"))
    body += ["<h2>Status and key numbers</h2>", _table(rows)]
    score = np.where(np.isfinite(peak[:, 0]), peak[:, 0], np.inf) if peak.size else np.zeros(V)
    best = np.argsort(score, kind="stable")[:5]
    body.append(f"<h2>Best variants (lowest peak input force {html.escape(drivers[0] if drivers else '')})</h2>")
    body.append(_table([(int(v), *[float(P[v, j]) for j in range(len(params))], float(score[v]))
                        for v in best], header=["variant", *params, f"peak [{funit}]"]))
    body.append("<h2>Peak input force against each parameter</h2>")
    fig, axes = plt.subplots(1, len(params), figsize=(WIDE[0], WIDE[1]), squeeze=False)
    for j, (ax, p) in enumerate(zip(axes[0], params)):
        ok = worst == 0 if worst is not None else np.ones(V, bool)
        ax.scatter(P[ok, j], score[ok], s=4, alpha=0.5, color="tab:blue", label="all ok")
        if (~ok).any():
            ax.scatter(P[~ok, j], np.where(np.isfinite(score[~ok]), score[~ok], np.nan), s=6,
                       color="tab:red", label="failed steps")
        ax.scatter(P[best[:1], j], score[best[:1]], s=60, marker="*", color="tab:orange",
                   label="best", zorder=3)
        ax.set_xlabel(p)
        ax.set_ylabel(f"peak input force [{funit}]")
        ax.legend(loc="best", fontsize=8)
    body.append(_svg(fig))
    return _html(f"{name}: linkpipe study report", body)


def _optimize_page(h5_path, root, variables) -> str:
    """An optimisation's ``<name>_optimize.h5``: the best design (each parameter with its
    bounds, where it started and whether it ended on a bound), its metrics, the search's
    progress per generation and the objective of every evaluated variant against each
    parameter (feasible ones coloured, the best starred)."""
    plt = _pyplot()
    name = str(root.get("scene_name") or h5_path.stem)
    params = _labels(variables, "parameter")
    metrics = _labels(variables, "metric")
    punits = str(variables["best"]["attrs"].get("parameter_units", "")).split(",")
    munits = str(variables["best_metric"]["attrs"].get("metric_units", "")).split(",")
    objective_name = str(np.atleast_1d(root.get("objective_name", [""]))[0])
    ounit = _unit(variables, "objective")
    P = np.asarray(variables["parameter_value"]["data"], float)        # (E, n_par)
    obj = np.asarray(variables["objective"]["data"], float)            # (E,)
    feasible = np.asarray(variables["feasible"]["data"]).astype(bool)  # (E,)
    best = int(root.get("best_evaluation", int(np.nanargmin(np.where(feasible, obj, np.inf)))))
    E = len(obj)
    gens = len(variables["population_best"]["data"])
    on_bound = dict(zip([str(p) for p in np.atleast_1d(root.get("on_bound", []))],
                        [str(p) for p in np.atleast_1d(root.get("on_bound_side", []))]))
    body = [f"<h1>{html.escape(name)}: optimisation</h1>",
            f"<div class=\"headline ok\">best {html.escape(objective_name)} "
            f"{_num(float(root.get('best_objective', obj[best])))} {html.escape(ounit)} "
            f"(evaluation {best:,} of {E:,}; {int(feasible.sum()):,} feasible, "
            f"{gens:,} generations)</div>",
            f"<p class=\"small\">{html.escape(h5_path.name)}, written by linkpipe "
            f"{html.escape(str(root.get('linkpipe_version', '')))}"
            + (f"; {html.escape(str(root['solved']))}" if root.get("solved") else "") + "</p>"]
    kinds = np.atleast_1d(variables["parameter"]["attrs"].get("kind", [""] * len(params)))
    tied = np.atleast_1d(variables["parameter"]["attrs"].get("tied_to", [""] * len(params)))
    rows = []
    for j, p in enumerate(params):
        u = punits[j] if j < len(punits) else ""
        lo, hi = (float(variables[k]["data"][j]) for k in ("lower", "upper"))
        where = (f"tied to {tied[j]}" if j < len(kinds) and str(kinds[j]) == "tie" else
                 f"{_num(lo)} .. {_num(hi)}" + (f" (on its {on_bound[p]} bound)"
                                                if p in on_bound else ""))
        rows.append((p, f"{_num(float(variables['best']['data'][j]))} {u}", where,
                     _num(float(variables["initial"]["data"][j]))))
    body += ["<h2>The best design</h2>",
             _table(rows, header=["parameter", "best", "range", "started at"])]
    mrows = [(m + ("  (objective)" if m == objective_name else ""),
              f"{_num(float(variables['best_metric']['data'][k]))} "
              f"{munits[k] if k < len(munits) else ''}") for k, m in enumerate(metrics)]
    for c in np.atleast_1d(root.get("constraints", [])):
        if str(c):
            mrows.append(("constraint", str(c)))
    body += ["<h2>Its metrics</h2>", _table(mrows)]
    body.append("<h2>The search</h2>")
    fig, ax = plt.subplots(figsize=WIDE)
    ax.plot(np.arange(gens), np.asarray(variables["population_best"]["data"], float), lw=1.6)
    ax.set_xlabel("generation")
    ax.set_ylabel(f"best feasible {objective_name} [{ounit}]")
    ax.set_yscale("log" if np.nanmin(variables["population_best"]["data"]) > 0 else "linear")
    body.append(_svg(fig))
    body.append(f"<h2>{html.escape(objective_name)} against each parameter</h2>")
    free = [j for j in range(len(params)) if not (j < len(kinds) and str(kinds[j]) == "tie")]
    cols = min(2, len(free)) or 1
    rows_n = int(np.ceil(len(free) / cols)) or 1
    fig, axes = plt.subplots(rows_n, cols, figsize=(WIDE[0], WIDE[1] * rows_n), squeeze=False)
    for ax in axes.flat[len(free):]:
        ax.set_visible(False)
    for ax, j in zip(axes.flat, free):
        ax.scatter(P[~feasible, j], obj[~feasible], s=3, color="0.75", label="infeasible")
        ax.scatter(P[feasible, j], obj[feasible], s=3, color="tab:blue", label="feasible")
        ax.scatter(P[best, j], obj[best], s=90, marker="*", color="tab:orange", zorder=3,
                   label="best")
        ax.set_xlabel(f"{params[j]} [{punits[j] if j < len(punits) else ''}]")
        ax.set_ylabel(f"{objective_name} [{ounit}]")
        if np.nanmin(obj) > 0:
            ax.set_yscale("log")
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    body.append(_svg(fig))
    return _html(f"{name}: linkpipe optimisation report", body)
