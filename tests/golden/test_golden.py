"""The safety net: every golden case solves to its stored reference arrays.

Positions, velocities, accelerations, link angles and rates, forces and every other stored
variable agree to 1e-12 of the array's largest magnitude (rounding-level reorderings of the
same arithmetic are allowed; a changed formula, branch or step is not), arrays of rounding
noise around zero to 1e-14 absolute; status is exact; the set of variables is exact. ``tests/golden/cases.py`` says which scenes and why.
"""
import numpy as np
import pytest

import linkpipe
from cases import CASES, DIAGNOSTICS, HERE, arrays

RTOL = 1e-12
#: arrays whose largest magnitude is below this hold rounding noise around zero (a link at rest
#: has angular accelerations of ~1e-16): compared to 1e-12 x this, i.e. 1e-14 absolute
NOISE_FLOOR = 1e-2


@pytest.mark.parametrize("name", sorted(CASES))
def test_case_matches_reference(name):
    ref = np.load(HERE / f"{name}.npz")
    got = arrays(linkpipe.solve(CASES[name]()))
    assert sorted(got) == sorted(ref.files)
    np.testing.assert_array_equal(got["status"], ref["status"])
    for var in ref.files:
        if var in DIAGNOSTICS or var == "status":
            continue
        want, have = ref[var], got[var]
        assert have.shape == want.shape, var
        if want.dtype.kind in "US":
            np.testing.assert_array_equal(have, want, err_msg=var)
            continue
        np.testing.assert_array_equal(np.isnan(have), np.isnan(want), err_msg=var)
        finite = np.isfinite(want)
        scale = float(np.abs(want[finite]).max()) if finite.any() else 0.0
        err = float(np.abs(have[finite] - want[finite]).max()) if finite.any() else 0.0
        assert err <= RTOL * max(scale, NOISE_FLOOR), f"{var}: {err:.3e} > {RTOL} x {scale:.3e}"
