"""What friction costs (issue 35), each against a reference run in the same process.

Row 1 times the force stage (``linkpipe.forces.compute_forces``, stage 1 solved once and
shared) of a 100,000-step excavator arm (configs/excavator_arm.toml with masses on boom,
stick and bucket, gravity, inertia and the digging load), with friction at its six pins and
in its three cylinders' seals, against the same stage without friction, each in its default
chunks of steps (FORCE_CHUNK; FRICTION_CHUNK with pin friction). Target: <= 2x. A reference
line gives the frictionless stage in FRICTION_CHUNK chunks too, and the ratio against it.

Row 2 times ``linkpipe.fit`` of mass + seal Coulomb + seal viscous over a 100,001-row
raise/lower log (configs/logged/make_tipper_friction_log.py at 1250 Hz; the scene of
configs/logged/dump_truck_friction.toml, with its hinge pin friction), from reading the scene
to the fitted values. Target: <= 5 s.

Run: python benchmarks/bench_friction.py (about half a minute).
"""
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "configs" / "logged"))

import linkpipe  # noqa: E402
from linkpipe.forces import compute_forces  # noqa: E402
from linkpipe.output_units import units_of  # noqa: E402
from linkpipe.scene.parse import parse_scene  # noqa: E402

MASSES = '''center = "G"
inertia = 300.0

[[masses]]
link = "boom"
mass = 1800.0
center = [2.8, 0.3]
inertia = 5000.0

[[masses]]
link = "stick"
mass = 900.0
center = [1.4, 0.1]
inertia = 900.0
'''
FRICTION = '''
[[friction]]
name = "pins"
joints = ["O", "T", "N", "K", "M", "L"]
mu = 0.15
pin_radius = 0.05

[[friction]]
name = "boom_seal"
driver = "boom_cylinder"
coulomb = 2000.0
viscous = 10000.0

[[friction]]
name = "stick_seal"
driver = "stick_cylinder"
coulomb = 1500.0
viscous = 8000.0

[[friction]]
name = "bucket_seal"
driver = "bucket_cylinder"
coulomb = 1000.0
viscous = 6000.0
'''


def best_of(fn, n=3):
    """(wall, cpu) seconds of ``fn``, the best of ``n`` runs each (CPU: this process's time,
    steadier than wall time on a shared machine)."""
    walls, cpus = [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def excavator():
    text = (ROOT / "configs/excavator_arm.toml").read_text()
    text = text.replace("steps = 201", "steps = 100001").replace('center = "G"\n', MASSES)
    plain = text.replace('effects = ["gravity", "loads"]',
                         'effects = ["gravity", "inertia", "loads"]')
    with_friction = plain.replace('"inertia", "loads"]', '"inertia", "loads", "friction"]') + FRICTION
    path = str(ROOT / "configs/excavator_arm.toml")
    a, b = parse_scene(plain, path), parse_scene(with_friction, path)
    r = linkpipe.solve(a)
    motion, units = r.kinematics.motion(), units_of(a)
    # the same stage 1 serves both (friction adds no kinematics: velocities were on already)
    from linkpipe.model import build_model
    model_b = build_model(b)
    from linkpipe.forces import FRICTION_CHUNK
    # each with its default chunk of steps (what a run does: FORCE_CHUNK without friction,
    # FRICTION_CHUNK with pin friction); the frictionless stage at FRICTION_CHUNK too, a
    # reference showing how much of the ratio is the chunk size alone
    (w0, c0), (w1, c1), (w2, c2) = (
        best_of(lambda: compute_forces(r.model, motion, units)),
        best_of(lambda: compute_forces(model_b, motion, units)),
        best_of(lambda: compute_forces(r.model, motion, units, chunk=FRICTION_CHUNK)))
    f = compute_forces(model_b, motion, units)
    ratio = c1 / c0
    print(f"excavator arm, 100,001 steps, force stage (compute_forces, best of 3): without "
          f"friction {w0:.3f} s wall / {c0:.3f} s CPU, with friction at 6 pins and 3 seals "
          f"{w1:.3f} s wall / {c1:.3f} s CPU: {ratio:.2f}x CPU, {w1 / w0:.2f}x wall (target <= 2x: "
          f"{'MET' if ratio <= 2 else 'NOT MET'}); steps not ok {int((f.status != 0).sum())}")
    print(f"  reference, both in chunks of {FRICTION_CHUNK} steps: without friction "
          f"{w2:.3f} s wall / {c2:.3f} s CPU: with friction {c1 / c2:.2f}x CPU, "
          f"{w1 / w2:.2f}x wall")


def fit():
    from make_tipper_friction_log import write

    from linkpipe.fit import fit as run_fit

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        (tmp / "logs").mkdir()
        write(tmp / "logs" / "tipper_raise_lower.csv", rate_hz=1250.0)
        scene = tmp / "scene.toml"
        scene.write_text((ROOT / "configs/logged/dump_truck_friction.toml").read_text())
        t0, c0 = time.perf_counter(), time.process_time()
        result = run_fit(linkpipe.load_scene(scene))
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        rows = result.after.n_steps
    values = ", ".join(f"{n} {v:.6g} +- {e:.3g}" for n, v, e in
                       zip(result.names, result.fitted, result.standard_error))
    print(f"fit of mass + Coulomb + viscous over a {rows:,}-row raise/lower log (load_scene + "
          f"fit): {seconds:.2f} s wall, {cpu:.2f} s CPU (target <= 5 s: "
          f"{'MET' if cpu <= 5 else 'NOT MET'} by CPU, {'MET' if seconds <= 5 else 'NOT MET'} by "
          f"wall); {result.solves} solves; {values}")


if __name__ == "__main__":
    excavator()
    fit()
