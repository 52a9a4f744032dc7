"""The sparse engine's exact 1-norm condition as one compiled loop over the steps.

What :meth:`.sparse.Engine.condition` computes without an inverse, ``|J|_1 max(|J^-1|'s column
sums)`` at every step (inf where not finite), in the numpy path's arithmetic and order, so to
the bit (``tests/test_block_kernel.py``):

* the 1-norm as :meth:`.sparse.Engine.norm1` adds it: each column's ``|entries|`` in the
  engine's entry order, the largest column (NaN anywhere: NaN);
* the inverse's column sums as :meth:`.sparse.Engine.inverse_column_sums` forms them: the unit
  right-hand sides by blocks, each block's right-hand side ``b - E x - ...`` in its ``outer``
  order, a 1x1 block by one division, a 2x2 block by Cramer's rule as ``_cramer2_into`` does it
  (``idet = 1 / (a d - b c)``; ``(r0 d - r1 b) idet``, ``(a r1 - c r0) idet``), then
  ``|x|`` summed over the unknowns in their order, the largest sum (NaN anywhere: NaN);
* ``cond = norm1 * largest``, inf where not finite.

Only engines whose diagonal blocks are all 1x1 or 2x2 take it (:func:`supported`): a larger
block is solved by LAPACK (``np.linalg.solve``), whose blocked, FMA-using factorisation this
loop cannot repeat to the bit, so those engines (the dump truck's and the excavator's 4x4
blocks) stay on the numpy path.

Two loops do it, the same operations in the same order. An engine's own loop
(:func:`_source`): this engine's blocks and terms written out once as straight-line Python,
one statement per operation, every intermediate a local, compiled by numba as one loop over
the steps (its coordinates gathered into contiguous rows first), which the compiler
vectorises across the steps; the source is written under this package's ``__pycache__``
(``block_kernels/``, named by its text's hash) so that numba caches its machine code beside
it, and an engine of the same structure on other numbers (a fit's trials) takes the same
loop (the coefficients are its arguments). The general loop (:func:`_condition_loop`): one
function for every engine, reading the structure from flat tables (:class:`Tables`) in runs
of a few dozen steps, each operation a loop over the run; it serves where an engine's own
loop would be too long (:data:`OWN_STATEMENTS`) or cannot be written (a read-only install).
The own loop is the faster (``benchmarks/bench_condition.py``, the crank-rocker at 360k steps:
0.013 s CPU against the general loop's 0.021 s and numpy's 0.044 s); each new structure costs
one compile (about a second), once per install.

With positions instead of entries (:func:`condition`'s ``X``, ``s``), the Jacobian's entries
are made in the loop too, from the engine's own affine terms (:attr:`.sparse.Engine._terms`,
read off ``model/equations.py``'s Jacobian) in :meth:`.sparse.Engine.entries_T`'s order, with
cos and sin of the angle drivers taken from numpy as ``entries_T`` takes them (or from the
caller, ``trig``): no (nnz, S) array and no gather of the coordinates. An engine with relative
angle rows (their entries come from the equations at every step,
:func:`.affine.relative_entries`) has its entries made by numpy and only the condition
compiled.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import pathlib
import sys
import threading
from dataclasses import dataclass

import numpy as np

from ..cache import derived
from . import compiled

#: steps per run of the loop: its scratch (n_q x n_q x RUN doubles for the solves) stays in
#: the cache for the small Jacobians that take the loop
RUN = 64
#: scratch doubles the solves' run may hold (the run is shortened for larger Jacobians)
RUN_DOUBLES = 1 << 16
#: steps per run of an engine's own loop (its coordinates gathered first, contiguous)
OWN_RUN = 256
#: the longest own loop written (statements per step); a larger engine takes the general loop
OWN_STATEMENTS = 1500
#: where the engines' own loops are written, beside this package's compiled files (numba keeps
#: their machine code beside them); where it cannot be written, the general loop serves
OWN_FOLDER = pathlib.Path(__file__).resolve().parent / "__pycache__" / "block_kernels"
_OWN: dict[str, object] = {}
_OWN_LOCK = threading.Lock()


@dataclass(frozen=True)
class Tables:
    """An engine's block structure and affine terms as flat arrays (built once per engine).

    ``nnz`` entries, ``n`` unknowns (= rows), ``nb`` blocks in the engine's order.
    """
    nnz: int
    n: int
    fused: bool  # the entries can be made in the loop (no relative angle rows)
    # blocks (nb,): first unknown's position in the block order, end, size (1 or 2)
    b_start: np.ndarray
    b_end: np.ndarray
    b_size: np.ndarray
    b_cols: np.ndarray  # (nb, 2) the block's unknowns (second -1 for a 1x1 block)
    b_inner: np.ndarray  # (nb, 4) entries a, b, c, d of the block (nnz: the zero row)
    o_ptr: np.ndarray  # (2 nb + 1,) outer entries of the block's row j at o_ptr[2b + j] ...
    o_e: np.ndarray    # outer entries, in each row's order
    o_c: np.ndarray    # their unknowns
    col_end: np.ndarray  # (n,) how many unit columns unknown c's solution has (its block's end)
    ce_ptr: np.ndarray   # (n + 1,) column c's entries ce_e[ce_ptr[c]:ce_ptr[c + 1]]
    ce_e: np.ndarray
    # the affine terms (entries_T): entry e = feature[t_f[t_ptr[e]]] * t_c[...] (+ c0) + ...
    t_ptr: np.ndarray
    t_f: np.ndarray
    t_c: np.ndarray
    c0: np.ndarray
    add_c0: np.ndarray  # (nnz,) bool(c0), as ``if c0:`` decides
    q_point: np.ndarray  # (n,) each coordinate's point and axis in X (S, P, 2)
    q_axis: np.ndarray
    order: np.ndarray  # (n,) the rows in block order (inverse_column_sums's unit columns)


def supported(eng) -> bool:
    """True when every diagonal block of the engine is 1x1 or 2x2 (see the module doc)."""
    return all(len(cols) <= 2 for _, cols, _, _ in eng.blocks)


def tables(eng) -> Tables:
    """The engine's :class:`Tables`, built once per engine (one :func:`supported`)."""
    if not supported(eng):
        raise ValueError("a diagonal block larger than 2x2: the numpy path "
                         "(block_kernel.supported)")
    return derived(eng, "block_kernel", _tables)


def _tables(eng) -> Tables:
    nnz, n = len(eng.rows), eng.model.n_q
    nb = len(eng.blocks)
    b_start, b_end, b_size = (np.zeros(nb, np.int64) for _ in range(3))
    b_cols = np.full((nb, 2), -1, np.int64)
    b_inner = np.full((nb, 4), nnz, np.int64)
    o_ptr, o_e, o_c = [0], [], []
    col_end = np.zeros(n, np.int64)
    end = 0
    for b, (rows, cols, inner, outer) in enumerate(eng.blocks):
        k = len(cols)
        b_start[b], b_size[b] = end, k
        end += len(rows)
        b_end[b] = end
        for a, c in enumerate(cols[:2]):
            b_cols[b, a] = c
            col_end[c] = end
        flat = [e for row in inner[:2] for e in row[:2]] if k == 2 else [inner[0][0], -1, -1, -1]
        b_inner[b] = [e if e >= 0 else nnz for e in flat]
        for j in range(2):
            for e, c in (outer[j] if j < k else ()):
                o_e.append(int(e))
                o_c.append(int(c))
            o_ptr.append(len(o_e))
    ce_ptr = np.cumsum([0] + [len(ce) for ce in eng.col_entries])
    ce_e = np.concatenate([np.asarray(ce, np.int64) for ce in eng.col_entries])
    t_ptr, t_f, t_c = [0], [], []
    for _, terms in eng._terms:
        for f, c in terms:
            t_f.append(f)
            t_c.append(c)
        t_ptr.append(len(t_f))
    c0 = np.array([c for c, _ in eng._terms], dtype=float)
    moving = eng.model.moving
    i64 = lambda a: np.asarray(a, dtype=np.int64)  # noqa: E731
    return Tables(nnz=nnz, n=n, fused=not len(eng.relative), b_start=b_start, b_end=b_end,
                  b_size=b_size, b_cols=b_cols, b_inner=b_inner, o_ptr=i64(o_ptr), o_e=i64(o_e),
                  o_c=i64(o_c), col_end=col_end, ce_ptr=i64(ce_ptr), ce_e=ce_e, t_ptr=i64(t_ptr),
                  t_f=i64(t_f), t_c=np.asarray(t_c, dtype=float), c0=c0,
                  add_c0=np.array([bool(c) for c in c0]),
                  q_point=i64(np.repeat(moving, 2)), q_axis=i64(np.tile([0, 1], len(moving))),
                  order=i64([r for rows, _, _, _ in eng.blocks for r in rows]))


def condition(eng, E: np.ndarray | None = None, X: np.ndarray | None = None,
              s: np.ndarray | None = None, trig: dict | None = None) -> np.ndarray:
    """The exact 1-norm condition (S,) of the engine's Jacobians, :meth:`.sparse.Engine.condition`
    without an inverse to the bit, compiled (the engine :func:`supported`): from entries E
    (nnz, S), or from positions X (S, P, 2) and driver values s (S, nd), the entries then made
    in the loop (by numpy first where the engine has relative angle rows).

    ``trig``: {driver: (cos, sin) (S,)} of the angle drivers' values, numpy's ``np.cos`` and
    ``np.sin`` of ``s[:, driver]`` already computed by the caller (the dyads' own: numpy's
    functions are elementwise, so these are the numbers :meth:`.sparse.Engine.entries_T`
    takes); without every angle driver's, they are computed here."""
    return _run(eng, E, X, s, False, trig)[0]


def parts(eng, E: np.ndarray | None = None, X: np.ndarray | None = None,
          s: np.ndarray | None = None) -> tuple:
    """(condition (S,), the 1-norm (S,) as :meth:`.sparse.Engine.norm1`, the inverse's column
    sums (m, S) as :meth:`.sparse.Engine.inverse_column_sums`) from the same loop, arguments as
    :func:`condition` (the checks compare each with numpy's)."""
    return _run(eng, E, X, s, True)


def _run(eng, E, X, s, keep: bool, trig: dict | None = None) -> tuple:
    t = tables(eng)
    if E is None and not t.fused:
        E = eng.entries_of(X, s)
    S = E.shape[1] if E is not None else X.shape[0]
    out = np.empty(S)
    n1, sums = (np.empty(S), np.empty((t.n, S))) if keep else (np.empty(0), np.empty((0, 0)))
    own = _own_loop(t, len(eng.angle), E is not None, keep)
    if own is not None:
        kept = (n1, sums) if keep else ()
        if E is not None:
            own(np.ascontiguousarray(E), t.t_c, t.c0, out, *kept)
        else:
            cos, sin = _trig(eng, s, trig or {})
            own(np.ascontiguousarray(X, dtype=float), cos, sin, t.t_c, t.c0, out, *kept)
        return _kept(t, out, n1, sums, keep)
    run = max(4, min(RUN, RUN_DOUBLES // max(1, t.n * t.n)))
    given = E is not None
    if given:
        E, X = np.ascontiguousarray(E), np.empty((0, 1, 2))
        cos, sin = np.empty((0, 0)), np.empty((0, 0))
    else:
        cos, sin = _trig(eng, s, trig or {})
        E, X = np.empty((0, 0)), np.ascontiguousarray(X, dtype=float)
    _loop()(E, given, X, cos, sin, t.t_ptr, t.t_f, t.t_c, t.c0, t.add_c0, t.q_point,
            t.q_axis, t.n, t.b_start, t.b_end, t.b_size, t.b_cols, t.b_inner, t.o_ptr, t.o_e,
            t.o_c, t.col_end, t.ce_ptr, t.ce_e, t.nnz, run, out, n1, sums)
    return _kept(t, out, n1, sums, keep)


def _kept(t: Tables, out, n1, sums, keep: bool) -> tuple:
    if not keep:
        return out, None, None
    by_row = np.empty_like(sums)
    by_row[t.order] = sums  # block order -> the rows' order, as inverse_column_sums
    return out, n1, by_row


def _trig(eng, s: np.ndarray, trig: dict) -> tuple:
    """cos and sin (na, S) of the engine's angle drivers, in its order: the caller's where it
    gave them, else as :meth:`.sparse.Engine.entries_T` takes them."""
    S, angle = s.shape[0], [int(j) for j in eng.angle]
    if not angle:
        return np.empty((0, S)), np.empty((0, S))
    if all(j in trig for j in angle):
        cos, sin = ([trig[j][k] for j in angle] for k in (0, 1))
        if len(angle) == 1:  # a (1, S) view of the caller's array, no copy
            return (np.ascontiguousarray(cos[0], dtype=float).reshape(1, S),
                    np.ascontiguousarray(sin[0], dtype=float).reshape(1, S))
        return np.array(cos, dtype=float), np.array(sin, dtype=float)
    th = np.ascontiguousarray(s.T)[eng.angle]
    return np.cos(th), np.sin(th)


def _condition_loop(E, from_entries, X, cos, sin, t_ptr, t_f, t_c, c0, add_c0, q_point, q_axis,
                    n, b_start, b_end, b_size, b_cols, b_inner, o_ptr, o_e, o_c, col_end,
                    ce_ptr, ce_e, nnz, run, out, n1_out, sums_out):  # pragma: no cover - numba
    """The loop of :func:`condition`; writes ``out`` (S,) (and the 1-norm ``n1_out`` (S,)
    and the column sums ``sums_out`` (n, S) in block order where they are not empty)."""
    S = out.shape[0]
    na = cos.shape[0]
    nb = b_start.shape[0]
    F = np.empty((1 + n + 2 * na, run))    # features of the run
    ent = np.zeros((nnz + 1, run))          # entries of the run; the last row: the zero entry
    x = np.empty((n, n, run))               # x[c, i]: unknown c for unit column i (block order)
    R = np.empty((2, n, run))               # a block's right-hand sides
    acc = np.empty(run)
    n1 = np.empty(run)
    big = np.empty(run)
    idet = np.empty(run)
    sums = np.empty((n, run))
    for lo in range(0, S, run):
        m = min(run, S - lo)
        # ---- the entries
        if from_entries:
            for e in range(nnz):
                for t in range(m):
                    ent[e, t] = E[e, lo + t]
        else:
            for k in range(n):
                p, ax = q_point[k], q_axis[k]
                for t in range(m):
                    F[1 + k, t] = X[lo + t, p, ax]
            for a in range(na):
                for t in range(m):
                    F[1 + n + a, t] = cos[a, lo + t]
                    F[1 + n + na + a, t] = sin[a, lo + t]
            for e in range(nnz):  # Engine.entries_T: f0 c (+ c0) + f1 c1 + ...
                p0, p1, k0 = t_ptr[e], t_ptr[e + 1], c0[e]
                row = ent[e]
                if p0 == p1:
                    for t in range(m):
                        row[t] = k0
                    continue
                fr, c = F[t_f[p0]], t_c[p0]
                for t in range(m):
                    row[t] = fr[t] * c
                if add_c0[e]:
                    for t in range(m):
                        row[t] = row[t] + k0
                for p in range(p0 + 1, p1):
                    fr, c = F[t_f[p]], t_c[p]
                    for t in range(m):
                        row[t] = row[t] + fr[t] * c
        # ---- the 1-norm (Engine.norm1): each column's |entries| in order, the largest
        for col in range(n):
            e0 = ce_e[ce_ptr[col]]
            for t in range(m):
                acc[t] = abs(ent[e0, t])
            for p in range(ce_ptr[col] + 1, ce_ptr[col + 1]):
                e = ce_e[p]
                for t in range(m):
                    acc[t] = acc[t] + abs(ent[e, t])
            if col == 0:
                for t in range(m):
                    n1[t] = acc[t]
            else:
                for t in range(m):
                    v, w = acc[t], n1[t]
                    n1[t] = v if (v > w) | (v != v) else w  # np.maximum: NaN wins
        # ---- the inverse's columns by blocks (Engine.inverse_column_sums)
        for b in range(nb):
            start, end, k = b_start[b], b_end[b], b_size[b]
            for j in range(k):
                for i in range(end):
                    for t in range(m):
                        R[j, i, t] = 0.0
                for t in range(m):
                    R[j, start + j, t] = 1.0
                for p in range(o_ptr[2 * b + j], o_ptr[2 * b + j + 1]):
                    e, c = o_e[p], o_c[p]
                    for i in range(col_end[c]):
                        for t in range(m):
                            R[j, i, t] = R[j, i, t] - ent[e, t] * x[c, i, t]
            c0_ = b_cols[b, 0]
            if k == 1:
                d = b_inner[b, 0]
                for i in range(end):
                    for t in range(m):
                        x[c0_, i, t] = R[0, i, t] / ent[d, t]
            else:
                c1_ = b_cols[b, 1]
                ia, ib, ic, id_ = b_inner[b, 0], b_inner[b, 1], b_inner[b, 2], b_inner[b, 3]
                for t in range(m):
                    idet[t] = 1.0 / (ent[ia, t] * ent[id_, t] - ent[ib, t] * ent[ic, t])
                for i in range(end):
                    for t in range(m):
                        r0, r1 = R[0, i, t], R[1, i, t]
                        x[c0_, i, t] = (r0 * ent[id_, t] - r1 * ent[ib, t]) * idet[t]
                        x[c1_, i, t] = (ent[ia, t] * r1 - ent[ic, t] * r0) * idet[t]
        # ---- |x| summed over the unknowns in their order; the largest sum; the condition
        for i in range(n):
            for t in range(m):
                sums[i, t] = 0.0
        for c in range(n):
            for i in range(col_end[c]):
                for t in range(m):
                    sums[i, t] = sums[i, t] + abs(x[c, i, t])
        for t in range(m):
            big[t] = sums[0, t]
        for i in range(1, n):
            for t in range(m):
                v, w = sums[i, t], big[t]
                big[t] = v if (v > w) | (v != v) else w
        for t in range(m):
            cond = n1[t] * big[t]
            out[lo + t] = cond if abs(cond) < np.inf else np.inf
        if n1_out.shape[0]:
            for t in range(m):
                n1_out[lo + t] = n1[t]
            for i in range(n):
                for t in range(m):
                    sums_out[i, lo + t] = sums[i, t]
    return out


_loop = compiled.loop(_condition_loop)


# ---------------------------------------------------------------------- an engine's own loop
def _own_loop(t: Tables, na: int, from_entries: bool, keep: bool = False):
    """The engine's own loop, compiled (:func:`_source`), or None where it is too long or
    cannot be written (the general loop :func:`_condition_loop` serves then); once per
    engine's tables."""
    return derived(t, f"own {na} {from_entries} {keep}",
                   lambda t: _own_compiled(t, na, from_entries, keep))


def _own_compiled(t: Tables, na: int, from_entries: bool, keep: bool = False):
    text = _source(t, na, from_entries, keep)
    if text is None:
        return None
    key = hashlib.sha1(text.encode()).hexdigest()[:20]
    with _OWN_LOCK:  # a study's worker threads: one compile
        if key not in _OWN:
            try:
                _OWN[key] = _load(text, key)
            except Exception:  # noqa: BLE001 - its source not written or not loaded (a
                _OWN[key] = None  # read-only install): the general loop, the same numbers
        return _OWN[key]


def _load(text: str, key: str):
    """Write the source (once: the same text keeps its file, so numba's cache of it stays
    valid), import it and return its loop compiled (:func:`.compiled.jit`)."""
    OWN_FOLDER.mkdir(parents=True, exist_ok=True)
    path = OWN_FOLDER / f"block_{key}.py"
    if not path.exists() or path.read_text() != text:
        tmp = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)  # whole or not at all, for another process reading it
    name = f"linkpipe.kinematics._block_{key}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # numba's cache finds the module of what it loads by name
    spec.loader.exec_module(module)
    return compiled.jit(module.loop)


def _source(t: Tables, na: int, from_entries: bool, keep: bool = False) -> str | None:
    """The source of one engine's loop: :func:`_condition_loop`'s operations for this
    engine's blocks and terms written out as one statement each (every intermediate a local:
    no scratch arrays, and one loop over the steps the compiler vectorises), in the same order
    (so the same numbers to the bit). The coefficients are arguments, so engines of one
    structure on other numbers (a fit's trials) share it. ``keep``: the 1-norm and the column
    sums (block order) written too, as :func:`_condition_loop` writes them. None: longer than
    OWN_STATEMENTS."""
    n, nnz = t.n, t.nnz
    if n * n + 2 * nnz + len(t.o_e) * n > OWN_STATEMENTS:
        return None
    args = ("E, tc, tk, out" if from_entries else "X, cos, sin, tc, tk, out") + (
        ", n1_out, sums_out" if keep else "")
    head = ["import numpy as np", "", "", f"def loop({args}):", "    S = out.shape[0]"]
    if not from_entries:  # the coefficients as locals (loaded once, not per step)
        head += [f"    k{p} = tc[{p}]" for p in range(len(t.t_c))]
        head += [f"    h{e} = tk[{e}]" for e in range(nnz)]
        head += [f"    F = np.empty(({n}, {OWN_RUN}))"]
    head += [f"    for lo in range(0, S, {OWN_RUN}):", f"        m = min({OWN_RUN}, S - lo)"]
    if not from_entries:  # the run's coordinates, gathered into contiguous rows
        for k in range(n):
            head += ["        for i in range(m):",
                     f"            F[{k}, i] = X[lo + i, {t.q_point[k]}, {t.q_axis[k]}]"]
    body = []
    if from_entries:
        body += [f"e{e} = E[{e}, lo + i]" for e in range(nnz)]
    else:
        body += [f"f{1 + k} = F[{k}, i]" for k in range(n)]
        for a in range(na):
            body += [f"f{1 + n + a} = cos[{a}, lo + i]", f"f{1 + n + na + a} = sin[{a}, lo + i]"]
        for e in range(nnz):  # Engine.entries_T: f0 c (+ c0) + f1 c1 + ...
            p0, p1 = t.t_ptr[e], t.t_ptr[e + 1]
            if p0 == p1:
                body.append(f"e{e} = h{e}")
                continue
            expr = f"f{t.t_f[p0]} * k{p0}"
            if t.add_c0[e]:
                expr = f"({expr}) + h{e}"
            for p in range(p0 + 1, p1):
                expr = f"({expr}) + f{t.t_f[p]} * k{p}"
            body.append(f"e{e} = {expr}")
    body.append(f"e{nnz} = 0.0")
    for col in range(n):  # Engine.norm1
        es = t.ce_e[t.ce_ptr[col]:t.ce_ptr[col + 1]]
        expr = f"abs(e{es[0]})"
        for e in es[1:]:
            expr = f"({expr}) + abs(e{e})"
        body += ([f"n1 = {expr}"] if col == 0 else
                 [f"v = {expr}", "n1 = v if (v > n1) | (v != v) else n1"])
    for b in range(len(t.b_start)):  # Engine.inverse_column_sums
        start, end, k = t.b_start[b], t.b_end[b], t.b_size[b]
        for j in range(k):
            body += [f"r{j}_{i} = {1.0 if i == start + j else 0.0}" for i in range(end)]
            for p in range(t.o_ptr[2 * b + j], t.o_ptr[2 * b + j + 1]):
                e, c = t.o_e[p], t.o_c[p]
                body += [f"r{j}_{i} = r{j}_{i} - e{e} * x{c}_{i}" for i in range(t.col_end[c])]
        c0_ = t.b_cols[b, 0]
        if k == 1:
            body += [f"x{c0_}_{i} = r0_{i} / e{t.b_inner[b, 0]}" for i in range(end)]
        else:
            c1_ = t.b_cols[b, 1]
            ia, ib, ic, id_ = t.b_inner[b]
            body.append(f"idet = 1.0 / (e{ia} * e{id_} - e{ib} * e{ic})")
            for i in range(end):
                body += [f"x{c0_}_{i} = (r0_{i} * e{id_} - r1_{i} * e{ib}) * idet",
                         f"x{c1_}_{i} = (e{ia} * r1_{i} - e{ic} * r0_{i}) * idet"]
    for i in range(n):
        expr = "0.0"
        for c in range(n):
            if t.col_end[c] > i:
                expr = f"({expr}) + abs(x{c}_{i})"
        body.append(f"q{i} = {expr}")
    body.append("big = q0")
    body += [f"big = q{i} if (q{i} > big) | (q{i} != q{i}) else big" for i in range(1, n)]
    body += ["cond = n1 * big", "out[lo + i] = cond if abs(cond) < np.inf else np.inf"]
    if keep:
        body += ["n1_out[lo + i] = n1"] + [f"sums_out[{i}, lo + i] = q{i}" for i in range(n)]
    lines = head + ["        for i in range(m):"] + ["            " + line for line in body]
    return "\n".join(lines) + "\n"
