"""What a failed step holds (docs/scene-format.md, "Results at steps that fail"), read back from
the HDF5 file: at a no_assembly, not_converged or no_input step every force-stage variable is
NaN, whatever its law does with a NaN length (a gas spring's clamp, a one-sided spring's slack
branch); at a singular step the positions and what they alone determine (spring lengths,
energies and forces, torsion angles and torques) are kept, every force the constraint Jacobian
gives (input force, multipliers, reactions) is NaN. The measurements' rms and max_abs are
taken over the steps where both sides are finite, so a failed step cannot pollute them."""
from __future__ import annotations

import pathlib

import h5py
import numpy as np

from linkpipe.__main__ import main
from linkpipe.status import NO_ASSEMBLY, NO_INPUT, OK, SINGULAR

ROOT = pathlib.Path(__file__).resolve().parents[2]

#: a crank O-A on a logged angle and a lever O2-P on a logged cylinder C-P, with a spring of
#: every kind, two torsion springs, gravity and three measurements
LOGGED = """\
[scene]
name = "every_spring"
units = { length = "m", mass = "kg", time = "s", force = "N" }

[points]
O = { x = 0.0, y = 0.0, fixed = true }
A = { x = 1.0, y = 0.0 }
O2 = { x = 0.0, y = -3.0, fixed = true }
C = { x = 1.5, y = -3.0, fixed = true }
P = { x = 1.0, y = -2.0 }

[[links]]
name = "crank"
points = ["O", "A"]

[[links]]
name = "lever"
points = ["O2", "P"]

[time]
log = "run"

[[logs]]
name = "run"
file = "run.csv"
time = "t"

[[drivers]]
name = "crank"
angle = ["O", "A"]
log = "run.angle_deg"

[[drivers]]
name = "cylinder"
distance = ["C", "P"]
log = "run.length_mm"
scale = 0.001

[analysis]
effects = ["gravity", "springs"]

[gravity]
g = [0.0, -9.81]

[[masses]]
link = "crank"
mass = 2.0
center = "A"

[[masses]]
link = "lever"
mass = 1.0
center = "P"

[[springs]]
name = "gas"
between = ["C", "A"]
kind = "gas"
force_extended = 40.0
extended_length = 5.0   # longer than the strut ever gets: in its stroke (version 3) at every step
dead_length = 0.5

[[springs]]
name = "cable"
between = ["O2", "A"]
kind = "tension_only"
k = 10.0
free_length = 2.0

[[springs]]
name = "bumper"
between = ["C", "P"]
kind = "compression_only"
k = 20.0
free_length = 5.0

[[springs]]
name = "coil"
between = ["O", "P"]
k = 30.0
free_length = 1.0

[[torsion_springs]]
name = "hinge"
links = ["crank", "ground"]
k = 5.0
free_angle = 10.0

[[torsion_springs]]
name = "elbow"
links = ["lever", "crank"]
k = 3.0
free_angle = -30.0

[[measurements]]
name = "gas_force"
log = "run.signal"
of = "spring_force.gas"

[[measurements]]
name = "cable_force"
log = "run.signal"
of = "spring_force.cable"

[[measurements]]
name = "crank_torque"
log = "run.signal"
of = "input_force.crank"
"""

#: step 1 misses the cylinder, step 3 the angle (no_input); at step 5 the cylinder's 3 m cannot
#: reach P (the lever is 1 m from O2, C 1.5 m from O2: at most 2.5 m): no_assembly
LOG = """\
t,angle_deg,signal,length_mm
0.0,10.0,0.0,1300.0
0.1,14.0,0.3,
0.25,20.0,0.74,1350.0
0.3,,0.89,1360.0
0.5,30.0,1.44,1400.0
0.6,34.0,1.69,3000.0
0.8,42.0,2.15,1460.0
1.0,50.0,2.52,1500.0
"""


def _run(tmp_path: pathlib.Path, scene: str, name: str) -> dict:
    (tmp_path / f"{name}.toml").write_text(scene)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / f"{name}.toml"), "--out", str(out), "--no-rrd",
                 "--quiet"]) == 0
    with h5py.File(out / f"{name}.h5", "r") as f:
        return {k: (f[k][()], dict(f[k].attrs)) for k in f if isinstance(f[k], h5py.Dataset)}


def test_failed_steps_hold_nan_for_every_spring_kind_and_force(tmp_path):
    (tmp_path / "run.csv").write_text(LOG)
    got = _run(tmp_path, LOGGED, "every_spring")
    status = got["status"][0]
    np.testing.assert_array_equal(status, [OK, NO_INPUT, OK, NO_INPUT, OK, NO_ASSEMBLY, OK, OK])
    failed = status != OK
    step_first = [k for k in got if k.startswith(("spring_", "torsion_spring_", "input_force",
                                                  "joint_force", "ground_reaction", "power",
                                                  "gravity_energy", "link_force"))]
    assert {"spring_force", "spring_energy", "spring_extension", "torsion_spring_torque",
            "input_force_lagrange", "joint_force", "ground_reaction"} <= set(step_first)
    for name in step_first:
        data = got[name][0]
        assert np.isnan(data[failed]).all(), name  # no law's clamp survives a failed step
        assert np.isfinite(data[~failed]).all(), name

    # the measurements' statistics over the steps where both sides are finite: the ok ones
    measured, residual = got["measured"][0], got["measured_residual"][0]
    force = got["spring_force"][0]
    np.testing.assert_array_equal(residual[:, 0], force[:, 0] - measured[:, 0])
    for j in range(3):
        r = residual[~failed, j]
        assert np.isnan(residual[failed, j]).all()
        np.testing.assert_allclose(got["measured_residual"][1]["rms"][j], np.sqrt(np.mean(r ** 2)),
                                   rtol=1e-15)
        np.testing.assert_allclose(got["measured_residual"][1]["max_abs"][j], np.abs(r).max(),
                                   rtol=1e-15)


def test_singular_steps_keep_what_positions_alone_give_and_no_force(tmp_path):
    """The cylinder-driven rocker over its whole stroke (singular at both dead centres) with a
    spring of each kind from the base C to the pin B, whose length is the cylinder's: at the two
    singular steps the spring lengths and energies are the closed forms at 0.2 and 1.8 m (the
    torsion spring's angle and energy at the rocker's angle); every force is NaN there, the
    springs' and the torsion spring's torque with the input force and every reaction, as the
    contract says ("singular steps keep their positions, with NaN derivatives and forces")."""
    scene = (ROOT / "configs" / "hard" / "cylinder_full_stroke.toml").read_text()
    scene = scene.replace('effects = ["loads"]', 'effects = ["loads", "springs", "damping"]')
    scene += """
[[springs]]
name = "coil"
between = ["C", "B"]
k = 100.0
free_length = 1.0

[[springs]]
name = "damped"
between = ["C", "B"]
k = 100.0
free_length = 1.0
damping = 3.0

[[springs]]
name = "cable"
between = ["C", "B"]
kind = "tension_only"
k = 50.0
free_length = 1.5

[[springs]]
name = "bumper"
between = ["C", "B"]
kind = "compression_only"
k = 20.0
free_length = 0.5

[[springs]]
name = "gas"
between = ["C", "B"]
kind = "gas"
force_extended = 40.0
extended_length = 2.0
dead_length = 0.1

[[torsion_springs]]
name = "hinge"
links = ["rocker", "ground"]
k = 5.0
free_angle = 0.0
"""
    got = _run(tmp_path, scene, "cylinder_full_stroke")
    status = got["status"][0]
    singular = status == SINGULAR
    assert list(np.flatnonzero(singular)) == [0, 160]
    for name in ("spring_force", "spring_damping_force", "torsion_spring_torque"):
        assert np.isnan(got[name][0][singular]).all(), name
        assert np.isfinite(got[name][0][~singular]).all(), name
    for name in ("spring_length", "spring_energy"):
        got[name] = (np.delete(got[name][0], 1, axis=1), got[name][1])
    length = got["spring_length"][0][singular]
    np.testing.assert_allclose(length, [[0.2] * 4, [1.8] * 4], atol=1e-8)  # the double root
    s = np.array([0.2, 1.8])[:, None]
    energy = np.column_stack([
        0.5 * 100.0 * (s - 1.0) ** 2, 0.5 * 50.0 * np.maximum(s - 1.5, 0) ** 2,
        0.5 * 20.0 * np.minimum(s - 0.5, 0) ** 2,
        40.0 * 1.9 * np.log(1.9 / (s - 0.1))])
    np.testing.assert_allclose(got["spring_energy"][0][singular], energy, rtol=1e-7)
    # the rocker O-B at the dead centres: B straight down (0.2 m: B between C and O, angle
    # -90 deg) and straight up (1.8 m: C, O, B in line, +90 deg); the hinge's free angle is 0
    angle = got["torsion_spring_angle"][0][singular][:, 0]
    np.testing.assert_allclose(angle, [-np.pi / 2, np.pi / 2], atol=1e-7)  # rad, the double root
    np.testing.assert_allclose(got["torsion_spring_energy"][0][singular][:, 0],
                               0.5 * 5.0 * angle ** 2, rtol=1e-14)
    for name in ("input_force", "input_force_lagrange", "joint_force", "ground_reaction"):
        data = got[name][0]
        assert np.isnan(data[singular]).all(), name
        assert np.isfinite(data[~singular]).all(), name
