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
    solid lines in ten distinct colours, guard points as grey dash patterns), the bottom
    row the coherence over repeats (empty when it was not assessable) with the line above
    which a frequency is trusted (:data:`~vibrofocus.calibration.quality.TRUSTED_COHERENCE`)
    and, dotted, the quality check's ``coherence_min``. The calibrated band is shaded and
    named in the legend. A calibration measured on the simulated forearm says so in a
    footer.

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
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from .._style import model_footer, point_styles
    from .quality import TRUSTED_COHERENCE

    lay = cal.layout
    n_a = cal.n_actuators
    fig = Figure(figsize=(3.2 * n_a + 1.5, 6.3), constrained_layout=True)
    axes = fig.subplots(2, n_a, sharex=True, sharey="row", squeeze=False)
    f = cal.freqs
    show = (f >= cal.band[0] / 2) & (f <= min(cal.band[1] * 2, cal.fs / 2))
    gain_db = 20 * np.log10(np.maximum(np.abs(cal.H[show]), 1e-30) / 1e-6)
    # 13 points: ten distinct colours for the locations, grey dash patterns for the guards.
    styles = point_styles(lay.n_locations, lay.n_points - lay.n_locations)
    flag_at = cal.quality.thresholds.coherence_min
    for a in range(n_a):
        top, bottom = axes[0, a], axes[1, a]
        for p, label in enumerate(lay.point_labels):
            colour, style = styles[p]
            top.semilogx(f[show], gain_db[:, p, a], linestyle=style, color=colour, lw=0.8, label=label)
            if np.isfinite(cal.coherence[show, p, a]).any():
                bottom.semilogx(f[show], cal.coherence[show, p, a], linestyle=style, color=colour, lw=0.8)
        for ax in (top, bottom):
            ax.axvspan(*cal.band, color="0.93", zorder=0)
            ax.grid(True, which="both", lw=0.3)
        top.set_title(lay.actuator_names[a])
        bottom.set_xlabel("frequency (Hz)")
        bottom.set_ylim(-0.05, 1.05)
        bottom.axhline(TRUSTED_COHERENCE, color="k", lw=0.9, ls="--", zorder=5)
        if flag_at != TRUSTED_COHERENCE:
            bottom.axhline(flag_at, color="k", lw=0.6, ls=":", zorder=5)
        if not np.isfinite(cal.coherence[show, :, a]).any():
            bottom.text(0.5, 0.5, "coherence not assessed\n(one repeat)", ha="center", va="center",
                        transform=bottom.transAxes)
    axes[0, 0].set_ylabel("|H| (dB re 1 µm/V)")
    axes[1, 0].set_ylabel("coherence")
    # Scale to the calibrated band: outside it the estimate is tapered to nothing.
    in_band = (f[show] >= cal.band[0]) & (f[show] <= cal.band[1])
    axes[0, 0].set_ylim(np.percentile(gain_db[in_band], 1) - 10, gain_db[in_band].max() + 5)
    handles, names = axes[0, 0].get_legend_handles_labels()
    handles += [Patch(color="0.93", label="band"),
                Line2D([], [], color="k", lw=0.9, ls="--")]
    names += [f"calibrated band\n{cal.band[0]:g}-{cal.band[1]:g} Hz",
              f"coherence {TRUSTED_COHERENCE:g}:\ntrusted above"]
    if flag_at != TRUSTED_COHERENCE:
        handles.append(Line2D([], [], color="k", lw=0.6, ls=":"))
        names.append(f"coherence {flag_at:g}:\nflagged below")
    fig.legend(handles, names, title="point", fontsize="x-small", loc="outside right center")
    fig.suptitle(f"Calibration of {cal.participant_id} ({cal.method}, {cal.created})")
    rig = cal.rig if isinstance(cal.rig, dict) else {}
    if rig.get("kind") == "simulated":
        model_footer(fig, f"Model: vibrofocus simulated forearm (skin {rig.get('skin', '?')}, seed "
                          f"{rig.get('seed', '?')}), simulated vibrometer; not a measurement on a person.")
    if path is not None:
        from .._atomic import save_figure

        save_figure(fig, Path(path), dpi=dpi)
    return fig
