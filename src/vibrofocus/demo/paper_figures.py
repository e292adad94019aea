"""The source paper's Figs. 4–7, drawn from the simulated forearm and simulated participants.

de Vlam et al., "Focused vibrotactile stimuli from a wearable sparse array of actuators",
IEEE Transactions on Haptics 16(4), 2023, lays its results out in four figures: the
inverse filter focusing one actuator's tap along a line (Fig. 4), the focus at location 5
(Fig. 5), perceived positions in Study 1 (Fig. 6) and selected-location counts in Study 2
(Fig. 7). :func:`write_paper_figures` draws the same layouts from vibrofocus' model; Figs. 6
and 7 use the very figure functions that ``vibrofocus analyze`` uses for real data. Every
figure's caption says what is model and what the paper measured.
"""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .._atomic import save_figure
from .._style import method_colors
from ..defaults import BAND_HZ, N_SAMPLES, SIGMA_S, TARGET_PEAK_M
from ..signals.ricker import ricker
from .figures import _pyplot, _reachable_upper_hz, arm_label, fields_around_the_tap, target_ring
from .run import DemoResult, record_clean

__all__ = ["PAPER", "fig4_focusing_along_a_line", "fig5_focus_at_a_location", "fig6_localization", "fig7_counts",
           "write_paper_figures"]

#: The paper these figures follow.
PAPER = "de Vlam et al., IEEE Trans. Haptics 16(4), 2023"
PAPER_METHODS = ("funneling", "inverse", "combination")


def _caption(fig, text: str) -> None:
    """A small caption line at the foot of ``fig`` (room kept under a constrained layout)."""
    engine = fig.get_layout_engine()
    if engine is not None and hasattr(engine, "set") and "rect" in getattr(engine, "get", dict)():
        engine.set(rect=(0, 0.035, 1, 0.965))
    fig.text(0.01, 0.005, text, fontsize=7.5, color="0.25", ha="left", va="bottom", wrap=True, gid="caption")


def _model_caption(model: str) -> str:
    """Caption of a figure drawn from simulated participants: their model and hypothesis."""
    return f"{model[:1].upper()}{model[1:]}. The paper ({PAPER}) reports 20 people."


def _lobes(x: np.ndarray, share: float = 0.2) -> int:
    """Lobes of ``x`` (runs of one sign) whose peak reaches ``share`` of the largest; a Ricker has 3."""
    x = np.asarray(x, dtype=float)
    if not np.any(x):
        return 0
    edges = np.flatnonzero(np.diff(np.signbit(x))) + 1
    peaks = np.array([np.abs(seg).max() for seg in np.split(x, edges) if seg.size])
    return int(np.sum(peaks >= share * peaks.max()))


def fig4_focusing_along_a_line(rig, path: Path, *, actuator: int | None = None,
                               distances_m: Sequence[float] = (0.004, 0.008, 0.012, 0.016),
                               n: int = N_SAMPLES, dynamic_range_db: float = 20.0) -> Path:
    """Fig. 4: one actuator, points on a line; a plain tap disperses, one drive focuses.

    Left: the actuator plays the Ricker and the points record it, spreading and late with
    distance. Middle: ONE drive, the single-actuator inverse filter designed to put the
    Ricker at the farthest point (band-limited to where that path loses less than
    ``dynamic_range_db`` more than at its best; see :func:`~vibrofocus.demo.figures.propagation_figure`).
    Right: that drive recorded at every point: a compact wavelet at the farthest, spread
    elsewhere.
    """
    from ..rendering import inverse_filter
    from ..signals.taper import band_taper

    plt = _pyplot()
    layout = rig.layout
    if actuator is None:
        actuator = int(np.argmin(layout.actuators_xy[:, 1]))
    src = layout.actuators_xy[actuator]
    away = np.array([0.0, -1.0]) if src[1] <= 0 else np.array([0.0, 1.0])
    points = src + np.asarray(distances_m, dtype=float)[:, None] * away
    fs = rig.fs
    t0 = n / (2 * fs)
    stimulus = ricker(fs, SIGMA_S, n / fs, t0)
    freqs = np.fft.rfftfreq(n, 1 / fs)
    time_ms = (np.arange(n) / fs - t0) * 1e3
    limit = 0.9 * rig.limits.peak_v

    plain = np.zeros((layout.n_actuators, n))
    plain[actuator] = limit * stimulus
    rec_plain, _ = record_clean(rig, plain, points)
    h = rig.transfer(points[-1:], freqs)[:, :, [actuator]]
    band = (BAND_HZ[0], _reachable_upper_hz(freqs, np.abs(h[:, 0, 0]), dynamic_range_db))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scaling to the limit is intended here
        single = inverse_filter(h, TARGET_PEAK_M * stimulus[None], fs, max_drive=limit, on_limit="scale", band=band)
    focused = np.zeros((layout.n_actuators, n))
    focused[actuator] = single[0]
    rec_focused, _ = record_clean(rig, focused, points)
    desired = np.fft.irfft(np.fft.rfft(stimulus) * band_taper(freqs, band, 0.5), n)

    fig, axes = plt.subplots(1, 3, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1, 1.1, 1]})
    view = (time_ms > -15) & (time_ms < 30)
    for ax, rec, title in ((axes[0], rec_plain, f"{layout.actuator_names[actuator]} alone plays a {limit:g} V Ricker pulse"),
                           (axes[2], rec_focused, "the drive in the middle, recorded")):
        for i, dist in enumerate(distances_m):
            trace = rec[i, :n]
            peak = np.nanmax(np.abs(trace))
            ax.plot(time_ms[view], trace[view] / peak * 0.45 + i, color="k", lw=1, gid=f"trace:{i}")
            ax.text(time_ms[view][-1], i + 0.2, f"{peak * 1e6:.2g} µm", ha="right", fontsize=8)
        ax.set_yticks(range(len(distances_m)), [f"{d * 1e3:.0f} mm" for d in distances_m])
        ax.set_xlabel("time from the stimulus centre (ms)")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    axes[2].plot(time_ms[view], desired[view] / np.abs(desired).max() * 0.45 + len(distances_m) - 1,
                 color="tab:red", lw=1.1, ls=(0, (3, 2)), zorder=3, gid="asked",
                 label=f"asked (Ricker up to {band[1]:.0f} Hz)")
    axes[2].legend(loc="lower right", fontsize=7, frameon=False)
    axes[0].set_ylabel("distance from the actuator")
    drive_view = (time_ms > -60) & (time_ms < 20)
    axes[1].plot(time_ms[drive_view], single[0][drive_view], color=method_colors(["inverse"])["inverse"], lw=0.9,
                 gid="drive")
    axes[1].set_xlabel("time from the stimulus centre (ms)")
    axes[1].set_ylabel("drive (V)")
    # What the drive shows, measured from it: how early its peak leaves (the travel time) and
    # how many lobes it has (the Ricker has 3): on a short, mildly lossy path nearly one
    # wavelet, on a lossy one a burst that boosts the top of the band.
    lead_ms = -float(time_ms[np.argmax(np.abs(single[0]))])
    lobes = _lobes(single[0])
    shape = ("nearly one wavelet; " if lobes <= 4 else
             f"a burst of {lobes} lobes, the band's top boosted against the path's loss;\n")
    axes[1].set_title(f"one drive, focused at {distances_m[-1] * 1e3:.0f} mm\n({shape}its peak "
                      f"{lead_ms:.1f} ms early: the travel time)", fontsize=10)
    axes[1].grid(alpha=0.3)
    fig.suptitle("Fig. 4 layout: focusing one actuator's tap along a line")
    _caption(fig, f"Model: vibrofocus {arm_label(rig)}, vibrometer noise on; "
                  f"not a measurement. The paper ({PAPER}) measured this with a laser vibrometer on a forearm.")
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def fig5_focus_at_a_location(result: DemoResult, path: Path, *, location: int = 5,
                             methods: Sequence[str] = PAPER_METHODS,
                             offsets_ms: Sequence[float] = (0.0, 3.0, 6.0, 9.0, 12.0),
                             half_width_m: float = 0.035, n_grid: int = 31) -> Path:
    """Fig. 5: the focus at one location, snapshots and the time course at every location.

    One row of skin snapshots per method, at the same instants after the tap is asked at
    the target (the design's ``t0``), on one colour scale; below, each method's
    displacement over time at every location, the target bold.
    """
    plt = _pyplot()
    rig = result.rig
    layout = rig.layout
    methods, fields, peak = fields_around_the_tap(result, location, methods, offsets_ms, half_width_m, n_grid)
    colors = method_colors(methods)
    offsets = np.asarray(offsets_ms, dtype=float) * 1e-3
    scale = 1.2 * peak * 1e6
    n_cols = len(offsets)
    fig = plt.figure(figsize=(2.3 * n_cols + 1.2, 2.3 * len(methods) + 3.0))
    spec = fig.add_gridspec(len(methods) + 1, n_cols, height_ratios=[1] * len(methods) + [1.3])
    im = None
    for row, (method, u) in enumerate(zip(methods, fields)):
        for col, offset in enumerate(offsets):
            ax = fig.add_subplot(spec[row, col])
            im = ax.imshow(u[:, col].reshape(n_grid, n_grid) * 1e6, origin="lower", cmap="RdBu_r", vmin=-scale,
                           vmax=scale, interpolation="bilinear", extent=np.array([-1, 1, -1, 1]) * half_width_m * 1e3)
            ax.plot(*(layout.actuators_xy.T * 1e3), "ks", ms=4, mfc="none")
            ax.plot(*(layout.locations_xy.T * 1e3), "k.", ms=2)
            target_ring(ax, layout.locations_xy[location - 1])
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"t = {offset * 1e3:+.0f} ms", fontsize=9)
            if col == 0:
                ax.set_ylabel(method, color=colors[method], fontsize=10)
    if im is not None:
        fig.colorbar(im, ax=fig.axes, shrink=0.5, label="displacement (µm)", location="right")
    fs = rig.fs
    bottom = spec[len(methods), :].subgridspec(1, len(methods), wspace=0.08)
    for k, method in enumerate(methods):
        ax = fig.add_subplot(bottom[0, k], sharey=fig.axes[-1] if k else None)
        if k:
            ax.tick_params(labelleft=False)
        rendering = result.renderings[(location, method)]
        rec = result.recordings[(location, method)]
        t_ms = (np.arange(rec.shape[1]) / fs - rendering.t0) * 1e3
        view = (t_ms > -10) & (t_ms < 20)
        for i in range(layout.n_locations):
            target = i == rendering.target_index
            ax.plot(t_ms[view], rec[i, view] * 1e6, color=colors[method] if target else "0.7",
                    lw=1.6 if target else 0.7, zorder=3 if target else 1, gid=f"time:{method}:{i + 1}")
        ax.set_title(f"{method}: every location (target bold)", fontsize=9)
        ax.set_xlabel("time (ms)")
        ax.set_ylim(-1.1 * peak * 1e6, 1.1 * peak * 1e6)
        ax.grid(alpha=0.3)
    fig.axes[-len(methods)].set_ylabel("µm")
    fig.suptitle(f"Fig. 5 layout: focus at location {location}, all methods at the same peak drive; "
                 "t = 0: the tap asked at the target", fontsize=10)
    note = _symmetry_note(result, location, methods)
    _caption(fig, f"Model: vibrofocus {arm_label(rig)}, designs from a simulated "
                  f"calibration; not a measurement. The paper ({PAPER}) measured the field with a vibrometer."
                  + (f"\n{note}" if note else ""))
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def _symmetry_note(result: DemoResult, location: int, methods: Sequence[str]) -> str:
    """A caption line when the combination keeps funneling's drive waveforms (a symmetric location).

    At a location equally far from every actuator, funneling plays the same tap on each,
    and the combination (funneling's own displacement at the target, the guards kept
    quiet) is met by the same waveforms, rebalanced only for the actuators' unequal
    coupling: the two rows then look alike by symmetry, not by a fault. Said only when
    every actuator's two drives correlate at 0.95 or more.
    """
    if not {"funneling", "combination"} <= set(methods):
        return ""
    a = np.asarray(result.renderings[(location, "funneling")].drives, dtype=float)
    b = np.asarray(result.renderings[(location, "combination")].drives, dtype=float)
    if a.shape != b.shape or not (np.std(a, axis=1) > 0).all() or not (np.std(b, axis=1) > 0).all():
        return ""
    corr = min(float(np.corrcoef(x, y)[0, 1]) for x, y in zip(a, b))
    if corr < 0.95:
        return ""
    levels = np.abs(b).max(axis=1)
    return (f"At location {location}, equally far from every actuator, the combination keeps funneling's drive "
            f"waveforms by symmetry (correlation >= {np.floor(corr * 100) / 100:.2f} per actuator), only "
            f"rebalanced for the actuators' coupling ({levels.min():.1f}-{levels.max():.1f} V): so the rows look "
            "alike.")


def fig6_localization(positions, layout, path: Path, *, n_participants: int, model: str) -> Path:
    """Fig. 6: mean perceived position and 1-SD ellipse per target and method.

    The figure of ``vibrofocus analyze`` (:func:`~vibrofocus.analysis.plot_localization`),
    captioned as model output with ``model``: the label of the simulated participants'
    model and hypothesis (the trials' ``model`` column).
    """
    from ..analysis.figures import plot_localization

    fig = plot_localization(positions, layout, title="Fig. 6 layout: Study 1, perceived positions "
                                                     f"({n_participants} simulated participants)")
    _caption(fig, _model_caption(model))
    return save_figure(fig, path)


def fig7_counts(counts, counts_hit, path: Path, *, n_participants: int, model: str) -> Path:
    """Fig. 7: selected-location counts per target and method (Study 2).

    The figure of ``vibrofocus analyze`` (:func:`~vibrofocus.analysis.plot_counts`),
    captioned as model output with ``model`` (as :func:`fig6_localization`).
    """
    from ..analysis.figures import plot_counts

    fig = plot_counts(counts, counts_hit)
    fig.suptitle(f"Fig. 7 layout: Study 2, locations selected ({n_participants} simulated participants)")
    _caption(fig, _model_caption(model))
    return save_figure(fig, path)


def write_paper_figures(out_dir: Path, *, seed: int = 0, participants: int = 12, location: int = 5,
                        progress: Callable[[str], None] | None = None, skin: str | None = None) -> list[Path]:
    """Draw Figs. 4–7 into ``out_dir``: ``paper_fig4.png`` ... ``paper_fig7.png``.

    Parameters
    ----------
    out_dir : path
        Created if needed.
    seed : int
        Simulated forearm of Figs. 4–5 and seed of the simulated study of Figs. 6–7.
    participants : int
        Simulated participants in the study (each is calibrated and runs Studies 1 and
        2, about 3 s each).
    location : int
        Focus location of Fig. 5.
    progress : callable, optional
        Called with a short label as each part starts.
    skin : str, optional
        Skin preset of the forearm of Figs. 4-5 (default ``"nominal"``). The simulated
        study of Figs. 6-7 uses the arms its perceptual model was fitted on (``STUDY_SKIN``, nominal).

    Returns
    -------
    list of Path
    """
    from ..analysis import analyze, load_trials
    from ..calibration import calibrate
    from ..rigs.simulated import SimulatedForearm
    from ..simulation import simulate_studies
    from ..studies import StudyStore
    from .run import calibrated_transfer, run_demo

    say = progress or (lambda _label: None)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = SimulatedForearm(seed=seed, skin=skin)
    say("Fig. 4: focusing along a line")
    paths = [fig4_focusing_along_a_line(rig, out / "paper_fig4.png")]
    say("Fig. 5: calibrating, then focusing at the location")
    cal = calibrate(rig, participant_id=f"simulated-{seed}")
    result = run_demo(rig, methods=PAPER_METHODS, locations=[location], transfer=calibrated_transfer(cal))
    paths.append(fig5_focus_at_a_location(result, out / "paper_fig5.png", location=location))
    say(f"Figs. 6-7: a simulated study with {participants} participants")
    with tempfile.TemporaryDirectory(prefix="vibrofocus-paper-") as tmp:
        db = Path(tmp) / "study.sqlite"
        simulate_studies(db, n_participants=participants, seed=seed)
        with StudyStore(db) as store:
            store.export_trials_csv(Path(tmp) / "trials.csv")
        analysis = analyze(load_trials(Path(tmp) / "trials.csv"))
    model = "; ".join(analysis.simulated_models)  # the trials' own label: model, hypothesis, version
    if analysis.study1 is not None:
        paths.append(fig6_localization(analysis.study1.positions, analysis.layout, out / "paper_fig6.png",
                                       n_participants=len(analysis.study1.participants), model=model))
    if analysis.study2 is not None:
        hit = analysis.study2.contains_target.counts
        paths.append(fig7_counts(analysis.study2.all_trials.counts, hit if len(hit) else None,
                                 out / "paper_fig7.png", n_participants=len(analysis.study2.all_trials.participants),
                                 model=model))
    return paths
