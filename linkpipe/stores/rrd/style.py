"""Colours and sizes of the recording, in one place."""
from __future__ import annotations

import colorsys

import numpy as np

#: the first ten colours of a series or a link (matplotlib's tab10); further ones by golden-angle
#: hues, so that every link and every series of a plot has a colour of its own
_TAB10 = [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
          [140, 86, 75], [227, 119, 194], [23, 190, 207], [188, 189, 34], [127, 127, 127]]


def colour(j: int) -> list[int]:
    """Return the j-th distinct colour (RGB): tab10, then hues 137.5 degrees apart."""
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
ACTUATOR = [175, 175, 185]
TRACE = [200, 200, 200, 150]
SPRING = [240, 200, 40]
VECTOR_COLORS = {"velocity": [0, 150, 70], "acceleration": [200, 30, 120]}
VECTOR_COLOR_NAMES = {"velocity": "green", "acceleration": "magenta"}
