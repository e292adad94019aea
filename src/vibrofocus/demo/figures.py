"""Figures of the demo (matplotlib, Agg backend; files only, no windows)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .._atomic import save_figure
from .._style import method_colors, model_footer
from ..defaults import BAND_HZ, N_SAMPLES, SIGMA_S, TARGET_PEAK_M
from ..signals.taper import band_taper
from ..signals.ricker import ricker
from .run import DemoResult, record_clean

__all__ = ["propagation_figure", "field_figure", "metrics_figure", "write_figures"]



def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def arm_label(rig) -> str:
    """How figures name the arm they come from: ``"simulated forearm (skin nominal, seed 0)"``."""
    skin = getattr(rig, "skin", None)
    if skin:
        return f"simulated forearm (skin {skin}, seed {getattr(rig, 'seed', '?')})"
    return "simulated forearm" if rig is None else f"{getattr(rig, 'kind', 'unknown')} rig"


def arm_footer(rig) -> str:
    """The footer of a figure drawn from the simulated forearm: it is a model, not data."""
    return (f"Model: vibrofocus {arm_label(rig)}, simulated vibrometer noise; not a measurement on a person.")


def target_ring(ax, xy_m, radius_m: float = 0.005) -> None:
    """Mark the target with a thin dashed circle around it, leaving the focal spot itself visible.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Axes in mm.
    xy_m : array-like, shape (2,)
        The target, m.
    radius_m : float
        Radius of the circle, m (half the locations' 10 mm spacing by default).
    """
    from matplotlib.patches import Circle

    ax.add_patch(Circle(tuple(np.asarray(xy_m, dtype=float) * 1e3), radius_m * 1e3, fill=False, ec="k", lw=0.7,
                        ls=(0, (2, 1.5)), zorder=4, gid="target-ring"))


def _reachable_upper_hz(freqs: np.ndarray, gain: np.ndarray, dynamic_range_db: float) -> float:
    """Highest frequency up to which ``gain`` stays within ``dynamic_range_db`` of its peak."""
    floor = gain.max() * 10 ** (-dynamic_range_db / 20)
    above = gain >= floor
    peak = int(np.argmax(gain))
    below = np.flatnonzero(~above[peak:])
    last = peak + (below[0] - 1 if below.size else above[peak:].size - 1)
    return float(min(freqs[last], BAND_HZ[1]))


def propagation_figure(rig, path: Path, *, actuator: int | None = None,
                       distances_m: tuple[float, ...] = (0.006, 0.015, 0.025, 0.035, 0.045),
                       n: int = N_SAMPLES, dynamic_range_db: float = 20.0) -> Path:
    """A tap from one actuator at growing distance, plain and inverse filtered.

    Left: the actuator plays the Ricker; the wave spreads, slows at low frequencies
    (dispersion) and loses its high frequencies (attenuation) as it travels. Right:
    for each point, a single-actuator inverse filter (designed on the rig's transfer at
    that point, kept within 90 % of the drive limit) restores the Ricker there, up to the
    frequency where the path's loss exceeds its smallest by ``dynamic_range_db``: the
    attenuation grows with frequency (about 190 Np/m at 250 Hz), and restoring more would
    ask for gains no drive limit allows. Traces are recorded (noise on) and normalised to
    their peak, which is printed beside them.
    """
    from ..rendering import inverse_filter

    plt = _pyplot()
    layout = rig.layout
    if actuator is None:  # an elbow-side actuator, fully coupled, waves going away from the array
        actuator = int(np.argmin(layout.actuators_xy[:, 1]))
    src = layout.actuators_xy[actuator]
    away = np.array([0.0, -1.0]) if src[1] <= 0 else np.array([0.0, 1.0])
    fs = rig.fs
    t0 = n / (2 * fs)
    stimulus = ricker(fs, SIGMA_S, n / fs, t0)
    freqs = np.fft.rfftfreq(n, 1 / fs)
    time_ms = (np.arange(n) / fs - t0) * 1e3
    view = (time_ms > -15) & (time_ms < 45)
    limit = 0.9 * rig.limits.peak_v

    fig, axes = plt.subplots(1, 2, figsize=(10, 5.5), sharey=True)
    for i, dist in enumerate(distances_m):
        point = (src + dist * away)[None]
        plain = np.zeros((layout.n_actuators, n))
        plain[actuator] = limit * stimulus
        rec_plain, _ = record_clean(rig, plain, point)
        h = rig.transfer(point, freqs)[:, :, [actuator]]
        band = (BAND_HZ[0], _reachable_upper_hz(freqs, np.abs(h[:, 0, 0]), dynamic_range_db))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scaling to the limit is intended here
            single = inverse_filter(h, TARGET_PEAK_M * stimulus[None], fs, max_drive=limit, on_limit="scale",
                                    band=band)
        corrected = np.zeros((layout.n_actuators, n))
        corrected[actuator] = single[0]
        rec_corr, _ = record_clean(rig, corrected, point)
        for ax, rec in ((axes[0], rec_plain[0, :n]), (axes[1], rec_corr[0, :n])):
            peak = np.nanmax(np.abs(rec))
            ax.plot(time_ms[view], rec[view] / peak * 0.45 + i, color="k", lw=1)
            ax.text(time_ms[view][-1], i + 0.15, f"{peak * 1e6:.3g} µm", ha="right", fontsize=8)
        desired = np.fft.irfft(np.fft.rfft(stimulus) * band_taper(freqs, band, 0.5), n)
        # Above the recorded trace and dashed: where the two agree, both stay visible.
        axes[1].plot(time_ms[view], desired[view] / np.abs(desired).max() * 0.45 + i, color="tab:red", lw=1.1,
                     ls=(0, (3, 2)), zorder=3, gid=f"asked:{i}")
        axes[1].text(time_ms[view][0], i + 0.3, f"up to {band[1]:.0f} Hz", fontsize=7, color="tab:red")
    axes[0].set_yticks(range(len(distances_m)), [f"{d * 1e3:.0f} mm" for d in distances_m])
    axes[0].set_ylabel("distance from the actuator")
    axes[0].set_title(f"{layout.actuator_names[actuator]} alone plays a {limit:g} V Ricker pulse (a tap's drive)\n",
                      fontsize=10)
    axes[1].set_title(f"inverse filtered at each point\n(red dashed: the Ricker asked, up to {dynamic_range_db:g} dB "
                      "of extra path loss)", fontsize=10)
    for ax in axes:
        ax.set_xlabel("time from the stimulus centre (ms)")
        ax.grid(alpha=0.3)
    fig.suptitle(f"Propagation on the {arm_label(rig)}: dispersion and attenuation, and their correction",
                 fontsize=10)
    model_footer(fig, arm_footer(rig))
    fig.tight_layout(rect=(0, 0.035, 1, 1))
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path


def fields_around_the_tap(result: DemoResult, location: int, methods, offsets_ms, half_width_m: float,
                          n_grid: int) -> tuple[list[str], list[np.ndarray], float]:
    """The skin field of each method at ``offsets_ms`` after its design's ``t0``.

    Returns the methods rendered at ``location`` (in the given order), their fields, each
    ndarray of shape (n_grid * n_grid, n_offsets) in m on a square grid of half-width
    ``half_width_m``, and the largest recorded displacement at the target, m.
    """
    axis = np.linspace(-half_width_m, half_width_m, n_grid)
    gx, gy = np.meshgrid(axis, axis)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    offsets = np.asarray(offsets_ms, dtype=float) * 1e-3
    methods = [m for m in methods if (location, m) in result.renderings]
    fields, target_peak = [], 0.0
    for method in methods:
        rendering = result.renderings[(location, method)]
        rec = result.recordings[(location, method)][rendering.target_index]
        target_peak = max(target_peak, float(np.nanmax(np.abs(rec))))
        fields.append(result.rig.field(rendering.drives, grid, times=np.clip(rendering.t0 + offsets, 0, None),
                                       rtol=1e-5))
    return methods, fields, target_peak


def field_figure(result: DemoResult, path: Path, *, location: int = 5,
                 methods: tuple[str, ...] = ("funneling", "inverse"),
                 offsets_ms: tuple[float, ...] = (-3.0, 0.0, 3.0, 6.0, 9.0),
                 half_width_m: float = 0.035, n_grid: int = 31) -> Path:
    """Displacement around the array at a few instants, every method on one time axis.

    Time 0 is the instant the tap is asked for at the target (the design's ``t0``), the
    same for every method, so a late arrival (funneling's) shows as such. One colour
    scale serves the whole figure: 1.2 times the largest displacement any method
    reaches at the target (the skin under the actuators saturates it on purpose).
    """
    plt = _pyplot()
    rig = result.rig
    layout = rig.layout
    methods, fields, target_peak = fields_around_the_tap(result, location, methods, offsets_ms, half_width_m, n_grid)
    offsets = np.asarray(offsets_ms, dtype=float) * 1e-3
    scale = 1.2 * target_peak * 1e6
    fig, axes = plt.subplots(len(methods), len(offsets_ms), figsize=(2.6 * len(offsets_ms) + 1.0, 2.6 * len(methods)),
                             squeeze=False, sharex=True, sharey=True)
    im = None
    for row, (method, u) in enumerate(zip(methods, fields)):
        for col, offset in enumerate(offsets):
            ax = axes[row, col]
            img = u[:, col].reshape(n_grid, n_grid) * 1e6
            im = ax.imshow(img, origin="lower", cmap="RdBu_r", vmin=-scale, vmax=scale, interpolation="bilinear",
                           extent=np.array([-1, 1, -1, 1]) * half_width_m * 1e3)
            ax.plot(*(layout.actuators_xy.T * 1e3), "ks", ms=5, mfc="none")
            ax.plot(*(layout.locations_xy.T * 1e3), "k.", ms=2)
            target_ring(ax, layout.locations_xy[location - 1])
            ax.set_title(f"{method}, t = {offset * 1e3:+.0f} ms", fontsize=9)
            if col == 0:
                ax.set_ylabel("y (mm, to wrist)")
            if row == len(methods) - 1:
                ax.set_xlabel("x (mm)")
    if im is not None:
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="displacement (µm)")
    fig.suptitle(f"Field around location {location} on the {arm_label(rig)}; "
                 "t = 0: the tap asked at the target (dashed circle)", fontsize=10)
    model_footer(fig, arm_footer(rig) + " Squares: actuators; dots: the nine locations.")
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def metrics_figure(result: DemoResult, path: Path) -> Path:
    """Fidelity, contrast and target peak per location, one bar per method.

    The fidelity panel also marks each method's shape fidelity (best lag) with a dot:
    funneling has the right shape but arrives late, which zero-lag fidelity cannot show.
    The contrast is the peak contrast against the other locations (the target's peak
    displacement over the largest peak at the other locations).
    """
    plt = _pyplot()
    rows = result.rows
    methods = list(dict.fromkeys(r["method"] for r in rows))
    locations = sorted({r["location"] for r in rows})
    width = 0.8 / max(len(methods), 1)
    colors = method_colors(methods)
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    keys = (("fidelity", "fidelity", 1.0), ("contrast_db", "peak contrast vs\nother locations (dB)", 1.0),
            ("target_peak_m", "target peak (µm)", 1e6))
    for ax, (key, label, factor) in zip(axes, keys):
        for j, method in enumerate(methods):
            vals = [next((r[key] for r in rows if r["location"] == loc and r["method"] == method), np.nan)
                    for loc in locations]
            x = np.arange(len(locations)) + (j - (len(methods) - 1) / 2) * width
            ax.bar(x, np.array(vals) * factor, width, label=method, color=colors[method])
            if key == "fidelity":
                shape = [next((r.get("shape_fidelity", np.nan) for r in rows
                               if r["location"] == loc and r["method"] == method), np.nan) for loc in locations]
                ax.plot(x, shape, "o", ms=4, mfc="white", color=colors[method])
        ax.set_ylabel(label)
        ax.axhline(0, color="k", lw=0.5)
        ax.grid(axis="y", alpha=0.3)
    # The shape marker takes each method's colour in the panel; its legend entry is neutral.
    from matplotlib.lines import Line2D

    handles, names = axes[0].get_legend_handles_labels()
    handles.append(Line2D([], [], ls="none", marker="o", ms=4, mfc="white", color="0.3"))
    names.append("shape (best lag)")
    axes[0].legend(handles, names, ncol=len(methods) + 1, fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0),
                   frameon=False)
    axes[-1].set_xticks(range(len(locations)), [str(loc) for loc in locations])
    axes[-1].set_xlabel("location")
    rig = getattr(result, "rig", None)
    fig.suptitle(f"Focus metrics measured on the {arm_label(rig)}")
    bottom = 0.0
    if rig is None or getattr(rig, "kind", "simulated") == "simulated":
        model_footer(fig, arm_footer(rig))
        bottom = 0.03
    if "combination" in methods:
        # One meaning per name: say which waveform the combination's fidelity is measured to.
        fig.text(0.01, bottom + 0.003, "Fidelity: zero-lag correlation with the tap; for the combination, with "
                 "funneling's displacement at the target (the waveform it asks).", fontsize=7.5, color="0.25",
                 ha="left", va="bottom", gid="fidelity-note")
        bottom += 0.025
    fig.tight_layout(rect=(0, bottom, 1, 0.97))
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path


def write_figures(result: DemoResult, out_dir: Path, *, location: int = 5) -> list[Path]:
    """Write the three demo figures into ``out_dir`` (created if needed)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [
        propagation_figure(result.rig, out_dir / "propagation.png"),
        field_figure(result, out_dir / "focused_field.png", location=location),
        metrics_figure(result, out_dir / "metrics.png"),
    ]
