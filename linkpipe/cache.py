"""Objects derived from a frozen one (a model's engine, a result's drawing scales), built once
and kept beside it (never set on it) until it is garbage-collected. A leaf: anyone may import it."""
from __future__ import annotations

import weakref

_DERIVED: dict[tuple[int, str], object] = {}


def derived(owner, name: str, build):
    """Return ``build(owner)``, built once per owner and kept beside it (not on the frozen
    dataclass) until the owner is garbage-collected."""
    key = (id(owner), name)
    if key not in _DERIVED:
        _DERIVED[key] = build(owner)
        weakref.finalize(owner, _DERIVED.pop, key, None)
    return _DERIVED[key]




def forget(owner) -> None:
    """Drop what was derived from ``owner`` now. A derived object that refers back to its owner
    (a model's step kernels hold the model) keeps it alive through this module's table, so
    the finaliser never runs: a process that makes many short-lived owners (``follow``: a
    model per block) forgets each one when it is done with it."""
    for key in [k for k in _DERIVED if k[0] == id(owner)]:
        _DERIVED.pop(key, None)
