"""Stage 1's exact condition at 360k steps of the crank-rocker: numpy against the compiled loop.

    .venv/bin/python benchmarks/bench_condition.py            # about 20 s
    .venv/bin/python benchmarks/bench_condition.py --steps 36000

The crank-rocker of ``configs/fourbar_crank_rocker.toml`` swept over one crank turn in S steps
(positions, velocities and accelerations by the dyads: ``kin.solve_sweep``), then, alternately
in the same minutes, best CPU seconds (``time.process_time``) and wall seconds of:

* condition, numpy: what stage 1 ran for the condition before the loop, chunk by chunk of
  ``linalg.CHUNK`` steps: ``Engine.entries_of`` (the Jacobian's entries) and
  ``Engine.condition(E)`` (the 1-norm and the inverse's column sums by block solves);
* condition, compiled: ``block_kernel.condition(eng, X=..., s=...)`` on the same chunks (the
  entries made in the loop), the same numbers to the bit (checked here); and the same given
  the crank's cos and sin (``trig=``, computed before the timing, as the dyads have them);
  and by the general loop (where the engine's own loop cannot be written);
* ``kin.derivatives`` as stage 1 calls it (the dyads' rates given, no influence
  coefficients) with ``compiled=False`` and ``compiled=True``: the whole "jacobian" stage;
* the first call in a fresh process: ``import numba`` and the loop loaded from numba's cache
  in ``__pycache__`` (and, in a second process with an empty ``NUMBA_CACHE_DIR``, compiled).

The target of issue 29 is ``run``'s (``benchmarks/bench_sweep.py``: its marginal at 360k steps
<= half of pylinkage+numba's warm kernel); this benchmark says how many ms of it the compiled
condition saves (its own verdict: compiled faster than numpy, bits equal).
"""
from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np, linkpipe
from linkpipe.model import build_model
from linkpipe.kinematics import block_kernel
from linkpipe.kinematics.sparse import engine
eng = engine(build_model(linkpipe.load_scene({path!r})))
X = np.repeat(eng.model.start_position[None], 100, axis=0)
t1 = time.perf_counter()
block_kernel.condition(eng, X=X, s=np.zeros((100, 1)))
print(time.perf_counter() - t1)
"""


def setup(S: int):
    import dataclasses as dc

    import linkpipe
    from linkpipe import kinematics as kin
    from linkpipe.model import build_model

    scene = linkpipe.load_scene(ROOT / "configs" / "fourbar_crank_rocker.toml")
    scene = dc.replace(scene, drivers=tuple(dc.replace(d, steps=S, step=None)
                                            for d in scene.drivers))
    model = build_model(scene)
    _, s, s_dot, s_ddot = kin.driver_motion(model)
    sweep = kin.solve_sweep(model, s, s_dot, s_ddot, order=2)
    assert sweep.method == "dyads"
    return model, sweep, s, s_dot, s_ddot


def cases(model, sweep, s, s_dot, s_ddot):
    from linkpipe import kinematics as kin
    from linkpipe.kinematics import block_kernel
    from linkpipe.kinematics.linalg import CHUNK
    from linkpipe.kinematics.sparse import engine
    from linkpipe.status import OK

    eng = engine(model)
    X, S = sweep.position, len(s)
    trig = {lo: {0: (np.cos(s[lo:lo + CHUNK, 0]), np.sin(s[lo:lo + CHUNK, 0]))}
            for lo in range(0, S, CHUNK)}  # the crank's cos and sin, as the dyads have them

    def general(fn):  # as where the engine's own loop cannot be written
        def run():
            own, block_kernel._own_loop = block_kernel._own_loop, lambda *args: None
            try:
                return fn()
            finally:
                block_kernel._own_loop = own
        return run

    def chunked(fn):
        def run():
            out = np.empty(S)
            for lo in range(0, S, CHUNK):
                out[lo:lo + CHUNK] = fn(X[lo:lo + CHUNK], s[lo:lo + CHUNK], lo)
            return out
        return run

    assert (sweep.status == OK).all()  # every step ok: derivatives writes nothing into the rates

    def derivatives(compiled):
        return lambda: kin.derivatives(model, X, s, s_dot, s_ddot, sweep.status, True,
                                       velocity=sweep.velocity, acceleration=sweep.acceleration,
                                       need_influence=False, compiled=compiled)

    return {  # key: (what is timed, the function)
        "numpy": ("condition, numpy (entries_of + Engine.condition)",
                  chunked(lambda x, ss, lo: eng.condition(eng.entries_of(x, ss)))),
        "compiled": ("condition, compiled (block_kernel.condition)",
                     chunked(lambda x, ss, lo: block_kernel.condition(eng, X=x, s=ss))),
        "trig": ("condition, compiled, given the crank's cos and sin",
                 chunked(lambda x, ss, lo: block_kernel.condition(eng, X=x, s=ss, trig=trig[lo]))),
        "general": ("condition, compiled, the general loop",
                    general(chunked(lambda x, ss, lo: block_kernel.condition(eng, X=x, s=ss)))),
        "der_numpy": ("kin.derivatives as stage 1 calls it, compiled=False", derivatives(False)),
        "der_compiled": ("kin.derivatives as stage 1 calls it, compiled=True", derivatives(True)),
    }


def first_call(cold: bool) -> float:
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as folder:
        if cold:
            env["NUMBA_CACHE_DIR"] = folder
        code = FIRST_CALL.format(path=str(ROOT / "configs" / "fourbar_crank_rocker.toml"))
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout
    return float(out.split()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=360_000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    model, sweep, s, s_dot, s_ddot = setup(args.steps)
    fns = cases(model, sweep, s, s_dot, s_ddot)
    results = {key: fn() for key, (_, fn) in fns.items()}  # warm-up (and the compile's cache)
    for key in ("compiled", "trig", "general"):
        np.testing.assert_array_equal(results[key], results["numpy"])
    for key, value in results["der_numpy"].items():
        if value is not None:
            np.testing.assert_array_equal(results["der_compiled"][key], value, err_msg=key)
    cpu = {key: np.inf for key in fns}
    wall = dict(cpu)
    for _ in range(args.repeats):  # alternately: old and new in the same seconds
        for key, (_, fn) in fns.items():
            t0, c0 = time.perf_counter(), time.process_time()
            fn()
            cpu[key] = min(cpu[key], time.process_time() - c0)
            wall[key] = min(wall[key], time.perf_counter() - t0)
    warm, cold = first_call(False), first_call(True)
    print(f"crank-rocker, {args.steps:,} steps, best of {args.repeats}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for key, (name, _) in fns.items():
        print(f"  {name:55s} {cpu[key]:7.4f} s CPU  {wall[key]:7.4f} s wall")
    for old, new in (("numpy", "compiled"), ("numpy", "trig"), ("numpy", "general"),
                     ("der_numpy", "der_compiled")):
        print(f"  {fns[new][0]}: saves {1e3 * (cpu[old] - cpu[new]):5.1f} ms CPU "
              f"({cpu[old] / cpu[new]:.2f}x)")
    print(f"  first call in a fresh process: {warm:.3f} s (numba imported, the loop from its "
          f"cache), {cold:.3f} s with an empty cache (compiled)")
    ok = cpu["compiled"] < cpu["numpy"] and cpu["der_compiled"] < cpu["der_numpy"]
    print(f"  verdict: {'PASS' if ok else 'FAIL'} (compiled faster than numpy, the same bits); "
          f"issue 29's target is run's marginal at 360k, benchmarks/bench_sweep.py")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
