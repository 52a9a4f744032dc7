"""The 2D view's legend: ``mechanism/legend``, one labelled arrow per kind of arrow drawn.

A row per force kind in its colour ("input force", "ground reactions", ...) and a scale bar
per quantity whose length is its true scale ("20,000 N", "velocity 5 m/s"; a force drawn at
the least length carries its own value). The rows sit in a band above the mechanism (the
view's bounds include it: :func:`.layout.view_bounds`), in columns of at most
:data:`ROWS_PER_COLUMN` (or in one column at its right, where that draws the mechanism larger), sized in screen pixels for the view at 1400x900 (bigger windows only
space them more). A title would be cut at the view's width; the legend is not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr

from . import style
from .forces import force_arrows, nice_ceiling, pin_couples
from .geometry import arrow_scales

#: the 2D view's drawing area in logical pixels at a 1400x900 window (its column share 3 of 5,
#: less the top bar, the view's title and the collapsed time panel)
VIEW_PIXELS = (750.0, 790.0)
#: a label's width per character and the arrow's length beyond its label, in pixels
CHAR_PIXELS, ARROW_MARGIN = 7.5, 56.0
ROW_PIXELS, COLUMN_GAP, EDGE_PIXELS = 30.0, 28.0, 12.0
ROWS_PER_COLUMN = 3
#: the legend goes in a column at the mechanism's right when that draws the mechanism this
#: much larger than a band above it would
SIDE_GAIN = 1.05


@dataclass(frozen=True)
class Row:
    label: str
    colour: tuple
    length: float | None = None   # a scale bar's true length (length units); None: to fit


def rows(result) -> list[Row]:
    """The legend's rows for what ``result`` draws."""
    out: list[Row] = []
    arrows, scale = force_arrows(result)
    if scale:
        kinds = dict.fromkeys(kind for kind, *_ in arrows)
        out += [Row(k.legend or k.name, k.colour) for k in kinds]
        if pin_couples(result) and not any(k.name == "friction" for k in kinds):
            out.append(Row("friction", tuple(style.arrow_colour("friction"))))  # couples only
        out.append(Row("", style.LEGEND, 1.0 / scale))         # the force scale: F set below
    if result.scene.outputs.vectors:   # scale bars: "velocity 5 m/s" once sized
        for quantity, s in arrow_scales(result).items():
            out.append(Row(quantity, tuple(style.VECTOR_COLORS[quantity]), 1.0 / s))
    return out


def layout(result, lo: np.ndarray, hi: np.ndarray):
    """Return (rows [(label, colour, origin (2,), vector (2,))], the height added above the box
    ``lo``..``hi`` (length units)): the legend in a band above the box or in one column at its
    right, whichever leaves the mechanism drawn larger in the view (a tall mechanism, a five-bar
    or a hatch, gets the column); sized for the view (module doc)."""
    entries = rows(result)
    if not entries:
        return [], 0.0
    units = result.units()
    variables = {v.name: v.units for v in result.variables()}
    W, H = float(hi[0] - lo[0]), float(hi[1] - lo[1])

    def scale_with(side: bool) -> float:
        """Pixels per length unit with the legend beside or above the box."""
        per_column = len(entries) if side else ROWS_PER_COLUMN
        ppu = min(VIEW_PIXELS[0] / W, VIEW_PIXELS[1] / H)
        for _ in range(3):  # the legend's size in length units depends on the scale it makes
            _, width_px = _place(entries, ppu, units, variables, per_column)
            if side:
                ppu = min(VIEW_PIXELS[0] / (W + (width_px + 2 * EDGE_PIXELS) / ppu),
                          VIEW_PIXELS[1] / H)
            else:
                band = (min(len(entries), per_column) + 0.5) * ROW_PIXELS / ppu
                ppu = min(VIEW_PIXELS[0] / max(W, (width_px + 2 * EDGE_PIXELS) / ppu),
                          VIEW_PIXELS[1] / (H + band))
        return ppu

    above, beside = scale_with(False), scale_with(True)
    side = beside > above * SIDE_GAIN
    ppu = beside if side else above
    per_column = len(entries) if side else ROWS_PER_COLUMN
    n_rows = min(len(entries), per_column)
    placed, _ = _place(entries, ppu, units, variables, per_column)
    band = 0.0 if side else (n_rows + 0.5) * ROW_PIXELS / ppu
    left = hi[0] if side else lo[0]
    out = []
    for label, colour, col_x, row, length in placed:
        y = hi[1] + band - (row + 0.75) * ROW_PIXELS / ppu
        x = left + (col_x + EDGE_PIXELS) / ppu
        out.append((label, colour, np.array([x, y]), np.array([length, 0.0])))
    return out, band


def _place(entries, ppu, units, variables, per_column=ROWS_PER_COLUMN):
    """[(label, colour, column x (px), row, length (length units))] and the width (px)."""
    sized = []
    for e in entries:
        label, length = e.label, e.length
        if length is not None:  # a scale bar: a round value at least its label's width long
            per = length  # force (or the quantity) per length unit
            quantity = label
            unit = variables[quantity] if quantity else units["force"]
            text = f"{quantity} 0,000.0 {unit}".strip()
            need_px = len(text) * CHAR_PIXELS + ARROW_MARGIN
            value = nice_ceiling(need_px / ppu * per)
            length = value / per
            label = f"{quantity} {value:,.6g} {unit}".strip()
        else:
            length = (len(label) * CHAR_PIXELS + ARROW_MARGIN) / ppu
        sized.append((label, e.colour, length))
    out, x, width = [], 0.0, 0.0
    for c in range(0, len(sized), per_column):
        column = sized[c:c + per_column]
        col_px = max(length for *_, length in column) * ppu
        for r, (label, colour, length) in enumerate(column):
            out.append((label, colour, x, r, length))
        x += col_px + COLUMN_GAP
        width = x - COLUMN_GAP
    return out, width


def log_legend(stream, result, lo, hi) -> None:
    """Log ``mechanism/legend`` (static): the rows of :func:`layout` as labelled arrows."""
    placed, _ = layout(result, lo, hi)
    if not placed:
        return
    stream.log("mechanism/legend", rr.Arrows2D(
        origins=np.array([o for _, _, o, _ in placed], dtype=np.float32),
        vectors=np.array([v for *_, v in placed], dtype=np.float32),
        colors=np.array([c[:3] for _, c, _, _ in placed], dtype=np.uint8),
        labels=[label for label, *_ in placed], show_labels=True,
        radii=rr.components.Radius.ui_points(2.0), draw_order=50.0), static=True)
