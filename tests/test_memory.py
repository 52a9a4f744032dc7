"""The memory estimate ``run`` and ``check`` refuse a sweep by (memory.memory_needed): it
counts every array a Result stores, so it can never be below what the run keeps. Peaks of whole
runs against it: benchmarks/bench_memory.py (1.8-1.9x at 1-2M steps, 2026-11-24)."""
import pathlib

import pytest

import linkpipe
from linkpipe.memory import bytes_per_step

CONFIGS = pathlib.Path(__file__).parent.parent / "configs"
SCENES = sorted(p.relative_to(CONFIGS).with_suffix("").as_posix()
                for p in list(CONFIGS.glob("*.toml")) + list(CONFIGS.glob("hard/*.toml"))
                + list(CONFIGS.glob("logged/*.toml")))


def stored_bytes(result) -> int:
    """Every per-step array the Result holds (its variables, as written to the .h5)."""
    return sum(v.data.nbytes for v in result.variables() if v.dims[:1] == ("step",))


@pytest.mark.parametrize("name", SCENES)
def test_the_estimate_counts_at_least_what_a_run_stores(name):
    scene = linkpipe.load_scene(CONFIGS / f"{name}.toml")
    result = linkpipe.solve(scene)
    assert bytes_per_step(scene) * scene.n_steps >= stored_bytes(result)


def test_the_estimate_is_not_a_blanket_bound():
    """Per step the estimate is the stored arrays plus what stage 1 hands the force stage (the
    influence coefficients, the driver values in internal units): within 2x of the stored
    bytes on a scene with every effect (the old estimate was 9x)."""
    scene = linkpipe.load_scene(CONFIGS / "basketball_goal.toml")
    result = linkpipe.solve(scene)
    ratio = bytes_per_step(scene) * scene.n_steps / stored_bytes(result)
    assert 1.0 <= ratio < 2.0


def test_a_small_scene_is_not_refused_on_a_machine_with_little_memory_free(monkeypatch):
    """What the steps need is what is compared with the memory free: the estimate's fixed
    part (the libraries, already loaded) is no reason to refuse a 9-step scene; a sweep whose
    steps alone need more is refused with the scene's error."""
    import linkpipe.memory as memory
    from linkpipe.errors import MemoryRefused

    monkeypatch.setattr(memory, "available_memory", lambda: 50 * 2**20)
    assert linkpipe.solve(CONFIGS / "shear_press.toml").n_ok == 9
    text = (CONFIGS / "fourbar_crank_rocker.toml").read_text().replace("steps = 361", "steps = 1000000")
    with pytest.raises(MemoryRefused, match="steps of 5 points need about"):
        linkpipe.solve(linkpipe.scene.parse_scene(text, "big.toml"))
