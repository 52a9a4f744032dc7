"""Names enter Rerun entity paths through Rerun's own escaping: distinct names stay distinct,
slashes, spaces and backslashes do not break paths, and the recording reads back."""
import pathlib
import subprocess
import sys

import rerun as rr
from rerun.chunk import RrdReader

import linkpipe
from linkpipe.stores import rrd

ROOT = pathlib.Path(__file__).resolve().parents[2]
HOSTILE = {"crank": "crank", "coupler": "crank/", "rocker": "a b\\c"}


def _scene(tmp_path):
    text = (ROOT / "configs" / "fourbar_crank_rocker.toml").read_text()
    for old, new in HOSTILE.items():
        text = text.replace(f'name = "{old}"\npoints', f'name = "{new}"\npoints'.replace("\\", "\\\\"))
    path = tmp_path / "hostile.toml"
    path.write_text(text)
    return path


def test_hostile_link_names_each_get_their_own_entity(tmp_path):
    scene = linkpipe.load_scene(str(_scene(tmp_path)))
    assert [link.name for link in scene.links] == ["crank", "crank/", "a b\\c"]
    result = linkpipe.solve(scene)
    out = tmp_path / "hostile.rrd"
    rrd.write(result, out)
    store = RrdReader(out).stream().collect()
    paths = {col.entity_path for col in store.schema().component_columns()}
    links = sorted(p for p in paths if p.startswith("/mechanism/links/"))
    want = sorted("/" + rr.new_entity_path(["mechanism", "links", n]).lstrip("/") for n in HOSTILE.values())
    assert links == want and len(set(links)) == 3
    plots = {p for p in paths if p.startswith("/plots/link_angle/")}
    assert len(plots) == 3
    verify = subprocess.run([str(pathlib.Path(sys.executable).with_name("rerun")), "rrd", "verify",
                             str(out)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr
