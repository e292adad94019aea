"""Figure of a calibration: |H| and coherence per actuator, one line per point."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .calibrate import Calibration

__all__ = ["plot_calibration"]


def plot_calibration(cal: Calibration, path: str | os.PathLike | None = None, *, dpi: int = 120):
    """Plot ``|H|`` (dB re 1 µm/V) and coherence against frequency.

    One column per actuator; the top row holds the gain to every point (locations as
    solid lines, guard points dashed), the bottom row the coherence over repeats (empty
    when it was not assessable). The calibrated band is shaded.

    Parameters
    ----------
    cal : Calibration
    path : str or PathLike, optional
        Where to save the figure (PNG by extension); if omitted it is only returned.
    dpi : int
        Resolution of the saved file.

    Returns
    -------
    matplotlib.figure.Figure
    """
    # The object-oriented API without pyplot: no GUI backend, no global figure state.
    from matplotlib.figure import Figure

    lay = cal.layout
    n_a = cal.n_actuators
    fig = Figure(figsize=(3.2 * n_a + 1.5, 6.0), constrained_layout=True)
    axes = fig.subplots(2, n_a, sharex=True, sharey="row", squeeze=False)
    f = cal.freqs
    show = (f >= cal.band[0] / 2) & (f <= min(cal.band[1] * 2, cal.fs / 2))
    gain_db = 20 * np.log10(np.maximum(np.abs(cal.H[show]), 1e-30) / 1e-6)
    from matplotlib import colormaps

    palette = colormaps["tab10" if lay.n_points <= 10 else "tab20"]
    colours = [palette(i % palette.N) for i in range(lay.n_points)]
    for a in range(n_a):
        top, bottom = axes[0, a], axes[1, a]
        for p, label in enumerate(lay.point_labels):
            style = "-" if p < lay.n_locations else "--"
            top.semilogx(f[show], gain_db[:, p, a], style, color=colours[p], lw=0.8, label=label)
            if np.isfinite(cal.coherence[show, p, a]).any():
                bottom.semilogx(f[show], cal.coherence[show, p, a], style, color=colours[p], lw=0.8)
        for ax in (top, bottom):
            ax.axvspan(*cal.band, color="0.92", zorder=0)
            ax.grid(True, which="both", lw=0.3)
        top.set_title(lay.actuator_names[a])
        bottom.set_xlabel("frequency (Hz)")
        bottom.set_ylim(-0.05, 1.05)
        bottom.axhline(cal.quality.thresholds.coherence_min, color="k", lw=0.6, ls=":")
        if not np.isfinite(cal.coherence[show, :, a]).any():
            bottom.text(0.5, 0.5, "coherence not assessed\n(one repeat)", ha="center", va="center",
                        transform=bottom.transAxes)
    axes[0, 0].set_ylabel("|H| (dB re 1 µm/V)")
    axes[1, 0].set_ylabel("coherence")
    # Scale to the calibrated band: outside it the estimate is tapered to nothing.
    in_band = (f[show] >= cal.band[0]) & (f[show] <= cal.band[1])
    axes[0, 0].set_ylim(np.percentile(gain_db[in_band], 1) - 10, gain_db[in_band].max() + 5)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, title="point", fontsize="x-small", loc="outside right center")
    fig.suptitle(f"Calibration of {cal.participant_id} ({cal.method}, {cal.created})")
    if path is not None:
        from .._atomic import save_figure

        save_figure(fig, Path(path), dpi=dpi)
    return fig
