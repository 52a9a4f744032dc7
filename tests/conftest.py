"""Shared fixtures: the shipped configs, each solved at most once per test session.

Stage 1's compiled loops are taken only where a test asks for them (``LINKPIPE_COMPILED=1``
in its environment, or ``compiled=True``): which path a test runs does not depend on what ran
before it in its worker (a process that has loaded them takes them from 100k steps). Run the
suite with ``LINKPIPE_COMPILED=1`` to put every test on them; the numbers are the same."""
import functools
import os
import pathlib

import pytest

import linkpipe

os.environ.setdefault("LINKPIPE_COMPILED", "0")

CONFIG_DIR = pathlib.Path(__file__).resolve().parent.parent / "configs"
CONFIGS = sorted(CONFIG_DIR.glob("*.toml"))


@functools.cache
def _solved(name: str) -> linkpipe.Result:
    return linkpipe.solve(str(CONFIG_DIR / f"{name}.toml"))


@pytest.fixture(scope="session")
def solve():
    """``solve(name)``: the Result of ``configs/<name>.toml``, cached (do not mutate it)."""
    return _solved


@pytest.fixture(params=[p.stem for p in CONFIGS])
def result(request, solve) -> linkpipe.Result:
    """The Result of each TOML file in ``configs/``."""
    return solve(request.param)
