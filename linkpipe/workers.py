"""Threads that share a sweep's chunks of steps.

A sweep's whole-array stages (the Jacobian stage's factorisations, the link angles' rates)
work chunk by chunk, and each chunk's numpy calls release the GIL for their loops, so another
core can take some of the chunks (measured alone: the Jacobian stage 1.9x faster on 2 cores;
a whole run on 2 cores gains nothing, its second core being the HDF5 writer's). Every chunk
computes exactly what it computes alone and writes its own rows of preallocated outputs, so
a result does not depend on the thread count to the last bit (``tests/test_workers.py``).

The count: :func:`using` sets it for a block (the CLI's ``--chunk-threads``; a study's Dask
workers, which already share the cores, set 1); by default the CPUs this process may use
but one (the writer's), at most :data:`MOST`.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
from concurrent.futures import ThreadPoolExecutor, wait

#: the default count's ceiling: past a few threads the Python between numpy calls (under the
#: GIL) is the limit
MOST = 4

_count: contextvars.ContextVar[int | None] = contextvars.ContextVar("linkpipe_chunk_threads",
                                                                   default=None)
_pools: dict[int, ThreadPoolExecutor] = {}
if hasattr(os, "register_at_fork"):  # a forked child has none of its parent's threads
    os.register_at_fork(after_in_child=_pools.clear)


def default_count() -> int:
    """The CPUs this process may use (its affinity) but one, at most :data:`MOST`: the one
    left is the HDF5 writer's, whose thread writes a segment while the next one solves
    (measured on 2 cores: two chunk threads beside the writer gave 0.98-1.06x the time of
    one, ``docs/performance.md``)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(MOST, cpus - 1))


def count() -> int:
    """The threads a chunked stage uses here: :func:`using`'s, else :func:`default_count`."""
    n = _count.get()
    return default_count() if n is None else n


@contextlib.contextmanager
def using(n: int | None):
    """Chunked stages inside the block use ``n`` threads (None or 0: the default count)."""
    token = _count.set(n or None)
    try:
        yield
    finally:
        _count.reset(token)


def _pool(n: int) -> ThreadPoolExecutor:
    pool = _pools.get(n)
    if pool is None:
        pool = _pools[n] = ThreadPoolExecutor(n, thread_name_prefix="linkpipe-chunks")
    return pool


def for_chunks(work, n_steps: int, chunk: int) -> None:
    """Call ``work(lo, hi)`` for each chunk ``lo .. hi - 1`` of ``n_steps`` steps, on
    :func:`count` threads (in this thread where that is 1 or there is one chunk). ``work``
    writes its own rows of preallocated outputs; the first chunk's exception (in step order), or
    a Ctrl-C while this thread waits, is raised here, after every started chunk has ended (none
    still writes)."""
    bounds = [(lo, min(n_steps, lo + chunk)) for lo in range(0, n_steps, chunk)]
    n = min(count(), len(bounds))
    if n <= 1:
        for lo, hi in bounds:
            work(lo, hi)
        return
    context = contextvars.copy_context()  # numpy's errstate; one thread inside a chunk
    context.run(_count.set, 1)  # (a chunk's own chunked calls must not wait on this pool)
    futures = [_pool(n).submit(context.copy().run, work, lo, hi) for lo, hi in bounds]
    try:
        for future in futures:
            future.result()
    except BaseException:  # a chunk's failure, or Ctrl-C while waiting: no chunk left writing
        for future in futures:
            future.cancel()
        held_interrupts(lambda: wait(futures))  # the first failure or Ctrl-C goes on
        raise


def held_interrupts(call) -> KeyboardInterrupt | None:
    """Run ``call()`` (a wait for threads whose work takes milliseconds) to its end, a Ctrl-C
    meanwhile held until then; return the first one held (None: none), for the caller to
    raise once it has cleaned up."""
    held = None
    while True:
        try:
            call()
            return held
        except KeyboardInterrupt as stop:
            held = held or stop


#: BLAS threads while a scene is solved: its solves are many small systems (stacks of 2x2 to
#: few-hundred-square blocks), where a multi-threaded BLAS only adds overhead (measured:
#: benchmarks/bench_threads.py; docs/performance.md)
DEFAULT_THREADS = 1
