"""Drivers from logged data (issue 14, item 2): [[logs]] read with pandas (.csv, .parquet),
log drivers through a spline, missing samples as no_input, and one clear error per bad log.

The known motion: crank angle = 40 + 30 sin(2 pi t / 3) degrees at unevenly spaced time stamps
(spacing 0.01 .. 0.03 s). The interpolating cubic spline's derivative error is bounded by
Hall & Meyer's constant for the complete cubic spline, |f' - s'| <= h^3 |f''''| / 24 (h the
largest spacing), which the tests take four times over for the not-a-knot ends and the
uneven mesh (spacing ratio up to 3).
"""
import pathlib
import tempfile

import h5py
import numpy as np
import pandas as pd
import pytest

import linkpipe
from linkpipe import closed_forms
from linkpipe.__main__ import main
from linkpipe.status import NO_INPUT, OK

CONFIGS = pathlib.Path(__file__).resolve().parent.parent / "configs"
CRANK_ROCKER = (CONFIGS / "fourbar_crank_rocker.toml").read_text()
V1_DRIVER = """from = 0.0
to = 360.0
steps = 361
rate = 572.9577951308232     # 10 rad/s in degrees per second"""
AMPLITUDE, MEAN, PERIOD = 30.0, 40.0, 3.0
W = 2 * np.pi / PERIOD


def angle(t):
    return MEAN + AMPLITUDE * np.sin(W * t)


def angle_rate(t):
    return AMPLITUDE * W * np.cos(W * t)


def stamps(n: int = 150, seed: int = 3) -> np.ndarray:
    """Uneven time stamps from 0: spacing drawn from 0.01 .. 0.03 s."""
    return np.r_[0.0, np.cumsum(np.random.default_rng(seed).uniform(0.01, 0.03, n - 1))]


def write_log(path: pathlib.Path, frame: pd.DataFrame) -> pathlib.Path:
    if path.suffix == ".csv":
        frame.to_csv(path, index=False)
    else:
        frame.to_parquet(path, index=False)
    return path


def encoder_frame(t=None, scale: float = 1.0) -> pd.DataFrame:
    t = stamps() if t is None else t
    return pd.DataFrame({"t": t, "crank_deg": angle(t) / scale, "other": np.ones(len(t))})


def scene_text(file: str = "enc.csv", column: str = "enc.crank_deg", time: str = 'log = "enc"',
               driver_extra: str = "", log_name: str = "enc") -> str:
    driver = f'log = "{column}"' + (f"\n{driver_extra}" if driver_extra else "")
    text = CRANK_ROCKER.replace(V1_DRIVER, driver)
    return text.replace("[[drivers]]", f'[time]\n{time}\n\n[[logs]]\nname = "{log_name}"\n'
                        f'file = "{file}"\ntime = "t"\n\n[[drivers]]', 1)


def write_scene(tmp_path, frame=None, file="enc.csv", **kw) -> pathlib.Path:
    write_log(tmp_path / file, encoder_frame() if frame is None else frame)
    path = tmp_path / "encoder.toml"
    path.write_text(scene_text(file=file, **kw))
    return path


def spline_velocity_bound(t: np.ndarray) -> float:
    """4 x h^3 |f''''| / 24 in degrees per second (see the module docstring)."""
    h = float(np.diff(t).max())
    return 4 * h ** 3 * AMPLITUDE * W ** 4 / 24


# ------------------------------------------------------------------ a known motion
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_logged_motion_is_reproduced(tmp_path, suffix):
    """Written as a real file, run through ``python -m linkpipe run``, read back with h5py: the
    instants are the stamps, driver values and positions exact at the samples (the four-bar's
    closed form there), velocities within the spline's error bound."""
    t = stamps()
    path = write_scene(tmp_path, encoder_frame(t, scale=1e-3), file="enc" + suffix,
                       driver_extra="scale = 1e-3")
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with h5py.File(tmp_path / "out" / "fourbar_crank_rocker.h5", "r") as f:
        np.testing.assert_array_equal(f["time"][:], t)
        value, rate = f["driver_value"][:, 0], f["driver_velocity"][:, 0]
        position, velocity = f["position"][:], f["velocity"][:]
        assert (f["status"][:] == OK).all()
    np.testing.assert_allclose(value, angle(t), rtol=1e-13, atol=0)
    bound = spline_velocity_bound(t)
    error = np.abs(rate - angle_rate(t)).max()
    assert error <= bound, (error, bound)
    scene = linkpipe.load_scene(str(path))
    form = closed_forms.detect(scene, position[0])
    X, V, _ = closed_forms.evaluate(form, scene, np.radians(angle(t)), np.radians(angle_rate(t)), 0.0)
    assert np.abs(X - position).max() <= 1e-11
    # the velocity error is the crank rate's error times |dX/dtheta| = |V| / |omega|
    lever = np.nanmax(np.abs(V).max(axis=(1, 2)) / np.abs(np.radians(angle_rate(t))).clip(1e-3))
    assert np.abs(V - velocity).max() <= np.radians(bound) * lever


def test_a_time_sweep_samples_the_spline_between_the_stamps(tmp_path):
    """[time] from/to/steps within the log: the values are the spline's, within the spline's
    value bound (5/384 h^4 |f''''|, times four) of the known motion."""
    t = stamps()
    path = write_scene(tmp_path, time="from = 0.5\nto = 2.5\nsteps = 301")
    r = linkpipe.solve(str(path))
    assert (r.status == OK).all()
    grid = np.linspace(0.5, 2.5, 301)
    np.testing.assert_allclose(r.time, grid, rtol=0, atol=1e-15)
    h = float(np.diff(t).max())
    assert np.abs(r.driver_value[:, 0] - angle(grid)).max() <= 4 * 5 / 384 * h ** 4 * AMPLITUDE * W ** 4
    assert np.abs(r.driver_velocity[:, 0] - angle_rate(grid)).max() <= spline_velocity_bound(t)


def test_smoothing_keeps_a_straight_line_exact(tmp_path):
    """A smoothing spline (smoothing > 0) of samples on a line is that line (its curvature
    penalty and residual are both zero there): value, rate 25 deg/s and acceleration 0."""
    t = stamps(60)
    frame = pd.DataFrame({"t": t, "crank_deg": 10.0 + 25.0 * t})
    r = linkpipe.solve(str(write_scene(tmp_path, frame, driver_extra="smoothing = 0.5")))
    # to rounding: the penalised system's condition grows as smoothing / h^3 (here ~1e7),
    # measured 1e-9 deg in value and 2e-9 deg/s in rate
    np.testing.assert_allclose(r.driver_value[:, 0], 10.0 + 25.0 * t, rtol=0, atol=1e-8)
    np.testing.assert_allclose(r.driver_velocity[:, 0], 25.0, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r.driver_acceleration[:, 0], 0.0, rtol=0, atol=1e-5)


def test_smoothing_reduces_noise(tmp_path):
    """Noise of 0.05 deg on the samples: the smoothing spline's rate is closer to the true
    rate than the interpolating spline's (which follows every noisy sample)."""
    t = stamps(300)
    noisy = angle(t) + np.random.default_rng(1).normal(0.0, 0.05, len(t))
    frame = pd.DataFrame({"t": t, "crank_deg": noisy})
    errors = {}
    for smoothing in (0.0, 1e-4):
        path = write_scene(tmp_path, frame, driver_extra=f"smoothing = {smoothing}")
        r = linkpipe.solve(str(path))
        errors[smoothing] = np.sqrt(np.mean((r.driver_velocity[:, 0] - angle_rate(t)) ** 2))
    assert errors[1e-4] < 0.2 * errors[0.0]


# ------------------------------------------------------------------ missing samples
def test_a_missing_sample_is_no_input_and_its_neighbours_are_unharmed(tmp_path):
    """An empty cell at row 60: that step is no_input with every moving quantity NaN; every
    other step is ok with the same positions as without the gap (the spline still passes
    through each finite sample). The spline's derivatives near the gap change (one cubic piece
    spans it): at the neighbouring samples by at most the interpolation error bound, decaying
    about 0.27 per sample away (the spline's influence factor 2 - sqrt(3)), so that 10 samples
    away the change is below 1e-4 of the change next to the gap."""
    t = stamps()
    full = linkpipe.solve(str(write_scene(tmp_path)))
    frame = encoder_frame(t)
    frame.loc[60, "crank_deg"] = np.nan
    path = write_scene(tmp_path, frame)
    assert ",," in (tmp_path / "enc.csv").read_text()  # a truly empty cell in the file
    r = linkpipe.solve(str(path))
    assert r.status[60] == NO_INPUT
    others = np.arange(len(t)) != 60
    assert (r.status[others] == OK).all()
    moving = ~r.model.fixed
    for arr in (r.position, r.velocity, r.acceleration):
        assert np.isnan(arr[60][moving]).all()
    assert np.isnan(r.driver_value[60]).all() and np.isnan(r.driver_velocity[60]).all()
    assert np.isnan(r.link_angle[60]).all()
    np.testing.assert_allclose(r.position[others], full.position[others], rtol=0, atol=1e-11)
    change = np.abs(r.driver_velocity[:, 0] - full.driver_velocity[:, 0])
    assert change[[59, 61]].max() <= 2 * spline_velocity_bound(t) + 1e-12
    assert change[[49, 71]].max() <= 1e-4 * change[[59, 61]].max()
    with h5py.File(_run(tmp_path, path), "r") as f:
        assert f["status"][60] == NO_INPUT
        assert f["status"].attrs["flag_meanings"].split()[NO_INPUT] == "no_input"


def _run(tmp_path, path) -> pathlib.Path:
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    return tmp_path / "out" / "fourbar_crank_rocker.h5"


# ------------------------------------------------------------------ bad logs
def _bad_time(t):
    t = t.copy()
    t[7] = t[6]
    return t


BAD_LOGS = {
    "unknown column": (dict(column="enc.crank_dg"), ("drivers", "log", '"crank_deg"')),
    "time not increasing": (dict(frame=encoder_frame(_bad_time(stamps()))),
                            ("logs", "time", "row 8 (line 9 of the file)")),
    "text in a number column": (dict(frame=encoder_frame().astype({"crank_deg": object})
                                     .assign(crank_deg=lambda f: f.crank_deg.where(
                                         f.index != 12, "about 40"))),
                                ("drivers", "log", 'row 13 (line 14 of the file), column "crank_deg"')),
    "log shorter than [time]": (dict(time="from = 0.0\nto = 9.0\nsteps = 10"),
                                ("time", "to", "covers only")),
    "missing file": (dict(file_in_scene="nothere.csv"), ("logs", "file", "no such log file")),
    "log not in [[logs]]": (dict(column="run9.crank_deg"), ("drivers", "log", "no [[logs]]")),
    "empty time stamp": (dict(frame=encoder_frame().assign(
        t=lambda f: f.t.where(f.index != 4, np.nan))), ("logs", "time", "row 5")),
}


@pytest.mark.parametrize("case", sorted(BAD_LOGS))
def test_each_bad_log_is_one_clear_error_and_nothing_is_written(tmp_path, capsys, case):
    kw, (table, key, words) = BAD_LOGS[case]
    kw = dict(kw)
    frame = kw.pop("frame", None)
    write_log(tmp_path / "enc.csv", encoder_frame() if frame is None else frame)
    path = tmp_path / "encoder.toml"
    path.write_text(scene_text(file=kw.pop("file_in_scene", "enc.csv"), **kw))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(path) in err and f"[{table}" in err and f"] {key}:" in err and words in err, err
    assert "Traceback" not in err and " — " in err  # what to do
    assert not out.exists() or not any(out.iterdir())


def test_unknown_column_lists_the_nearest_names(tmp_path):
    path = write_scene(tmp_path, column="enc.crank")
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.load_scene(str(path))
    assert 'nearest columns: "crank_deg"' in str(err.value)


@pytest.mark.parametrize("stamp", ["datetime", "timedelta", "datetime_utc"])
def test_a_parquet_time_column_of_dates_is_seconds_from_its_first_row(tmp_path, stamp):
    """A Parquet log whose time column holds timestamps (or durations) drives the sweep
    exactly as the same log with seconds: the dates are seconds from the first row (they
    were read as nanoseconds labelled "s")."""
    t = stamps()
    seconds = write_scene(tmp_path, encoder_frame(t), file="enc_s.parquet")
    by_seconds = linkpipe.solve(str(seconds))
    frame = encoder_frame(t)
    delta = pd.to_timedelta(np.round(t * 1e9).astype(np.int64), unit="ns")
    origin = pd.Timestamp("2026-03-01 08:00:00", tz="UTC" if stamp == "datetime_utc" else None)
    frame["t"] = delta if stamp == "timedelta" else origin + delta
    dated = write_scene(tmp_path, frame, file="enc_d.parquet")
    by_dates = linkpipe.solve(str(dated))
    np.testing.assert_allclose(by_dates.time, by_seconds.time, rtol=0, atol=1e-9)  # ns stamps
    np.testing.assert_allclose(by_dates.position, by_seconds.position, rtol=0, atol=1e-9)
    assert (by_dates.status == OK).all()


@pytest.mark.parametrize("stamp", ["date", "date_offset", "duration"])
def test_a_csv_time_column_of_dates_is_seconds_from_its_first_row(tmp_path, stamp):
    """A rig's CSV whose time column holds ISO 8601 dates ("2026-03-01 08:00:00.123456789",
    or with a UTC offset that changes mid-log) or "hh:mm:ss.f" durations drives the sweep as
    the same log in seconds: seconds from the first row (to the nanoseconds written)."""
    t = stamps()
    by_seconds = linkpipe.solve(str(write_scene(tmp_path, encoder_frame(t), file="enc_s.csv")))
    delta = pd.to_timedelta(np.round(t * 1e9).astype(np.int64), unit="ns")
    frame = encoder_frame(t)
    if stamp == "duration":  # 00:00:01.234567890
        frame["t"] = [f"{int(d.total_seconds()) // 3600:02d}:{int(d.total_seconds()) // 60 % 60:02d}:"
                      f"{d.total_seconds() % 60:012.9f}" for d in delta]
    else:
        when = pd.Timestamp("2026-03-01 08:00:00", tz="UTC") + delta
        if stamp == "date":
            frame["t"] = [w.strftime("%Y-%m-%d %H:%M:%S.") + f"{w.microsecond * 1000 + w.nanosecond:09d}"
                          for w in when]
        else:  # the second half of the log written in +02:00, the same instants
            frame["t"] = [(w if i < len(when) // 2 else w.tz_convert("+02:00")).isoformat()
                          for i, w in enumerate(when)]
    by_stamps = linkpipe.solve(str(write_scene(tmp_path, frame, file="enc_d.csv")))
    np.testing.assert_allclose(by_stamps.time, by_seconds.time, rtol=0, atol=2e-9)
    np.testing.assert_allclose(by_stamps.position, by_seconds.position, rtol=0, atol=1e-8)
    assert (by_stamps.status == OK).all()


def test_a_csv_date_column_with_a_stamp_that_is_not_a_date_names_its_row(tmp_path):
    """Dates in every row but one: that row and the first row's form, not "not a number"."""
    t = stamps(5)
    frame = encoder_frame(t)
    frame["t"] = [f"2026-03-01 08:00:0{i}" for i in range(5)]
    frame.loc[3, "t"] = "08:00:03"
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.solve(str(write_scene(tmp_path, frame)))
    assert (err.value.table, err.value.key) == ('logs "enc"', "time")
    assert 'row 4 (line 5 of the file), column "t": "08:00:03" is not a date' in err.value.message
    assert "ISO 8601" in err.value.hint


def rig_csv(path: pathlib.Path, t_ms: np.ndarray, deg: np.ndarray, units_row: bool = True):
    """A rig's CSV: time in milliseconds and, under the header, a row of units."""
    rows = ["t,crank_deg,other"] + (["ms,deg,-"] if units_row else [])
    rows += [f"{a!r},{b!r},1" for a, b in zip(t_ms.tolist(), deg.tolist())]
    path.write_text("\n".join(rows) + "\n")


def test_a_time_column_in_milliseconds_under_a_units_row(tmp_path):
    """time_scale = 0.001 and skip_rows = 1 read a rig's log (ms, a units row) as the same
    log written in seconds without one: the same instants and positions, bit for bit."""
    t = stamps()
    by_seconds = linkpipe.solve(str(write_scene(tmp_path, encoder_frame(t), file="enc_s.csv")))
    rig_csv(tmp_path / "rig.csv", t * 1000.0, angle(t))
    path = tmp_path / "rig.toml"
    path.write_text(scene_text(file="rig.csv").replace(
        'time = "t"', 'time = "t"\ntime_scale = 0.001\nskip_rows = 1'))
    by_ms = linkpipe.solve(str(path))
    # t * 1000 * 0.001 is t to a rounding or two: 1e-15 s
    np.testing.assert_allclose(by_ms.time, by_seconds.time, rtol=0, atol=1e-15)
    np.testing.assert_allclose(by_ms.position, by_seconds.position, rtol=0, atol=1e-12)
    assert (by_ms.status == OK).all()


@pytest.mark.parametrize("units_row, extra, key, words", [
    (True, "", "time", ['row 1 (line 2 of the file), column "t": "ms" is not a number',
                        "if it is a row of units under the header, skip_rows = 1"]),
    (True, "skip_rows = 1\ntime_scale = -1.0", "time_scale", ["must be positive"]),
    (False, "skip_rows = 2", "time", ["row 3 (line 6 of the file)", "does not increase"]),
])
def test_rig_log_mistakes_name_the_line_and_the_key(tmp_path, units_row, extra, key, words):
    """A units row without skip_rows points to it; lines are the file's own, skipped rows
    counted (line 6: header, 2 skipped, rows 1..3)."""
    t = np.arange(8) * 0.01
    ms = t * 1000.0
    if not units_row:  # skip_rows = 2 drops the first two samples: row 3 repeats a time
        ms[4] = ms[3]
    rig_csv(tmp_path / "rig.csv", ms, angle(t), units_row)
    path = tmp_path / "rig.toml"
    path.write_text(scene_text(file="rig.csv").replace('time = "t"', f'time = "t"\n{extra}'))
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.load_scene(str(path))
    assert (err.value.table, err.value.key) == ('logs "enc"', key), str(err.value)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_csv_dates_with_and_without_an_offset_are_named(tmp_path):
    """Naive stamps would be read as UTC beside +02:00 ones, two hours apart: a scene error
    naming the first stamp unlike the first row's."""
    frame = encoder_frame(np.arange(5) * 0.5)
    frame["t"] = [f"2026-03-01T08:00:0{i}+02:00" for i in range(5)]
    frame.loc[2, "t"] = "2026-03-01T08:00:02"
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.load_scene(str(write_scene(tmp_path, frame)))
    assert err.value.key == "time"
    assert 'row 3 (line 4 of the file), column "t": "2026-03-01T08:00:02" has no UTC offset' in str(err.value)


def test_skip_rows_is_for_csv_and_time_scale_for_numbers(tmp_path):
    """A Parquet log has no rows under its header to skip; a column of dates is seconds
    already: each a scene error naming its key."""
    write_log(tmp_path / "enc.parquet", encoder_frame())
    path = tmp_path / "p.toml"
    path.write_text(scene_text(file="enc.parquet").replace('time = "t"', 'time = "t"\nskip_rows = 1'))
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.load_scene(str(path))
    assert err.value.key == "skip_rows" and "Parquet" in err.value.message
    frame = encoder_frame(np.arange(5) * 0.5)
    frame["t"] = [f"2026-03-01 08:00:0{i}" for i in range(5)]
    write_log(tmp_path / "d.csv", frame)
    path.write_text(scene_text(file="d.csv").replace('time = "t"', 'time = "t"\ntime_scale = 0.001'))
    with pytest.raises(linkpipe.SceneError) as err:
        linkpipe.load_scene(str(path))
    assert err.value.key == "time_scale" and "dates or durations" in err.value.message


def test_a_ragged_csv_row_is_named_in_one_line(tmp_path, capsys):
    """A data row with one field more than the header (line 6 of the file): one line naming
    the line and both counts, not the CSV parser's own two-line text."""
    write_log(tmp_path / "enc.csv", encoder_frame())
    lines = (tmp_path / "enc.csv").read_text().splitlines()
    header = len(lines[0].split(","))
    lines[5] += ",9.0"
    (tmp_path / "enc.csv").write_text("\n".join(lines) + "\n")
    path = tmp_path / "encoder.toml"
    path.write_text(scene_text(file="enc.csv"))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f'error: {path}: [logs "enc"] file: cannot read "{tmp_path / "enc.csv"}": '
                   f"line 6 has {header + 1} fields, the header {header} — give every row the "
                   "header's columns (a comma inside a value needs quotes)"), err


def test_too_few_samples_for_a_smoothing_spline_says_where_the_count_comes_from():
    """Three samples: enough for the interpolating spline (2), not for a smoothing one (5):
    the message says the 5 comes from smoothing and that smoothing = 0 would take them."""
    from linkpipe.scene.timing import MIN_SMOOTHING_SAMPLES

    assert MIN_SMOOTHING_SAMPLES == 5
    with tempfile.TemporaryDirectory() as folder:
        path = write_scene(pathlib.Path(folder), encoder_frame(np.array([0.0, 0.1, 0.2])),
                           driver_extra="smoothing = 0.5")
        with pytest.raises(linkpipe.SceneError) as err:
            linkpipe.load_scene(str(path))
    assert (err.value.table, err.value.key) == ('drivers "crank"', "log")
    assert ("has 3 value(s): a smoothing spline (smoothing = 0.5) needs at least 5; the "
            "interpolating one (smoothing = 0) needs 2 — give the log more samples, or set "
            "smoothing = 0") in str(err.value)
