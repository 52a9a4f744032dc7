"""Objects derived from a frozen one (a model's engine, a result's drawing scales), built once
and kept beside it (never set on it) until it is garbage-collected. A leaf: anyone may import it."""
from __future__ import annotations

import threading
import weakref

_DERIVED: dict[tuple[int, str], object] = {}
#: (content key, name) -> what was derived from an owner with that content, newest last
_SHARED: dict[tuple, object] = {}
#: the content keys' entries kept (a fit's recent trials, follow's one model: a few suffice)
SHARED_KEEP = 32
_MISSING = object()
_SHARED_LOCK = threading.Lock()  # a study's worker threads derive too


def derived(owner, name: str, build, same=None):
    """Return ``build(owner)``, built once per owner and kept beside it (not on the frozen
    dataclass) until the owner is garbage-collected. ``same``: a key of everything ``build``
    reads from the owner (:func:`linkpipe.model.build.content_key`): an owner equal to an earlier
    one in it gets the earlier one's object, not a new build (``follow`` builds a model per
    block of one scene, a fit per trial; the last :data:`SHARED_KEEP` are kept)."""
    key = (id(owner), name)
    if key not in _DERIVED:
        with _SHARED_LOCK:
            value = _MISSING if same is None else _SHARED.pop((same, name), _MISSING)
        if value is _MISSING:
            value = build(owner)
        if same is not None:
            with _SHARED_LOCK:
                _SHARED[same, name] = value  # newest last
                while len(_SHARED) > SHARED_KEEP:
                    _SHARED.pop(next(iter(_SHARED)))
        _DERIVED[key] = value
        weakref.finalize(owner, _DERIVED.pop, key, None)
    return _DERIVED[key]



def forget(owner) -> None:
    """Drop what was derived from ``owner`` now. A derived object that refers back to its owner
    (a model's step kernels hold the model) keeps it alive through this module's table, so
    the finaliser never runs: a process that makes many short-lived owners (``follow``: a
    model per block) forgets each one when it is done with it."""
    for key in [k for k in _DERIVED if k[0] == id(owner)]:
        _DERIVED.pop(key, None)
