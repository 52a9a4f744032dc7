"""Where many independent tasks run: here, or on a Dask cluster (``dask.distributed``).

An executor takes a function, the argument it shares with every task (sent to each worker
once) and the tasks (tuples of further arguments), and yields ``(task index, result)`` in the
order tasks finish. ``in_process`` runs them one after another; ``on_dask`` on a
``LocalCluster`` of ``workers`` single-threaded processes, or on the existing cluster whose
scheduler is at ``scheduler``. Studies (:mod:`linkpipe.study.run`) and fleets of logs
(:mod:`linkpipe.fleet`) run on them.
"""
from __future__ import annotations

import contextlib
import logging


def in_process(fn, shared, tasks, workers=None, scheduler=None):
    """Yield ``(i, fn(shared, *tasks[i]))`` for each task, one after another, here."""
    for i, args in enumerate(tasks):
        yield i, fn(shared, *args)


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None):
    """A ``dask.distributed.Client``: on the scheduler at ``scheduler``, else on a new
    ``LocalCluster`` of ``workers`` single-threaded processes (closed on exit)."""
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    # Dask's default worker environment sets MALLOC_TRIM_THRESHOLD_ (memory back to the system
    # at every free): for numpy's short-lived arrays that doubles a batch's time (measured:
    # 0.077 -> 0.146 s a batch of 1000 variants), so the local workers keep glibc's default
    import dask

    single_threaded = {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": single_threaded}), \
            LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True,
                         dashboard_address=":0", silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def on_dask(fn, shared, tasks, workers=None, scheduler=None):
    """Yield ``(i, fn(shared, *tasks[i]))`` as the Dask cluster finishes each task."""
    from dask.distributed import as_completed

    with dask_client(workers, scheduler) as client:
        sent = client.scatter(shared, broadcast=True)
        futures = {client.submit(_on_one_thread, fn, sent, *args, pure=False): i
                   for i, args in enumerate(tasks)}
        for future in as_completed(futures):
            yield futures[future], future.result()
            future.release()


def _on_one_thread(fn, shared, *args):
    """``fn(shared, *args)`` with one thread over chunks of steps (:mod:`linkpipe.workers`):
    a cluster's workers already take a core each."""
    from .workers import using

    with using(1):
        return fn(shared, *args)


class Pool:
    """One executor kept for many rounds of tasks (an optimiser's generations): here, or one
    Dask cluster (``workers`` / ``scheduler`` as :func:`dask_client`) started once. ``share``
    sends the argument every task shares (once to each worker); ``map`` runs one round and
    returns the results in the tasks' order."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        self.dask = bool(workers or scheduler)
        self.workers, self.scheduler = workers, scheduler
        self._stack = contextlib.ExitStack()
        self.client = None

    def __enter__(self):
        if self.dask:
            self.client = self._stack.enter_context(dask_client(self.workers, self.scheduler))
        return self

    def __exit__(self, *exc):
        return self._stack.__exit__(*exc)

    @property
    def n_workers(self) -> int:
        """How many tasks run at once (1 here)."""
        return max(1, len(self.client.scheduler_info()["workers"])) if self.client else 1

    def share(self, shared):
        return self.client.scatter(shared, broadcast=True) if self.client else shared

    def map(self, fn, shared, tasks) -> list:
        if self.client is None:
            return [fn(shared, *args) for args in tasks]
        futures = [self.client.submit(_on_one_thread, fn, shared, *args, pure=False)
                   for args in tasks]
        return self.client.gather(futures)


EXECUTORS = {"in_process": in_process, "dask": on_dask}


def executor_name(workers: int | None, scheduler: str | None) -> str:
    """The executor the command line's ``--workers`` / ``--scheduler`` ask for."""
    return "dask" if workers or scheduler else "in_process"
