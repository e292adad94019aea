"""Figures of the localization studies (matplotlib, no display needed).

Every function returns a :class:`matplotlib.figure.Figure` built without pyplot, so it
works headless and leaves no global state; :func:`save_figure` writes it as PNG.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from .. import _style
from .._docs import fill_doc
from ..layout import ArrayLayout
from .trials import method_order

__all__ = ["plot_localization", "plot_errors", "plot_counts", "save_figure", "method_colors"]

def method_colors(methods) -> dict[str, str]:
    """Colour per method, the same in every figure of the package (Okabe–Ito palette).

    Parameters
    ----------
    methods : iterable of str
        Method names; unknown names get colours no known method uses.

    Returns
    -------
    dict of str to str
        Method to hex colour, in :func:`method_order`.
    """
    return _style.method_colors(method_order(methods))


def _new_figure(figsize):
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained")


def _grid_shape(xy_mm: np.ndarray) -> tuple[int, int, list[tuple[int, int]]]:
    """Panel (row, column) of each location: by its grid position when the locations
    form a regular grid (rows from +y down, columns from -x right), else row-major."""
    xs, ys = np.unique(np.round(xy_mm[:, 0], 6)), np.unique(np.round(xy_mm[:, 1], 6))
    if len(xs) * len(ys) == len(xy_mm):
        cells = [(int(np.flatnonzero(ys[::-1] == round(y, 6))[0]), int(np.flatnonzero(xs == round(x, 6))[0]))
                 for x, y in xy_mm]  # fmt: skip
        return len(ys), len(xs), cells
    n_cols = int(np.ceil(np.sqrt(len(xy_mm))))
    n_rows = int(np.ceil(len(xy_mm) / n_cols))
    return n_rows, n_cols, [divmod(i, n_cols) for i in range(len(xy_mm))]


@fill_doc
def plot_localization(positions: pd.DataFrame, layout: ArrayLayout | None = None, *, title: str | None = None):
    """Perceived positions per target: mean and 1-SD covariance ellipse per method.

    Parameters
    ----------
    positions : DataFrame
        Output of :func:`~vibrofocus.analysis.localization_summary`.
    %(layout_default)s
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per target location (a 3 × 3 grid for the reference layout, laid out
        as on the arm: wrist side up), all locations as grey dots, the target as a black
        ring, each method's mean as a dot with its ellipse, in mm.
    """
    from matplotlib.colors import to_rgb
    from matplotlib.lines import Line2D
    from matplotlib.patches import Ellipse

    layout = ArrayLayout.reference() if layout is None else layout
    xy = np.asarray(layout.locations_xy) * 1e3
    n_rows, n_cols, cells = _grid_shape(xy)
    colors = method_colors(positions["method"].unique()) if len(positions) else {}
    styles = {m: _style.method_style(m, i) for i, m in enumerate(colors)}
    fig = _new_figure((3.0 * n_cols + 1.2, 3.0 * n_rows))
    axes = fig.subplots(n_rows, n_cols, squeeze=False, sharex=True, sharey=True)
    pad = 0.6 * max(np.ptp(xy[:, 0]), np.ptp(xy[:, 1]), 10.0) / max(n_cols - 1, 1)
    for ax in axes.flat:
        ax.set_visible(False)
    for index, (row, col) in enumerate(cells):
        ax = axes[row, col]
        ax.set_visible(True)
        location = index + 1
        ax.scatter(xy[:, 0], xy[:, 1], s=12, color="0.75", zorder=1)
        ax.scatter(*xy[index], s=160, facecolor="none", edgecolor="black", linewidth=1.6, zorder=3)
        for row_ in positions[positions["location"] == location].itertuples(index=False):
            style = styles[row_.method]
            c = style["color"]
            # Three methods' ellipses overlap near the centre: told apart by line style
            # and marker, with a faint fill, and a line from the target to each mean.
            ax.plot([xy[index, 0], row_.mean_x_mm], [xy[index, 1], row_.mean_y_mm], color=c, lw=0.8, zorder=3,
                    gid=f"offset:{row_.method}:{location}")
            ax.scatter(row_.mean_x_mm, row_.mean_y_mm, s=34, color=c, marker=style["marker"], edgecolor="white",
                       linewidth=0.5, zorder=4, gid=f"mean:{row_.method}:{location}")
            if np.isfinite(row_.ellipse_width_mm):
                ax.add_patch(
                    Ellipse(
                        (row_.mean_x_mm, row_.mean_y_mm),
                        width=max(row_.ellipse_width_mm, 0.2),
                        height=max(row_.ellipse_height_mm, 0.2),
                        angle=row_.ellipse_angle_deg,
                        facecolor=(*to_rgb(c), 0.07),
                        edgecolor=c,
                        linestyle=style["linestyle"],
                        linewidth=1.6,
                        zorder=2,
                        gid=f"ellipse:{row_.method}:{location}",
                    )
                )
        ax.set_title(f"target {location}", fontsize=10)
        ax.set_xlim(xy[:, 0].min() - pad, xy[:, 0].max() + pad)
        ax.set_ylim(xy[:, 1].min() - pad, xy[:, 1].max() + pad)
        ax.set_aspect("equal")
        ax.grid(True, linewidth=0.3, alpha=0.5)
        if row == n_rows - 1:
            ax.set_xlabel("x (mm, thumb side →)")
        if col == 0:
            ax.set_ylabel("y (mm, wrist ↑)")
    handles = [
        Line2D([], [], color=st["color"], linestyle=st["linestyle"], marker=st["marker"], label=m)
        for m, st in styles.items()
    ] + [Line2D([], [], linestyle="none", marker="o", markersize=9, markerfacecolor="none", markeredgecolor="black",
                label="target")]
    fig.legend(handles=handles, loc="outside right center", frameon=False)
    counts = sorted({int(k) for k in positions["n"]}) if len(positions) else []
    per = "" if not counts else f", {counts[0]}" if len(counts) == 1 else f", {counts[0]}–{counts[-1]}"
    per = per + " trials per ellipse" if per else ""
    fig.suptitle(title or f"Study 1: perceived positions, mean and 1-SD ellipse per method (pooled{per})")
    return fig


def _grouped_boxes(ax, data: pd.DataFrame, dv: str, locations, methods, colors) -> None:
    width = 0.8 / max(len(methods), 1)
    for j, method in enumerate(methods):
        values = [data.loc[(data["location"] == loc) & (data["method"] == method), dv].to_numpy() for loc in locations]
        positions = np.arange(len(locations)) + (j - (len(methods) - 1) / 2) * width
        bp = ax.boxplot(values, positions=positions, widths=width * 0.85, patch_artist=True, showfliers=True,
                        medianprops={"color": "black"}, flierprops={"markersize": 3})  # fmt: skip
        for box in bp["boxes"]:
            box.set_facecolor(colors[method])
            box.set_alpha(0.75)
    ax.set_xticks(np.arange(len(locations)), [str(loc) for loc in locations])
    ax.set_xlim(-0.6, len(locations) - 0.4)
    ax.grid(True, axis="y", linewidth=0.3, alpha=0.6)


def _method_boxes(ax, data: pd.DataFrame, dv: str, methods, colors) -> None:
    per_subject = data.groupby(["participant", "method"])[dv].mean().reset_index()
    values = [per_subject.loc[per_subject["method"] == m, dv].to_numpy() for m in methods]
    bp = ax.boxplot(values, patch_artist=True, medianprops={"color": "black"}, flierprops={"markersize": 3})
    for box, m in zip(bp["boxes"], methods):
        box.set_facecolor(colors[m])
        box.set_alpha(0.75)
    ax.set_xticks(np.arange(1, len(methods) + 1), methods)
    ax.grid(True, axis="y", linewidth=0.3, alpha=0.6)


def _legend(ax, methods, colors) -> None:
    """Method colours in one row above the axes, clear of the data."""
    handles = [ax.scatter([], [], color=colors[m], marker="s", label=m) for m in methods]
    ax.legend(handles=handles, frameon=False, ncols=len(methods), loc="lower left", bbox_to_anchor=(0.0, 1.0))


def plot_errors(errors: pd.DataFrame):
    """Box plots of the mean localization error per participant (study 1).

    Parameters
    ----------
    errors : DataFrame
        Output of :func:`~vibrofocus.analysis.study1_errors`.

    Returns
    -------
    matplotlib.figure.Figure
        Left: per location and method; right: per method (each participant's mean over
        locations).
    """
    methods = method_order(errors["method"].unique())
    locations = sorted(errors["location"].unique())
    colors = method_colors(methods)
    fig = _new_figure((11, 4))
    ax1, ax2 = fig.subplots(1, 2, width_ratios=[3, 1], sharey=True)
    _grouped_boxes(ax1, errors, "error_mm", locations, methods, colors)
    ax1.set_xlabel("target location")
    ax1.set_ylabel("mean Euclidean error (mm)")
    _legend(ax1, methods, colors)
    _method_boxes(ax2, errors, "error_mm", methods, colors)
    ax2.set_xlabel("method")
    fig.suptitle("Study 1: localization error per participant")
    return fig


def plot_counts(counts: pd.DataFrame, counts_hit: pd.DataFrame | None = None):
    """Box plots of the number of selected locations per participant (study 2).

    Parameters
    ----------
    counts : DataFrame
        Output of :func:`~vibrofocus.analysis.study2_counts` on all trials.
    counts_hit : DataFrame, optional
        The same restricted to trials whose selection contains the target (second row).

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = [("all trials", counts)]
    if counts_hit is not None and len(counts_hit):
        rows.append(("selection contains the target", counts_hit))
    methods = method_order(counts["method"].unique())
    locations = sorted(counts["location"].unique())
    colors = method_colors(methods)
    fig = _new_figure((11, 3.8 * len(rows)))
    axes = fig.subplots(len(rows), 2, width_ratios=[3, 1], squeeze=False)
    for (label, data), (ax1, ax2) in zip(rows, axes):
        _grouped_boxes(ax1, data, "n_selected", locations, methods, colors)
        n = data["participant"].nunique()
        # Participants without such a trial in a cell leave its box smaller, or empty.
        each = f"N = {n}" if label == "all trials" else f"N \u2264 {n} per box"
        ax1.set_ylabel(f"selected locations\n({label}, {each})")
        _method_boxes(ax2, data, "n_selected", methods, colors)
        ax2.set_title("per method", fontsize=10)
        ax2.sharey(ax1)
    axes[-1, 0].set_xlabel("target location")
    _legend(axes[0, 0], methods, colors)
    fig.suptitle("Study 2: number of selected locations per participant")
    return fig


def save_figure(fig, path: str | os.PathLike, *, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG to ``path`` (atomically; the folder is created) and return the path.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : path-like
    dpi : int
        Resolution, dots per inch.

    Returns
    -------
    Path
    """
    from .._atomic import save_figure as _save_atomic

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return _save_atomic(fig, path, dpi=dpi, format="png")
