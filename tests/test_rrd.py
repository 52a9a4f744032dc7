"""The Rerun store against the output contract: write real .rrd files, read them back."""
import contextlib
import dataclasses
import os
import pathlib
import re
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from rerun.chunk import RrdReader

from linkpipe import solve as solve_scene
from linkpipe.stores import hdf5, rrd

RERUN = pathlib.Path(sys.executable).with_name("rerun")
ROOT = pathlib.Path(__file__).resolve().parent.parent
ARCHETYPE = {"links": "LineStrips2D", "guides": "LineStrips2D", "trace": "LineStrips2D",
             "springs": "LineStrips2D", "points": "Points2D", "ground": "Points2D",
             "velocity": "Arrows2D", "acceleration": "Arrows2D", "forces": "Arrows2D",
             "actuators": "LineStrips2D", "legend": "Arrows2D"}


class Recording:
    """A written .rrd read back: entity paths, archetypes, and one row per step (pandas)."""

    def __init__(self, path):
        reader = RrdReader(path)
        self.reader = reader
        self.blueprints = reader.blueprints()
        self.store = reader.store().stream().collect()
        columns = self.store.schema().component_columns()
        self.archetypes = {}
        for col in columns:
            if col.is_property:      # /__properties: the recording's name and start time
                continue
            self.archetypes.setdefault(col.entity_path, set()).add(col.archetype.rsplit(".", 1)[-1])
        self.entities = set(self.archetypes) - {"/mechanism"}   # its Transform3D flips y up

    def steps(self, entity):
        """Return the pandas frame of ``entity`` on the ``step`` timeline (static columns too)."""
        return self.store.reader(index="step", contents=entity).to_pandas()

    def _named(self, contents: str, kind: str):
        """(the blueprint's frame of ``contents``, [(path, display name)] of each ``kind``
        ("ViewBlueprint", "ContainerBlueprint") that has one)."""
        (entry,) = self.blueprints
        store = self.reader.store(store=entry).stream().collect()
        frame = _frame(store.reader(index="blueprint", contents=contents))
        named = [(col.split(":", 1)[0], str(name)) for col in frame.columns
                 if col.endswith(f":{kind}:display_name")
                 for (name,) in [[n for v in frame[col].dropna() for n in v]]]  # one each
        return frame, named

    def view_titles(self) -> set[str]:
        """The display names of the embedded blueprint's views."""
        return {name for _, name in self._named("/view/**", "ViewBlueprint")[1]}

    def views(self) -> dict[str, list[str]]:
        """{display name: the view's contents queries} of the embedded blueprint."""
        frame, named = self._named("/view/**", "ViewBlueprint")
        return {name: [str(q) for v in frame[f"{view}/ViewContents:ViewContents:query"].dropna()
                       for q in v] for view, name in named}

    def legends(self) -> dict[str, bool]:
        """{display name: whether its plot legend is visible} of the embedded blueprint's
        views that set one (a legend set only by its corner is visible)."""
        frame, named = self._named("/view/**", "ViewBlueprint")
        out = {}
        for view, name in named:
            corner = f"{view}/PlotLegend:PlotLegend:corner"
            visible = f"{view}/PlotLegend:PlotLegend:visible"
            if visible in frame.columns:
                out[name] = bool([x for v in frame[visible].dropna() for x in v][0])
            elif corner in frame.columns:
                out[name] = True
        return out

    def containers(self) -> dict[str, dict[str, object]]:
        """{display name: {component: value}} of the embedded blueprint's named containers
        (``container_kind``, ``grid_columns``, ...)."""
        frame, named = self._named("/container/**", "ContainerBlueprint")
        return {name: {c.rsplit(":", 1)[1]: [x for v in frame[c].dropna() for x in v]
                       for c in frame.columns if c.startswith(f"{path}:")}
                for path, name in named}

    def static(self, entity, component):
        return self.store.reader(index=None, contents=entity).to_pandas()[f"{entity}:{component}"][0]


def _frame(reader):
    """A blueprint's rows as pandas, without the columns pandas cannot hold (a plot's x-axis
    range is an Arrow union)."""
    table = reader.to_arrow_table()
    keep = [c for c, f in zip(table.column_names, table.schema) if "union" not in str(f.type)]
    return table.select(keep).to_pandas()


def _column(frame, entity, component):
    return frame[f"{entity}:{component}"]


def _area(xy) -> float:
    x, y = np.asarray(xy, float).T
    return 0.5 * float(x @ np.roll(y, -1) - y @ np.roll(x, -1))


def _write(result, folder):
    folder.mkdir(exist_ok=True)
    path = folder / f"{result.scene.name}.rrd"
    rrd.write(result, path)
    assert sorted(os.listdir(folder)) == [path.name]   # no temporary file left behind
    verify = subprocess.run([str(RERUN), "rrd", "verify", str(path)], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    return path


def _expected_entities(result) -> set[str]:
    """The contract's entity paths for what this scene computed."""
    sc = result.scene
    out = {"/mechanism/points", "/solver/residual", "/solver/iterations"}
    out |= {"/solver/log10_residual", "/solver/log10_tolerance"}   # additions: readable scale
    out |= {"/mechanism/ground"} if any(p.fixed for p in sc.points) else set()
    out |= {f"/mechanism/links/{link}" for link in result.link_names}
    out |= {f"/plots/link_angle/{link}" for link in result.link_names}
    out |= {f"/plots/link_angle_deg/{link}" for link in result.link_names}   # addition: degrees
    out |= {f"/mechanism/guides/{s.name}" for s in sc.sliders}
    out |= {f"/mechanism/trace/{p}" for p in sc.outputs.trace}
    for quantity in ("velocity", "acceleration"):
        if getattr(result, quantity) is not None:
            out |= {f"/mechanism/{quantity}/{p}" for p in sc.outputs.vectors}
    forces = result.forces or {}
    if "input_force" in forces:
        out |= {f"/plots/input_force/{d}" for d in result.driver_names}
    if "spring_force" in forces:
        out |= {f"/plots/spring_force/{s}" for s in result.spring_names}
        out |= {f"/mechanism/springs/{s}" for s in result.spring_names}   # an addition
    if "torsion_spring_torque" in forces:
        out |= {f"/plots/torsion_spring_torque/{t}" for t in result.force_coords["torsion_spring"]}
    out |= {f"/mechanism/actuators/{d.name}" for d in sc.drivers if d.kind == "distance"}  # addition
    for m in sc.measurements:
        out |= {f"/plots/measurements/{m.name}/computed", f"/plots/measurements/{m.name}/measured"}
    if "input_force" in forces:  # force arrows: only where forces are computed
        out |= {f"/mechanism/forces/input/{d}" for d in result.driver_names}
        out |= {f"/mechanism/forces/input/{d.name}/reaction" for d in sc.drivers
                if d.relative_to is not None and (d.bodies or ("", ""))[1] != "ground"}
        if "loads" in sc.effects:
            out |= {f"/mechanism/forces/loads/{x.name}" for x in sc.loads if x.point is not None}
        if "gravity" in sc.effects:
            out |= {f"/mechanism/forces/weights/{m.link}" for m in sc.masses}
        out |= {f"/mechanism/forces/springs/{s}" for s in result.spring_names if sc.springs}
        out |= {f"/mechanism/forces/reactions/{p}" for p in result.force_coords.get("fixed_point", [])}
    if "friction_force" in forces:  # version 3: each entry plotted; seals and sliders drawn
        out |= {f"/plots/friction_force/{f.name}" for f in sc.friction}
        out |= {f"/mechanism/forces/friction/{f.name}" for f in sc.friction
                if f.kind == "slider" or (f.kind == "driver" and next(
                    d for d in sc.drivers if d.name == f.driver).kind == "distance")}
        if result.velocity is not None:  # a pin friction's couple: an arc arrow at each pin
            out |= {f"/mechanism/forces/friction/{f.name}/{j}" for f in sc.friction
                    if f.kind == "pins" for j in f.joints}
    if result.stroke_margin is not None:  # version 3: margins and the out-of-stroke markers
        from linkpipe.stroke import names

        out |= {f"/plots/stroke_margin/{n}" for n in names(sc)} | {"/plots/stroke_margin/out_of_stroke"}
    if "input_force" in forces or sc.outputs.vectors:   # addition: the arrows' legend
        out |= {"/mechanism/legend"}
    return out


def test_each_config_has_exactly_the_contract_entities(result, tmp_path):
    rec = Recording(_write(result, tmp_path))
    assert rec.entities == _expected_entities(result)
    for entity in rec.entities:
        kind = entity.split("/")[2] if entity.startswith("/mechanism/") else None
        expected = ARCHETYPE.get(kind, "Scalars")
        assert expected in rec.archetypes[entity], entity
    assert len(rec.blueprints) == 1


def test_shipped_scenes_in_particular(solve, tmp_path):
    press = Recording(_write(solve("shear_press"), tmp_path / "press"))
    assert "/mechanism/guides/blade_guide" in press.entities
    assert not {e for e in press.entities if "velocity" in e or "acceleration" in e}
    assert "/plots/input_force/handle" in press.entities
    goal = Recording(_write(solve("basketball_goal"), tmp_path / "goal"))
    assert {"/plots/spring_force/left", "/plots/spring_force/right", "/plots/input_force/theta3a",
            "/mechanism/velocity/C", "/mechanism/acceleration/C"} <= goal.entities
    rocker = Recording(_write(solve("fourbar_crank_rocker"), tmp_path / "rocker"))
    assert not {e for e in rocker.entities if e.startswith(("/plots/input_force", "/plots/spring_force"))}


def test_values_match_the_result_and_the_hdf5_file(solve, tmp_path):
    result = solve("fourbar_crank_rocker")
    rec = Recording(_write(result, tmp_path))
    h5 = tmp_path / "r.h5"
    hdf5.write(result, h5)
    with h5py.File(h5, "r") as f:
        position = f["position"][:]
    S = result.n_steps

    points = rec.steps("/mechanism/points")
    np.testing.assert_array_equal(points["step"], np.arange(S))
    got = np.array([np.stack(row) for row in _column(points, "/mechanism/points", "Points2D:positions")])
    assert got.shape == position.shape
    np.testing.assert_allclose(got, position, rtol=1e-6, atol=1e-6)      # rerun stores float32
    labels = _column(points, "/mechanism/points", "Points2D:labels")
    assert all(list(row) == list(result.point_names) for row in labels)
    nanoseconds = points["time"].to_numpy().astype("timedelta64[ns]").astype(np.int64)
    # the instants to the nearest nanosecond (rerun's float conversion truncated: 1 ns short)
    np.testing.assert_array_equal(nanoseconds, np.round(result.time * 1e9).astype(np.int64))

    iterations = rec.steps("/solver/iterations")
    np.testing.assert_array_equal(iterations["step"], np.arange(S))
    got = np.concatenate(_column(iterations, "/solver/iterations", "Scalars:scalars").to_list())
    np.testing.assert_array_equal(got, result.iterations)

    # the coupler's outline is its triangle, closed and counter-clockwise; the crank's is its
    # two points
    i = {n: k for k, n in enumerate(result.point_names)}
    coupler = rec.steps("/mechanism/links/coupler")
    strips = _column(coupler, "/mechanism/links/coupler", "LineStrips2D:strips")
    step = 100
    (strip,) = strips[step]
    k = rrd.outline(result, [i["A"], i["B"], i["P"]])
    assert sorted(k[:3]) == sorted([i["A"], i["B"], i["P"]]) and k[3] == k[0]
    np.testing.assert_array_equal(np.stack(strip), position[step, k].astype(np.float32))
    assert _area(np.stack(strip)[:-1]) > 0

    # arrows: scaled so the longest is 25 % of the mechanism's size; the label names the scale
    scale = rrd.arrow_scales(result)["velocity"]
    arrows = rec.steps("/mechanism/velocity/P")
    vectors = np.array([np.stack(r)[0] for r in _column(arrows, "/mechanism/velocity/P", "Arrows2D:vectors")])
    np.testing.assert_allclose(vectors / scale, result.velocity[:, i["P"]], rtol=1e-5, atol=1e-5)
    lengths = np.hypot(*result.velocity[:, [i["P"], i["B"]]].reshape(-1, 2).T) * scale
    assert lengths.max() == pytest.approx(0.25 * rrd.mechanism_size(result))
    (label,) = rec.static("/mechanism/velocity/P", "Arrows2D:labels")
    assert f"1 m = {1 / scale:.3g} m/s" in label
    # labels of arrows at one point would overlap: stored (hover), not drawn; the legend gives
    # both scales as bars of their true length ("velocity 5 m/s")
    assert not rec.static("/mechanism/velocity/P", "Arrows2D:show_labels")
    accel = rrd.arrow_scales(result)["acceleration"]
    labels = list(rec.static("/mechanism/legend", "Arrows2D:labels"))
    bars = np.stack(rec.static("/mechanism/legend", "Arrows2D:vectors"))
    for quantity, unit, s in (("velocity", "m/s", scale), ("acceleration", "m/s^2", accel)):
        (k,) = [k for k, label in enumerate(labels) if label.startswith(quantity)]
        value = float(labels[k].split()[1].replace(",", ""))
        assert labels[k] == f"{quantity} {value:,.6g} {unit}"
        assert bars[k][0] == pytest.approx(value * s, rel=1e-6) and bars[k][1] == 0
    titles = rec.view_titles()
    assert {"fourbar_crank_rocker (y up)", "link angle [deg]", "log10 residual [m]",
            "residual [m]", "iterations [1]"} <= titles

    # the traced coupler curve is one static strip through every step
    (trace,) = rec.static("/mechanism/trace/P", "LineStrips2D:strips")
    np.testing.assert_allclose(np.stack(trace), position[:, i["P"]], rtol=1e-6, atol=1e-6)


def test_log10_residual_beside_the_tolerance(solve, tmp_path):
    """The viewer labels no axis below ~1e-13: the residual is also plotted as its log10, beside
    log10(tol x size); an exact zero sits one decade below rounding level, NaN stays NaN."""
    base = solve("fourbar_crank_rocker")
    residual = base.residual.copy()
    residual[:4] = [0.0, np.nan, 2.5e-3, np.inf]  # inf: a failed step's least-squares residual
    result = dataclasses.replace(base, residual=residual)
    rec = Recording(_write(result, tmp_path))
    size = base.model.size
    frame = rec.steps("/solver/log10_residual")
    got = np.concatenate(_column(frame, "/solver/log10_residual", "Scalars:scalars").to_list())
    floor = np.log10(np.finfo(float).eps * size) - 1
    assert got[0] == pytest.approx(floor)
    assert np.isnan(got[1]) and got[2] == pytest.approx(np.log10(2.5e-3))
    assert np.isnan(got[3])  # +-inf is sent as NaN (a gap), never as an infinite value
    raw = np.concatenate(_column(rec.steps("/solver/residual"), "/solver/residual",
                                 "Scalars:scalars").to_list())
    assert np.isnan(raw[3]) and raw[2] == 2.5e-3
    rest = residual[4:]
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(got[4:], np.where(rest == 0, floor, np.log10(rest)), rtol=1e-12)
    assert (got[4:] < np.log10(1e-14 * size)).all()   # the dyads: rounding level
    frame = rec.steps("/solver/log10_tolerance")
    tol = np.concatenate(_column(frame, "/solver/log10_tolerance", "Scalars:scalars").to_list())
    np.testing.assert_allclose(tol, np.log10(base.scene.solver.tol * size), rtol=1e-12)
    assert len(tol) == base.n_steps


def test_nan_steps_are_cleared_not_fatal(solve, tmp_path):
    base = solve("fourbar_crank_rocker")
    moving = [k for k, p in enumerate(base.scene.points) if not p.fixed]
    position = base.position.copy()
    velocity = base.velocity.copy()
    position[10:20, moving] = np.nan
    velocity[10:20, moving] = np.nan
    result = dataclasses.replace(base, position=position, velocity=velocity)
    rec = Recording(_write(result, tmp_path))

    points = _column(rec.steps("/mechanism/points"), "/mechanism/points", "Points2D:positions")
    counts = np.array([len(row) for row in points])
    assert (counts[10:20] == len(base.point_names) - len(moving)).all()
    assert (np.delete(counts, range(10, 20)) == len(base.point_names)).all()
    strips = _column(rec.steps("/mechanism/links/crank"), "/mechanism/links/crank", "LineStrips2D:strips")
    assert [len(s) for s in strips] == [1] * 10 + [0] * 10 + [1] * (base.n_steps - 20)
    trace = rec.static("/mechanism/trace/P", "LineStrips2D:strips")
    assert [len(run) for run in trace] == [10, base.n_steps - 20]      # split at the gap
    got = _column(rec.steps("/solver/iterations"), "/solver/iterations", "Scalars:scalars")
    np.testing.assert_array_equal(np.concatenate(got.to_list()), base.iterations)
    # plotted series keep a row at every step, NaN where the step failed: the viewer breaks
    # the line there instead of bridging the gap with a straight segment
    link_angle = base.link_angle.copy()
    link_angle[10:20] = np.nan
    result = dataclasses.replace(result, link_angle=link_angle)
    rec = Recording(_write(result, tmp_path / "again"))
    frame = rec.steps("/plots/link_angle/coupler")
    np.testing.assert_array_equal(frame["step"], np.arange(base.n_steps))
    got = np.concatenate(_column(frame, "/plots/link_angle/coupler", "Scalars:scalars").to_list())
    coupler = base.link_names.index("coupler")
    np.testing.assert_array_equal(got, result.link_angle[:, coupler].astype(got.dtype))
    assert np.isnan(got[10:20]).all() and np.isfinite(np.delete(got, range(10, 20))).all()


MOVING_GUIDE = """
[scene]
name = "inverted_slider"
units = { length = "m", mass = "kg", time = "s", force = "N" }

[points]
O2 = { x = 0.0, y = 2.0, fixed = true }
A  = { x = 1.0, y = 2.0 }
O4 = { x = 0.0, y = 0.0, fixed = true }
D  = { x = 1.5, y = 3.0 }

[[links]]
name = "crank"
points = ["O2", "A"]

[[links]]
name = "rocker"
points = ["O4", "D"]

[[sliders]]
name = "slot"
point = "A"
along = ["O4", "D"]

[[drivers]]
name = "crank"
angle = ["O2", "A"]
from = 0.0
to = 360.0
steps = 37
"""


def test_friction_and_stroke_in_the_recording(tmp_path):
    """Version 3: friction plotted per entry (a torque for pins, a force for a seal) with the
    stored values, seal friction drawn on the cylinder's pins in its own colour, the stroke
    margin plotted and the steps outside the stroke marked at their margin."""
    from linkpipe.scene.parse import parse_scene

    text = (ROOT / "configs/logged/dump_truck_friction.toml").read_text()
    text = text.replace("stroke = [1.30, 5.25]", "stroke = [1.30, 5.0]")
    result = solve_scene(parse_scene(text, str(ROOT / "configs/logged/dump_truck_friction.toml")))
    rec = Recording(_write(result, tmp_path))
    assert rec.entities == _expected_entities(result)
    seal = rec.steps("/plots/friction_force/seal")
    assert np.allclose(np.concatenate(_column(seal, "/plots/friction_force/seal",
                                              "Scalars:scalars").to_numpy()),
                       result.forces["friction_force"][1][:, 0])
    colours = rec.static("/mechanism/forces/friction/seal", "Arrows2D:colors")
    inputs = rec.static("/mechanism/forces/input/tipping_cylinder", "Arrows2D:colors")
    assert list(colours) != list(inputs)
    # the hinge pin's friction couple: an arc arrow in friction's hue, on a circle about H
    hinge = "/mechanism/forces/friction/hinge/H"
    assert list(rec.static(hinge, "LineStrips2D:colors")) == list(colours)
    from linkpipe.stores.rrd.forces import COUPLE_RADIUS, COUPLE_SWEEP, COUPLE_LEAST
    from linkpipe.stores.rrd.geometry import mechanism_size
    rho = COUPLE_RADIUS * mechanism_size(result)      # float32 in the file: 1e-6 of the size
    torque = result.forces["friction_force"][1][:, 1]
    frame = rec.steps(hinge)
    H = result.position[:, result.point_names.index("H")]
    for step, strips in zip(frame["step"], _column(frame, hinge, "LineStrips2D:strips")):
        arc = np.stack(strips[0])[:24]
        assert np.allclose(np.hypot(*(arc - H[step]).T), rho, atol=1e-5 * rho)
        turned = np.arctan2(*(arc[-1] - H[step])[::-1]) - np.pi / 2   # started at the top
        want = max(COUPLE_SWEEP * abs(torque[step]) / np.abs(torque).max(), COUPLE_LEAST)
        assert np.isclose(abs((turned + np.pi) % (2 * np.pi) - np.pi)
                          if want <= np.pi else 2 * np.pi - abs((turned + np.pi) % (2 * np.pi) - np.pi),
                          want, atol=1e-4)
    marks = rec.steps("/plots/stroke_margin/out_of_stroke")
    values = np.array([v[0] if v is not None and len(v) else np.nan for v in _column(
        marks, "/plots/stroke_margin/out_of_stroke", "Scalars:scalars")], float)
    outside = result.status == 7
    assert outside.any() and (~outside).any()
    assert np.allclose(values[outside], result.stroke_margin[outside, 0])
    assert np.isnan(values[~outside]).all()


def test_a_moving_guide_is_logged_per_step(tmp_path):
    scene = tmp_path / "inverted_slider.toml"
    scene.write_text(MOVING_GUIDE)
    result = solve_scene(str(scene))
    rec = Recording(_write(result, tmp_path / "out"))
    assert "/mechanism/guides/slot" in rec.entities
    frame = rec.steps("/mechanism/guides/slot")
    np.testing.assert_array_equal(frame["step"], np.arange(37))
    assert "time" not in frame or frame["time"].isna().all()             # no rate: no time
    i = {n: k for k, n in enumerate(result.point_names)}
    for step, (strip,) in enumerate(_column(frame, "/mechanism/guides/slot", "LineStrips2D:strips")):
        a, b = np.stack(strip)
        for name in ("O4", "D", "A"):             # the segment lies on the line and covers them
            p = result.position[step, i[name]]
            t = np.dot(p - a, b - a) / np.dot(b - a, b - a)
            assert 0 < t < 1
            np.testing.assert_allclose(a + t * (b - a), p, atol=1e-5)


def test_a_crash_mid_write_keeps_the_previous_recording(solve, tmp_path, monkeypatch):
    result = solve("shear_press")
    path = _write(result, tmp_path)
    before = path.read_bytes()

    def failing(*args):
        raise RuntimeError("viewer on fire")

    monkeypatch.setattr(rrd.series, "log_series", failing)
    with pytest.raises(RuntimeError, match="viewer on fire"):
        rrd.write(result, path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == [path.name]


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextlib.contextmanager
def saving_rerun_server(saved):
    """A real Rerun gRPC server (the rerun binary itself) saving what it receives to ``saved``,
    listening when this yields its port; ended (with its own children) at the exit, once the
    file has stopped growing."""
    import socket

    port = _free_port()
    # its own process group: the rerun launcher may leave the server as a child of its own,
    # which must go too (it outlived the test when only the launcher was terminated)
    server = subprocess.Popen([str(RERUN), "--port", str(port), "--save", str(saved)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        deadline = time.monotonic() + 30
        while True:  # wait until the server listens
            with socket.socket() as sock:
                if sock.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert time.monotonic() < deadline, "the rerun server did not start"
            time.sleep(0.1)
        yield port
        size = -1
        while saved.exists() and saved.stat().st_size != size:  # until the server has it all
            size = saved.stat().st_size
            time.sleep(0.5)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=30)


def _stream_entities(path) -> dict:
    """Entity path -> archetypes of a streamed .rrd (no footer: read eagerly, not lazily)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "RRD file has no footer/manifest": expected here
        store = RrdReader(path).stream().collect()
    out = {}
    for col in store.schema().component_columns():
        out.setdefault(col.entity_path, set()).add(col.archetype)
    return out


def test_connect_streams_the_recording_to_a_running_viewer(tmp_path):
    """`run --connect ADDR` streams to a running Rerun server (here the rerun binary itself,
    listening and saving what it receives): it gets every entity the written file has."""
    from linkpipe.__main__ import main
    from conftest import CONFIG_DIR

    saved = tmp_path / "streamed.rrd"
    out = tmp_path / "out"
    with saving_rerun_server(saved) as port:
        assert main(["run", str(CONFIG_DIR / "fourbar_crank_rocker.toml"), "--out", str(out),
                     "--no-h5", "--quiet", "--connect", f"rerun+http://127.0.0.1:{port}/proxy"]) == 0
    written = _stream_entities(out / "fourbar_crank_rocker.rrd")
    streamed = _stream_entities(saved)
    assert "/mechanism/points" in streamed and "/solver/log10_residual" in streamed
    assert streamed == written


def test_connect_to_no_viewer_is_one_message_and_the_file_is_still_written(tmp_path, capsys):
    """Nothing listens at the address: one message naming it, exit 1 (an output not
    delivered), at once (no 6 s of rerun's retries and log lines), the .h5 and .rrd written
    and complete; a malformed address is the user's mistake, exit 2, before any work."""
    from linkpipe.__main__ import main
    from conftest import CONFIG_DIR

    port = _free_port()  # free: nobody listens there
    out = tmp_path / "out"
    t0 = time.monotonic()
    code = main(["run", str(CONFIG_DIR / "fourbar_crank_rocker.toml"), "--out", str(out),
                 "--quiet", "--connect", f"rerun+http://127.0.0.1:{port}/proxy"])
    assert code == 1 and time.monotonic() - t0 < 5.0
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    assert f"no viewer listens at 127.0.0.1:{port}" in err and "fourbar_crank_rocker.rrd is written" in err
    assert sorted(p.name for p in out.iterdir()) == ["fourbar_crank_rocker.h5",
                                                     "fourbar_crank_rocker.rrd"]
    verify = subprocess.run([str(RERUN), "rrd", "verify", str(out / "fourbar_crank_rocker.rrd")],
                            capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    for bad in ("rerun+http://127.0.0.1:98x/proxy", "127.0.0.1:9876"):
        with pytest.raises(SystemExit) as stop:  # argparse: usage and one error line
            main(["run", str(CONFIG_DIR / "fourbar_crank_rocker.toml"), "--out",
                  str(tmp_path / "b"), "--connect", bad])
        assert stop.value.code == 2 and not (tmp_path / "b").exists()
        assert "rerun+http://127.0.0.1:9876/proxy" in capsys.readouterr().err


# -- forces, plates, colours, the driver's timeline (issue 13, item 5) ----------------------------


def _arrows(rec, entity):
    """(origins, vectors) (S, k, 2) float32 of an Arrows2D entity at every step, as logged."""
    frame = rec.steps(entity)
    np.testing.assert_array_equal(frame["step"], np.arange(len(frame)))
    origins = np.array([np.stack(r) for r in _column(frame, entity, "Arrows2D:origins")])
    vectors = np.array([np.stack(r) for r in _column(frame, entity, "Arrows2D:vectors")])
    return origins, vectors


def _f32(a):
    return np.asarray(a, dtype=np.float32)


def _unit(d):
    return d / np.hypot(d[:, 0], d[:, 1])[:, None]


def _drawn(result, at, force, scale, outward=False):
    """The arrows the recording should draw for forces ``force`` (S, k, 2) acting at ``at``
    (S, k, 2): the force times the scale, at least MIN_FRACTION of the size long where it is
    not zero (issue 34: a 2.7 lbf spring force at 1 ft = 100 lbf was an invisible dot); with
    ``outward`` (the ground reactions at fixed point ``outward``) an arrow pointing towards the
    point's neighbours (the other points of its links and the other fixed points: the unit
    vectors to them summed) ends at its point. Returns (origins, vectors, short), float32."""
    at, v = np.asarray(at, float), np.asarray(force, float) * scale
    least = rrd.MIN_FRACTION * rrd.mechanism_size(result)
    length = np.hypot(v[..., 0], v[..., 1])
    short = (length > 0) & (length < least)
    v = np.where(short[..., None], v / np.where(short, length, 1.0)[..., None] * least, v)
    if outward:
        sc, X = result.scene, result.position
        names = [p.name for p in sc.points]
        k = names.index(outward)
        near = {p for ln in sc.links if outward in ln.points for p in ln.points}
        near |= {p.name for p in sc.points if p.fixed}
        towards = np.zeros((len(X), 2))
        for p in near - {outward}:
            d = X[:, names.index(p)] - X[:, k]
            towards += d / np.hypot(d[:, 0], d[:, 1])[:, None]
        inward = np.einsum("skc,sc->sk", v, towards) > 0
        at = np.where(inward[..., None], at - v, at)
    return _f32(at), _f32(v), short


def test_force_arrows_are_the_stored_forces_times_one_scale_where_they_act(solve, tmp_path):
    """The basketball goal (springs, gravity, inertia, a handle input): at every step each arrow
    starts at the stored point and is the stored force times the one scale (float32: exact)."""
    result = solve("basketball_goal")
    rec = Recording(_write(result, tmp_path))
    arrows, scale = rrd.force_arrows(result)
    X, F = result.position, result.forces
    i = {n: k for k, n in enumerate(result.point_names)}
    # the handle's input force at its point, along its direction
    (driver,) = result.scene.drivers
    n = np.asarray(driver.input.direction, float) / np.hypot(*driver.input.direction)
    close = dict(rtol=2e-6, atol=2e-6 * rrd.mechanism_size(result))   # float32
    origins, vectors = _arrows(rec, f"/mechanism/forces/input/{driver.name}")
    o, v, _ = _drawn(result, X[:, [i[driver.input.point]]], F["input_force"][1][:, :1, None] * n, scale)
    np.testing.assert_allclose(origins, o, **close)
    np.testing.assert_allclose(vectors, v, **close)
    # each spring's force on both ends: a tension pulls them together; 0.3 .. 2.7 lbf at
    # 1 ft = 100 lbf: drawn at the least length, labelled with its value once (at its first
    # end); the right spring lies on the left one (same points): one label says both
    left, right = result.scene.springs
    assert left.between == right.between
    frame = rec.steps("/mechanism/forces/springs/left")
    labels = _column(frame, "/mechanism/forces/springs/left", "Arrows2D:labels")
    tension = F["spring_force"][1][:, 0]
    assert [list(r) for r in labels] == [[f"left = right {abs(t):.3g} lbf", ""] for t in tension]
    assert list(rec.static("/mechanism/forces/springs/right", "Arrows2D:labels")) == ["right"]
    assert not rec.static("/mechanism/forces/springs/right", "Arrows2D:show_labels")
    for k, spring in enumerate(result.scene.springs):
        a, b = (X[:, i[p]] for p in spring.between)
        pull = F["spring_force"][1][:, k, None] * _unit(b - a)
        origins, vectors = _arrows(rec, f"/mechanism/forces/springs/{spring.name}")
        o, v, short = _drawn(result, np.stack([a, b], axis=1), np.stack([pull, -pull], axis=1), scale)
        assert short.all()
        np.testing.assert_allclose(origins, o, **close)
        np.testing.assert_allclose(vectors, v, **close)
    # the ground's reaction at each fixed point, drawn from its point outward (one pointing
    # into the mechanism ends at its point)
    ends = {}
    for k, name in enumerate(result.force_coords["fixed_point"]):
        origins, vectors = _arrows(rec, f"/mechanism/forces/reactions/{name}")
        o, v, _ = _drawn(result, X[:, [i[name]]], F["ground_reaction"][1][:, k, None], scale, name)
        np.testing.assert_allclose(origins, o, **close)
        np.testing.assert_allclose(vectors, v, **close)
        ends[name] = np.allclose(origins[:, 0] + vectors[:, 0], X[:, i[name]], atol=close["atol"])
    # O4 and O2 on the pole: their upward reactions end at them from below instead of running
    # up the pole through O2 and S1 (issue 34)
    assert ends["O4"] and ends["O2"]
    # each weight m g at its centre (the backboard's centre is its point G)
    g = np.asarray(result.scene.gravity)
    for mass in result.scene.masses:
        origins, vectors = _arrows(rec, f"/mechanism/forces/weights/{mass.link}")
        if isinstance(mass.center, str):
            np.testing.assert_array_equal(origins[:, 0], _f32(X[:, i[mass.center]]))
        _, v, _ = _drawn(result, origins.astype(float), np.broadcast_to(mass.mass * g, origins.shape), scale)
        np.testing.assert_allclose(vectors, v, **close)
    # one scale: 1 ft stands for a round force; the longest arrow is at most 30 % of the
    # mechanism's size and at least half of that; the 2D view's title says it
    per = 1 / scale
    assert per / 10 ** np.floor(np.log10(per)) in (1.0, 2.0, 2.5, 5.0)
    longest = max(np.nanmax(np.hypot(v[..., 0], v[..., 1])) for *_, v in arrows) * scale
    size = rrd.mechanism_size(result)
    assert 0.15 * size <= longest <= 0.3 * size * (1 + 1e-12)
    # the legend names each kind in its colour and draws the scale as a bar of its true length
    labels = list(rec.static("/mechanism/legend", "Arrows2D:labels"))
    colours = [int(c) for c in rec.static("/mechanism/legend", "Arrows2D:colors")]
    bars = np.stack(rec.static("/mechanism/legend", "Arrows2D:vectors"))
    for kind in rrd.KINDS:
        if kind.name in ("input", "weights", "springs", "reactions"):
            k = labels.index(kind.legend)
            r, g_, b_ = kind.colour
            assert colours[k] == (r << 24) | (g_ << 16) | (b_ << 8) | 255
    (bar,) = [k for k, label in enumerate(labels) if label.endswith(" lbf")]
    force = float(labels[bar][:-4].replace(",", ""))
    assert bars[bar][0] * per == pytest.approx(force, rel=1e-6)
    assert force / 10 ** np.floor(np.log10(force)) in (1.0, 2.0, 2.5, 5.0)
    assert "basketball_goal (y up)" in rec.view_titles()
    # each item long enough is labelled with what it is, once (a spring's two arrows: at their
    # centre; here they are short: their values instead, above)
    assert list(rec.static("/mechanism/forces/input/theta3a", "Arrows2D:labels")) == ["theta3a"]


def test_cylinders_loads_and_weights_of_the_excavator(solve, tmp_path):
    """Each cylinder is drawn between its pins and its axial force pushes both pins apart when
    positive; the bucket load acts at its point; a kinematics step cleared clears its arrows."""
    base = solve("excavator_arm")
    input_force = base.forces["input_force"][1].copy()
    input_force[5] = np.nan                       # a step without an input force
    result = dataclasses.replace(base, forces={**base.forces, "input_force": (
        base.forces["input_force"][0], input_force, base.forces["input_force"][2])})
    rec = Recording(_write(result, tmp_path))
    _, scale = rrd.force_arrows(result)
    X = result.position
    i = {n: k for k, n in enumerate(result.point_names)}
    for j, driver in enumerate(result.scene.drivers):
        a, b = (X[:, i[p]] for p in driver.points)
        entity = f"/mechanism/actuators/{driver.name}"
        strips = _column(rec.steps(entity), entity, "LineStrips2D:strips")
        np.testing.assert_array_equal(np.stack(strips[10][0]), _f32(np.stack([a[10], b[10]])))
        frame = rec.steps(f"/mechanism/forces/input/{driver.name}")
        counts = [len(r) for r in _column(frame, f"/mechanism/forces/input/{driver.name}",
                                          "Arrows2D:vectors")]
        assert counts == [2] * 5 + [0] + [2] * (result.n_steps - 6)
        push = input_force[:, j, None] * _unit(b - a)
        keep = np.arange(result.n_steps) != 5
        frame = frame[keep]
        vectors = np.array([np.stack(r) for r in _column(frame, f"/mechanism/forces/input/{driver.name}",
                                                         "Arrows2D:vectors")])
        _, v, _ = _drawn(result, np.stack([a, b], axis=1)[keep], np.stack([-push, push], axis=1)[keep], scale)
        np.testing.assert_allclose(vectors, v, rtol=2e-6, atol=2e-6 * rrd.mechanism_size(result))
    (load,) = [ld for ld in result.scene.loads if ld.point is not None]
    origins, vectors = _arrows(rec, f"/mechanism/forces/loads/{load.name}")
    np.testing.assert_array_equal(origins[:, 0], _f32(X[:, i[load.point]]))
    _, v, _ = _drawn(result, origins.astype(float), np.broadcast_to(np.asarray(load.force, float),
                                                                     origins.shape), scale)
    np.testing.assert_allclose(vectors, v, rtol=2e-6, atol=2e-6 * rrd.mechanism_size(result))
    assert rec.entities == _expected_entities(result)


def test_an_angle_drivers_torque_is_drawn_as_the_force_at_its_arm(solve, tmp_path, monkeypatch):
    """Without an input point, an angle driver's torque is the force at the driven vector's
    head, perpendicular to it, whose moment about its tail is the torque (no least length
    here: each arrow is its force times the scale)."""
    monkeypatch.setattr(rrd.forces, "MIN_FRACTION", 0.0)
    result = dataclasses.replace(solve("hatch_gas_spring"))   # its own drawn arrows
    rec = Recording(_write(result, tmp_path))
    _, scale = rrd.force_arrows(result)
    (driver,) = result.scene.drivers
    i = {n: k for k, n in enumerate(result.point_names)}
    a, b = (result.position[:, i[p]] for p in driver.points)
    origins, vectors = _arrows(rec, f"/mechanism/forces/input/{driver.name}")
    np.testing.assert_array_equal(origins[:, 0], _f32(b))
    force = vectors[:, 0].astype(float) / scale
    arm = b - a
    torque = result.forces["input_force"][1][:, 0]
    np.testing.assert_allclose(arm[:, 0] * force[:, 1] - arm[:, 1] * force[:, 0], torque,
                               rtol=1e-6, atol=1e-6 * np.abs(torque).max())
    np.testing.assert_allclose(np.einsum("ij,ij->i", arm, force), 0, atol=1e-6 * np.abs(torque).max())


def test_a_kinematics_only_scene_draws_no_force(solve, tmp_path):
    result = solve("fourbar_crank_rocker")
    assert result.forces is None
    rec = Recording(_write(result, tmp_path))
    assert not {e for e in rec.entities if e.startswith("/mechanism/forces")}
    assert not any("forces" in t for t in rec.view_titles())
    assert rrd.force_arrows(result) == ([], 0.0)


def _crosses(strip) -> bool:
    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    edges = list(zip(strip[:-1], strip[1:]))
    for k, (a, b) in enumerate(edges):
        for c, d in edges[k + 2:len(edges) - (k == 0)]:
            if cross(a, b, c) * cross(a, b, d) < 0 and cross(c, d, a) * cross(c, d, b) < 0:
                return True
    return False


def test_plates_are_closed_polygons_that_do_not_cross(solve, tmp_path):
    """The excavator's boom lists O, T, BR, SC and its stick T, K, SR, BB, N out of outline
    order: each is drawn as the convex hull of its pins, closed, counter-clockwise, at every
    step, with every pin inside or on it. Three pins on one line (the goal's upper arm) are a
    segment between the extreme two."""
    result = solve("excavator_arm")
    rec = Recording(_write(result, tmp_path / "excavator"))
    i = {n: k for k, n in enumerate(result.point_names)}
    for link in result.scene.links:
        entity = f"/mechanism/links/{link.name}"
        strips = _column(rec.steps(entity), entity, "LineStrips2D:strips")
        for step in (0, result.n_steps // 2, result.n_steps - 1):
            (strip,) = strips[step]
            strip = np.stack(strip).astype(float)
            if len(link.points) == 2:
                assert len(strip) == 2
                continue
            np.testing.assert_array_equal(strip[0], strip[-1])              # closed
            assert _area(strip[:-1]) > 0 and not _crosses(strip)
            for p in link.points:                                            # covers its pins
                q = result.position[step, i[p]]
                edge = np.diff(strip, axis=0)
                side = edge[:, 0] * (q[1] - strip[:-1, 1]) - edge[:, 1] * (q[0] - strip[:-1, 0])
                assert (side >= -1e-5 * np.hypot(*edge.T)).all(), (link.name, p)
    boom = [result.point_names[k] for k in rrd.outline(result, [i[p] for p in ("O", "T", "BR", "SC")])]
    assert boom[0] == boom[-1] and sorted(boom[:-1]) == ["BR", "O", "SC", "T"]
    goal = solve("basketball_goal")
    j = {n: k for k, n in enumerate(goal.point_names)}
    upper = [goal.point_names[k] for k in rrd.outline(goal, [j[p] for p in ("O2", "B", "S2")])]
    assert sorted(upper) == ["B", "O2"]


def _rgba(colour) -> int:
    r, g, b = colour[:3]
    return (int(r) << 24) | (int(g) << 16) | (int(b) << 8) | 255


def test_each_series_of_a_plot_has_its_own_colour(solve, tmp_path):
    result = solve("excavator_arm")
    rec = Recording(_write(result, tmp_path))
    for plot in ("input_force", "link_angle"):
        colours = {e: int(rec.static(e, "SeriesLines:colors")[0]) for e in rec.entities
                   if e.startswith(f"/plots/{plot}/")}
        assert len(colours) >= 3 and len(set(colours.values())) == len(colours), plot
    # a link's angle is plotted in the link's colour
    for link in result.link_names:
        strip = int(rec.static(f"/mechanism/links/{link}", "LineStrips2D:colors")[0])
        assert int(rec.static(f"/plots/link_angle/{link}", "SeriesLines:colors")[0]) == strip
    residual = int(rec.static("/solver/log10_residual", "SeriesLines:colors")[0])
    assert residual != int(rec.static("/solver/log10_tolerance", "SeriesLines:colors")[0])
    many = [tuple(rrd.style.colour(j)) for j in range(40)]
    assert len(set(many)) == 40


def test_one_driver_sweeps_have_a_timeline_of_the_drivers_value(solve, tmp_path):
    """The crank-rocker's crank in whole degrees: timeline "crank [degree]"; the dump truck's
    cylinder length in metres: a decimal fraction of a metre; several drivers: none."""
    rocker = solve("fourbar_crank_rocker")
    rec = Recording(_write(rocker, tmp_path / "rocker"))
    frame = rec.store.reader(index="crank [degree]", contents="/plots/link_angle/rocker").to_pandas()
    np.testing.assert_array_equal(frame["crank [degree]"].to_numpy(),
                                  rocker.driver_value[:, 0].astype(np.int64))
    np.testing.assert_array_equal(frame["step"].to_numpy(), np.arange(rocker.n_steps))
    truck = solve("dump_truck")
    name, values = rrd.driver_timeline(truck)
    assert name.startswith("tipping_cylinder [0.") and name.endswith(" m]")
    per = 1 / float(name.split("[")[1].split()[0])
    np.testing.assert_array_equal(values, np.round(truck.driver_value[:, 0] * per).astype(np.int64))
    assert (np.diff(values) >= 10).all() or (np.diff(values) <= -10).all()
    rec = Recording(_write(truck, tmp_path / "truck"))
    frame = rec.store.reader(index=name, contents="/mechanism/points").to_pandas()
    np.testing.assert_array_equal(frame[name].to_numpy(), values)
    assert rrd.driver_timeline(solve("excavator_arm")) is None        # three drivers
    encoder = solve("fourbar_crank_encoder")                           # a missing sample: NaN
    assert not np.isfinite(encoder.driver_value).all() and rrd.driver_timeline(encoder) is None


def test_a_motor_between_links_is_drawn_on_both(tmp_path, monkeypatch):
    """tests/data/two_link_arm.toml: the elbow motor (B about A, relative to A -> O) turns the
    forearm with its torque (force at B, moment about A) and the upper arm with minus it (force
    at O, moment about A); the shoulder's torque is a force at A (no least length here)."""
    from conftest import CONFIG_DIR

    monkeypatch.setattr(rrd.forces, "MIN_FRACTION", 0.0)
    result = solve_scene(str(CONFIG_DIR.parent / "tests" / "data" / "two_link_arm.toml"))
    rec = Recording(_write(result, tmp_path))
    _, scale = rrd.force_arrows(result)
    i = {n: k for k, n in enumerate(result.point_names)}
    X, tau = result.position, result.forces["input_force"][1]
    origins, vectors = _arrows(rec, "/mechanism/forces/input/elbow")
    reaction_at, reaction = _arrows(rec, "/mechanism/forces/input/elbow/reaction")
    np.testing.assert_array_equal(np.concatenate([origins, reaction_at], axis=1),
                                  _f32(X[:, [i["B"], i["O"]]]))
    force = np.concatenate([vectors, reaction], axis=1).astype(float) / scale
    assert list(rec.static("/mechanism/forces/input/elbow/reaction", "Arrows2D:labels")) == [
        "elbow reaction"]

    def moment(at, f, about):
        r = at - about
        return r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]

    A = X[:, i["A"]]
    scale_tau = np.abs(tau).max()
    np.testing.assert_allclose(moment(X[:, i["B"]], force[:, 0], A), tau[:, 1], atol=1e-5 * scale_tau)
    np.testing.assert_allclose(moment(X[:, i["O"]], force[:, 1], A), -tau[:, 1], atol=1e-5 * scale_tau)
    origins, vectors = _arrows(rec, "/mechanism/forces/input/shoulder")
    np.testing.assert_array_equal(origins[:, 0], _f32(A))
    np.testing.assert_allclose(moment(A, vectors[:, 0].astype(float) / scale, X[:, i["O"]]), tau[:, 0],
                               atol=1e-5 * scale_tau)


def test_a_long_sweep_is_recorded_at_a_stride_and_says_so(tmp_path, capsys):
    """--rrd-max-steps 100 on 361 steps: every 4th step in the recording (91 rows), numbered as
    in the sweep; a static info text says so, as does the summary; the .h5 keeps all 361."""
    from linkpipe.__main__ import main
    from conftest import CONFIG_DIR

    assert main(["run", str(CONFIG_DIR / "fourbar_crank_rocker.toml"), "--out", str(tmp_path),
                 "--rrd-max-steps", "100"]) == 0
    out = capsys.readouterr().out
    assert "recording: every 4th step (91 of 361; --rrd-max-steps 100); the .h5 keeps every step" in out
    rec = Recording(tmp_path / "fourbar_crank_rocker.rrd")
    frame = rec.steps("/mechanism/points")
    np.testing.assert_array_equal(frame["step"].to_numpy(), np.arange(0, 361, 4))
    result = solve_scene(str(CONFIG_DIR / "fourbar_crank_rocker.toml"))
    got = np.array([np.stack(r) for r in _column(frame, "/mechanism/points", "Points2D:positions")])
    np.testing.assert_allclose(got, result.position[::4], rtol=1e-6, atol=1e-6)
    (text,) = rec.static("/info", "TextDocument:text")
    assert "every 4th step (91 of 361" in str(text)
    assert "the .h5 keeps every step" in str(text)
    with h5py.File(tmp_path / "fourbar_crank_rocker.h5") as f:
        assert f["position"].shape[0] == 361
    # with --no-h5 no file keeps every step: neither the summary nor the recording says one does
    other = tmp_path / "no_h5"
    assert main(["run", str(CONFIG_DIR / "fourbar_crank_rocker.toml"), "--out", str(other),
                 "--rrd-max-steps", "100", "--no-h5"]) == 0
    out = capsys.readouterr().out
    assert "recording: every 4th step (91 of 361; --rrd-max-steps 100); no .h5 written" in out
    (text,) = Recording(other / "fourbar_crank_rocker.rrd").static("/info", "TextDocument:text")
    assert "no file of this run keeps every step" in str(text) and ".h5 keeps" not in str(text)
    assert not (other / "fourbar_crank_rocker.h5").exists()


def test_short_sweeps_keep_every_step_and_no_info(solve, tmp_path):
    rec = Recording(_write(solve("fourbar_crank_rocker"), tmp_path))
    assert "/info" not in rec.entities


def test_a_recording_past_its_size_cap_keeps_a_stride_and_stays_within_it(tmp_path, capsys):
    """--rrd-max-mb 0.5 on a 10,000-step crank-rocker with every effect (about 0.9 kB a step,
    ~9 MB whole; a sweep this short was recorded whole whatever the cap): the size measured on
    two samples of steps sets the stride, the file is within 0.5 MB and above half of it (the
    stride is not wildly coarse), and the info text and the summary say why; the .h5 keeps
    every step."""
    import re

    from linkpipe.__main__ import main
    from conftest import CONFIG_DIR

    sys.path.insert(0, str(CONFIG_DIR.parent / "benchmarks"))
    from bench_sweep import EFFECTS

    text = (CONFIG_DIR / "fourbar_crank_rocker.toml").read_text()
    scene = tmp_path / "capped.toml"
    scene.write_text(re.sub(r"steps = \d+", "steps = 10000", text) + EFFECTS)
    assert main(["run", str(scene), "--out", str(tmp_path), "--rrd-max-mb", "0.5"]) == 0
    out = capsys.readouterr().out
    size = (tmp_path / "fourbar_crank_rocker.rrd").stat().st_size
    assert 0.25e6 < size <= 0.5e6
    stride = int(re.search(r"recording: every (\d+)th step \(([\d,]+) of 10,000; 0\.5 MB at "
                           r"most\); the \.h5 keeps every step", out).group(1))
    rec = Recording(tmp_path / "fourbar_crank_rocker.rrd")
    np.testing.assert_array_equal(rec.steps("/mechanism/points")["step"].to_numpy(),
                                  np.arange(0, 10000, stride))
    (info,) = rec.static("/info", "TextDocument:text")
    assert "0.5 MB at most" in str(info)
    with h5py.File(tmp_path / "fourbar_crank_rocker.h5") as f:
        assert f["position"].shape[0] == 10000


def test_a_step_cap_given_alone_is_the_recordings_only_cap(tmp_path, capsys):
    """--rrd-max-steps is the contract's option as written: past N steps a stride, and not
    before (no size cap unless --rrd-max-mb is given). The 10,000-step crank-rocker with every
    effect (~9 MB) keeps every step under --rrd-max-steps 20000, and a stride under
    --rrd-max-steps 20000 --rrd-max-mb 0.5; the defaults are the recording store's own
    constants, 100,000 steps and no size cap (a 90,000-step sweep of ~80 MB keeps every step:
    the plan says so without measuring)."""
    import re

    from linkpipe import __main__ as cli
    from linkpipe.stores import rrd
    from conftest import CONFIG_DIR

    assert cli.recording_caps(None, None) == (rrd.MAX_STEPS, rrd.MAX_BYTES / 1e6) == (100_000, 0)
    assert cli.recording_caps(20000, None) == (20000, 0.0)
    assert cli.recording_caps(None, 5.0) == (rrd.MAX_STEPS, 5.0)
    assert cli.recording_caps(0, 7.0) == (0, 7.0)
    sys.path.insert(0, str(CONFIG_DIR.parent / "benchmarks"))
    from bench_sweep import EFFECTS

    text = (CONFIG_DIR / "fourbar_crank_rocker.toml").read_text()
    scene = tmp_path / "capped.toml"
    scene.write_text(re.sub(r"steps = \d+", "steps = 10000", text) + EFFECTS)
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "a"), "--no-h5",
                     "--rrd-max-steps", "20000"]) == 0
    assert "recording:" not in capsys.readouterr().out
    rec = Recording(tmp_path / "a" / "fourbar_crank_rocker.rrd")
    assert len(rec.steps("/mechanism/points")["step"]) == 10000
    result = solve_scene(str(scene))
    assert rrd.plan(result, rrd.MAX_STEPS, rrd.MAX_BYTES, n_steps=90_000) == (1, "--rrd-max-steps 100,000")
    assert rrd.plan(result, rrd.MAX_STEPS, rrd.MAX_BYTES, n_steps=250_000) == (3, "--rrd-max-steps 100,000")
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "b"), "--no-h5",
                     "--rrd-max-steps", "20000", "--rrd-max-mb", "0.5"]) == 0
    assert "0.5 MB at most" in capsys.readouterr().out


def test_a_sweep_where_every_step_fails_keeps_its_plots(tmp_path):
    """The triple rocker swept 170 .. 190 deg never assembles: every step no_assembly. Its
    plots still hold a row at every step, NaN (the contract's per-step Scalars; a series NaN
    throughout had been left out, so plots/link_angle and plots/input_force were missing)."""
    from conftest import CONFIG_DIR
    from linkpipe.__main__ import main

    text = (CONFIG_DIR / "hard" / "triple_rocker_limits.toml").read_text()
    text = re.sub(r"from = [-0-9.e]+\nto = [-0-9.e]+\nsteps = \d+",
                  "from = 170.0\nto = 190.0\nsteps = 21", text)
    text += '\n[analysis]\neffects = ["gravity"]\n[gravity]\ng = [0.0, -9.81]\n' \
            '[[masses]]\nlink = "coupler"\nmass = 1.0\ncenter = [1.0, 0.0]\n'
    scene = tmp_path / "never.toml"
    scene.write_text(text)
    assert main(["run", str(scene), "--out", str(tmp_path), "--no-h5"]) == 0
    rec = Recording(tmp_path / "triple_rocker_limits.rrd")
    for entity in ("/plots/link_angle/crank", "/plots/input_force/crank"):
        frame = rec.steps(entity)
        np.testing.assert_array_equal(frame["step"], np.arange(21))
        values = np.concatenate(_column(frame, entity, "Scalars:scalars").to_list())
        assert values.shape == (21,) and np.isnan(values).all(), entity
    frame = rec.steps("/solver/residual")  # the residual where Newton stopped: above tolerance
    values = np.concatenate(_column(frame, "/solver/residual", "Scalars:scalars").to_list())
    assert values.shape == (21,) and (values > 1e-12 * 3.5).all()
