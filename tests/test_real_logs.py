"""Logs as rigs write them (issue 30): any delimited text or Parquet, headers as written, units
per column, offsets, lags, combined columns, speeds measured, robust losses, one model fitted
to many logs. The answers come from the closed-form offset slider-crank of
configs/logged/make_slider_crank_logs.py (written without linkpipe), from unit definitions,
and from a least squares built by hand on that closed form."""
import importlib.util
import math
import pathlib

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import linkpipe
from linkpipe.__main__ import main
from linkpipe.fit import fit
from linkpipe.scene import load_scene
from linkpipe.scene import units as unit_table

ROOT = pathlib.Path(__file__).resolve().parent.parent
LOGGED = ROOT / "configs" / "logged"
_spec = importlib.util.spec_from_file_location("make_slider_crank_logs",
                                               LOGGED / "make_slider_crank_logs.py")
rig = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rig)

#: the scene of configs/logged/slider_crank_rig.toml (drawing 58, 243, 12 mm), with its
#: [[logs]] file and [fit] table replaced per test
RIG = (LOGGED / "slider_crank_rig.toml").read_text()


def rig_scene(folder: pathlib.Path, logs: str, fit_table: str = "", measurements: str | None = None,
              driver_extra: str = "", geometry=(58.0, 243.0, 12.0)) -> pathlib.Path:
    """The rig scene with its [[logs]] tables ``logs``, its measurements (default the rig's)
    and ``fit_table``, written into ``folder``."""
    head = RIG[:RIG.index("\n[[logs]]") + 1]
    a, b, e = geometry
    head = (head.replace('"O-A" = 58.0', f'"O-A" = {a!r}').replace('"A-B" = 243.0', f'"A-B" = {b!r}')
            .replace("through = [0.0, 12.0]", f"through = [0.0, {e!r}]"))
    body = RIG[RIG.index("\n[[drivers]]"):RIG.index("\n[fit]")]
    if measurements is not None:
        body = body[:body.index("[[measurements]]")] + measurements
    body = body.replace("offset = 0.0                               # crank angle",
                        driver_extra + "offset = 0.0                               # crank angle")
    path = folder / "rig.toml"
    path.write_text(head + logs + "\n" + body + "\n" + fit_table)
    return path


RIG_LOG = '''[[logs]]
name = "rig"
file = "{file}"
delimiter = "\\t"
time = "%time"
skip_rows = 1
units = {{ wheel = "deg", slide = "mm", wheel_speed = "rpm", slide_speed = "mm/s" }}
'''


def write_run(path: pathlib.Path, rows=201, rpm=60.0, start=43.0, count0=5444.9, zero=310.0,
              noise=0.0, spikes=0, seed=0, sep="\t", header_extra=True, units_row=True,
              geometry=(rig.CRANK, rig.ROD, rig.OFFSET)) -> dict:
    """A rig log from the closed form (the generator's crank and slide with ``geometry``):
    returns the truth (the driver's offset in (-180, 180], the slide's zero, t, x, dx)."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / 50.0
    theta, rate = rig.crank(t, rpm, start)
    saved = rig.CRANK, rig.ROD, rig.OFFSET
    rig.CRANK, rig.ROD, rig.OFFSET = geometry
    try:
        x, dx = rig.slide(theta, rate)
    finally:
        rig.CRANK, rig.ROD, rig.OFFSET = saved
    wheel = count0 + np.degrees(theta - theta[0])
    reading = zero - x + rng.normal(0.0, noise, rows) if noise else zero - x
    if spikes:
        at = rng.choice(np.arange(3, rows - 3), spikes, replace=False)
        reading[at] += rng.uniform(20.0, 40.0, spikes)
    names = ["%time", "wheel", "slide", "wheel_speed", "slide_speed"]
    lines = [sep.join(names + (["comment"] if header_extra else []))]
    if units_row:
        lines.append(sep.join(["s", "deg", "mm", "rpm", "mm/s"]))
    lines += [sep.join(repr(float(v)) for v in row) for row in
              zip(t, wheel, reading, rate * 60.0 / (2.0 * np.pi), -dx)]
    path.write_text("\n".join(lines) + "\n")
    offset = (start - count0 + 180.0) % 360.0 - 180.0
    return {"offset": offset, "zero": zero, "t": t, "x": x, "dx": dx, "theta": theta}


# -- 1. any delimited file, headers as rigs write them --------------------------------------

@pytest.mark.parametrize("sep, written", [("\t", "\\t"), (",", ","), (";", ";"), ("|", "|"),
                                          (" ", " ")])
def test_any_delimiter_and_any_file_name_read_the_rigs_numbers(tmp_path, sep, written):
    """A file without suffix, a "%" header with one more field than the rows, a units row:
    the slide's position equals the closed form at every row (the driver's offset and the
    slide's zero given as the truth: computed - measured is the solver's rounding)."""
    truth = write_run(tmp_path / "run1", sep=sep)
    logs = RIG_LOG.format(file="run1").replace('delimiter = "\\t"', f'delimiter = "{written}"')
    path = rig_scene(tmp_path, logs, geometry=(rig.CRANK, rig.ROD, rig.OFFSET))
    text = path.read_text().replace("offset = 0.0                               # crank",
                                    f"offset = {truth['offset']!r}  # crank")
    path.write_text(text.replace("offset = 300.0", f"offset = {truth['zero']!r}"))
    r = linkpipe.solve(str(path))
    assert r.message == f"all {r.n_steps} steps ok" and r.n_steps == 201
    np.testing.assert_allclose(r.position[:, r.point_names.index("B"), 0], truth["x"],
                               rtol=0, atol=1e-9)  # mm; positions at the log's own rows: exact
    k = r.measurements["names"].index("slide")
    assert np.nanmax(np.abs(r.measurements["residual"][:, k])) < 1e-9
    scene = load_scene(str(path))
    assert scene.logs[0].names[-1] == "comment"   # the header's extra name: an empty column
    assert scene.logs[0].time == "%time"


def test_a_parquet_log_of_any_name_with_format(tmp_path):
    write_run(tmp_path / "run1.txt", units_row=False, header_extra=False)
    frame = pd.read_csv(tmp_path / "run1.txt", sep="\t")
    frame.to_parquet(tmp_path / "run1.dat")
    logs = (RIG_LOG.format(file="run1.dat").replace('delimiter = "\\t"\n', 'format = "parquet"\n')
            .replace("skip_rows = 1\n", ""))
    r = linkpipe.solve(str(rig_scene(tmp_path, logs)))
    r_text = linkpipe.solve(str(rig_scene(tmp_path, logs.replace('format = "parquet"',
                                                                   'delimiter = "\\t"')
                                          .replace("run1.dat", "run1.txt"))))
    np.testing.assert_array_equal(r.position, r_text.position)


def _run_fails(tmp_path, scene, capsys, *more) -> str:
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), *more]) == 2
    assert not out.exists() or not any(out.iterdir())   # nothing written
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err
    return err


def test_a_delimiter_that_yields_one_column_is_one_message(tmp_path, capsys):
    write_run(tmp_path / "run1")
    logs = RIG_LOG.format(file="run1").replace('delimiter = "\\t"', 'delimiter = ","')
    err = _run_fails(tmp_path, rig_scene(tmp_path, logs), capsys)
    assert 'run1" line 1: delimiter "," leaves the header' in err
    assert 'write delimiter = "\\t"' in err and "[logs \"rig\"] delimiter" in err


def test_a_bad_value_is_named_by_file_line_and_column(tmp_path, capsys):
    write_run(tmp_path / "run1")
    lines = (tmp_path / "run1").read_text().splitlines()
    fields = lines[7].split("\t")
    fields[2] = "1.2.3"   # the slide column of data row 6, line 8 of the file
    lines[7] = "\t".join(fields)
    (tmp_path / "run1").write_text("\n".join(lines) + "\n")
    err = _run_fails(tmp_path, rig_scene(tmp_path, RIG_LOG.format(file="run1")), capsys)
    assert 'run1" row 6 (line 8 of the file), column "slide": "1.2.3" is not a number' in err


def test_a_row_longer_than_the_header_is_named_by_its_line(tmp_path, capsys):
    write_run(tmp_path / "run1", header_extra=False)
    lines = (tmp_path / "run1").read_text().splitlines()
    lines[10] += "\t7.0"
    (tmp_path / "run1").write_text("\n".join(lines) + "\n")
    err = _run_fails(tmp_path, rig_scene(tmp_path, RIG_LOG.format(file="run1")), capsys)
    assert "line 11 has 6 fields, the header 5" in err


# -- 2. units per column -----------------------------------------------------------------------

@pytest.mark.parametrize("unit, quantity, order, si", [
    ("mm", "length", 0, 1e-3), ("in", "length", 0, 0.0254), ("ft/s", "length", 1, 0.3048),
    ("um", "length", 0, 1e-6), ("deg", "angle", 0, math.pi / 180), ("rev", "angle", 0, 2 * math.pi),
    ("rpm", "angle", 1, 2 * math.pi / 60), ("deg/s^2", "angle", 2, math.pi / 180),
    ("ms", "time", 0, 1e-3), ("min", "time", 0, 60.0), ("kN", "force", 0, 1e3),
    ("lbf", "force", 0, 4.4482216152605), ("bar", "pressure", 0, 1e5), ("MPa", "pressure", 0, 1e6),
    ("psi", "pressure", 0, 6894.757293168361), ("kPa", "pressure", 0, 1e3), ("mN", "force", 0, 1e-3)])
def test_column_units_are_their_definitions(unit, quantity, order, si):
    """Each unit's SI value by definition (1 in = 25.4 mm, 1 lbf = 4.4482216152605 N, 1 psi
    = 1 lbf/in^2 = 6894.757293168361 Pa, 1 bar = 1e5 Pa)."""
    got = unit_table.column_unit(unit)
    assert got[:2] == (quantity, order) and got[2] == pytest.approx(si, rel=1e-15)


def test_a_pressure_becomes_force_per_length_squared_of_the_scene():
    """bar in a (mm, N) scene: N/mm^2 = MPa, so 1 bar = 0.1; in (m, N): 1e5; in (in, lbf): psi."""
    assert 1e5 / unit_table.scene_unit_si("pressure", 0, {"length": "mm", "force": "N"}) == pytest.approx(0.1)
    assert 1e5 / unit_table.scene_unit_si("pressure", 0, {"length": "m", "force": "N"}) == pytest.approx(1e5)
    psi = unit_table.column_unit("psi")[2]
    assert psi / unit_table.scene_unit_si("pressure", 0, {"length": "in", "force": "lbf"}) == pytest.approx(1.0, rel=1e-12)


@given(value=st.floats(-1e6, 1e6, allow_nan=False), unit=st.sampled_from(["mm", "cm", "in", "ft", "um"]),
       scene=st.sampled_from(["m", "mm", "in", "ft"]))
@settings(max_examples=60, deadline=None)
def test_length_conversions_round_trip(value, unit, scene):
    """x [unit] -> scene length -> back to [unit] is x (to rounding)."""
    _, _, si = unit_table.column_unit(unit)
    factor = si / unit_table.scene_unit_si("length", 0, {"length": scene})
    assert value * factor * unit_table.scene_unit_si("length", 0, {"length": scene}) / si == pytest.approx(value, rel=1e-13, abs=1e-300)


def test_the_tipper_reads_its_pressure_in_bar(tmp_path):
    """configs/logged/dump_truck_logged.toml: pressure_bar with units = bar and scale = the
    bore's area in m^2 gives the same measured force as the v2 hand-made scale 1130.97...
    (bar x 1e5 Pa x pi 0.06^2 m^2), to rounding."""
    scene = load_scene(str(LOGGED / "dump_truck_logged.toml"))
    (m,) = scene.measurements
    raw = pd.read_csv(LOGGED / "logs" / "tipper_run.csv")["pressure_bar"].to_numpy()
    np.testing.assert_allclose(m.values, raw * 1e5 * math.pi * 0.06 ** 2, rtol=1e-14)


def test_an_unknown_unit_is_a_scene_error_naming_the_column(tmp_path, capsys):
    write_run(tmp_path / "run1")
    logs = RIG_LOG.format(file="run1").replace('slide = "mm"', 'slide = "furlong"')
    err = _run_fails(tmp_path, rig_scene(tmp_path, logs), capsys)
    assert '[logs "rig"] units: column "slide": unknown unit "furlong"' in err


def test_a_scene_without_the_units_a_column_needs(tmp_path, capsys):
    write_run(tmp_path / "run1")
    path = rig_scene(tmp_path, RIG_LOG.format(file="run1"))
    path.write_text(path.read_text().replace(
        'units = { length = "mm", mass = "kg", time = "s", force = "N" }', ""))
    err = _run_fails(tmp_path, path, capsys)
    assert 'column "slide": [scene].units.length is not given' in err


def test_a_driver_column_in_the_wrong_quantity(tmp_path, capsys):
    write_run(tmp_path / "run1")
    logs = RIG_LOG.format(file="run1").replace('wheel = "deg"', 'wheel = "mm"')
    err = _run_fails(tmp_path, rig_scene(tmp_path, logs), capsys)
    assert 'column "wheel" of log "rig" is in "mm", not an angle' in err


# -- 3. offsets, lags, combined columns, speeds: recovered exactly from noise-free data ------

FIT3 = '''[fit]
parameters = ["drivers.crank.offset", "measurements.slide.offset"]
'''


def test_zeros_are_recovered_exactly_from_a_noise_free_log(tmp_path):
    """The encoder's offset (crank angle - wheel, modulo turns) and the string-pot's zero
    with the true geometry: to 1e-6 deg and 1e-6 mm (the fit's tolerance, not noise)."""
    truth = write_run(tmp_path / "run1", zero=312.4, count0=5444.9, start=41.3)
    path = rig_scene(tmp_path, RIG_LOG.format(file="run1"), FIT3,
                     geometry=(rig.CRANK, rig.ROD, rig.OFFSET))
    result = fit(load_scene(str(path)))
    offset, zero = result.fitted
    # 1e-6: the fit's stopping tolerances on differences of step 1e-7, far below the 0.03 deg
    # and 0.2 mm one standard error is at the rig's noise
    assert (offset - truth["offset"] + 180) % 360 - 180 == pytest.approx(0, abs=1e-6)
    assert zero == pytest.approx(312.4, abs=1e-6)


def test_a_lag_is_recovered_exactly_and_speeds_are_measured(tmp_path):
    """A second logger (ms stamps, metres, comma-separated) 6 ms late: ``logs.laser.lag``
    comes back to 1e-8 s from noise-free data, the laser's zero to 1e-6 mm; the slide's logged
    speed (mm/s, from the closed form's derivative) set against velocity.B.x differs by the
    spline's derivative error only (< 0.05 mm/s of ~250)."""
    truth = write_run(tmp_path / "run1", zero=310.0, count0=400.0, start=40.0)
    t = np.arange(-10, 211) / 50.0   # the laser's samples: 0.2 s more on either side
    theta, rate = rig.crank(t, 60.0, 40.0)
    x, _ = rig.slide(theta, rate)
    lag = 0.006
    stamps = (t + lag) * 1000.0  # sampled at the rig's instants (and beyond), stamped late
    pd.DataFrame({"t_ms": stamps, "d_m": (x + 100.0) / 1000.0}).to_csv(
        tmp_path / "laser.csv", index=False)
    logs = RIG_LOG.format(file="run1") + '''
[[logs]]
name = "laser"
file = "laser.csv"
time = "t_ms"
units = { t_ms = "ms", d_m = "m" }
lag = 0.002
'''
    measurements = '''[[measurements]]
name = "laser"
log = "laser.d_m"
offset = -90.0
of = "position.B.x"
sigma = 0.01

[[measurements]]
name = "slide_speed"
log = "rig.slide_speed"
scale = -1.0
of = "velocity.B.x"
sigma = 0.5
'''
    fit_table = '[fit]\nparameters = ["logs.laser.lag", "measurements.laser.offset"]\n'
    path = rig_scene(tmp_path, logs, fit_table, measurements,
                     geometry=(rig.CRANK, rig.ROD, rig.OFFSET))
    text = path.read_text().replace("offset = 0.0                               # crank",
                                    f"offset = {truth['offset']!r}  # crank")
    path.write_text(text.replace('[time]\nlog = "rig"', '[time]\nlog = "rig"'))
    result = fit(load_scene(str(path)))
    got_lag, got_zero = result.fitted
    assert got_lag == pytest.approx(lag, abs=1e-8)     # s; the fit's tolerance
    assert got_zero == pytest.approx(-100.0, abs=1e-6)  # mm
    k = result.after.measurements["names"].index("slide_speed")
    assert result.after.measurements["max_abs"][k] < 0.05


def test_a_lag_that_moves_the_log_off_time_is_one_message(tmp_path, capsys):
    write_run(tmp_path / "run1")
    logs = RIG_LOG.format(file="run1") + "lag = 0.5\n"
    path = rig_scene(tmp_path, logs)
    path.write_text(path.read_text().replace('[time]\nlog = "rig"',
                                             "[time]\nfrom = 0.0\nto = 4.0\nsteps = 201"))
    err = _run_fails(tmp_path, path, capsys)
    assert "covers only -0.5 s to 3.5 s (its stamps less lag = 0.5 s)" in err


def test_several_columns_combined_linearly(tmp_path):
    """measured = p_cap x A_cap - p_rod x A_rod + offset, the pressures in bar from a second
    logger: in the (mm, N) scene a bar is 0.1 N/mm^2, so with areas in mm^2 the sum is in N.
    The pressures are linear in time: the logger's spline reads them exactly at the instants."""
    truth = write_run(tmp_path / "run1")
    t = np.linspace(-1.0, 5.0, 13)
    pd.DataFrame({"t": t, "p_cap": 50.0 + t, "p_rod": 10.0 * t}).to_csv(tmp_path / "h.csv",
                                                                      index=False)
    logs = RIG_LOG.format(file="run1") + """
[[logs]]
name = "h"
file = "h.csv"
time = "t"
units = { p_cap = "bar", p_rod = "bar" }
"""
    measurements = """[[measurements]]
name = "force"
log = ["h.p_cap", "h.p_rod"]
scale = [1963.4954084936207, -1472.621556370215]
offset = 5.0
of = "driver_value.crank"
"""
    (m,) = load_scene(str(rig_scene(tmp_path, logs, measurements=measurements))).measurements
    ti = truth["t"]
    expected = 0.1 * ((50.0 + ti) * 1963.4954084936207 - 10.0 * ti * 1472.621556370215) + 5.0
    np.testing.assert_allclose(m.values, expected, rtol=1e-13)
    assert m.columns == (("h", "p_cap"), ("h", "p_rod"))


def test_offsets_and_lags_are_fit_addresses_when_left_out(tmp_path):
    from linkpipe.fit import locate

    write_run(tmp_path / "run1")
    path = rig_scene(tmp_path, RIG_LOG.format(file="run1"))
    path.write_text(path.read_text().replace("offset = 0.0                               # crank", "# crank"))
    scene = load_scene(str(path))
    import tomllib
    data = tomllib.loads(scene.text)
    assert locate(scene, data, "drivers.crank.offset") == (("drivers", 0, "offset"), 0.0)
    assert locate(scene, data, "logs.rig.lag") == (("logs", 0, "lag"), 0.0)
    assert locate(scene, data, "measurements.slide_speed.offset")[1] == 0.0


# -- 4, 5. one model, many logs; robust losses ------------------------------------------------

SLIDE_ONLY = '''[[measurements]]
name = "slide"
log = "rig.slide"
scale = -1.0
offset = 300.0
of = "position.B.x"
sigma = 0.05
'''
JOINT_FIT = '''[fit]
parameters = ["links.crank.lengths.O-A", "links.rod.lengths.A-B",
              "sliders.slide.along.through.1", "drivers.crank.offset",
              "measurements.slide.offset"]
per_log = ["drivers.crank.offset", "measurements.slide.offset"]
'''


def hand_built(logs: list[pd.DataFrame], x0: np.ndarray, loss="linear", f_scale=1.0):
    """The joint least squares written out on the closed form: x = [a, b, e, offset_1,
    zero_1, offset_2, zero_2, ...]; residual (x_B(a, b, e, wheel + offset) - (zero -
    reading)) / 0.05 per row; standard errors from inv(J^T J) of scipy's loss-weighted J."""
    from scipy.optimize import least_squares

    def residuals(x):
        a, b, e = x[:3]
        out = []
        for i, frame in enumerate(logs):
            offset, zero = x[3 + 2 * i: 5 + 2 * i]
            theta = np.radians(frame["wheel"].to_numpy() + offset)
            xb = a * np.cos(theta) + np.sqrt(b ** 2 - (a * np.sin(theta) - e) ** 2)
            out.append((xb - (zero - frame["slide"].to_numpy())) / 0.05)
        return np.concatenate(out)

    sol = least_squares(residuals, x0, method="trf", x_scale="jac", xtol=1e-14, ftol=1e-14,
                        gtol=1e-14, loss=loss, f_scale=f_scale)
    cov = np.linalg.inv(sol.jac.T @ sol.jac)
    return sol.x, np.sqrt(np.diag(cov))


def test_the_joint_fit_equals_a_hand_built_joint_least_squares(tmp_path, capsys):
    """Two noisy runs (0.05 mm), 3 shared + 2 per-log parameters: `fit --logs` gives the
    minimum and standard errors of the same least squares written by hand on the closed form,
    to 1e-5 mm / deg (two optimisers' stopping points on one cost) and 1 % (the standard
    errors from finite-difference Jacobians); <name>_fleet_fit.h5 holds them as the contract
    names them."""
    import xarray as xr

    runs = tmp_path / "runs"
    runs.mkdir()
    write_run(runs / "a", rpm=50.0, start=42.0, count0=5444.9, zero=312.4, noise=0.05, seed=1)
    write_run(runs / "b", rpm=110.0, start=37.5, count0=11917.5, zero=309.8, noise=0.05, seed=2)
    path = rig_scene(tmp_path, RIG_LOG.format(file="runs/a"), JOINT_FIT, SLIDE_ONLY)
    out = tmp_path / "out"
    assert main(["fit", str(path), "--logs", str(runs / "*"), "--out", str(out)]) == 0
    assert "joint fit of 3 shared + 2 per-log parameter(s) over 2 log(s)" in capsys.readouterr().out
    frames = [pd.read_csv(runs / n, sep="\t", skiprows=[1], index_col=False) for n in ("a", "b")]
    x0 = np.array([58.0, 243.0, 12.0, 0.0, 300.0, 0.0, 300.0])
    want, want_se = hand_built(frames, x0)
    with xr.open_dataset(out / "slider_crank_rig_fleet_fit.h5", engine="h5netcdf") as ds:
        assert list(ds["log"].values) == ["a", "b"]
        assert ds["fitted"].dims == ("parameter",)
        assert ds["fitted_per_log"].dims == ("log", "per_log_parameter")
        assert list(ds["per_log_parameter"].values) == ["drivers.crank.offset",
                                                        "measurements.slide.offset"]
        got = np.concatenate([ds["fitted"].values, ds["fitted_per_log"].values.ravel()])
        got_se = np.concatenate([ds["standard_error"].values,
                                 ds["standard_error_per_log"].values.ravel()])
        corr = ds["correlation"].values
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
    np.testing.assert_allclose(got_se, want_se, rtol=1e-2)
    np.testing.assert_allclose(np.diag(corr), 1.0, rtol=1e-12)
    np.testing.assert_allclose(corr, corr.T, atol=1e-12)


def test_the_demo_runs_give_the_rigs_geometry_within_its_standard_errors(tmp_path):
    """configs/logged/rig: six runs with noise and glitches, the soft_l1 loss: each shared
    and per-log value within 3 standard errors of the generator's truth."""
    from linkpipe.joint import joint_fit

    scene = load_scene(str(LOGGED / "slider_crank_rig.toml"))
    result = joint_fit(scene, str(LOGGED / "rig" / "run*"))
    truth = [rig.truth(k) for k in range(1, 7)]
    for p, v, se in zip(result.shared, result.fitted, result.standard_error):
        assert abs(v - truth[0][p.address]) < 3 * se, (p.address, v, se)
    for i, label in enumerate(result.labels):
        k = int(label.removeprefix("run"))
        for j, p in enumerate(result.per_log):
            error = result.fitted_per_log[i, j] - truth[k - 1][p.address]
            if p.address == "drivers.crank.offset":
                error = (error + 180.0) % 360.0 - 180.0
            assert abs(error) < 3 * result.standard_error_per_log[i, j], (label, p.address)


def test_the_robust_loss_holds_the_truth_where_the_linear_loss_does_not(tmp_path):
    """One run, 0.05 mm of noise and eight glitches of 20 to 40 mm: least squares follows
    the glitches (the string-pot's zero more than 10 standard errors off); soft_l1 with
    f_scale = 3 stays within 3 of them."""
    truth = write_run(tmp_path / "run1", start=41.0, count0=401.0, zero=311.0, noise=0.05,
                      spikes=8, seed=3)
    fit_table = ('[fit]\nparameters = ["links.rod.lengths.A-B", "drivers.crank.offset", '
                 '"measurements.slide.offset"]\n')
    path = rig_scene(tmp_path, RIG_LOG.format(file="run1"), fit_table, SLIDE_ONLY,
                     geometry=(rig.CRANK, 243.0, rig.OFFSET))
    linear = fit(load_scene(str(path)))
    path.write_text(path.read_text() + 'loss = "soft_l1"\nf_scale = 3.0\n')
    robust = fit(load_scene(str(path)))
    assert robust.loss == "soft_l1"
    want = [rig.ROD, truth["offset"], 311.0]
    robust_off = np.abs(robust.fitted - want) / robust.standard_error
    linear_off = np.abs(linear.fitted - want) / linear.standard_error
    assert (robust_off < 3).all(), robust_off
    assert linear_off.max() > 10, linear_off


def test_joint_fit_bad_inputs_are_one_message_and_nothing_written(tmp_path, capsys):
    runs = tmp_path / "runs"
    runs.mkdir()
    write_run(runs / "a")
    bad_per_log = JOINT_FIT.replace('per_log = ["drivers.crank.offset"',
                                    'per_log = ["drivers.crank.scale"')
    path = rig_scene(tmp_path, RIG_LOG.format(file="runs/a"), bad_per_log, SLIDE_ONLY)
    out = tmp_path / "out"
    assert main(["fit", str(path), "--logs", str(runs / "*"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert '[fit] per_log: "drivers.crank.scale" is not one of [fit] parameters' in err
    assert err.count("error:") == 1 and not out.exists()
    path = rig_scene(tmp_path, RIG_LOG.format(file="runs/a"), JOINT_FIT, SLIDE_ONLY)
    assert main(["fit", str(path), "--logs", str(runs / "nothing*"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no file matches" in err and err.count("error:") == 1 and not out.exists()
    bad_loss = JOINT_FIT + 'loss = "l1"\n'
    path = rig_scene(tmp_path, RIG_LOG.format(file="runs/a"), bad_loss, SLIDE_ONLY)
    assert main(["fit", str(path), "--out", str(out)]) == 2
    assert 'loss: unknown loss' in capsys.readouterr().err and not out.exists()


# -- 6. plotted against time --------------------------------------------------------------------

def test_time_is_a_coordinate_and_the_recording_plots_on_time(tmp_path):
    """The .h5's time opens in xarray as a coordinate of step; the dataframe keeps units; the
    .rrd's measured and computed series are on the time timeline at the log's instants."""
    import xarray as xr
    from test_rrd import Recording

    truth = write_run(tmp_path / "run1")
    path = rig_scene(tmp_path, RIG_LOG.format(file="run1"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--quiet"]) == 0
    with xr.open_dataset(out / "slider_crank_rig.h5", engine="h5netcdf") as ds:
        assert "time" in ds.coords and ds["time"].dims == ("step",)
        assert "time" in ds["measured"].coords
        np.testing.assert_array_equal(ds["time"].values, truth["t"])
    df = linkpipe.read(out / "slider_crank_rig.h5", "dataframe")
    assert df.attrs["units"]["position.B.x"] == "mm"
    assert df.attrs["units"]["time"] == "s"
    assert df.attrs["units"]["measured.slide_speed"] == "mm/s"
    rec = Recording(out / "slider_crank_rig.rrd")
    for series in ("measured", "computed"):
        entity = f"/plots/measurements/slide/{series}"
        frame = rec.store.reader(index="time", contents=entity).to_pandas()
        stamps = frame["time"].to_numpy().astype("timedelta64[ns]").astype(np.int64)
        np.testing.assert_array_equal(stamps, np.round(truth["t"] * 1e9).astype(np.int64))


def test_the_demo_second_logger_gives_its_lag_within_its_standard_error():
    """configs/logged/slider_crank_laser.toml: run 1 and the laser logger (6 ms late, noise
    and glitches): the lag, the laser's zero and the geometry within 3 standard errors of the
    generator's truth."""
    result = fit(load_scene(str(LOGGED / "slider_crank_laser.toml")))
    truth = rig.truth(1)
    for p, v, se in zip(result.parameters, result.fitted, result.standard_error):
        error = v - truth[p.address]
        if p.address == "drivers.crank.offset":
            error = (error + 180.0) % 360.0 - 180.0
        assert abs(error) < 3 * se, (p.address, v, se)


def test_the_shipped_rig_logs_are_what_their_script_writes(tmp_path):
    import runpy
    import shutil

    shutil.copy(LOGGED / "make_slider_crank_logs.py", tmp_path)
    runpy.run_path(str(tmp_path / "make_slider_crank_logs.py"), run_name="__main__")
    for name in [f"rig/run{k}" for k in range(1, 7)] + ["rig_laser/run1.csv"]:
        assert (tmp_path / name).read_text() == (LOGGED / name).read_text(), name


def test_a_tab_delimiter_on_a_comma_file_names_the_comma(tmp_path, capsys):
    write_run(tmp_path / "run1.csv", sep=",")
    err = _run_fails(tmp_path, rig_scene(tmp_path, RIG_LOG.format(file="run1.csv")), capsys)
    assert 'line 1: delimiter "\\t" leaves the header' in err and 'write delimiter = ","' in err


def test_the_time_logs_lag_moves_its_instants(tmp_path):
    """[time] log = "rig" with lag = 0.25: the steps are the rows at t_logged - 0.25 s; the
    driver, read from the same log, gives the same positions at the same rows."""
    truth = write_run(tmp_path / "run1")
    plain = linkpipe.solve(str(rig_scene(tmp_path, RIG_LOG.format(file="run1"))))
    lagged = linkpipe.solve(str(rig_scene(tmp_path, RIG_LOG.format(file="run1") + "lag = 0.25\n")))
    np.testing.assert_array_equal(lagged.time, truth["t"] - 0.25)
    np.testing.assert_array_equal(lagged.position, plain.position)


def test_a_logged_speed_in_rpm_against_the_drivers_velocity(tmp_path):
    """wheel_speed in rpm (the closed form's rate) beside driver_velocity.crank (deg/s, the
    wheel spline's derivative): 1 rpm = 6 deg/s; they differ by the cubic spline's derivative
    error alone at 50 Hz (< 0.01 deg/s of 360; measured 5e-4), and an acceleration column in
    deg/s^2 is read against driver_acceleration the same way (< 1 deg/s^2 of ~70; 0.09)."""
    truth = write_run(tmp_path / "run1")
    frame = pd.read_csv(tmp_path / "run1", sep="\t", skiprows=[1], index_col=False)
    _, rate = rig.crank(truth["t"], 60.0, 43.0)
    w, f = 2 * np.pi, 1.0
    A = 0.03 * w / (2 * np.pi * f)
    acc = -A * (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * truth["t"])   # rad/s^2
    frame.insert(5, "wheel_acc", np.degrees(acc))
    lines = ["\t".join(frame.columns), "s\tdeg\tmm\trpm\tmm/s\tdeg/s^2\t"]
    lines += ["\t".join(repr(float(v)) for v in row[:6]) for row in frame.to_numpy()]
    (tmp_path / "run1").write_text("\n".join(lines) + "\n")
    logs = RIG_LOG.format(file="run1").replace('slide_speed = "mm/s" }',
                                               'slide_speed = "mm/s", wheel_acc = "deg/s^2" }')
    measurements = '''[[measurements]]
name = "wheel_speed"
log = "rig.wheel_speed"
of = "driver_velocity.crank"

[[measurements]]
name = "wheel_acc"
log = "rig.wheel_acc"
of = "driver_acceleration.crank"
'''
    r = linkpipe.solve(str(rig_scene(tmp_path, logs, measurements=measurements)))
    speed, accel = r.measurements["max_abs"]
    assert speed < 0.01 and accel < 1.0, (speed, accel)
    np.testing.assert_allclose(r.measurements["measured"][:, 0], np.degrees(rate), rtol=1e-12)
