"""Colours and sizes of the recording, in one place.

The palette keeps links and arrows apart at a glance: every kind of arrow (each force kind,
velocity, acceleration; "friction" reserved) has a saturated hue of its own
(:data:`ARROW_HUES`), and links take muted tones (low saturation) of hues at least
:data:`HUE_CLEARANCE` degrees from every arrow's, so that a link never looks like a force lying
along it. Series of a plot (other than a link's angle, drawn in its link's colour) take
matplotlib's tab10.
"""
from __future__ import annotations

import colorsys

import numpy as np

#: the first ten colours of a plot's series (matplotlib's tab10); further ones by golden-angle
#: hues, so that every series of a plot has a colour of its own
_TAB10 = [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
          [140, 86, 75], [227, 119, 194], [23, 190, 207], [188, 189, 34], [127, 127, 127]]

#: each kind of arrow's hue (degrees on the HSV wheel): one hue per kind, saturated. "friction"
#: is reserved for the friction forces (version 3), so that no link or other kind takes it
ARROW_HUES = {"input": 0.0, "loads": 30.0, "springs": 54.0, "velocity": 125.0,
              "reactions": 188.0, "friction": 222.0, "weights": 272.0, "acceleration": 318.0}
#: the colour's name said in legends and docs
ARROW_HUE_NAMES = {"input": "red", "loads": "orange", "springs": "yellow", "velocity": "green",
                   "reactions": "cyan", "friction": "blue", "weights": "violet",
                   "acceleration": "magenta"}
#: saturation and value of the arrows (vivid) and of the links (muted)
ARROW_SV = (0.85, 1.0)
LINK_SV = ((0.38, 0.85), (0.30, 0.62))   # the first six links, then six more a shade darker
#: the least angle between a link's hue and any arrow's
HUE_CLEARANCE = 20.0


def hsv(hue_deg: float, s: float, v: float) -> list[int]:
    return [int(round(255 * c)) for c in colorsys.hsv_to_rgb((hue_deg % 360.0) / 360.0, s, v)]


def hue_of(rgb) -> float:
    """The hue (degrees) of an RGB colour (0..255)."""
    h, _, _ = colorsys.rgb_to_hsv(*(c / 255.0 for c in rgb[:3]))
    return 360.0 * h


def saturation_of(rgb) -> float:
    return colorsys.rgb_to_hsv(*(c / 255.0 for c in rgb[:3]))[1]


def hue_distance(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def arrow_colour(kind: str) -> list[int]:
    """The saturated colour of an arrow kind ("input", "reactions", "velocity", ...)."""
    return hsv(ARROW_HUES[kind], *ARROW_SV)


def _link_hues() -> list[float]:
    """The hues in the middle of the gaps between the arrows' hues, widest gap first, kept
    where they clear every arrow's hue by :data:`HUE_CLEARANCE`."""
    hues = sorted(ARROW_HUES.values())
    gaps = [(b - a) % 360.0 or 360.0 for a, b in zip(hues, hues[1:] + hues[:1])]
    middles = [((a + g / 2) % 360.0, g) for a, g in zip(hues, gaps)]
    return [m for m, g in sorted(middles, key=lambda x: -x[1]) if g / 2 >= HUE_CLEARANCE]


LINK_HUES = _link_hues()


def link_colour(j: int) -> list[int]:
    """The j-th link's muted colour: the link hues (:data:`LINK_HUES`) in turn, a shade darker
    on each further round."""
    n = len(LINK_HUES)
    s, v = LINK_SV[(j // n) % len(LINK_SV)]
    return hsv(LINK_HUES[j % n], s, v)


def colour(j: int) -> list[int]:
    """Return the j-th distinct colour of a plot's series (RGB): tab10, then hues 137.5
    degrees apart."""
    if j < len(_TAB10):
        return list(_TAB10[j])
    hue = (0.11 + 0.381966 * (j - len(_TAB10))) % 1.0
    value = 0.95 if (j // len(_TAB10)) % 2 else 0.75
    return [int(round(255 * c)) for c in colorsys.hsv_to_rgb(hue, 0.65, value)]


def palette(n: int) -> np.ndarray:
    """Return n distinct colours (n, 3) uint8."""
    return np.array([colour(j) for j in range(n)], dtype=np.uint8).reshape(n, 3)


POINT = [235, 235, 235]
GROUND = [110, 110, 110]
GUIDE = [150, 150, 150]
ACTUATOR = [150, 150, 158]
TRACE = [200, 200, 200, 150]
SPRING = hsv(ARROW_HUES["springs"], 0.35, 0.75)   # the spring itself: its forces' hue, muted
LEGEND = [220, 220, 220]                          # the legend's scale bars
VECTOR_COLORS = {q: arrow_colour(q) for q in ("velocity", "acceleration")}
VECTOR_COLOR_NAMES = {q: ARROW_HUE_NAMES[q] for q in ("velocity", "acceleration")}


#: the most labels of one kind drawn in the 2D view (points, or one force kind's items): past
#: it they overlap into an unreadable smear (the 40-bar chain's "BBBB AAAA"); each stays
#: logged and shows on hover
CROWD = 16
