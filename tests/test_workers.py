"""Threads over chunks of steps (linkpipe.workers) change no result: every chunk computes what
it computes alone, into its own rows. The exact answer is the one-thread run, bit for bit."""
from __future__ import annotations

import pathlib
import re
import threading

import numpy as np
import pytest

import linkpipe
from linkpipe import kinematics as kin
from linkpipe.model import build_model
from linkpipe.spine import Stages
from linkpipe.stage1 import Stage1
from linkpipe.status import finite_rows
from linkpipe.workers import count, default_count, for_chunks, using

ROOT = pathlib.Path(__file__).resolve().parent.parent
CONFIGS = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "configs" / "hard").glob("*.toml"))


def test_each_chunk_once_on_the_threads_asked_for():
    seen, names, lock = [], set(), threading.Lock()

    def work(lo, hi):
        with lock:
            seen.append((lo, hi))
            names.add(threading.current_thread().name)

    with using(3):
        assert count() == 3
        for_chunks(work, 1000, 64)
    assert sorted(seen) == [(lo, min(1000, lo + 64)) for lo in range(0, 1000, 64)]
    assert all(n.startswith("linkpipe-chunks") for n in names)
    seen.clear(), names.clear()
    with using(1):
        for_chunks(work, 1000, 64)
    assert len(seen) == 16 and names == {threading.current_thread().name}
    assert count() == default_count() >= 1


def test_a_failing_chunk_raises_once_every_started_chunk_has_ended():
    ended = []

    def work(lo, hi):
        if lo == 128:
            raise ValueError("chunk 128")
        ended.append(lo)

    with using(2), pytest.raises(ValueError, match="chunk 128"):
        for_chunks(work, 1024, 64)
    # nothing runs after the raise: no chunk is left writing (cancelled ones never start)
    n = len(ended)
    threading.Event().wait(0.05)
    assert len(ended) == n


def test_a_chunk_does_not_share_out_its_own_chunks():
    inner = []

    def work(lo, hi):
        inner.append(count())

    with using(2):
        for_chunks(work, 256, 64)
    assert inner == [1, 1, 1, 1]


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_jacobian_stage_and_rates_equal_on_one_and_three_threads(config, monkeypatch):
    """Every shipped scene's Jacobian stage, link angles, rates and finiteness in chunks of 16
    steps (many chunks, whatever the sweep's length): three threads give one thread's arrays."""
    from linkpipe import status
    from linkpipe.kinematics import angles as angles_module

    monkeypatch.setattr(angles_module, "CHUNK", 16)  # link angles' chunks
    monkeypatch.setattr(status, "FINITE_CHUNK", 16)
    scene = linkpipe.load_scene(config)
    model = build_model(scene)
    stages = Stages.of(scene)
    with using(1):
        stage1 = Stage1(scene, model, stages)
        sweep = stage1.plan.positions(slice(0, stage1.n_steps), stage1.s_dot, stage1.s_ddot,
                                      stage1.order)
    X = np.where(np.isfinite(sweep.position), sweep.position, 0.0)

    def run():
        der = kin.derivatives(model, X, stage1.s, stage1.s_dot, stage1.s_ddot, sweep.status,
                              stages.acceleration, need_influence=True, chunk=16)
        rates = kin.link_rates(model, X, der["velocity"], der["acceleration"], chunk=16)
        angles = kin.link_angles_unwrapped(model, sweep.position)
        finite = finite_rows([sweep.position, der["velocity"]], len(X))
        return der, rates, angles, finite

    with using(1):
        one = run()
    with using(3):
        three = run()
    for key, value in one[0].items():
        if value is not None:
            np.testing.assert_array_equal(three[0][key], value, err_msg=key)
    for a, b in zip(one[1:], three[1:]):
        for x, y in zip(a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,)):
            np.testing.assert_array_equal(y, x)


def arrays_of(result) -> dict:
    """Every stored array of a Result (its coordinates and variables), by name."""
    return {v.name: v.data for v in result.coordinates() + result.variables()}


def _crank_rocker(steps: int, extra: str = "") -> linkpipe.Scene:
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    return linkpipe.parse_scene(re.sub(r"steps = \d+", f"steps = {steps}", text) + extra,
                                "crank_rocker.toml")


@pytest.mark.parametrize("method", ["auto", "newton"])
def test_whole_solve_equal_on_one_and_two_threads(method):
    """A 50,001-step sweep (7 chunks of the Jacobian stage) with every effect: every stored
    array of the solve on two threads is the one-thread solve's, bit for bit."""
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_sweep import EFFECTS

    scene = _crank_rocker(50_001, EFFECTS + f'\n[solver]\nmethod = "{method}"\n')
    with using(1):
        one = arrays_of(linkpipe.solve(scene))
    with using(2):
        two = arrays_of(linkpipe.solve(scene))
    assert sorted(one) == sorted(two)
    for name, value in one.items():
        np.testing.assert_array_equal(two[name], value, err_msg=name)


def test_finite_rows_equal_the_entrywise_test_with_overflowing_sums():
    """finite_rows reads a row's sum first: it must still say exactly which rows hold an inf
    or NaN, also where finite entries (1.7e308) sum to inf, on one thread and on three."""
    from hypothesis import given, settings, strategies as st

    @settings(max_examples=60, deadline=None)
    @given(seed=st.integers(0, 10_000), S=st.integers(1, 70_000), k=st.integers(1, 12),
           exponent=st.integers(-300, 300), n_bad=st.integers(0, 30))
    def check(seed, S, k, exponent, n_bad):
        rng = np.random.default_rng(seed)
        a = rng.normal(size=(S, k)) * 10.0 ** exponent
        i, j = rng.integers(0, S, n_bad), rng.integers(0, k, n_bad)
        a[i, j] = rng.choice([np.nan, np.inf, -np.inf, 1.7e308, -1.7e308], n_bad)
        want = np.isfinite(a).all(axis=1)
        for n in (1, 3):
            with using(n):
                np.testing.assert_array_equal(finite_rows([a, a[:, :1].copy()], S), want)

    check()


def test_ctrl_c_while_waiting_returns_once_every_started_chunk_has_ended():
    """A signal that lands while this thread waits for the chunks (here SIGALRM raising
    KeyboardInterrupt, as Ctrl-C does) is raised only after every chunk that had started has
    ended: no chunk still writes into the outputs when the caller unwinds."""
    import signal
    import time

    state, lock = {}, threading.Lock()

    def work(lo, hi):
        with lock:
            state[lo] = "start"
        time.sleep(0.4 if lo == 0 else 0.1)  # the chunk waited on when the signal lands is
        with lock:                            # the last of the started ones to end
            state[lo] = "end"

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        with using(2), pytest.raises(KeyboardInterrupt):
            for_chunks(work, 64, 8)  # 8 chunks on 2 threads
        with lock:
            at_raise = dict(state)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert at_raise and set(at_raise.values()) == {"end"}  # started ones ended, none mid-way
    assert len(at_raise) < 8  # the others were cancelled, never started
    time.sleep(0.5)
    assert state == at_raise  # and none started after


def test_a_forked_child_solves_with_threads_of_its_own(tmp_path):
    """The pools are the parent's threads: a child forked after a threaded solve (multiprocessing
    on Linux) gets new ones instead of waiting forever on threads it does not have."""
    import multiprocessing

    with using(2):
        for_chunks(lambda lo, hi: None, 64, 8)  # the parent's pool exists
    ctx = multiprocessing.get_context("fork")

    def child(path):
        out = np.zeros(64)

        def work(lo, hi):
            out[lo:hi] = 1.0

        with using(2):
            for_chunks(work, 64, 8)
        np.save(path, out)

    proc = ctx.Process(target=child, args=(str(tmp_path / "out.npy"),))
    proc.start()
    proc.join(20)
    alive = proc.is_alive()
    if alive:
        proc.kill()
    assert not alive and proc.exitcode == 0
    assert (np.load(tmp_path / "out.npy") == 1.0).all()
