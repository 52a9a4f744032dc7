"""How many rows settle a followed row: follow's blocks against a batch run, per ``settle``.

    python benchmarks/bench_settle.py [--seconds 3] [--rates 1000,500,100]
                                      [--settle 28,24,20,18,16,12]

For each logging rate, a log of configs/logged/fourbar_live.toml's rig is written beforehand
(configs/logged/rig_logger.py --fast: the crank's angle to 1e-9 degree, as the demo logger
writes it) and also with the crank's angle rounded to 0.001 degree (an encoder's
quantisation: a rough log, whose spline's end condition moves much more with each new row).
The log is handed to follow's :class:`linkpipe.follow.blocks.Window` in pieces of 5 rows
(blocks as follow solves them at 1 kHz) with ``settle`` rows held back, and the rows stored
are compared with a batch ``linkpipe.solve`` of the whole log: the largest absolute
difference, in the scene's units (m, m/s, m/s^2, rad, N, N m), over every per-step float
array (positions, velocities, accelerations, link angles, the drivers' values and rates, every
force, the measurements' residuals) and every row. The issue's bound is 1e-9 (positions, and
rates and forces away from the last block's settling window); printed per ``settle`` with the
verdict. No timing: this measures agreement only.
"""
from __future__ import annotations

import argparse
import pathlib
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
SCENE = ROOT / "configs" / "logged" / "fourbar_live.toml"
LOGGER = ROOT / "configs" / "logged" / "rig_logger.py"
BOUND = 1e-9


def _arrays(result) -> dict[str, np.ndarray]:
    """Every per-step float array of ``result`` (step first), by name."""
    out = {}
    for name in result.PER_STEP:
        v = getattr(result, name)
        if v is not None and np.asarray(v).dtype.kind == "f":
            out[name] = np.asarray(v)
    for name, (dims, data, _) in (result.forces or {}).items():
        if dims[:1] == ("step",):
            out[f"forces.{name}"] = np.asarray(data)
    if result.measurements:
        out["measured_residual"] = np.asarray(result.measurements["residual"])
    return out


def deviation(scene, batch, settle: int, piece: int = 5) -> dict[str, float]:
    """{array: largest |followed - batch|} over every row, the log fed in ``piece`` rows."""
    from linkpipe.follow.blocks import Window

    data = scene.logs[0]
    window = Window(scene, settle=settle)
    parts = []
    n = len(data.t)
    for lo in range(0, n, piece):
        window.add(data.t[lo:lo + piece], {c: data.columns[c][lo:lo + piece]
                                           for c in window.columns})
        while (part := window.block()) is not None:
            parts.append(part)
    while (part := window.block(final=True)) is not None:
        parts.append(part)
    got = {}
    for p in parts:
        for name, v in _arrays(p).items():
            got.setdefault(name, []).append(v)
    want = _arrays(batch)
    out = {}
    for name, pieces in got.items():
        a, b = np.concatenate(pieces), want[name]
        both = np.isfinite(a) & np.isfinite(b)
        assert (np.isfinite(a) == np.isfinite(b)).all(), name
        out[name] = float(np.abs(a[both] - b[both]).max()) if both.any() else 0.0
    return out


def main(argv=None) -> int:
    import linkpipe

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--rates", default="1000,500,100")
    p.add_argument("--settle", default="28,24,20,18,16,12")
    args = p.parse_args(argv)
    settles = [int(x) for x in args.settle.split(",")]
    for rate in [float(x) for x in args.rates.split(",")]:
        for rough in (False, True):
            with tempfile.TemporaryDirectory() as tmp:
                folder = pathlib.Path(tmp)
                (folder / "logs").mkdir()
                shutil.copy(SCENE, folder / SCENE.name)
                log = folder / "logs" / "live_rig.csv"
                subprocess.run([sys.executable, str(LOGGER), str(log), "--rate", str(rate),
                                "--seconds", str(args.seconds), "--fast"], check=True)
                if rough:
                    import pandas as pd

                    frame = pd.read_csv(log)
                    frame["crank_deg"] = frame["crank_deg"].round(3)
                    frame.to_csv(log, index=False, float_format="%.9f")
                scene = linkpipe.load_scene(str(folder / SCENE.name))
                batch = linkpipe.solve(scene)
                what = "crank to 0.001 deg" if rough else "crank to 1e-9 deg"
                for settle in settles:
                    dev = deviation(scene, batch, settle)
                    worst = max(dev, key=dev.get)
                    pos = max(v for k, v in dev.items() if k in ("position", "link_angle"))
                    print(f"settle  {rate:,.0f} Hz, {what}, {batch.n_steps:,} rows, "
                          f"settle {settle:2d}: positions {pos:.1e}, largest {dev[worst]:.1e} "
                          f"({worst}); bound {BOUND:g}: "
                          f"{'within' if dev[worst] <= BOUND else 'BEYOND'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
