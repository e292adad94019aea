"""One look for every figure the package draws: a colour, line style and marker per method.

The colours are the colour-blind-safe Okabe–Ito palette (Okabe & Ito 2008, "Color
Universal Design"), fixed per method so that a method keeps its colour whichever other
methods a figure shows; methods the package does not know take the remaining colours in
name order.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["METHOD_COLORS", "METHOD_LINESTYLES", "METHOD_MARKERS", "method_colors", "method_style"]

METHOD_COLORS = {
    "funneling": "#E69F00",  # orange
    "inverse": "#0072B2",  # blue
    "combination": "#009E73",  # bluish green
    "time_reversal": "#CC79A7",  # reddish purple
    "contrast": "#D55E00",  # vermillion
    "constrained": "#56B4E9",  # sky blue
}
_SPARE_COLORS = ("#000000", "#F0E442", "#999999")
METHOD_LINESTYLES = {"funneling": "-", "inverse": "--", "combination": ":", "time_reversal": "-.",
                     "contrast": (0, (5, 1, 1, 1, 1, 1)), "constrained": (0, (1, 2))}
METHOD_MARKERS = {"funneling": "o", "inverse": "s", "combination": "^", "time_reversal": "D",
                  "contrast": "v", "constrained": "P"}


def method_colors(methods: Iterable[str]) -> dict[str, str]:
    """Colour per method: the fixed one for the package's methods, spares for others."""
    methods = list(dict.fromkeys(methods))
    unknown = sorted(m for m in methods if m not in METHOD_COLORS)
    spare = {m: _SPARE_COLORS[i % len(_SPARE_COLORS)] for i, m in enumerate(unknown)}
    return {m: METHOD_COLORS.get(m, spare.get(m)) for m in methods}


def method_style(method: str, index: int = 0) -> dict:
    """Matplotlib keywords (``color``, ``linestyle``, ``marker``) of a method.

    ``index`` picks the line style and marker of a method the package does not know.
    """
    styles, markers = list(METHOD_LINESTYLES.values()), list(METHOD_MARKERS.values())
    return {
        "color": method_colors([method])[method],
        "linestyle": METHOD_LINESTYLES.get(method, styles[index % len(styles)]),
        "marker": METHOD_MARKERS.get(method, markers[index % len(markers)]),
    }
