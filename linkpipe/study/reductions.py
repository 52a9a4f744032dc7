"""User-named reductions of stored variables (``[study.metrics]``), parsed, never eval'd.

A reduction is a small expression: numbers, ``+ - * /``, parentheses, the functions ``max``,
``min``, ``mean``, ``rms`` and ``percentile(x, q)`` (a series to one number), ``abs`` (either),
the values at one pose ``at(x, step)`` (step 0 first, -1 the last) and ``at_driver(x, driver,
value)`` (x interpolated linearly where the driver's value first passes ``value``, in the
driver's units: NaN where the ok steps never reach it), ``count_failed()`` (the steps that are
not ok),
and references to one stored series ``<variable>[.<label>...]``: a variable of the output
contract with the step axis first and one label per further dimension (``input_force.crank``,
``spring_force.left``, ``position.P.x``, ``joint_force.B@upper.y``, ``gravity_energy``). The
whole expression must reduce to one number per variant: every series sits inside a reduction.

A tiny recursive-descent parser builds a tree of tuples; :func:`resolve` checks every name
against the variables a solved base scene stores (a name that is not there is a
:class:`SceneError` naming the study file, ``[study.metrics]`` and the metric), and
:func:`evaluate` computes it on arrays with a leading variant axis, over the ok steps only.

Grammar::

    expr  := term (("+" | "-") term)*
    term  := unary (("*" | "/") unary)*
    unary := "-" unary | atom
    atom  := NUMBER | FUNC "(" expr ["," NUMBER] ")" | "at_driver(" expr "," NAME "," NUMBER ")"
           | "count_failed()" | REF | "(" expr ")"
"""
from __future__ import annotations

import re

import numpy as np

from ..errors import SceneError
from ..scene.keys import _suggest

REDUCE = ("max", "min", "mean", "rms", "percentile")
#: a series to its value at one pose, and the count of failed steps
POSE = ("at", "at_driver", "count_failed")
FUNCTIONS = REDUCE + POSE + ("abs",)
_TOKEN = re.compile(r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
                    r"|(?P<name>[A-Za-z_][\w@]*(?:\.[\w@]+)*)|(?P<op>[-+*/(),]))")


class ReductionError(ValueError):
    """A malformed reduction (turned into a SceneError naming the file, table and key)."""


def tokens(text: str) -> list[tuple[str, str]]:
    """Return the tokens ``[(kind, text)]`` of ``text`` (kind: num, name, op)."""
    out, pos, text = [], 0, text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            raise ReductionError(f"unexpected {text[pos:].strip()[:12]!r} at character {pos + 1}")
        kind = m.lastgroup
        out.append((kind, m.group(kind)))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, text: str):
        self.toks, self.i = tokens(text), 0

    def peek(self):
        return self.toks[self.i] if self.i < len(self.toks) else ("end", "")

    def take(self, want: str | None = None):
        tok = self.peek()
        if want is not None and tok[1] != want:
            raise ReductionError(f"expected {want!r}, found {tok[1] or 'the end'!r}")
        self.i += 1
        return tok

    def expr(self):
        node = self.term()
        while self.peek()[1] in ("+", "-"):
            node = ("bin", self.take()[1], node, self.term())
        return node

    def term(self):
        node = self.unary()
        while self.peek()[1] in ("*", "/"):
            node = ("bin", self.take()[1], node, self.unary())
        return node

    def unary(self):
        if self.peek()[1] == "-":
            self.take()
            return ("neg", self.unary())
        return self.atom()

    def atom(self):
        kind, text = self.take()
        if kind == "num":
            return ("num", float(text))
        if text == "(":
            node = self.expr()
            self.take(")")
            return node
        if kind != "name":
            raise ReductionError(f"unexpected {text or 'end'!r}")
        if self.peek()[1] != "(":
            return ("ref", text)
        if text not in FUNCTIONS:
            raise ReductionError(f"unknown function {text!r} ({_suggest(text, FUNCTIONS)})")
        self.take("(")
        if text == "count_failed":
            self.take(")")
            return ("call", text, [])
        args = [self.expr()]
        if text == "at_driver":
            self.take(",")
            kind, driver = self.take()
            if kind != "name":
                raise ReductionError(f"at_driver(x, driver, value): name a driver, not {driver!r}")
            args.append(("driver", driver))
        if text in ("percentile", "at", "at_driver"):
            self.take(",")
            q = self.unary()
            if q[0] != "num" and not (q[0] == "neg" and q[1][0] == "num"):
                raise ReductionError({"percentile": "percentile(x, q): q must be a number",
                                      "at": "at(x, step): step must be a number",
                                      "at_driver": "at_driver(x, driver, value): value must be "
                                                   "a number"}[text])
            args.append(q)
        self.take(")")
        return ("call", text, args)


#: the longest reduction accepted (a parser's recursion stays far from Python's limit below it)
MAX_LENGTH = 2000


def parse(text: str):
    """Return the tree of a reduction (ReductionError when it is not one)."""
    if not isinstance(text, str) or not text.strip():
        raise ReductionError("expected a reduction such as \"max(abs(input_force.crank))\"")
    if len(text) > MAX_LENGTH:
        raise ReductionError(f"longer than {MAX_LENGTH} characters: write a shorter reduction")
    p = _Parser(text)
    try:
        node = p.expr()
    except RecursionError:
        raise ReductionError("nested too deeply: write it with fewer parentheses") from None
    if p.peek()[0] != "end":
        raise ReductionError(f"unexpected {p.peek()[1]!r} after a complete expression")
    return node


def resolve(node, catalog: dict, n_steps: int | None = None):
    """Return ``(tree, kind)``: references resolved to ``("ref", variable, index, text)`` and
    the tree's kind ("series" or "scalar"). ``catalog``: {variable: (dims, {dim: labels})} of
    the stored variables (step axis first); ``n_steps``: the sweep's steps (``at``'s range)."""
    tag = node[0]
    if tag == "num":
        return node, "scalar"
    if tag == "ref":
        return _reference(node[1], catalog), "series"
    if tag == "neg":
        inner, kind = resolve(node[1], catalog, n_steps)
        return ("neg", inner), kind
    if tag == "bin":
        (a, ka), (b, kb) = resolve(node[2], catalog, n_steps), resolve(node[3], catalog, n_steps)
        return ("bin", node[1], a, b), "series" if "series" in (ka, kb) else "scalar"
    name, args = node[1], node[2]
    if name == "count_failed":
        return ("call", name, []), "scalar"
    inner, kind = resolve(args[0], catalog, n_steps)
    if name == "abs":
        return ("call", name, [inner]), kind
    if kind != "series":
        raise ReductionError(f"{name}() reduces a stored series over the steps; it got a number")
    if name in ("at", "at_driver"):
        return _pose(name, inner, args, catalog, n_steps), "scalar"
    q = args[1] if len(args) > 1 else None
    if q is not None:
        value = q[1] if q[0] == "num" else -q[1][1]
        if not 0 <= value <= 100:
            raise ReductionError(f"percentile q must be within 0..100, got {value:g}")
        q = value
    return ("call", name, [inner] + ([q] if q is not None else [])), "scalar"


def _number(node) -> float:
    return node[1] if node[0] == "num" else -node[1][1]


def _pose(name: str, inner, args, catalog: dict, n_steps):
    """``("call", "at", [x, step])`` or ``("call", "at_driver", [x, driver series, value])``."""
    value = _number(args[-1])
    if name == "at":
        if value != int(value):
            raise ReductionError(f"at(x, step): step is a whole number (0 the first step, -1 the "
                                 f"last), got {value:g}")
        if n_steps is not None and not -n_steps <= value < n_steps:
            raise ReductionError(f"at(x, step): step {value:g} is outside the sweep's {n_steps} "
                                 f"steps (0 .. {n_steps - 1}, or -1 .. -{n_steps} from the end)")
        return ("call", name, [inner, int(value)])
    driver = args[1][1]
    names = catalog.get("driver_value", ((), {"driver": []}))[1].get("driver", [])
    if driver not in names:
        raise ReductionError(f"at_driver: no driver {driver!r} ({_suggest(driver, names)})")
    return ("call", name, [inner, ("ref", "driver_value", (names.index(driver),),
                                   f"driver_value.{driver}"), value])


def _reference(text: str, catalog: dict):
    parts = text.split(".")
    var, labels = parts[0], parts[1:]
    if var not in catalog and var in ("velocity_residual", "acceleration_residual"):
        raise ReductionError(f"{var!r} is stored only when the scene asks for it: set "
                             "[solver] rate_residuals = true in the base scene")
    if var not in catalog:
        raise ReductionError(f"{var!r} is not a variable this scene stores "
                             f"({_suggest(var, sorted(catalog))})")
    dims, coords = catalog[var]
    rest = dims[1:]
    if len(labels) != len(rest):
        want = ".".join(f"<{d}>" for d in rest)
        raise ReductionError(f"{text!r} names no single series: write {var}{'.' if rest else ''}"
                             f"{want} (one label for each of {', '.join(rest) or 'no'} dimension)")
    index = []
    for dim, label in zip(rest, labels):
        names = [str(x) for x in coords[dim]]
        if label not in names:
            raise ReductionError(f"{text!r}: no {dim} {label!r} ({_suggest(label, names)})")
        index.append(names.index(label))
    return ("ref", var, tuple(index), text)


def references(tree) -> list[tuple[str, tuple]]:
    """Every ``(variable, index)`` a resolved tree reads."""
    if tree[0] == "ref":
        return [(tree[1], tree[2])]
    if tree[0] == "num":
        return []
    children = (tree[1:] if tree[0] == "neg" else tree[2:] if tree[0] == "bin"
                else tree[2][:2] if tree[1] == "at_driver" else tree[2][:1])
    return [r for c in children for r in references(c)]


def evaluate(tree, series, failed=None) -> np.ndarray:
    """The reduction's value per variant ``(V,)``. ``series(variable, index)`` returns that
    series ``(V, S)`` with NaN at the steps that are not ok (reductions skip them; a variant
    with no ok step gives NaN); ``failed`` (V, S) bool: the steps that are not ok (for
    ``count_failed()``)."""
    tag = tree[0]
    if tag == "num":
        return np.float64(tree[1])
    if tag == "ref":
        return series(tree[1], tree[2])
    if tag == "neg":
        return -evaluate(tree[1], series, failed)
    if tag == "bin":  # x / 0 is inf (NaN for 0 / 0), reported as not finite: not a warning
        a, b = evaluate(tree[2], series, failed), evaluate(tree[3], series, failed)
        with np.errstate(all="ignore"):
            return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide}[tree[1]](a, b)
    name, args = tree[1], tree[2]
    if name == "count_failed":
        return failed.sum(axis=1).astype(float)
    x = evaluate(args[0], series, failed)
    if name == "abs":
        return np.abs(x)
    if name == "at":
        return x[:, args[1]]
    if name == "at_driver":
        return at_value(x, series(*args[1][1:3]), args[2])
    return reduce_steps(name, x, args[1] if len(args) > 1 else None)


def at_value(x: np.ndarray, d: np.ndarray, value: float) -> np.ndarray:
    """(V,): ``x`` (V, S) interpolated linearly where ``d`` (V, S) first passes ``value``
    between two neighbouring finite steps (either way; at a step that equals it: that step's
    x); NaN where no pair of neighbours brackets it."""
    with np.errstate(all="ignore"):
        if x.shape[1] == 1:
            return np.where(d[:, 0] == value, x[:, 0], np.nan)
        a, b = d[:, :-1] - value, d[:, 1:] - value
        x0, x1 = x[:, :-1], x[:, 1:]
        bracket = (a * b <= 0) & np.isfinite(a * b) & np.isfinite(x0) & np.isfinite(x1)
        k = bracket.argmax(axis=1)
        rows = np.arange(x.shape[0])
        a, b, x0, x1 = a[rows, k], b[rows, k], x0[rows, k], x1[rows, k]
        t = np.where(a == b, 0.0, a / (a - b))
        return np.where(bracket.any(axis=1), x0 + t * (x1 - x0), np.nan)


def reduce_steps(name: str, x: np.ndarray, q=None) -> np.ndarray:
    """One reduction over the step axis (1) of ``x`` (V, S), NaN steps left out."""
    with np.errstate(all="ignore"):
        return _reduce_rows(name, x, q)


def _reduce_rows(name: str, x: np.ndarray, q) -> np.ndarray:
    present = ~np.isnan(x)
    n = present.sum(axis=1)
    filled = np.where(present, x, 0.0)
    if name == "max":
        out = np.where(present, x, -np.inf).max(axis=1)
    elif name == "min":
        out = np.where(present, x, np.inf).min(axis=1)
    elif name == "mean":
        out = filled.sum(axis=1) / n
    elif name == "rms":
        out = np.sqrt((filled * filled).sum(axis=1) / n)
    else:  # numpy's "linear" percentile, row by row without a loop: NaN sorts last
        ordered = np.sort(x, axis=1)
        pos = q / 100.0 * np.maximum(n - 1, 0)
        lo = np.floor(pos).astype(np.intp)
        hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
        rows = np.arange(x.shape[0])
        a, b, t = ordered[rows, lo], ordered[rows, hi], pos - lo
        out = np.where(t >= 0.5, b - (b - a) * (1 - t), a + (b - a) * t)
    return np.where(n > 0, out, np.nan)


def counts_failed(tree) -> bool:
    """Whether a resolved tree reads ``count_failed()``."""
    if tree[0] in ("num", "ref", "driver"):
        return False
    if tree[0] == "call" and tree[1] == "count_failed":
        return True
    children = tree[1:] if tree[0] == "neg" else tree[2:] if tree[0] == "bin" else tree[2][:1]
    return any(counts_failed(c) for c in children)


def compile_metric(path, name: str, text, catalog: dict, n_steps: int | None = None):
    """Parse and resolve one ``[study.metrics]`` entry; SceneError naming file, table, key."""
    try:
        tree, kind = resolve(parse(text), catalog, n_steps)
    except ReductionError as exc:
        raise SceneError(path, "study.metrics", name, f"{exc}",
                         'write e.g. peak = "max(abs(input_force.<driver>))"; reductions: '
                         + ", ".join(FUNCTIONS)) from None
    if kind != "scalar":
        raise SceneError(path, "study.metrics", name, "gives a series, not one number per "
                         "variant", f'wrap it in a reduction: "max({text})"')
    if not references(tree) and not counts_failed(tree):
        raise SceneError(path, "study.metrics", name, "names no stored variable",
                         'reduce a variable the scene stores, e.g. "max(abs(input_force.<driver>))"')
    return tree


def unit_of(tree, entry_unit) -> str:
    """The unit of a resolved reduction's value, from ``entry_unit(variable, label)`` of each
    series it reads: a reduction, ``abs`` or a sign keep it; a sum or difference of one unit
    keeps it; a product or quotient joins them (``a*b``, ``a/b``; a number leaves the other's);
    "" where it cannot be told (units that differ in a sum, or an unknown variable)."""
    tag = tree[0]
    if tag == "num":
        return "1"
    if tag == "ref":
        parts = tree[3].split(".")
        return entry_unit(tree[1], parts[1] if len(parts) > 1 else None)
    if tag == "neg":
        return unit_of(tree[1], entry_unit)
    if tag == "call":
        return unit_of(tree[2][0], entry_unit) if tree[2] else "1"
    a, b = unit_of(tree[2], entry_unit), unit_of(tree[3], entry_unit)
    if tree[1] in "+-":
        return a if a == b else ""
    if not a or not b:
        return ""
    if b == "1":
        return a
    if a == "1":
        return b if tree[1] == "*" else f"1/{b}"
    return f"{a}{tree[1]}{b}"
