"""The HTML report (`report NAME.h5`, `run --report`): a self-contained page, opened in a real
headless Chromium for every shipped config and a study, with no console message and a
screenshot that shows the page; its numbers are the .h5's."""
import pathlib
import re
import shutil
import subprocess

import h5py
import numpy as np
import pytest

from linkpipe.__main__ import main
from linkpipe.html_report import _num

ROOT = pathlib.Path(__file__).parent.parent
CONFIGS = sorted((ROOT / "configs").glob("*.toml")) + sorted((ROOT / "configs" / "hard").glob("*.toml")) \
    + sorted((ROOT / "configs" / "logged").glob("*.toml")) \
    + sorted((ROOT / "configs" / "dynamics").glob("*.toml"))
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed "
                                    "(apt-get install chromium)")


def open_in_chromium(page: pathlib.Path, png: pathlib.Path, profile: pathlib.Path) -> list[str]:
    """Open ``page`` in headless Chromium (a fresh profile), screenshot it to ``png``; return
    the console messages it logged (Chromium logs every level as ``INFO:CONSOLE``)."""
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
           "--disable-background-networking", "--no-first-run", f"--user-data-dir={profile}",
           "--enable-logging=stderr", "--v=0", "--hide-scrollbars", "--window-size=1100,2400",
           f"--screenshot={png}", page.resolve().as_uri()]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert png.is_file(), done.stderr[-2000:]
    return [line for line in done.stderr.splitlines() if ":CONSOLE" in line]


def shows_a_page(png: pathlib.Path) -> bool:
    """A screenshot of a rendered page: mostly the white background, with text and plots on it
    (a blank or failed page is one colour)."""
    import matplotlib.image

    img = matplotlib.image.imread(png)[..., :3]
    ink = (img < 0.85).any(axis=-1).mean()          # share of pixels that are not background
    colours = len(np.unique((img * 255).astype(np.uint8).reshape(-1, 3)[::7], axis=0))
    return 0.01 < ink < 0.6 and colours > 50


def self_contained(text: str) -> bool:
    """No script and no reference to any other file or address."""
    return not re.search(r"<script|<link|<img|<iframe|\bsrc=|url\((?!#)|@import|xlink:href=\"(?!#)",
                         text, re.I)


@needs_chromium
def test_the_harness_sees_a_console_error(tmp_path):
    """The check can fail: a page that logs an error and throws is caught."""
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><body><p>x</p><script>console.error("boom");'
                   "missing();</script></body></html>")
    messages = open_in_chromium(bad, tmp_path / "bad.png", tmp_path / "profile")
    assert any('"boom"' in m for m in messages)
    assert any("missing is not defined" in m for m in messages)


@needs_chromium
@pytest.mark.parametrize("config", CONFIGS, ids=[c.stem for c in CONFIGS])
def test_every_shipped_configs_report_renders_without_a_console_message(config, tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--no-rrd", "--report", "--quiet"]) == 0
    (page,) = out.glob("*.html")
    text = page.read_text()
    assert self_contained(text)
    assert text.count("<svg") >= 1
    png = tmp_path / "page.png"
    assert open_in_chromium(page, png, tmp_path / "profile") == []
    assert shows_a_page(png)


@needs_chromium
def test_a_studys_report_renders(tmp_path):
    out = tmp_path / "out"
    assert main(["study", str(ROOT / "configs" / "studies" / "basketball_goal.toml"), "--out",
                 str(out), "--no-rrd", "--quiet"]) == 0
    (h5,) = out.glob("*_study.h5")
    assert main(["report", str(h5)]) == 0
    page = h5.with_suffix(".html")
    text = page.read_text()
    assert self_contained(text) and "design study" in text
    with h5py.File(h5) as f:
        peak = f["peak_input_force"][:, 0]
        best = int(np.nanargmin(peak))
    # the best variant's row: its number and its peak, as the .h5 holds them
    assert re.search(rf"<td class=\"num\">{best:,}</td>.*?<td class=\"num\">"
                     rf"{re.escape(_num(peak[best]))}</td>", text, re.S)
    png = tmp_path / "study.png"
    assert open_in_chromium(page, png, tmp_path / "profile") == []
    assert shows_a_page(png)


def test_the_pages_numbers_are_the_h5s(tmp_path):
    """The basketball goal: the status line, the input force's range and peak (with the handle
    angle there), each spring's range, as in the .h5; the mechanism, the input force and the
    springs drawn."""
    out = tmp_path / "out"
    assert main(["run", str(ROOT / "configs" / "basketball_goal.toml"), "--out", str(out),
                 "--no-rrd", "--quiet"]) == 0
    h5 = out / "basketball_goal.h5"
    assert main(["report", str(h5), "--out", str(tmp_path / "goal.html")]) == 0
    text = (tmp_path / "goal.html").read_text()
    with h5py.File(h5) as f:
        F = f["input_force"][:, 0]
        theta = f["driver_value"][:, 0]
        T = f["spring_force"][:]
        springs = [s.decode() if isinstance(s, bytes) else str(s) for s in f["spring"][:]]
        n = len(f["status"])
    assert f"all {n:,} steps ok" in text
    k = int(np.argmax(np.abs(F)))
    assert f"{_num(F.min())} .. {_num(F.max())} lbf; peak |F| {_num(abs(F[k]))}" in text
    assert f"= {_num(theta[k])}" in text
    for j, s in enumerate(springs):
        assert f"spring {s}</td><td>{_num(T[:, j].min())} .. {_num(T[:, j].max())} lbf" in text
    for heading in ("The mechanism", "Input force", "Springs"):
        assert f"<h2>{heading}</h2>" in text
    assert text.count("<svg") == 3
    # the two springs coincide: one curve, said once
    assert "(coincide)" in text


def test_a_logged_scene_plots_measured_against_computed_against_time(tmp_path):
    out = tmp_path / "out"
    assert main(["run", str(ROOT / "configs" / "logged" / "dump_truck_logged.toml"), "--out",
                 str(out), "--no-rrd", "--report", "--quiet"]) == 0
    text = (out / "dump_truck_logged.html").read_text()
    assert "<h2>Measured against computed</h2>" in text
    assert "time [s]" in text
    with h5py.File(out / "dump_truck_logged.h5") as f:
        rms = f["measured_residual"].attrs["rms"][0]
    assert f"computed − measured rms {_num(rms)}" in text


def test_report_of_a_missing_file_is_one_message(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nothing.h5")]) == 2
    err = capsys.readouterr().err
    assert "nothing.h5: no such file" in err and "Traceback" not in err


def test_report_of_a_file_it_does_not_draw_is_one_message(tmp_path, capsys):
    """A scene's .toml (not HDF5 at all), an accuracy ladder's .h5 and a .h5 of other
    variables: one message each saying what the file is, exit 2, no page (they were an
    internal KeyError and a raw h5py message, exit 1)."""
    scene = ROOT / "configs" / "shear_press.toml"
    assert main(["accuracy", str(scene), "--quick", "--out", str(tmp_path)]) == 0
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3.0)
    capsys.readouterr()
    for path, words in ((scene, "not an HDF5 file"),
                        (tmp_path / "shear_press_accuracy.h5", "an accuracy ladder's file"),
                        (other, "not a file that run, study or optimize wrote")):
        assert main(["report", str(path), "--out", str(tmp_path / "page.html")]) == 2
        err = capsys.readouterr().err
        assert err.count("error:") == 1 and words in err and "Traceback" not in err, err
        assert "report takes a .h5 that run, study or optimize wrote" in err
        assert not (tmp_path / "page.html").exists()


def test_run_report_without_the_h5_is_one_message_before_any_work(tmp_path, capsys):
    """--report draws from the .h5: with --no-h5 it wrote nothing and said nothing."""
    out = tmp_path / "out"
    assert main(["run", str(ROOT / "configs" / "shear_press.toml"), "--out", str(out),
                 "--no-h5", "--report"]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "--report" in err and "--no-h5" in err
    assert not out.exists()


def _run_report(config: pathlib.Path, tmp_path) -> tuple[pathlib.Path, str]:
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--no-rrd", "--report", "--quiet"]) == 0
    (page,) = out.glob("*.html")
    return page, page.read_text()


def _axis_labels(text: str) -> list[str]:
    """The text of the page's SVG axis labels and legends (svg.fonttype none: each a <text>)."""
    import html

    return [html.unescape(t) for t in re.findall(r"<text[^>]*>(.*?)</text>", text, re.S)]


@needs_chromium
def test_a_dynamics_scenes_report_is_against_time_and_shows_its_motion(tmp_path):
    """The pendulum (IFToMM A01) moves freely: its page plots against time, shows the swing's
    angle and the energy error, and says it has no input force instead of plotting the
    Lagrange check's 1e-15 rounding."""
    page, text = _run_report(ROOT / "configs" / "dynamics" / "pendulum_a01.toml", tmp_path)
    labels = _axis_labels(text)
    assert "time [s]" in labels and not any(lab.startswith("swing [") for lab in labels)
    assert "<h2>Motion</h2>" in text and "driver's value [degree]" in labels
    assert any(lab.startswith("energy error") for lab in labels)
    assert "every driver moves freely" in text and "input force [N*m]" not in labels
    assert open_in_chromium(page, tmp_path / "p.png", tmp_path / "profile") == []
    assert shows_a_page(tmp_path / "p.png")


@needs_chromium
def test_a_friction_scenes_report_shows_friction_and_stroke_margin(tmp_path):
    """The logged dump truck with friction: its seal's force (N) and its hinge's torque (N*m)
    on two axes, not one labelled [N, N*m]; the cylinder's stroke margin."""
    page, text = _run_report(ROOT / "configs" / "logged" / "dump_truck_friction.toml", tmp_path)
    labels = _axis_labels(text)
    assert {"friction force [N]", "friction force [N*m]"} <= set(labels)
    assert not any("N, N*m" in lab for lab in labels)
    assert "stroke margin (< 0: out of stroke) [m]" in labels and "time [s]" in labels
    assert open_in_chromium(page, tmp_path / "f.png", tmp_path / "profile") == []
    assert shows_a_page(tmp_path / "f.png")


@needs_chromium
def test_an_optimisations_report_renders_with_its_best_design(tmp_path):
    """`report` of an optimisation's .h5 (it had failed: KeyError 'status'): the best design's
    parameters and objective as the .h5 holds them, the search's progress, the objective
    against each free parameter."""
    out = tmp_path / "out"
    config = tmp_path / "opt.toml"
    text = (ROOT / "configs" / "studies" / "basketball_goal_optimize.toml").read_text()
    config.write_text(text.replace("../basketball_goal.toml",
                                   str(ROOT / "configs" / "basketball_goal.toml")))
    assert "[optimize]" in text
    assert main(["optimize", str(config), "--out", str(out), "--no-rrd", "--quiet"]) == 0
    (h5,) = out.glob("*_optimize.h5")
    assert main(["report", str(h5)]) == 0
    page = h5.with_suffix(".html")
    text = page.read_text()
    assert self_contained(text) and "optimisation" in text
    with h5py.File(h5) as f:
        best = f.attrs["best_objective"]
        params = [p.decode() if isinstance(p, bytes) else str(p) for p in f["parameter"][:]]
        values = f["best"][:]
    assert f"best peak_handle {_num(best)} lbf" in text
    for p, v in zip(params, values):
        assert re.search(rf"<td>{re.escape(p)}</td>\s*<td[^>]*>{re.escape(_num(v))} ", text), p
    labels = _axis_labels(text)
    assert "generation" in labels
    assert "springs.left.k [lbf/ft]" in labels and "springs.right.k [lbf/ft]" not in labels
    png = tmp_path / "opt.png"
    assert open_in_chromium(page, png, tmp_path / "profile") == []
    assert shows_a_page(png)
