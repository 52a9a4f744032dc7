"""Forward dynamics against its targets (issue 31), each row printed with what it times, the
target and a verdict (not a test: timings on a shared machine are noisy):

    .venv/bin/python benchmarks/bench_dynamics.py            # every case (about a minute)
    .venv/bin/python benchmarks/bench_dynamics.py --no-exudyn

1. Andrews' squeezing mechanism (IFToMM A03, configs/dynamics/andrews_squeezer.toml) to
   0.03 s with |beta error| <= 1e-6 rad against the Test Set's 15.81077119629904 rad: the
   loosest rtol of 1e-6, 1e-7, ... that meets it, and the wall time of ``linkpipe.solve`` (the
   whole run: integration, the output instants' positions, forces and Result; median of 3)
   beside EXUDYN's generalized-alpha (``pip install exudyn``; spectral radius 1, its most
   accurate setting) on the same model (the scene's bodies, pins, spring and torque translated
   below), at the largest step h = 1e-5 / 2^k that meets the same error, timing
   ``mbs.SolveDynamic`` alone (the model built before the clock starts; median of 3).
   Target: linkpipe's time <= EXUDYN's.
2. The pendulum (IFToMM A01) over 10 s: max |energy_error| / (m g L). Target <= 1e-8.
3. A chain of 2N + 1 links (the N-four-bar hanging 30 degrees off, a pendulum of parallel
   rods: configs/dynamics/make_n_fourbar.py --hanging) over 10 s at rtol 1e-8, N = 5, 10, 20
   (11, 21, 41 links): wall time of the integration and per right-hand-side evaluation.
   Target: the cost grows at most linearly in links (the 41-link time over the 11-link time
   at most 41 / 11).
"""
from __future__ import annotations

import argparse
import importlib.util
import pathlib
import re
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import linkpipe  # noqa: E402
from linkpipe.model import build_model  # noqa: E402
from linkpipe.scene import parse_scene  # noqa: E402

DYN = ROOT / "configs" / "dynamics"
BETA, BETA_DOT = 15.81077119629904, 1139.920302151208


def median_time(fn, repeats=3):
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return value, float(np.median(times))


def with_dynamics(text: str, **keys) -> str:
    for key, value in keys.items():
        text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value!r}", text, count=1)
    return text


# -- 1. Andrews ------------------------------------------------------------------------------

def andrews_linkpipe():
    """(rtol, |beta error|, the Result, a function that runs it): the loosest rtol of the
    ladder that meets |beta error| <= 1e-6."""
    text = (DYN / "andrews_squeezer.toml").read_text()
    for rtol in (1e-6, 5e-7, 2e-7, 1e-7, 5e-8, 2e-8, 1e-8, 5e-9, 2e-9, 1e-9, 1e-10):
        scene = parse_scene(with_dynamics(text, rtol=rtol), "andrews_squeezer.toml")
        result = linkpipe.solve(scene)
        err = abs(np.deg2rad(result.driver_value[-1, 0]) - BETA)
        if err <= 1e-6:
            return rtol, err, result, lambda: linkpipe.solve(scene)
    raise SystemExit("no rtol down to 1e-10 met |beta error| <= 1e-6")


def exudyn_model(scene):
    """The scene's links as EXUDYN 2D rigid bodies (mass, inertia about the centre), its pins
    as revolute joints (bodies meeting at a point chained pairwise; a fixed point pins each
    body it carries to ground), its linear springs as spring-dampers, its first driver's force
    as a torque on the link that carries the driver's points. Returns (mbs, crank node)."""
    import exudyn as exu
    from exudyn.itemInterface import (LoadTorqueVector, MarkerBodyPosition, MarkerBodyRigid,
                                      NodeRigidBody2D, ObjectConnectorSpringDamper, ObjectGround,
                                      ObjectRigidBody2D, RevoluteJoint2D)

    model = build_model(scene)
    X0, names = model.start_position, model.point_names
    idx = {n: i for i, n in enumerate(names)}
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround(referencePosition=[0, 0, 0]))
    masses = {m.link: m for m in scene.masses}
    bodies = {}
    for link in scene.links:
        a, b = X0[idx[link.points[0]]], X0[idx[link.points[1]]]
        d = b - a
        L, phi = np.hypot(*d), np.arctan2(d[1], d[0])
        m = masses[link.name]
        u, v = m.center
        G = a + (u * d + v * np.array([-d[1], d[0]])) / L
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[G[0], G[1], phi]))
        body = mbs.AddObject(ObjectRigidBody2D(physicsMass=m.mass, inertia=m.inertia,
                                               nodeNumber=node))
        R = np.array([[np.cos(phi), np.sin(phi)], [-np.sin(phi), np.cos(phi)]])
        bodies[link.name] = (body, node, G, R)

    def marker(point, link=None):
        if link is None and scene.points[idx[point]].fixed:
            x, y = X0[idx[point]]
            return mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[x, y, 0]))
        link = link or next(ln.name for ln in scene.links if point in ln.points)
        body, _, G, R = bodies[link]
        loc = R @ (X0[idx[point]] - G)
        return mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=[loc[0], loc[1], 0]))

    for p in names:
        on = [ln.name for ln in scene.links if p in ln.points]
        if scene.points[idx[p]].fixed:
            for ln in on:
                mbs.AddObject(RevoluteJoint2D(markerNumbers=[marker(p), marker(p, ln)]))
        else:
            for l1, l2 in zip(on[:-1], on[1:]):
                mbs.AddObject(RevoluteJoint2D(markerNumbers=[marker(p, l1), marker(p, l2)]))
    for s in scene.springs:
        mbs.AddObject(ObjectConnectorSpringDamper(
            markerNumbers=[marker(s.between[0]), marker(s.between[1])], stiffness=s.k,
            referenceLength=s.free_length, damping=0.0))
    d = scene.drivers[0]
    crank = next(ln.name for ln in scene.links if set(d.points) <= set(ln.points))
    torque = mbs.AddMarker(MarkerBodyRigid(bodyNumber=bodies[crank][0]))
    mbs.AddLoad(LoadTorqueVector(markerNumber=torque, loadVector=[0, 0, d.force]))
    mbs.Assemble()
    return mbs, bodies[crank][1]


def andrews_exudyn():
    """(h, |beta error|, version, a function that builds the model and returns the timed
    SolveDynamic's seconds): the largest h = 1e-5 / 2^k that meets |beta error| <= 1e-6."""
    import exudyn as exu

    scene = linkpipe.load_scene(DYN / "andrews_squeezer.toml")
    h = 1e-5
    while h > 1e-8:
        ss = exu.SimulationSettings()
        ss.timeIntegration.endTime = 0.03
        ss.timeIntegration.numberOfSteps = int(round(0.03 / h))
        ss.timeIntegration.verboseMode = 0
        ss.timeIntegration.generalizedAlpha.spectralRadius = 1.0
        ss.solutionSettings.writeSolutionToFile = False

        def run(ss=ss):  # a fresh model each time: the clock runs on SolveDynamic alone
            mbs, node = exudyn_model(scene)
            t0 = time.perf_counter()
            mbs.SolveDynamic(ss)
            seconds = time.perf_counter() - t0
            return seconds, float(np.ravel(mbs.GetNodeOutput(node, exu.OutputVariableType.Rotation))[-1])

        _, phi = run()
        err = abs(phi - BETA)
        if err <= 1e-6:
            return h, err, exu.__version__, lambda: run()[0]
        h /= 2
    raise SystemExit("EXUDYN: no step down to 1e-8 s met |beta error| <= 1e-6")


# -- 2. pendulum -----------------------------------------------------------------------------

def pendulum():
    result, seconds = median_time(lambda: linkpipe.solve(DYN / "pendulum_a01.toml"), 1)
    return float(np.nanmax(np.abs(result.forces["energy_error"][1]))) / (1.0 * 9.81 * 1.0), seconds


# -- 3. chain --------------------------------------------------------------------------------

def chain(n: int):
    spec = importlib.util.spec_from_file_location("make_n_fourbar", DYN / "make_n_fourbar.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    scene = parse_scene(gen.scene_text(n, hanging=True, to=10.0, output_step=0.01, rtol=1e-8),
                        f"chain{n}.toml")
    from linkpipe.dynamics import equations_of, integrate

    eqs = equations_of(scene)
    traj, seconds = median_time(lambda: integrate(scene, eqs), 1)
    return 2 * n + 1, seconds, seconds / traj.evaluations, traj.steps, traj.evaluations


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-exudyn", action="store_true")
    args = ap.parse_args(argv)
    print("1. Andrews' squeezer to 0.03 s, |beta error| <= 1e-6 rad")
    rtol, err, result, run_linkpipe = andrews_linkpipe()
    exudyn = None
    if not args.no_exudyn:
        try:
            exudyn = andrews_exudyn()
        except ImportError:
            print("   EXUDYN: not installed (pip install exudyn): no comparison")
    # round-robin, so that the shared machine's load falls on both alike
    ours, theirs = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        run_linkpipe()
        ours.append(time.perf_counter() - t0)
        if exudyn is not None:
            theirs.append(exudyn[3]())
    wall = float(np.median(ours))
    print(f"   linkpipe.solve (the whole run: integration, output instants, forces, Result; "
          f"median of 5): {wall:.3f} s at rtol {rtol:g} (|beta error| {err:.2e} rad; "
          f"{result.time_note})")
    if exudyn is not None:
        h, xerr, version, _ = exudyn
        xwall = float(np.median(theirs))
        print(f"   EXUDYN {version} generalized-alpha (SolveDynamic alone, median of 5, "
              f"alternating with linkpipe's runs): {xwall:.3f} s at h = {h:.3g} s "
              f"({int(round(0.03 / h))} steps; |beta error| {xerr:.2e} rad)")
        print(f"   ratio linkpipe / EXUDYN {wall / xwall:.2f} (target <= 1): "
              f"{'MET' if wall <= xwall else 'MISSED'}")
    elif args.no_exudyn:
        print("   EXUDYN: skipped (--no-exudyn)")
    print("2. IFToMM A01 pendulum over 10 s")
    ratio, seconds = pendulum()
    print(f"   max |energy_error| / (m g L) = {ratio:.2e} (target <= 1e-8): "
          f"{'MET' if ratio <= 1e-8 else 'MISSED'}; linkpipe.solve {seconds:.2f} s")
    print("3. a chain of parallel rods over 10 s at rtol 1e-8 (integration alone)")
    rows = [chain(n) for n in (5, 10, 20)]
    for links, seconds, per_eval, steps, evals in rows:
        print(f"   {links:3d} links: {seconds:7.3f} s, {steps} steps, {evals} evaluations, "
              f"{per_eval * 1e3:.3f} ms per evaluation")
    grow = rows[-1][1] / rows[0][1]
    bound = rows[-1][0] / rows[0][0]
    print(f"   cost {rows[-1][0]} links / {rows[0][0]} links = {grow:.2f} (target <= "
          f"{bound:.2f}, linear): {'MET' if grow <= bound else 'MISSED'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
