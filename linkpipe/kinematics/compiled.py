"""Whether stage 1 takes its compiled loops (numba) or numpy: the one place that decides.

The compiled loops (:mod:`.chain_kernel`: the closed-form dyads; :mod:`.block_kernel`: the
sparse engine's exact condition; :mod:`.unwrap_kernel`: the links' angles unwrapped) run the
numpy path's arithmetic in its order, with the transcendental functions taken from numpy
around them (cos and sin of the drivers, arctan2 of the links, mod): they give the numpy
path's numbers to the bit (a zero's sign aside), which ``tests/test_chain_kernel.py``,
``tests/test_block_kernel.py`` and ``tests/test_unwrap_kernel.py`` prove on every shipped
scene and on families of mechanisms. So the choice changes no stored number, only the time.

They are taken where they pay for themselves. Loading them costs about 0.45 s once per
process (importing numba, starting its compiler and loading the machine code it cached in
``__pycache__``; about 7 s the first time after an install, when it compiles them), and they
save about 0.2 us a step (``benchmarks/bench_sweep.py``). So a sweep takes them from
:data:`COLD_FROM` steps in a process that has not loaded them, and from :data:`WARM_FROM` steps
once it has (a second long scene of ``run configs/*.toml``, a fit's trials, a study's variants
solved one by one, a notebook's later solves; a study's vectorised variants, with per-row
numbers, stay on numpy: :func:`.dyads.solve_chain`). As the numbers are the same either way, this history decides only the time.
``LINKPIPE_COMPILED=0`` in the environment turns them off, ``=1`` takes them at any length.
"""
from __future__ import annotations

import functools
import os

#: a sweep of this many steps or more takes the compiled loops where they are not loaded yet:
#: about where their saving (~0.2 us a step) repays loading them (~0.45 s)
COLD_FROM = 3_000_000
#: ... and from this many where they are (shorter sweeps gain too little to matter)
WARM_FROM = 100_000
_loaded = False  # a compiled loop has been made (compiled, or loaded from the cache) here


def wanted(n_steps: int) -> bool:
    """True when a sweep of ``n_steps`` steps takes the compiled loops (module docstring)."""
    flag = os.environ.get("LINKPIPE_COMPILED", "")
    if flag == "0":
        return False
    if flag != "1" and n_steps < (WARM_FROM if _loaded else COLD_FROM):
        return False
    return available()


def loaded() -> bool:
    """True once a compiled loop has been made in this process (its cost is paid)."""
    return _loaded


@functools.cache
def available() -> bool:
    """True when numba imports (it is a dependency; a broken install falls back to numpy)."""
    try:
        import numba  # noqa: F401
    except Exception:  # noqa: BLE001 - any failure to import means: numpy
        return False
    return True


def jit(fn=None, *, inline: bool = False):
    """``fn`` compiled by numba, now: for a module of compiled loops that is imported only
    where :func:`wanted` said so (numba is imported here). Cached on disk, without the GIL,
    IEEE semantics (division by zero gives inf or NaN, as numpy's; no fast-math, so no fused
    multiply-adds: every operation rounds as numpy's); where numba finds nowhere to write its
    cache, compiled afresh in each process (the same machine code). ``inline``: a small
    function inlined where it is called (so that a loop calling it stays one loop the
    compiler can vectorise)."""
    import numba

    def wrap(f):
        global _loaded
        options = dict(nogil=True, error_model="numpy", fastmath=False,
                       inline="always" if inline else "never")
        try:
            made = numba.njit(cache=True, **options)(f)
        except Exception:  # noqa: BLE001 - nowhere to write numba's cache (a read-only
            made = numba.njit(cache=False, **options)(f)  # install, no writable home):
        _loaded = True                                    # compiled in each process instead
        return made

    return wrap if fn is None else wrap(fn)


def loop(fn):
    """``fn``, a module-level function of loops over steps in a module imported whatever the
    path, compiled by :func:`jit` on first use: returns ``get()`` -> the compiled function
    (numba is imported then, not when the module defining ``fn`` is)."""
    @functools.cache
    def get():
        return jit(fn)

    return get
