"""One look for every figure the package draws: a colour, line style and marker per method.

The colours are the colour-blind-safe Okabe–Ito palette (Okabe & Ito 2008, "Color
Universal Design"), fixed per method so that a method keeps its colour whichever other
methods a figure shows; methods the package does not know take the remaining colours in
name order.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["METHOD_COLORS", "METHOD_LINESTYLES", "METHOD_MARKERS", "method_colors", "method_style", "model_footer",
           "point_styles"]

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


def point_styles(n_locations: int, n_guards: int) -> list[tuple[str, object]]:
    """A (colour, line style) pair per calibrated point that no two points share.

    Locations take the ten distinct colours of matplotlib's ``tab10`` palette as solid
    lines (then, past ten, the same colours dashed, dotted, ...); guard points are dark
    grey, each with its own dash pattern. Paired palettes (``tab20``) give neighbouring
    points near-identical colours, which is what this avoids.

    Parameters
    ----------
    n_locations : int
        Locations, drawn first.
    n_guards : int
        Guard points, after the locations.

    Returns
    -------
    list of (str, str or tuple)
        ``(n_locations + n_guards)`` pairs of a colour and a matplotlib line style.
    """
    colours = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
               "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")  # tab10
    location_lines = ("-", (0, (4, 1.5)), (0, (1, 1)))
    guard_lines = ((0, (5, 2)), (0, (1, 1.5)), (0, (5, 1.5, 1, 1.5)), (0, (8, 2, 1, 2, 1, 2)),
                   (0, (2, 2)), (0, (10, 3)))
    out: list[tuple[str, object]] = []
    for i in range(n_locations):
        out.append((colours[i % len(colours)], location_lines[(i // len(colours)) % len(location_lines)]))
    for g in range(n_guards):
        out.append(("0.25" if g < len(guard_lines) else "0.55", guard_lines[g % len(guard_lines)]))
    return out


def model_footer(fig, text: str, *, color: str = "0.25") -> None:
    """Write ``text`` (what in the figure is a model) in small grey type at the figure's foot.

    Keeps room for it under a constrained layout; under ``tight_layout`` the caller leaves
    about 4 % of the height free at the bottom. The text carries ``gid="model-footer"``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    text : str
        The footer, one line.
    color : str
        Its colour (matplotlib colour).
    """
    engine = fig.get_layout_engine()
    if engine is not None and hasattr(engine, "set") and "rect" in getattr(engine, "get", dict)():
        engine.set(rect=(0, 0.04, 1, 0.96))
    fig.text(0.01, 0.005, text, fontsize=7.5, color=color, ha="left", va="bottom", gid="model-footer")
