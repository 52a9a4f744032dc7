"""Run linkpipe over ~2,200 systematically extreme scenes; count hangs, internal errors and
steps that say "ok" with non-finite numbers.

    .venv/bin/python benchmarks/extreme_scenes.py              # every scene (~10 min, 2 cores)
    .venv/bin/python benchmarks/extreme_scenes.py --limit 200  # a sample (every k-th scene)

Each scene runs ``linkpipe.__main__.main(["run", scene, "--out", tmp])`` in a forked child
(imports paid once, in the parent) with a 30 s limit. A scene passes when the child exits 0
or 2 within the limit, wrote no traceback and no "internal error", and every step it stored
as ``ok`` holds finite numbers only. The scenes: every numeric value of six shipped configs
(crank-rocker, slider-crank, basketball goal with every effect, shear press, five-bar, Jansen's
linkage) replaced in turn
by each of EXTREMES; whole-scene scalings; points a denormal apart; long under-driven chains;
and paths that are no regular file (a FIFO, /dev/zero, a folder, an empty and a binary file).
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures
import copy
import math
import os
import pathlib
import sys
import tempfile
import time
import tomllib

import tomli_w

ROOT = pathlib.Path(__file__).resolve().parents[1]
BASES = ["fourbar_crank_rocker", "slider_crank", "basketball_goal", "shear_press", "five_bar", "jansen"]
EXTREMES = [0.0, -0.0, 5e-324, 1e-300, 1e-12, -1.0, 1e12, 1e300, 1e308, -1e308,
            math.inf, -math.inf, math.nan]
TIMEOUT_S = 30.0


def _numeric_leaves(node, path=()):
    """Yield (path, value) of every int/float leaf of a parsed TOML document."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numeric_leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numeric_leaves(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path, node


def _set(doc, path, value):
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value


def _scaled(doc, factor):
    """The scene with every point coordinate multiplied by ``factor`` (lengths too)."""
    doc = copy.deepcopy(doc)
    for p in doc.get("points", {}).values():
        p["x"], p["y"] = p["x"] * factor, p["y"] * factor
    for link in doc.get("links", []):
        for key in list(link.get("lengths", {})):
            link["lengths"][key] *= factor
    return doc


def _chain(n_points: int) -> dict:
    """An under-driven open chain of ``n_points`` pinned bars with one driver."""
    pts = {f"P{i}": {"x": float(i), "y": 0.0} for i in range(n_points)}
    pts["P0"]["fixed"] = True
    links = [{"name": f"l{i}", "points": [f"P{i}", f"P{i + 1}"]} for i in range(n_points - 1)]
    return {"scene": {"name": f"chain_{n_points}"}, "points": pts, "links": links,
            "drivers": [{"name": "d", "angle": ["P0", "P1"], "from": 0.0, "to": 90.0, "steps": 10}]}


def scenes(work: pathlib.Path) -> list[tuple[str, pathlib.Path]]:
    """Write every extreme scene into ``work``; return (label, path) pairs."""
    out = []

    def add(label, doc):
        doc = copy.deepcopy(doc)
        doc.setdefault("scene", {})["name"] = f"x{len(out):05d}"
        path = work / f"x{len(out):05d}.toml"
        path.write_text(tomli_w.dumps(doc))
        out.append((label, path))

    for base in BASES:
        doc = tomllib.loads((ROOT / "configs" / f"{base}.toml").read_text())
        for path, _ in _numeric_leaves(doc):
            for value in EXTREMES:
                mutated = copy.deepcopy(doc)
                _set(mutated, path, value)
                add(f"{base}:{'.'.join(map(str, path))}={value!r}", mutated)
        for factor in (5e-324, 1e-300, 1e-150, 1e150, 1e300):
            add(f"{base}:scale={factor!r}", _scaled(doc, factor))
        near = copy.deepcopy(doc)  # the first two points a denormal apart
        first, second = list(near["points"])[:2]
        near["points"][second] = dict(near["points"][first], x=near["points"][first]["x"] + 5e-324)
        add(f"{base}:points 5e-324 apart", near)
    for n in (3, 50, 500):
        add(f"under-driven chain of {n} points", _chain(n))
    special = work / "special"
    special.mkdir()
    os.mkfifo(special / "fifo.toml")
    (special / "empty.toml").write_text("")
    (special / "binary.toml").write_bytes(bytes(range(256)) * 64)
    out += [("a FIFO", special / "fifo.toml"), ("/dev/zero", pathlib.Path("/dev/zero")),
            ("a folder", special), ("an empty file", special / "empty.toml"),
            ("a binary file", special / "binary.toml")]
    return out


def _child(path: str, outdir: str, log: str) -> None:
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    from linkpipe.__main__ import main

    code = main(["run", path, "--out", outdir, "--quiet"])
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _wrong_ok(outdir: pathlib.Path) -> int:
    """Steps stored as ok whose stored numbers are not all finite."""
    import h5py
    import numpy as np

    bad = 0
    for h5 in outdir.glob("*.h5"):
        with h5py.File(h5, "r") as f:
            ok = f["status"][()] == 0
            for name, ds in f.items():
                if ds.is_scale or not ds.shape or ds.dtype.kind != "f" or ds.shape[0] != len(ok):
                    continue
                finite = np.isfinite(ds[()].reshape(len(ok), -1)).all(axis=1)
                bad = max(bad, int((ok & ~finite).sum()))
    return bad


def _run_forked(path: str, outdir: str, log: str) -> tuple[int | None, float]:
    """Run one scene in a forked child; return (exit code or None if it hung, seconds).
    os.fork and os.waitpid of this child only (multiprocessing reaps other threads' children)."""
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # the child
        try:
            _child(path, outdir, log)
        finally:
            os._exit(70)
    while time.perf_counter() - t0 < TIMEOUT_S:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status), time.perf_counter() - t0
        time.sleep(0.01)
    os.kill(pid, 9)
    os.waitpid(pid, 0)
    return None, time.perf_counter() - t0


def run_one(label_path, work: pathlib.Path):
    label, path = label_path
    outdir = pathlib.Path(tempfile.mkdtemp(dir=work))
    log = outdir / "_log"
    code, seconds = _run_forked(str(path), str(outdir), str(log))
    if code is None:
        return label, "hang", seconds, ""
    text = log.read_text(errors="replace") if log.exists() else ""
    if "Traceback" in text:
        return label, "traceback", seconds, text[-400:]
    if code not in (0, 2) or "internal error" in text:
        return label, f"exit {code}", seconds, text[-400:]
    wrong = _wrong_ok(outdir)
    if wrong:
        return label, "wrong ok", seconds, f"{wrong} ok steps hold non-finite values"
    return label, f"clean (exit {code})", seconds, ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limit", type=int, default=0, help="run every k-th scene, about this many")
    ap.add_argument("--show", type=int, default=20, help="failures to print in full")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="scenes at a time")
    args = ap.parse_args(argv)
    import linkpipe.__main__  # noqa: F401 - imported once, in the parent, before forking
    import h5py  # noqa: F401
    import rerun  # noqa: F401

    with tempfile.TemporaryDirectory() as tmp:
        work = pathlib.Path(tmp)
        todo = scenes(work)
        if args.limit and args.limit < len(todo):
            todo = todo[::max(1, len(todo) // args.limit)]
        t0 = time.perf_counter()
        with concurrent.futures.ThreadPoolExecutor(max(1, args.jobs)) as pool:  # each waits on
            results = list(pool.map(lambda item: run_one(item, work), todo))  # its own child
        wall = time.perf_counter() - t0
    tally = collections.Counter(kind for _, kind, _, _ in results)
    slowest = max(results, key=lambda r: r[2])
    print(f"{len(results)} extreme scenes in {wall:.0f} s; slowest {slowest[2]:.1f} s ({slowest[0]})")
    for kind, n in sorted(tally.items()):
        print(f"  {kind}: {n}")
    failures = [r for r in results if not r[1].startswith("clean")]
    for label, kind, seconds, detail in failures[:args.show]:
        print(f"- {kind} ({seconds:.1f} s): {label}\n    {detail.strip().splitlines()[-1] if detail.strip() else ''}")
    print(f"{len(failures)} failed, {len(results) - len(failures)} passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
