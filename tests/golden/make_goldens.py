"""Write the golden reference arrays: ``python tests/golden/make_goldens.py [CASE...]``."""
import sys

import numpy as np

import linkpipe
from cases import CASES, HERE, arrays

if __name__ == "__main__":
    names = sys.argv[1:] or list(CASES)
    for name in names:
        result = linkpipe.solve(CASES[name]())
        np.savez_compressed(HERE / f"{name}.npz", **arrays(result))
        print(f"{name}: {result.message}")
