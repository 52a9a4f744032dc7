"""The safety net: every golden case solves to its stored reference arrays.

Positions, velocities, accelerations, link angles and rates, forces and every other stored
variable agree to 1e-11 of the array's largest magnitude; status is exact; the set of
variables is exact. A changed formula, branch or step moves results by far more than that;
what may differ is rounding, and it does between machines: the references were made with
OpenBLAS's AVX2 kernels (AMD EPYC), and its AVX-512 kernels (Intel Xeon, "SkylakeX") sum in
another order. Measured on such a machine (2026-11-28), the largest difference at an ok step
is 3.6e-12 of the array's magnitude (the double parallelogram's power beside its change
point, where the redundant constraint amplifies the accelerations' rounding into the
forces); ``test_kernels_agree`` below solves the cases again under each kernel this CPU runs.
Two kinds of step are held to what rounding can fix there, with the reason:

- at a ``singular`` step (a dead centre, a limit of the assembly range) the constraint
  residual is quadratic in the distance along the singular direction, so a rounding of eps
  in the residual moves the solution by ~sqrt(eps) = 1.5e-8 of the scale: positions, link
  angles and what the positions alone give (``POSITIONAL``) agree there to ``SINGULAR_RTOL``
  (measured: 8.3e-9);
- an array that is rounding noise around zero (the link angular accelerations of links
  turning at a constant rate) is compared on the scale of the terms whose cancellation made
  it: for link angular accelerations the largest squared link rate (the centripetal terms of
  the same solve, in rad/s^2); other arrays on ``NOISE_FLOOR``.
``tests/golden/cases.py`` says which scenes and why.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

import linkpipe
from linkpipe.forces import POSITION_ONLY
from cases import CASES, DIAGNOSTICS, HERE, arrays

RTOL = 1e-11
#: arrays whose largest magnitude is below this hold rounding noise around zero: compared to
#: RTOL x this
NOISE_FLOOR = 1e-2
#: positions at singular steps: sqrt(eps) ~ 1.5e-8 of the scale, with a margin of ~7
SINGULAR_RTOL = 1e-7
SINGULAR = 2  # status code
#: variables fixed only to SINGULAR_RTOL at singular steps: the positions and what they alone
#: give (linkpipe.forces.POSITION_ONLY: spring lengths, extensions and energies, torsion spring
#: angles and energies, gravity's energy); every other variable is NaN there
POSITIONAL = {"position", "link_angle"} | POSITION_ONLY


def _scale(var: str, want: np.ndarray, ref) -> float:
    """The magnitude ``var``'s rounding is relative to (see the module's docstring)."""
    finite = np.isfinite(want)
    scale = float(np.abs(want[finite]).max()) if finite.any() else 0.0
    if var == "link_angular_acceleration" and "link_angular_velocity" in ref.files:
        rate = ref["link_angular_velocity"]
        rate = rate[np.isfinite(rate)]
        if rate.size:
            scale = max(scale, float(np.abs(rate).max()) ** 2)
    return max(scale, NOISE_FLOOR)


def compare(name: str, got: dict, ref) -> list[str]:
    """Every difference of ``got`` from the reference ``ref`` beyond its tolerance, as text."""
    problems = []
    if sorted(got) != sorted(ref.files):
        return [f"variables {sorted(got)} != {sorted(ref.files)}"]
    if not np.array_equal(got["status"], ref["status"]):
        return ["status differs"]
    singular = ref["status"] == SINGULAR
    for var in ref.files:
        if var in DIAGNOSTICS or var == "status":
            continue
        want, have = ref[var], got[var]
        if have.shape != want.shape:
            problems.append(f"{var}: shape {have.shape} != {want.shape}")
            continue
        if want.dtype.kind in "US":
            if not np.array_equal(have, want):
                problems.append(f"{var}: labels differ")
            continue
        if not np.array_equal(np.isnan(have), np.isnan(want)):
            problems.append(f"{var}: NaN at other places")
            continue
        scale = _scale(var, want, ref)
        tol = np.full(want.shape[:1], RTOL * scale)
        if var in POSITIONAL and want.shape[:1] == singular.shape:
            tol[singular] = SINGULAR_RTOL * scale
        diff = np.where(np.isfinite(want), np.abs(have - want), 0.0)
        err = diff.reshape(len(diff), -1).max(axis=1) if diff.ndim > 1 else diff
        if diff.ndim and (err > tol).any():
            i = int(np.argmax(err / tol))
            problems.append(f"{var}: {err[i]:.3e} at step {i} > {tol[i]:.3e} "
                            f"({tol[i] / scale:.0e} x {scale:.3e})")
    return problems


@pytest.mark.parametrize("name", sorted(CASES))
def test_case_matches_reference(name):
    ref = np.load(HERE / f"{name}.npz")
    problems = compare(name, arrays(linkpipe.solve(CASES[name]())), ref)
    assert not problems, "\n".join(problems)


#: OpenBLAS kernel families and the CPU flag each needs (``OPENBLAS_CORETYPE`` picks one)
KERNELS = {"Nehalem": "sse4_2", "Sandybridge": "avx", "Haswell": "avx2", "SkylakeX": "avx512f"}

_CHILD = """
import sys, numpy as np
sys.path.insert(0, {here!r})
import linkpipe, threadpoolctl
from cases import CASES, HERE, arrays
from test_golden import compare
info = [i for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"]
print("kernel", info[0]["architecture"] if info else "none")
for name in sorted(CASES):
    for line in compare(name, arrays(linkpipe.solve(CASES[name]())), np.load(HERE / f"{{name}}.npz")):
        print(name, line)
"""


def _cpu_flags() -> set[str]:
    try:
        text = open("/proc/cpuinfo").read()
    except OSError:
        return set()
    line = next((ln for ln in text.splitlines() if ln.startswith("flags")), "")
    return set(line.split(":", 1)[-1].split())


@pytest.mark.parametrize("kernel", sorted(KERNELS))
def test_kernels_agree(kernel):
    """Every golden case, solved with each OpenBLAS kernel family this CPU can run, meets the
    references within the tolerances above (rounding moves with the kernel; results may not)."""
    flags = _cpu_flags()
    if KERNELS[kernel] not in flags:
        pytest.skip(f"this CPU has no {KERNELS[kernel]} (OpenBLAS's {kernel} kernels)")
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel, OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", _CHILD.format(here=str(HERE))], env=env,
                         capture_output=True, text=True, check=True).stdout.splitlines()
    if out[0] == "kernel none":
        pytest.skip("numpy's BLAS is not OpenBLAS")
    assert out[0].lower() == f"kernel {kernel}".lower(), out[0]  # the kernel really ran
    assert out[1:] == []
