"""``[study]``: read and check a study, and lay out its variants (no solving beyond the base).

A study is a ``[study]`` table in a scene, or a study file whose ``[study] base`` names the
scene to vary (a path relative to the study file). Parameters are addressed as ``[fit]``
addresses them (:func:`linkpipe.fit.locate`); each is a grid ``{ from, to, steps }`` or a
distribution ``{ normal = [mean, sd] }`` / ``{ uniform = [low, high] }``. The grids form
their full product (the first parameter varies slowest); each grid point gets ``samples``
joint draws of the distributions (``numpy.random.default_rng(seed)``, one column per
distribution in the order written, drawn for all variants at once), or one variant when
there are none. Every mistake is a :class:`SceneError` naming the study file, the table
(``study``, ``study.parameters``, ``study.metrics``) and the key.
"""
from __future__ import annotations

import dataclasses
import hashlib
import os
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..fit import acts, locate
from ..scene import Scene, load_scene
from ..scene.keys import KEYS, _is_number, _suggest
from ..version import __version__
from . import paths, reductions

#: variants solved together (one task of an executor, one write to the HDF5), at most, and
#: the (variant, step) rows a batch holds at most when the study file gives no batch_size:
#: fewer, larger tasks halve the Dask client's own work (100,000 variants of 25 steps on a
#: 2-worker cluster: client CPU 0.79 s with batches of 1000 variants, 0.39 s with 4000),
#: which shares the cores with the workers; a batch's force arrays stay ~100 MB
DEFAULT_BATCH, BATCH_ROWS = 4000, 100_000
#: the default number of batches is a multiple of this (where there are that many variants):
#: 2 or 4 workers then get the same number of batches, none waits for the others' last one
#: (100,000 variants: 28 batches of 3,572, not 25 of 4,000, whose 25th ran alone on one of two
#: workers: 1/13 of the run)
BATCH_MULTIPLE = 4
#: the names every study file stores: a metric may not take one
RESERVED = ("variant", "parameter", "driver", "batch", "parameter_value", "peak_input_force",
            "rms_input_force", "input_force_range", "min_transmission_angle", "worst_status",
            "first_failed_step", "batch_done")
#: parameters that would change the number of steps (variants share one step axis)
_STEP_KEYS = ("steps", "step")


@dataclass(frozen=True)
class StudyParameter:
    """One varied value: its address, path into the scene's TOML data, its value in the base
    scene, and how it varies: ``kind`` "grid" (``spec`` = (from, to, steps)), "normal"
    (mean, sd) or "uniform" (low, high)."""

    address: str
    path: tuple
    initial: float
    kind: str
    spec: tuple


@dataclass(frozen=True)
class Metric:
    name: str
    text: str
    tree: tuple


@dataclass(frozen=True)
class Study:
    """A checked study. ``values`` (V, n_parameters): every variant's parameter values;
    ``scene``: the base scene; ``data``: its TOML data without ``[study]`` and ``[fit]``;
    ``catalog``: {variable: (dims, {dim: labels})} of what a variant stores (from the base
    scene solved once); ``fingerprint``: what a resumed run must match."""

    path: str
    name: str
    text: str
    scene: Scene
    data: dict
    parameters: tuple[StudyParameter, ...]
    values: np.ndarray
    metrics: tuple[Metric, ...]
    catalog: dict
    samples: int
    seed: int
    batch_size: int
    fingerprint: str
    slots: tuple | None = None  # the vectorised path's places of the parameters (None: not)
    path_note: str = ""  # which path solves the variants, and why

    @property
    def n_variants(self) -> int:
        return self.values.shape[0]

    @property
    def names(self) -> list[str]:
        return [p.address for p in self.parameters]

    @property
    def driver_names(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.scene.drivers)

    def metric_units(self) -> dict[str, str]:
        """{metric: the unit of its value} ("" where it cannot be told:
        :func:`.reductions.unit_of`)."""
        from ..output_units import entry_unit

        return {m.name: reductions.unit_of(m.tree, lambda v, label: entry_unit(self.scene, v, label))
                for m in self.metrics}

    def parameter_units(self) -> list[str]:
        """Each parameter's unit, in order ("" where its key has none)."""
        from ..output_units import parameter_units

        return parameter_units(self.scene, self.parameters)

    def batches(self) -> list[tuple[int, int, int]]:
        """``(batch, first variant, end)`` of every batch."""
        V, n = self.n_variants, self.batch_size
        return [(b, lo, min(V, lo + n)) for b, lo in enumerate(range(0, V, n))]


def study_kind(path) -> str | None:
    """``"study"`` if ``path`` is readable TOML with a ``[study]`` table and no ``[points]`` (a
    study file: its scene is the base it names), ``"scene"`` for a scene that holds a
    ``[study]`` of its own, else None (no study, or a file the scene reader will explain: a
    path that is no regular file is never opened here, a FIFO would block)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except (OSError, ValueError, RecursionError):  # nested too deeply: the scene reader says so
        return None
    if not isinstance(data.get("study"), dict):
        return None
    return "scene" if "points" in data else "study"


def _read(path: str) -> tuple[str, dict]:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(path, "", None, "no such study file",
                         "check the path (studies live in configs/studies/*.toml)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(path, "", None, f"cannot read the file ({exc})",
                         "give the path of a UTF-8 .toml file") from None
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(path, "", None, f"not valid TOML: {exc}", "fix the syntax there") from None
    except RecursionError:  # the TOML reader recurses
        raise SceneError(path, "", None, "arrays or inline tables nested more deeply than the "
                         "TOML reader can follow", "remove the extra brackets") from None


def load_study(path, catalog_of=None) -> Study:
    """Read and check the study at ``path`` (a study file or a scene with ``[study]``).

    ``catalog_of(scene)``: the stored variables of the base scene (default: solve it once)."""
    path = str(path)
    text, data = _read(path)
    raw = data.get("study")
    if not isinstance(raw, dict):
        scene = "points" in data or "links" in data  # a scene's own [study] takes no base
        raise SceneError(path, "study", None, "no [study] table" if raw is None else
                         "expected a table [study]",
                         "add [study.parameters] to this scene (its own [study] has no base), "
                         "or write a study file whose [study] base names it" if scene else
                         "add [study] with base and [study.parameters]")
    unknown = sorted(set(raw) - set(KEYS["study"]))
    if unknown:
        raise SceneError(path, "study", unknown[0], "unknown key", _suggest(unknown[0], KEYS["study"]))
    scene, name = _base_scene(path, data, raw)
    base = tomllib.loads(scene.text)
    for table in ("study", "fit", "optimize"):
        base.pop(table, None)
    samples, seed = (_whole(path, raw, key, default, low) for key, default, low in
                     (("samples", 1, 1), ("seed", 0, 0)))
    batch = _whole(path, raw, "batch_size", 1, 1) if "batch_size" in raw else None
    params = _parameters(path, raw, scene, base)
    catalog = (catalog_of or _catalog)(scene)
    metrics = _metrics(path, raw, catalog, scene.n_steps)
    _check_variant_count(path, params, samples)
    values = variant_values(params, samples, seed)
    if batch is None:
        batch = default_batch_size(values.shape[0], scene.n_steps)
    digest = hashlib.sha256("\0".join([__version__, text, scene.text, str(batch)]).encode())
    for log in scene.logs:  # the data a scene reads, not only its text: a changed log restarts
        digest.update(np.ascontiguousarray(log.t).tobytes())
        for column in sorted(log.columns):
            digest.update(column.encode() + np.ascontiguousarray(log.columns[column]).tobytes())
    study = Study(path, name, text, scene, base, params, values, metrics, catalog, samples, seed,
                  batch, digest.hexdigest())
    slots, why = paths.plan(study)
    kinds = {s[0] for s in slots or ()}
    rebuilt = [what for kind, what in (("length", "the link lengths"),
                                       ("side", "the plates' side lengths"),
                                       ("drawn", "the moving points' drawn coordinates"))
               if kind in kinds]
    note = (f"variant by variant: {why}" if slots is None else
            "vectorised: the pivots as per-row columns, stage 1 and the force stage on all "
            "variants of a batch at once (a variant on another path or branch: its own run)"
            if "pivot" in kinds and not rebuilt else
            "vectorised: " + " and ".join(rebuilt) + " as per-row constants"
            + (" and the pivots as per-row columns" if "pivot" in kinds else "")
            + ", stage 1 and the force stage on all variants of a batch at once (a variant on "
            "another path or branch, with other dyads or failing its scene's checks: its own "
            "run)"
            if rebuilt else
            "vectorised: stage 1 solved once, the force stage on all variants of a batch at once")
    return dataclasses.replace(study, slots=None if slots is None else tuple(slots), path_note=note)


def _base_scene(path: str, data: dict, raw: dict) -> tuple[Scene, str]:
    """The scene to vary and the study's name."""
    if "base" not in raw:  # a scene with its own [study]
        scene = load_scene(path)
        return scene, scene.name
    extra = sorted(set(data) - {"study", "scene", "optimize"})
    if extra:
        raise SceneError(path, extra[0], None, "a study file holds [study] (and [scene] name) only "
                         "(and [optimize] to optimise)", "put scene tables in the base scene")
    if not isinstance(raw["base"], str):
        raise SceneError(path, "study", "base", "expected a string (a path)",
                         'write base = "../basketball_goal.toml"')
    base = Path(path).parent / raw["base"]
    if not base.is_file():
        raise SceneError(path, "study", "base", f'no scene file "{base}"',
                         "give the base scene's path relative to the study file")
    if study_kind(base) == "study":
        raise SceneError(path, "study", "base", f'"{base}" is a study file, not a scene',
                         "give the scene that study varies (its own base) as base")
    scene_table = data.get("scene", {})
    if not isinstance(scene_table, dict) or set(scene_table) - {"name"}:
        raise SceneError(path, "scene", None, "a study file's [scene] holds its name only",
                         'write [scene] name = "goal_spring"; the rest belongs in the base scene')
    name = scene_table.get("name")
    if not isinstance(name, str) or not name.strip() or any(c in name for c in "/\\"):
        if name is not None:
            raise SceneError(path, "scene", "name", f"{name!r} cannot be a file name",
                             'write e.g. name = "goal_spring"')
        name = Path(path).stem
    return load_scene(str(base)), name


def default_batch_size(n_variants: int, n_steps: int) -> int:
    """Variants per batch where the study file gives no ``batch_size``: at most DEFAULT_BATCH
    and BATCH_ROWS (variant, step) rows; where that needs more than one batch, a number of
    batches that is a multiple of BATCH_MULTIPLE (where there are enough variants), each as
    large as that allows."""
    cap = max(1, min(DEFAULT_BATCH, BATCH_ROWS // max(1, n_steps)))
    n_batches = -(-n_variants // cap)
    if n_batches == 1:  # one batch holds them all: no split (it would only add batches' costs)
        return max(1, n_variants)
    n_batches = min(n_variants, -(-n_batches // BATCH_MULTIPLE) * BATCH_MULTIPLE)
    return max(1, -(-n_variants // max(1, n_batches)))


def _whole(path, raw, key, default, low) -> int:
    value = raw.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise SceneError(path, "study", key, f"expected a whole number >= {low}, got {value!r}",
                         f"write e.g. {key} = {KEYS['study'][key]}")
    return value


def _parameters(path, raw, scene: Scene, base: dict) -> tuple[StudyParameter, ...]:
    table = raw.get("parameters")
    if not isinstance(table, dict) or not table:
        raise SceneError(path, "study", "parameters", "missing or empty: a study varies at "
                         "least one parameter", 'add [study.parameters] with e.g. '
                         '"springs.left.k" = { from = 2.0, to = 6.0, steps = 9 }')
    out = []
    table = dict(table)
    tie = table.pop("tie", None)
    if not table:
        raise SceneError(path, "study", "parameters", "only a tie: a study varies at least one "
                         "parameter", 'add e.g. "springs.left.k" = { from = 2.0, to = 6.0, steps = 9 }')
    for address, spec in table.items():
        where = (path, "study.parameters", address)
        p_path, value = locate(scene, base, address, where)
        acts(scene, address, p_path, where)
        if p_path[0] == "time":
            raise SceneError(*where, "would change the instants; the variants of a study share "
                             "one sweep of steps (one time axis)", "vary another value")
        if p_path[-1] in _STEP_KEYS or _moves_step_count(base, p_path):
            raise SceneError(*where, "would change the number of steps; the variants of a "
                             "study share one step axis", "vary another value")
        twin = next((q.address for q in out if q.path == p_path), None)
        if twin is not None:
            raise SceneError(*where, f'is the same value as "{twin}" (two addresses of one '
                             "number)", "vary it once")
        kind, numbers = _variation(where, spec)
        out.append(StudyParameter(address, p_path, float(value), kind, numbers))
    return tuple(out) + tied(path, "study.parameters", tie, scene, base, out)


def tied(path, table: str, tie, scene: Scene, base: dict, params) -> tuple[StudyParameter, ...]:
    """The parameters ``tie = { "<address>" = "<address it follows>" }`` adds (kind "tie",
    ``spec`` = (the varied parameter it takes its value from,), chains followed to it):
    SceneError naming ``table``'s ``tie`` for a tie that is not a table of addresses, to an
    address no parameter varies, of a value that is varied or tied already, or in a cycle."""
    if tie is None:
        return ()
    hint = 'write tie = { "springs.right.k" = "springs.left.k" } (a value = the one it follows)'
    if not isinstance(tie, dict) or not all(isinstance(v, str) for v in tie.values()):
        raise SceneError(path, table, "tie", "expected a table of addresses", hint)
    varied = {p.address: p for p in params}
    out = []
    for address, target in tie.items():
        where = (path, f"{table}.tie", address)
        if address in varied:
            raise SceneError(*where, "is varied itself; a tied value follows another and is "
                             "not varied", "remove it from the parameters, or from tie")
        root, seen = target, [address]
        while root in tie and root not in varied:
            if root in seen:
                raise SceneError(*where, "a cycle of ties: " + " -> ".join(seen + [root]),
                                 "tie each value to a varied parameter (or to a value tied to one)")
            seen.append(root)
            root = tie[root]
        if root not in varied:
            raise SceneError(*where, f'ties to "{target}", which no parameter varies',
                             _suggest(target, list(varied)) or "tie to one of the parameters: "
                             + ", ".join(varied))
        p_path, value = locate(scene, base, address, where)
        twin = next((q.address for q in (*params, *out) if q.path == p_path), None)
        if twin is not None:
            raise SceneError(*where, f'is the same value as "{twin}" (two addresses of one '
                             "number)", "name it once")
        out.append(StudyParameter(address, p_path, float(value), "tie", (root,)))
    return tuple(out)


def _moves_step_count(base: dict, p_path: tuple) -> bool:
    """Whether a driver's ``from`` or ``to`` sets its number of steps (a driver given by
    ``step``: (to - from) / step + 1 steps)."""
    if p_path[0] != "drivers" or p_path[-1] not in ("from", "to") or len(p_path) != 3:
        return False
    return "step" in base["drivers"][p_path[1]] and "steps" not in base["drivers"][p_path[1]]


def _variation(where, spec) -> tuple[str, tuple]:
    """("grid", (from, to, steps)) or ("normal" | "uniform", (a, b)) of one parameter."""
    hint = ("write { from = 2.0, to = 6.0, steps = 9 }, { normal = [mean, sd] } or "
            "{ uniform = [low, high] }")
    if not isinstance(spec, dict):
        raise SceneError(*where, f"expected a table, got {spec!r}", hint)
    keys = set(spec)
    if keys == {"from", "to", "steps"}:
        lo, hi, n = spec["from"], spec["to"], spec["steps"]
        if not (_is_number(lo) and _is_number(hi)) or isinstance(n, bool) or not isinstance(n, int):
            raise SceneError(*where, "from and to must be numbers, steps a whole number", hint)
        if n < 1 or (n > 1 and lo == hi):
            raise SceneError(*where, f"an empty range (from {lo}, to {hi}, steps {n})",
                             "give steps >= 1, and from != to when steps > 1")
        if n == 1 and lo != hi:  # one step cannot reach `to`: say which value is meant
            raise SceneError(*where, f"one step cannot cover from {lo} to {hi}",
                             "give steps >= 2, or from = to = the one value")
        return "grid", (float(lo), float(hi), n)
    if len(keys) == 1 and keys <= {"normal", "uniform"}:
        kind = keys.pop()
        pair = spec[kind]
        if not (isinstance(pair, list) and len(pair) == 2 and all(map(_is_number, pair))):
            raise SceneError(*where, f"{kind} needs two numbers, got {pair!r}", hint)
        a, b = map(float, pair)
        if (kind == "normal" and not b > 0) or (kind == "uniform" and not a < b):
            raise SceneError(*where, f"an empty range ({kind} = {pair})",
                             "normal = [mean, sd] with sd > 0; uniform = [low, high] with low < high")
        return kind, (a, b)
    bad = sorted(keys - {"from", "to", "steps", "normal", "uniform"})
    raise SceneError(*where, f"unknown key {bad[0]!r}" if bad else f"keys {sorted(keys)} do not "
                     "make a grid or one distribution", hint)


#: the most variants a study may have (its table of values alone is 8 bytes a parameter each)
MAX_VARIANTS = 100_000_000


def _check_variant_count(path, params, samples: int) -> None:
    """SceneError before any work when the grids' product times the samples is too many."""
    count = samples if any(p.kind in ("normal", "uniform") for p in params) else 1
    for p in params:
        if p.kind == "grid":
            count *= p.spec[2]
    if count > MAX_VARIANTS:
        raise SceneError(path, "study", "parameters", f"{count:,} variants (the grids' product "
                         f"times samples) is more than {MAX_VARIANTS:,}",
                         "use fewer grid steps or samples, or split the study into several files")


def variant_values(params, samples: int, seed: int) -> np.ndarray:
    """(V, n_parameters): the grids' full product, each point with ``samples`` joint draws."""
    grids = [np.linspace(*p.spec) for p in params if p.kind == "grid"]
    # the full product in itertools.product's order (last grid fastest), as one array
    points = (np.stack(np.meshgrid(*grids, indexing="ij"), axis=-1).reshape(-1, len(grids))
              if grids else np.zeros((1, 0)))
    draws = [p for p in params if p.kind in ("normal", "uniform")]
    per_point = samples if draws else 1
    V = points.shape[0] * per_point
    rng = np.random.default_rng(seed)
    out = np.empty((V, len(params)))
    g = 0
    for j, p in enumerate(params):
        if p.kind == "grid":
            out[:, j] = np.repeat(points[:, g], per_point)
            g += 1
        elif p.kind == "normal":
            out[:, j] = rng.normal(p.spec[0], p.spec[1], V)
        elif p.kind == "uniform":
            out[:, j] = rng.uniform(p.spec[0], p.spec[1], V)
    return with_ties(params, out)


def with_ties(params, values: np.ndarray) -> np.ndarray:
    """``values`` (V, n_parameters) with each tied column set to the column it follows."""
    names = [p.address for p in params]
    for j, p in enumerate(params):
        if p.kind == "tie":
            values[:, j] = values[:, names.index(p.spec[0])]
    return values


def _catalog(scene: Scene) -> dict:
    from ..pipeline import solve

    return catalog_of_result(solve(scene))


def catalog_of_result(result) -> dict:
    """{variable: (dims, {dim: labels})} of a result's step-first variables."""
    labels = {c.name: [str(x) for x in c.data] for c in result.coordinates()}
    return {v.name: (v.dims, {d: labels.get(d, []) for d in v.dims[1:]})
            for v in result.variables() if v.dims[:1] == ("step",)}


def _metrics(path, raw, catalog, n_steps: int | None = None) -> tuple[Metric, ...]:
    table = raw.get("metrics", {})
    if not isinstance(table, dict):
        raise SceneError(path, "study", "metrics", "expected a table of named reductions",
                         'write [study.metrics] with peak = "max(abs(input_force.<driver>))"')
    out = []
    for name, text in table.items():
        if not name.isidentifier() or name in RESERVED:
            raise SceneError(path, "study.metrics", name, "cannot name a metric (a variable "
                             "of the study file needs a plain name of its own)",
                             "use letters, digits and _; not " + ", ".join(RESERVED))
        out.append(Metric(name, text, reductions.compile_metric(path, name, text, catalog,
                                                                n_steps)))
    return tuple(out)
