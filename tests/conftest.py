"""Shared fixtures: the shipped configs, each solved at most once per test session."""
import functools
import pathlib

import pytest

import linkpipe

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
