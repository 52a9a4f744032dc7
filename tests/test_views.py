"""Recordings a person reads at a glance (issue 34): the palette keeps links and arrow kinds
apart, the legend is an entity, plots read in degrees against the quantity that moves the
scene, coinciding series are one legend entry. Real .rrd files, read back."""
import pathlib

import numpy as np
from rerun.blueprint.components import ContainerKind

from linkpipe import solve as solve_scene
from linkpipe.stores import rrd
from linkpipe.stores.rrd import style
from linkpipe.stores.rrd.series import hidden

from test_rrd import Recording, _column, _write

CONFIGS = pathlib.Path(__file__).parent.parent / "configs"


def test_links_and_arrow_kinds_never_share_a_hue():
    """Every link colour (as many as the largest shipped mechanism has, and more) is muted and
    at least HUE_CLEARANCE degrees from every arrow kind's hue (friction's reserved one too);
    every force kind and vector has a saturated hue of its own."""
    arrows = {k: style.arrow_colour(k) for k in style.ARROW_HUES}
    assert {tuple(kind.colour) for kind in rrd.KINDS} <= {tuple(c) for c in arrows.values()}
    assert len({style.hue_of(c) // 1 for c in arrows.values()}) == len(arrows)
    for c in arrows.values():
        assert style.saturation_of(c) >= 0.8
    for j in range(24):
        link = style.link_colour(j)
        assert style.saturation_of(link) <= 0.4
        for name, c in arrows.items():
            assert style.hue_distance(style.hue_of(link), style.hue_of(c)) >= 19.5, (j, name)
    # the velocity and acceleration arrows are two of the kinds
    assert style.VECTOR_COLORS["velocity"] == arrows["velocity"]


def test_arrows_are_drawn_above_links(solve, tmp_path):
    result = solve("basketball_goal")
    rec = Recording(_write(result, tmp_path))
    link = float(np.ravel(rec.static("/mechanism/links/lower", "LineStrips2D:draw_order"))[0])
    for entity in ("/mechanism/forces/input/theta3a", "/mechanism/acceleration/C",
                   "/mechanism/legend"):
        assert float(np.ravel(rec.static(entity, "Arrows2D:draw_order"))[0]) > link


def test_the_legend_names_every_kind_drawn_and_fits_the_view(solve, tmp_path):
    """The excavator: input, loads, weights, reactions and the vectors; each row's arrow in its
    kind's colour; every row inside the view's bounds and clear of the mechanism (above it, or
    at its right for a tall one)."""
    for name in ("excavator_arm", "five_bar"):
        result = solve(name)
        rec = Recording(_write(result, tmp_path / name))
        labels = list(rec.static("/mechanism/legend", "Arrows2D:labels"))
        kinds = dict.fromkeys(kind for kind, *_ in rrd.force_arrows(result)[0])
        assert [k.legend for k in kinds] == labels[:len(kinds)]
        origins = np.stack(rec.static("/mechanism/legend", "Arrows2D:origins"))
        tips = origins + np.stack(rec.static("/mechanism/legend", "Arrows2D:vectors"))
        lo, hi = rrd.view_bounds(result)
        mlo, mhi = rrd.mechanism_bounds(result)
        for xy in (origins, tips):
            tol = 1e-6 * float(np.max(hi - lo))                        # float32
            assert (xy >= lo - tol).all() and (xy <= hi + tol).all()
            assert ((xy[:, 1] > mhi[1]) | (xy[:, 0] > mhi[0])).all()   # not over the mechanism


def test_link_angles_in_degrees_and_coinciding_series_as_one_entry(solve, tmp_path):
    """The basketball goal: its upper and lower links are a parallelogram's (their angles
    coincide), its two springs the same spring on either side (their forces coincide)."""
    result = solve("basketball_goal")
    rec = Recording(_write(result, tmp_path))
    j = result.link_names.index("upper")
    frame = rec.steps("/plots/link_angle_deg/upper")
    got = np.concatenate(_column(frame, "/plots/link_angle_deg/upper", "Scalars:scalars").to_list())
    np.testing.assert_array_equal(got, np.degrees(result.link_angle[:, j]))
    frame = rec.steps("/plots/link_angle/upper")                   # the contract's radians kept
    got = np.concatenate(_column(frame, "/plots/link_angle/upper", "Scalars:scalars").to_list())
    np.testing.assert_array_equal(got, result.link_angle[:, j])
    assert list(rec.static("/plots/spring_force/left", "SeriesLines:names")) == [
        "left = right (coincide)"]
    assert list(rec.static("/plots/link_angle_deg/upper", "SeriesLines:names")) == [
        "upper = lower (coincide)"]
    assert list(rec.static("/plots/input_force/theta3a", "SeriesLines:names")) == [
        "force at H (theta3a)"]
    views = rec.views()
    assert "/plots/spring_force/right" not in str(views["spring force [lbf]"])
    assert "/plots/spring_force/left" in str(views["spring force [lbf]"])
    assert "/plots/link_angle_deg/lower" not in str(views["link angle [deg]"])
    assert hidden(result) == {"/plots/spring_force/right", "/plots/link_angle/lower",
                              "/plots/link_angle_deg/lower"}
    # both contract entities are there, with their own values
    assert {"/plots/spring_force/right", "/plots/link_angle/lower"} <= rec.entities


def test_series_that_differ_are_not_merged(solve):
    result = solve("excavator_arm")
    assert hidden(result) == set()


def test_plots_open_on_time_for_timed_scenes_and_on_the_driver_for_sweeps(solve):
    logged = solve_scene(str(CONFIGS / "logged" / "dump_truck_logged.toml"))
    assert rrd.active_timeline(logged) == "time"
    assert rrd.active_timeline(solve("basketball_goal")) == "theta3a [degree]"
    assert rrd.active_timeline(solve("fourbar_crank_rocker")) == "crank [degree]"
    # two drivers: a timeline each, the first opened
    five = solve("five_bar")
    names = [n for n, _ in rrd.driver_timelines(five)]
    assert [n.split(" [")[0] for n in names] == list(five.driver_names)
    assert all(n.endswith("degree]") for n in names)
    assert rrd.active_timeline(five) == names[0]


def test_a_dynamics_scene_opens_on_time(tmp_path):
    """A forward-dynamics scene's motion is the answer (the driver's value one of its outputs,
    the crank of Andrews' squeezer turning 900 degrees): its plots open on ``time``, as a
    logged scene's do (they had opened on the crank's value, in steps of 0.0001 degree)."""
    for name in ("pendulum_a01", "andrews_squeezer"):
        result = solve_scene(str(CONFIGS / "dynamics" / f"{name}.toml"))
        assert result.scene.time is None and result.time is not None
        assert rrd.active_timeline(result) == "time"


def test_more_than_four_plots_go_in_two_columns(tmp_path):
    """The dump truck with friction has six plots (input force, link angle, two friction
    forces, stroke margin, the measured cylinder force): a sixth of 900 px shows no number on
    a y axis, so they are a grid of two columns; the basketball goal's three stay one column."""
    result = solve_scene(str(CONFIGS / "logged" / "dump_truck_friction.toml"))
    rec = Recording(_write(result, tmp_path / "friction"))
    plots = [v for v in rec.views() if "[" in v and not v.startswith(("log10", "residual",
                                                                       "iterations"))]
    assert len(plots) == 6 > rrd.layout.MAX_ROWS
    assert {"friction force [N]", "friction force [N*m]", "stroke margin [m]"} <= set(plots)
    # half a column wide: the measurement's title is short (its legend says what is which)
    assert "cylinder_force [N]" in plots
    container = rec.containers()["plots"]
    assert [ContainerKind(int(k)) for k in container["container_kind"]] == [ContainerKind.Grid]
    assert [int(c) for c in container["grid_columns"]] == [2]
    goal = Recording(_write(solve_scene(str(CONFIGS / "basketball_goal.toml")), tmp_path / "g"))
    assert [ContainerKind(int(k)) for k in goal.containers()["plots"]["container_kind"]] == [
        ContainerKind.Vertical]


def test_a_tiny_force_is_drawn_at_the_least_length_with_its_value(solve):
    """MIN_FRACTION of the size, along the force, where force x scale is shorter."""
    result = solve("basketball_goal")
    arrows, scale = rrd.force_arrows(result)
    least = rrd.MIN_FRACTION * rrd.mechanism_size(result)
    for (kind, item, _, forces), (_, _, origins, vectors, short) in zip(arrows, rrd.drawn_arrows(result)):
        F = np.hypot(forces[..., 0], forces[..., 1])
        L = np.hypot(vectors[..., 0], vectors[..., 1])
        np.testing.assert_allclose(L, np.where((F > 0) & (F * scale < least), least, F * scale),
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(short, (F > 0) & (F * scale < least))
        cross = vectors[..., 0] * forces[..., 1] - vectors[..., 1] * forces[..., 0]
        np.testing.assert_allclose(cross, 0, atol=1e-9 * F.max() * L.max())
        assert (np.einsum("skc,skc->sk", vectors, forces) >= 0).all()


def test_a_crank_turning_many_times_is_wrapped_and_the_computed_line_shows(tmp_path):
    """The live four-bar's log: its crank turns ~110 times in a minute (40,000 degrees), which
    flattened the coupler's and rocker's angles to a line at 0; it is plotted wrapped into
    [-180, 180) (said in its name), the others as they are; the measured series is
    translucent, so the computed one under it shows."""
    result = solve_scene(str(CONFIGS / "logged" / "fourbar_live.toml"))
    rec = Recording(_write(result, tmp_path))
    for j, link in enumerate(result.link_names):
        entity = f"/plots/link_angle_deg/{link}"
        got = np.concatenate(_column(rec.steps(entity), entity, "Scalars:scalars").to_list())
        turns = np.ptp(np.degrees(result.link_angle[:, j])) > 360
        name = list(rec.static(entity, "SeriesLines:names"))
        assert (name == [f"{link} (wrapped to ±180)"]) == bool(turns)
        if turns:
            assert (got >= -180).all() and (got < 180).all()
            # the same angle: a whole number of turns from the contract's radians
            k = (np.degrees(result.link_angle[:, j]) - got) / 360
            np.testing.assert_allclose(k, np.round(k), atol=1e-9)
        else:
            np.testing.assert_allclose(got, np.degrees(result.link_angle[:, j]), rtol=1e-6)
    assert any("wrapped" in str(rec.static(f"/plots/link_angle_deg/{n}", "SeriesLines:names"))
               for n in result.link_names)
    for m in result.measurements["names"]:
        (measured,) = rec.static(f"/plots/measurements/{m}/measured", "SeriesLines:colors")
        (computed,) = rec.static(f"/plots/measurements/{m}/computed", "SeriesLines:colors")
        assert int(measured) & 0xFF == rrd.series.MEASURED_ALPHA < 255
        assert int(computed) & 0xFF == 255


def test_a_crowd_of_labels_and_legend_entries_is_left_to_hover(tmp_path):
    """The 40-bar chain (IFToMM A02): 82 points and 81 links. Its point labels drew as a smear
    ("BBBB AAAA"), its weights' and reactions' labels likewise, and its link-angle legend of
    81 entries covered the plot (Andrews' 7 a third of it): past style.CROWD labels of one kind
    and MAX_LEGEND entries
    they are hidden (logged: hover shows them). The crank-rocker keeps all of them."""
    result = solve_scene(str(CONFIGS / "dynamics" / "n_fourbar_a02.toml"))
    rec = Recording(_write(result, tmp_path / "chain"))
    assert len(result.point_names) > style.CROWD
    assert list(rec.static("/mechanism/points", "Points2D:show_labels")) == [False]
    weights = [e for e in rec.entities if e.startswith("/mechanism/forces/weights/")]
    assert len(weights) > style.CROWD
    for e in weights[:3]:
        assert list(rec.static(e, "Arrows2D:show_labels")) == [False]
    assert rec.legends()["link angle [deg]"] is False
    andrews = solve_scene(str(CONFIGS / "dynamics" / "andrews_squeezer.toml"))  # 7 links
    assert len(andrews.link_names) > rrd.layout.MAX_LEGEND
    assert Recording(_write(andrews, tmp_path / "a")).legends()["link angle [deg]"] is False
    jansen = solve_scene(str(CONFIGS / "jansen.toml"))   # 7 links, its only plot: full height
    assert len(jansen.link_names) > rrd.layout.MAX_LEGEND
    assert Recording(_write(jansen, tmp_path / "j")).legends()["link angle [deg]"] is True
    small = Recording(_write(solve_scene(str(CONFIGS / "fourbar_crank_rocker.toml")),
                             tmp_path / "small"))
    assert list(small.static("/mechanism/points", "Points2D:show_labels")) == [True]
    assert all(small.legends()[v] for v in small.legends() if not v.startswith(("residual",
                                                                               "iterations")))


def test_a_dynamics_run_that_ends_early_fills_its_plots_ends_its_timeline_and_a_free_driver_has_no_force_plot(
        tmp_path):
    """The falling lever's tether runs out at 0.328 s of its 1 s: the plots' time axis spans
    the assembled instants (3 % either side), not the NaN tail; its driver moves freely (input
    force 0 at every step), so no flat input-force plot (the series stays logged)."""
    result = solve_scene(str(CONFIGS / "dynamics" / "falling_lever.toml"))
    assembled = np.isfinite(result.position).all(axis=(1, 2))
    t_end = float(result.time[assembled][-1])
    assert 0.3 < t_end < 0.35 and not assembled[-1]
    rec = Recording(_write(result, tmp_path / "lever"))
    assert not any(v.startswith("input force") for v in rec.views())
    assert "/plots/input_force/fall" in rec.entities
    assert "link angle [deg]" in rec.views()
    axis = rrd.layout.x_range(result, "time")
    # the view's range as the blueprint holds it, seconds
    (start, end) = _time_range_seconds(axis)
    np.testing.assert_allclose([start, end], [-0.03 * t_end, 1.03 * t_end], rtol=1e-6)
    # nothing was integrated after the tether ran out: the recording's timeline ends at the
    # last assembled instant (the viewer would otherwise play 0.67 s of an empty mechanism),
    # and its info note says so; the result (and the .h5) keep every instant
    last = int(np.flatnonzero(assembled)[-1])
    steps = rec.steps("/mechanism/links/**")
    assert int(steps["step"].max()) == last and len(result.time) == 1001
    (note,) = rec.static("/info", "TextDocument:text")
    assert f"integrated to t = {t_end:.6g} s" in note and f"{1000 - last:,} instants" in note
    goal = solve_scene(str(CONFIGS / "basketball_goal.toml"))    # a driven sweep keeps its plot
    assert any(v.startswith("input force") for v in
               Recording(_write(goal, tmp_path / "goal")).views())


def _time_range_seconds(axis) -> tuple[float, float]:
    """(start, end) in seconds of a TimeAxis's absolute view range."""
    arrow = axis.view_range.as_arrow_array()
    values = arrow.to_pylist()[0]
    return values["start"] / 1e9, values["end"] / 1e9       # Absolute, nanoseconds
