"""The figure of one rendered tap: its drives, the predicted displacements and their peaks over the layout.

What the web app's *Preview* shows and ``vibrofocus render --plot`` writes
(docs/method.md, "Rendering methods"). matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_preview"]


def plot_preview(rendering: Any, layout: Any, fs: float, *, method: str, location: int):
    """Drive signals, predicted displacements and their peaks over the locations: one figure.

    The web app's *Preview* and ``vibrofocus render --plot`` draw this figure.

    Parameters
    ----------
    rendering : Rendering
        ``drives`` (n_actuators, n) V and ``predicted`` (n_points, n) m.
    layout : ArrayLayout
        Positions of actuators, locations and guards.
    fs : float
        Sample rate, Hz.
    method : str
        Method name for the title.
    location : int
        Target location number (1-based).

    Returns
    -------
    matplotlib.figure.Figure
        Three axes (drives, predicted displacements, peak map) and the map's colour bar;
        a bare Figure (no pyplot state), safe to draw from any thread.
    """
    # The object-oriented API with a bare Figure never touches pyplot's global state, so
    # request threads can draw at the same time without a GUI backend.
    from matplotlib.figure import Figure

    drives = np.asarray(rendering.drives)
    predicted = np.asarray(rendering.predicted)
    t_ms = np.arange(drives.shape[1]) / fs * 1e3
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax_d, ax_u, ax_map = fig.subplots(1, 3, width_ratios=(1.4, 1.4, 1))
    # Show the part of the window where something happens, not 400 ms of near silence.
    energy = np.abs(drives).max(axis=0) + np.abs(predicted).max(axis=0) / max(np.abs(predicted).max(), 1e-30) * np.abs(drives).max()
    active = np.flatnonzero(energy > 0.02 * energy.max()) if energy.max() > 0 else np.arange(len(t_ms))
    lo, hi = (t_ms[max(active[0] - 20, 0)], t_ms[min(active[-1] + 20, len(t_ms) - 1)]) if len(active) else (0, t_ms[-1])
    names = layout.actuator_names
    for q in range(drives.shape[0]):
        ax_d.plot(t_ms, drives[q], label=names[q], lw=1)
    ax_d.set_xlim(lo, hi)
    ax_d.set_xlabel("time (ms)")
    ax_d.set_ylabel("drive (V)")
    ax_d.set_title("drive signals")
    ax_d.legend(fontsize=8)
    n_loc = layout.n_locations
    target = location - 1
    for i in range(predicted.shape[0]):
        if i == target:
            continue
        ax_u.plot(t_ms, predicted[i] * 1e6, color="0.7", lw=0.7)
    ax_u.plot(t_ms, predicted[target] * 1e6, color="C3", lw=1.6, label=f"location {location}")
    ax_u.set_xlim(lo, hi)
    ax_u.set_xlabel("time (ms)")
    ax_u.set_ylabel("predicted displacement (µm)")
    ax_u.set_title("target (red), other points (grey)", fontsize=10)
    ax_u.legend(fontsize=8)
    peaks_um = np.abs(predicted).max(axis=1) * 1e6
    loc_xy = np.asarray(layout.locations_xy) * 1e3
    act_xy = np.asarray(layout.actuators_xy) * 1e3
    # One colour scale for locations and guards, so a loud guard shows as loud.
    norm = {"cmap": "viridis", "vmin": 0.0, "vmax": float(peaks_um.max()) or 1.0}
    sc = ax_map.scatter(loc_xy[:, 0], loc_xy[:, 1], c=peaks_um[:n_loc], s=500, **norm)
    for k, (x, y) in enumerate(loc_xy):
        ax_map.annotate(str(k + 1), (x, y), ha="center", va="center", color="w" if k != target else "r", fontsize=10, weight="bold")
    ax_map.scatter(act_xy[:, 0], act_xy[:, 1], marker="s", s=120, color="k")
    guards = np.asarray(layout.guards_xy) * 1e3
    if len(guards):
        ax_map.scatter(guards[:, 0], guards[:, 1], c=peaks_um[n_loc:n_loc + len(guards)], s=80, marker="^", **norm)
    fig.colorbar(sc, ax=ax_map, label="peak |u| (µm)")
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (mm, thumb side →)")
    ax_map.set_ylabel("y (mm, wrist ↑)")
    ax_map.set_title("peak |u|: ■ actuators, ▲ guards", fontsize=10)
    fig.suptitle(f"{method} at location {location}")
    return fig
