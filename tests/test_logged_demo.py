"""configs/logged/: a tipper driven by a (synthetic) rig log, its loaded mass fitted to the
logged pressure. The log comes from make_tipper_log.py, a closed-form model of the tipper
written without linkpipe (law of cosines, power balance) plus stated pressure noise."""
import pathlib
import shutil
import sys

import numpy as np

import linkpipe
from linkpipe.fit import fit
from linkpipe.scene import load_scene

LOGGED = pathlib.Path(__file__).resolve().parents[1] / "configs" / "logged"
sys.path.insert(0, str(LOGGED))
import make_tipper_log as model  # noqa: E402


def test_the_shipped_log_is_what_its_script_writes(tmp_path):
    text = (LOGGED / "logs" / "tipper_run.csv").read_text()
    shutil.copy(LOGGED / "make_tipper_log.py", tmp_path)
    (tmp_path / "logs").mkdir()
    import runpy
    runpy.run_path(str(tmp_path / "make_tipper_log.py"), run_name="__main__")
    assert (tmp_path / "logs" / "tipper_run.csv").read_text() == text


def test_linkpipe_forces_along_the_log_equal_the_independent_model(tmp_path):
    """At the true mass, the cylinder force linkpipe computes from the logged stroke (a spline
    through 25 Hz samples) is the closed-form model's to 10 N of ~60 kN: the spline's error in
    the acceleration (inertia) is all that separates them (measured 3 N)."""
    text = (LOGGED / "dump_truck_logged.toml").read_text().replace("mass = 15000.0", "mass = 17500.0")
    path = LOGGED / "_true_mass.toml"
    try:
        path.write_text(text)
        r = linkpipe.solve(str(path))
    finally:
        path.unlink()
    assert r.message == f"all {r.n_steps} steps ok"
    force = r.forces["input_force"][1][:, 0]
    assert np.abs(force - model.cylinder_force(r.time)).max() < 10.0


def test_the_fit_recovers_the_mass_within_its_standard_error():
    res = fit(load_scene(str(LOGGED / "dump_truck_logged.toml")))
    assert res.stage1_solves == 1  # a mass only: the kinematics were solved once
    z = (res.fitted[0] - model.MASS_TRUE) / res.standard_error[0]
    assert abs(z) < 3, z
    # the residual left is the pressure noise: rms within 10 % of sigma (1001 samples)
    sigma = res.scene.measurements[0].sigma
    assert abs(res.after.measurements["rms"][0] / sigma - 1) < 0.1


def test_no_bias_over_other_noise_draws(tmp_path):
    """Six other noise seeds: each fit within 4 standard errors and their mean deviation near 0
    (the mean of six standard normal draws has standard deviation 0.41)."""
    shutil.copy(LOGGED / "dump_truck_logged.toml", tmp_path / "s.toml")
    (tmp_path / "logs").mkdir()
    t = np.arange(0.0, model.DURATION + 1e-9, 1.0 / model.RATE_HZ)
    s, _, _ = model.stroke(t)
    z = []
    for seed in range(1, 7):
        p = (model.cylinder_force(t) / model.BORE_AREA / 1e5
             + np.random.default_rng(seed).normal(0.0, model.PRESSURE_NOISE_BAR, len(t)))
        lines = ["t_s,stroke_mm,pressure_bar"] + [f"{a:.3f},{1000 * b:.4f},{c:.3f}"
                                                  for a, b, c in zip(t, s, p)]
        (tmp_path / "logs" / "tipper_run.csv").write_text("\n".join(lines) + "\n")
        res = fit(load_scene(str(tmp_path / "s.toml")))
        z.append((res.fitted[0] - model.MASS_TRUE) / res.standard_error[0])
    assert max(abs(x) for x in z) < 4 and abs(np.mean(z)) < 1.5, z
