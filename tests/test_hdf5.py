"""The HDF5 store against the output contract (docs/output-format.md), on real files."""
import datetime
import os
import pathlib

import h5py
import numpy as np
import pandas as pd
import pytest

import linkpipe
from linkpipe.stores import hdf5

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

CONTRACT = ("driver_value", "time", "position", "velocity", "acceleration", "link_angle",
            "link_angular_velocity", "link_angular_acceleration", "spring_length", "spring_force",
            "spring_energy", "input_force", "input_force_lagrange", "status", "residual",
            "iterations", "condition")
FORCE_VARIABLES = ("spring_length", "spring_force", "spring_energy", "input_force",
                   "input_force_lagrange")


def expected_contract_variables(scene) -> set[str]:
    """The contract's variables a scene calls for, from the scene alone (SCENE_FORMAT.md:
    velocities when damping or inertia is on or outputs ask, accelerations when inertia is on
    or outputs ask, `vectors` asking for both; spring variables with springs; input forces
    when any effect is on; time with [time], or when every driver has a rate, no acceleration,
    and all agree)."""
    out = {"driver_value", "position", "link_angle", "status", "residual", "iterations",
           "condition"}
    effects, asked = set(scene.effects), set(scene.outputs.kinematics)
    acc = "inertia" in effects or "acceleration" in asked or bool(scene.outputs.vectors)
    vel = acc or "damping" in effects or "velocity" in asked
    if vel:
        out |= {"velocity", "link_angular_velocity"}
    if acc:
        out |= {"acceleration", "link_angular_acceleration"}
    if "springs" in effects and scene.springs:
        out |= {"spring_length", "spring_force", "spring_energy"}
    if effects:
        out |= {"input_force", "input_force_lagrange"}
    drivers = scene.drivers
    if scene.time is not None:  # a [time] sweep: its instants
        out.add("time")
    elif all(d.rate != 0 and d.acceleration == 0 for d in drivers):
        durations = {round(abs(d.to_value - d.from_value) / abs(d.rate), 9) for d in drivers}
        if len(durations) == 1:
            out.add("time")
    return out


def _written(result, tmp_path):
    path = tmp_path / f"{result.scene.name}.h5"
    hdf5.write(result, path)
    return path


def linkpipe_read(path, form="dataset"):
    """``linkpipe.read`` once the package exports it, else the store's own."""
    return getattr(linkpipe, "read", hdf5.read)(path, form)


def _strings(values) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(values).ravel()]


def test_every_variable_with_dims_units_and_values(result, tmp_path):
    path = _written(result, tmp_path)
    variables = result.variables()
    names = [v.name for v in variables]
    assert {"driver_value", "position", "link_angle", "status", "residual", "iterations",
            "condition"} <= set(names)
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["position"][:], result.position)
        for coord in result.coordinates():
            assert f[coord.name].is_scale
            assert f[coord.name].attrs["units"] == coord.units
            assert _strings(f[coord.name][:]) == _strings(coord.data)
        for var in variables:
            ds = f[var.name]
            assert hdf5.dimensions(ds) == var.dims, var.name
            assert ds.attrs["units"] == var.units, var.name
            assert ds.dtype == np.asarray(var.data).dtype, var.name
            np.testing.assert_array_equal(ds[()], var.data, err_msg=var.name)  # NaN == NaN
        assert set(CONTRACT) & set(f) == expected_contract_variables(result.scene)


def test_xarray_opens_it_labelled(result, tmp_path):
    path = _written(result, tmp_path)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        expected_coords = {"step", "point", "xy", "link", "driver"} | (
            {"spring"} if result.spring_names else set())
        assert expected_coords <= set(ds.coords)
        assert list(ds["point"].values) == list(result.point_names)
        assert list(ds["xy"].values) == ["x", "y"]
        assert list(ds["link"].values) == list(result.link_names)
        assert list(ds["driver"].values) == list(result.driver_names)
        assert list(ds["step"].values) == list(range(result.n_steps))
        if result.spring_names:
            assert list(ds["spring"].values) == list(result.spring_names)
        for var in result.variables():
            assert ds[var.name].dims == var.dims, var.name
            assert ds[var.name].attrs["units"] == var.units, var.name
            np.testing.assert_array_equal(ds[var.name].values, var.data, err_msg=var.name)
        np.testing.assert_array_equal(
            ds["position"].sel(point=result.point_names[-1], xy="y").values, result.position[:, -1, 1])


def test_status_flags_follow_cf(solve, tmp_path):
    path = _written(solve("fourbar_crank_rocker"), tmp_path)
    with h5py.File(path, "r") as f:
        status = f["status"]
        assert status.dtype == np.int8
        values = status.attrs["flag_values"]
        meanings = status.attrs["flag_meanings"].split()
        assert values.dtype == np.int8
        assert meanings[:4] == ["ok", "no_assembly", "singular", "not_converged"]
        np.testing.assert_array_equal(values, np.arange(len(meanings), dtype=np.int8))
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds["status"].attrs["flag_meanings"].split()[:4] == meanings[:4]


def test_root_attributes(result, tmp_path):
    path = _written(result, tmp_path)
    scene = result.scene
    with h5py.File(path, "r") as f:
        a = f.attrs
        assert a["linkpipe_version"] == linkpipe.__version__
        assert a["scene_toml"] == pathlib.Path(scene.path).read_text(encoding="utf-8")
        assert a["scene_path"] == str(scene.path)
        assert _strings(a["effects"]) == list(scene.effects)
        created = datetime.datetime.fromisoformat(a["created"])
        assert created.tzinfo is not None
        assert abs(datetime.datetime.now(datetime.timezone.utc) - created).total_seconds() < 600
        assert a["solver_tol"] == scene.solver.tol
        assert a["units_length"] == result.units()["length"]
        assert {k for k in a if k.startswith("seconds_")} == {f"seconds_{k}" for k in result.seconds}
        assert "seconds_positions" in a
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert list(np.atleast_1d(ds.attrs["effects"])) == list(scene.effects)
        assert ds.attrs["scene_toml"] == scene.text


def test_empty_effects_list_opens_in_xarray(solve, tmp_path):
    result = solve("fourbar_crank_rocker")
    assert result.scene.effects == ()
    path = _written(result, tmp_path)
    with h5py.File(path, "r") as f:
        assert f.attrs["effects"].shape == (0,)
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert len(ds.attrs["effects"]) == 0


def test_effects_off_means_absent_never_zero_filled(solve, tmp_path):
    rocker = _written(solve("fourbar_crank_rocker"), tmp_path)
    press = _written(solve("shear_press"), tmp_path)
    with h5py.File(rocker, "r") as f:
        assert not set(FORCE_VARIABLES) & set(f)
        assert "spring" not in f
        assert "velocity" in f and "acceleration" in f   # asked for by [outputs]
    with h5py.File(press, "r") as f:
        assert "velocity" not in f and "acceleration" not in f
        assert "link_angular_velocity" not in f
        assert "input_force" in f                        # effects = ["loads"]
        assert not {"spring_length", "spring_force", "spring_energy", "spring"} & set(f)


def test_dataframe_is_tidy_by_step(solve, tmp_path):
    result = solve("fourbar_crank_rocker")
    df = linkpipe_read(_written(result, tmp_path), "dataframe")
    assert isinstance(df, pd.DataFrame)
    assert df.index.name == "step"
    np.testing.assert_array_equal(df.index, np.arange(result.n_steps))
    p = result.point_names.index("P")
    np.testing.assert_array_equal(df["position.P.x"], result.position[:, p, 0])
    np.testing.assert_array_equal(df["position.P.y"], result.position[:, p, 1])
    np.testing.assert_array_equal(df["velocity.B.y"], result.velocity[:, result.point_names.index("B"), 1])
    np.testing.assert_array_equal(df["link_angle.crank"], result.link_angle[:, 0])
    np.testing.assert_array_equal(df["driver_value.crank"], result.driver_value[:, 0])
    assert df["status"].dtype == np.int8
    np.testing.assert_array_equal(df["status"], result.status)
    np.testing.assert_array_equal(df["time"], result.time)
    n_columns = sum(int(np.prod(np.shape(v.data)[1:])) for v in result.variables())
    assert df.shape == (result.n_steps, n_columns)


def test_dataframe_has_force_columns(solve, tmp_path):
    result = solve("basketball_goal")
    df = linkpipe_read(_written(result, tmp_path), "dataframe")
    _, input_force, _ = result.forces["input_force"]
    np.testing.assert_array_equal(df["input_force.theta3a"], input_force[:, 0])
    _, spring_force, _ = result.forces["spring_force"]
    np.testing.assert_array_equal(df["spring_force.right"], spring_force[:, 1])


def test_dataset_form(solve, tmp_path):
    result = solve("slider_crank")
    ds = linkpipe_read(_written(result, tmp_path))
    assert isinstance(ds, xr.Dataset)
    np.testing.assert_array_equal(ds["position"].values, result.position)
    np.testing.assert_array_equal(ds["time"].values, result.time)
    with pytest.raises(ValueError, match="dataframe"):
        linkpipe_read(tmp_path / "slider_crank.h5", "table")


def test_a_crash_mid_write_keeps_the_previous_file(solve, tmp_path, monkeypatch):
    result = solve("slider_crank")
    path = _written(result, tmp_path)
    before = path.read_bytes()
    written = []
    real = hdf5._write_variable

    def failing(f, var, scales, *rest):
        if var.name == "link_angle":
            raise RuntimeError("disk on fire")
        written.append(var.name)
        return real(f, var, scales, *rest)

    monkeypatch.setattr(hdf5, "_write_variable", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        hdf5.write(result, path)
    assert written == ["driver_value", "time", "driver_velocity", "driver_acceleration", "position",
                       "velocity", "acceleration"]  # part-way
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == [path.name]    # no temporary file left behind
    with pytest.raises(RuntimeError, match="disk on fire"):
        hdf5.write(result, tmp_path / "new.h5")
    assert os.listdir(tmp_path) == [path.name]
