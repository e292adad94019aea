"""Quality verdicts of a calibration: what to trust, what to re-measure, and why.

Checks (docs/method.md, calibration), each with its criterion (thresholds in :class:`QualityThresholds`):

low coherence
    Per (point, actuator), the in-band frequencies where the coherence over repeats is
    below ``coherence_min`` (default 0.5: the repeat-to-repeat noise is as large as the
    response), when they cover at least ``coherence_share`` of the band. If they lie
    (80 % or more) in one range reaching the top of the band, the pair is reported as
    usable up to that range (info: typical far from an actuator, where skin damps high
    frequencies below the sensor noise; :attr:`QualityReport.coherent_to_hz`);
    otherwise as a warning with the frequency ranges. Not assessable with a single
    repeat.
dead actuator
    The actuator's largest in-band RMS gain over all points is below ``dead_ratio``
    (default 0.1, -20 dB) of the median of that figure over the actuators, or it never
    rises ``snr_min_db`` above the noise floor at any point.
reversed actuator
    Polarity is judged relative to the other actuators, because a rig's absolute sign
    convention (exciter wiring, vibrometer axis) is arbitrary. For each actuator take its
    *near-field* transfer function, at the calibrated point nearest to it, over the band;
    identical exciters at similar distances give near-field responses that differ mainly
    in gain. The normalised real correlations ``Re <g_a, g_b>`` form a matrix whose
    leading eigenvector gives each actuator a sign; the actuators in the minority sign
    are reversed (for a tie, those of opposite sign to the first actuator). Needs at
    least three live actuators to say which one is wrong; with two, opposite signs are
    reported for the pair.
clipping
    A recording whose largest magnitude repeats on ``clip_samples`` or more samples (a
    flat top) or reaches the sensor range the rig reports (``sensor_range_m``); a drive
    whose peak is within 1 % of the rig's peak limit (the amplifier may clip).
low SNR
    In-band SNR of the response over the noise floor measured in the silence before
    each sweep, below ``snr_min_db`` (default 10 dB).
a point that barely moves
    The point's largest in-band RMS gain over the actuators is below ``still_ratio``
    (default 0.1) of the median over points: usually a mis-aimed vibrometer.
dropouts
    Recordings with NaN/Inf samples were left out of the estimate; reported as info.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..layout import ArrayLayout

__all__ = ["QualityThresholds", "QualityIssue", "QualityReport", "assess_quality", "detect_clipping"]

SEVERITIES = ("info", "warning", "error")


@dataclass(frozen=True)
class QualityThresholds:
    """Thresholds of the quality checks (see the module docstring)."""

    coherence_min: float = 0.5
    coherence_share: float = 0.1
    dead_ratio: float = 0.1
    still_ratio: float = 0.1
    snr_min_db: float = 10.0
    clip_samples: int = 4

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class QualityIssue:
    """One verdict.

    Parameters
    ----------
    check : str
        ``low_coherence``, ``coherence_limit``, ``dead_actuator``, ``reversed_actuator``, ``clipping``,
        ``drive_at_limit``, ``low_snr``, ``still_point`` or ``dropouts``.
    severity : {"info", "warning", "error"}
    message : str
        What was found and what to do, in words.
    point : int, optional
        Point index (into ``layout.points_xy``) it concerns, if one.
    actuator : int, optional
        Actuator index it concerns, if one.
    """

    check: str
    severity: str
    message: str
    point: int | None = None
    actuator: int | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "QualityIssue":
        return cls(**data)


@dataclass
class QualityReport:
    """Quality figures and verdicts of one calibration.

    Attributes
    ----------
    issues : list of QualityIssue
    snr_db : ndarray, shape (n_points, n_actuators)
        In-band SNR, dB.
    noise_rms_m : ndarray, shape (n_points, n_actuators)
        In-band noise floor during the recordings of each pair, m.
    band_gain : ndarray, shape (n_points, n_actuators)
        RMS of ``|H|`` over the band, m/V.
    low_coherence_share : ndarray, shape (n_points, n_actuators)
        Share of band frequencies with low coherence (NaN: not assessable).
    coherent_to_hz : ndarray, shape (n_points, n_actuators)
        Frequency up to which the pair is coherent when its low coherence lies at the
        top of the band; the band's top otherwise; NaN where not assessable.
    clipped : ndarray of bool, shape (n_points, n_actuators)
    repeats_used : ndarray of int, shape (n_points, n_actuators)
        Recordings kept after excluding dropouts.
    dropouts : ndarray of int, shape (n_points, n_actuators)
        Recordings left out because of dropouts.
    polarity : ndarray of int, shape (n_actuators,)
        +1 / -1 relative polarity, 0 where not judged (dead or too few actuators).
    thresholds : QualityThresholds
    """

    issues: list[QualityIssue]
    snr_db: np.ndarray
    noise_rms_m: np.ndarray
    band_gain: np.ndarray
    low_coherence_share: np.ndarray
    coherent_to_hz: np.ndarray
    clipped: np.ndarray
    repeats_used: np.ndarray
    dropouts: np.ndarray
    polarity: np.ndarray
    thresholds: QualityThresholds = field(default_factory=QualityThresholds)

    @property
    def _band_top(self) -> float:
        finite = self.coherent_to_hz[np.isfinite(self.coherent_to_hz)]
        return float(finite.max()) if finite.size else np.inf

    @property
    def ok(self) -> bool:
        """True when no issue is an error."""
        return not any(i.severity == "error" for i in self.issues)

    def by_check(self, check: str) -> list[QualityIssue]:
        """The issues of one check."""
        return [i for i in self.issues if i.check == check]

    def verdicts(self) -> np.ndarray:
        """Short verdict per (point, actuator), e.g. ``"ok"`` or ``"reversed; SNR 4 dB"``.

        Returns
        -------
        ndarray of str, shape (n_points, n_actuators)
        """
        n_p, n_a = self.snr_db.shape
        tags: list[list[list[str]]] = [[[] for _ in range(n_a)] for _ in range(n_p)]
        for issue in self.issues:
            if issue.check == "dead_actuator":
                for p in range(n_p):
                    tags[p][issue.actuator].append("dead actuator")
            elif issue.check == "reversed_actuator":
                for p in range(n_p):
                    tags[p][issue.actuator].append("reversed")
            elif issue.check == "still_point":
                for a in range(n_a):
                    tags[issue.point][a].append("point still")
        t = self.thresholds
        for p in range(n_p):
            for a in range(n_a):
                if self.clipped[p, a]:
                    tags[p][a].append("clipped")
                if self.snr_db[p, a] < t.snr_min_db:
                    tags[p][a].append(f"SNR {self.snr_db[p, a]:.0f} dB")
                share = self.low_coherence_share[p, a]
                top = self.coherent_to_hz[p, a]
                if np.isfinite(share) and share >= t.coherence_share:
                    if np.isfinite(top) and top < self._band_top:
                        tags[p][a].append(f"to {top:.0f} Hz")
                    else:
                        tags[p][a].append(f"low coh. {share:.0%}")
        out = np.empty((n_p, n_a), dtype=object)
        for p in range(n_p):
            for a in range(n_a):
                out[p, a] = "; ".join(tags[p][a]) or "ok"
        return out.astype(str)

    def table(self, layout: ArrayLayout, title: str = "Calibration quality"):
        """A rich table: one row per point, one column per actuator, the verdict in each
        cell with the SNR."""
        from rich.table import Table

        verdicts = self.verdicts()
        table = Table(title=title)
        table.add_column("point")
        table.add_column("x, y (mm)", justify="right", no_wrap=True)
        for name in layout.actuator_names:
            table.add_column(name)
        for p, (label, xy) in enumerate(zip(layout.point_labels, layout.points_xy)):
            cells = []
            for a in range(layout.n_actuators):
                v = verdicts[p, a]
                style = "green" if v == "ok" else ("red" if _is_error(v) else
                                                   "cyan" if v.startswith("to ") else "yellow")
                snr = self.snr_db[p, a]
                cells.append(f"[{style}]{v}[/] ({snr:.0f} dB)" if v == "ok"
                             else f"[{style}]{v}[/]")
            table.add_row(label, f"{xy[0] * 1e3:+.1f}, {xy[1] * 1e3:+.1f}", *cells)
        return table

    def lines(self) -> list[str]:
        """The issues as ``severity: message`` lines (errors first)."""
        order = {s: i for i, s in enumerate(reversed(SEVERITIES))}
        return [f"{i.severity}: {i.message}" for i in sorted(self.issues, key=lambda i: order[i.severity])]


def _is_error(verdict: str) -> bool:
    return any(tag in verdict for tag in ("dead", "reversed", "clipped"))


def detect_clipping(recordings: np.ndarray, *, clip_samples: int = 4, sensor_range_m: float | None = None) -> np.ndarray:
    """Flag recordings that look clipped.

    Parameters
    ----------
    recordings : ndarray, shape (..., n_samples)
        Displacement, m; non-finite samples are ignored.
    clip_samples : int
        A flat top: the largest magnitude occurs on at least this many samples (a
        linear response to a sweep plus noise practically never repeats its maximum).
    sensor_range_m : float, optional
        The sensor's range, m; reaching 99.9 % of it counts as clipping.

    Returns
    -------
    ndarray of bool, shape (...)
    """
    mag = np.abs(np.where(np.isfinite(recordings), recordings, 0.0))
    peak = mag.max(axis=-1)
    at_peak = (mag >= peak[..., None] * (1 - 1e-9)) & (peak[..., None] > 0)
    clipped = at_peak.sum(axis=-1) >= clip_samples
    if sensor_range_m is not None:
        clipped |= peak >= 0.999 * sensor_range_m
    return clipped


def _ranges(freqs: np.ndarray, mask: np.ndarray, min_gap: int = 1) -> list[tuple[float, float]]:
    """Runs of True in ``mask`` as (first, last) frequency pairs; runs separated by fewer
    than ``min_gap`` False bins are merged (scattered dips read as one range)."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    runs = [[s, e] for s, e in zip(edges[::2], edges[1::2])]
    merged: list[list[int]] = []
    for run in runs:
        if merged and run[0] - merged[-1][1] < min_gap:
            merged[-1][1] = run[1]
        else:
            merged.append(run)
    return [(float(freqs[s]), float(freqs[e - 1])) for s, e in merged]


def _format_ranges(ranges: list[tuple[float, float]], limit: int = 4) -> str:
    parts = [f"{lo:.0f} Hz" if lo == hi else f"{lo:.0f}-{hi:.0f} Hz" for lo, hi in ranges[:limit]]
    if len(ranges) > limit:
        parts.append(f"and {len(ranges) - limit} more range(s)")
    return ", ".join(parts)


def _polarity(
    H: np.ndarray, in_band: np.ndarray, layout: ArrayLayout, live: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative polarity from the near-field transfer functions (module docstring)."""
    points = layout.points_xy
    dist = np.linalg.norm(points[:, None, :] - layout.actuators_xy[None, :, :], axis=-1)
    nearest = dist.argmin(axis=0)  # (n_actuators,)
    g = H[in_band][:, nearest, np.arange(layout.n_actuators)].T  # (n_act, n_band)
    norms = np.linalg.norm(g, axis=1, keepdims=True)
    g = np.divide(g, norms, out=np.zeros_like(g), where=norms > 0)
    corr = np.real(g @ g.conj().T)
    polarity = np.zeros(layout.n_actuators, dtype=int)
    idx = np.flatnonzero(live)
    if idx.size >= 2:
        sub = corr[np.ix_(idx, idx)]
        _, vecs = np.linalg.eigh(sub)
        signs = np.where(vecs[:, -1] >= 0, 1, -1)
        majority = np.sign(signs.sum()) or signs[0]
        polarity[idx] = signs * majority
    return polarity, corr, nearest


def assess_quality(
    H: np.ndarray,
    coherence: np.ndarray,
    freqs: np.ndarray,
    band: tuple[float, float],
    layout: ArrayLayout,
    *,
    snr_db: np.ndarray,
    noise_rms_m: np.ndarray,
    clipped: np.ndarray,
    repeats_used: np.ndarray,
    dropouts: np.ndarray,
    drive_peak_v: float,
    peak_limit_v: float,
    thresholds: QualityThresholds | None = None,
) -> QualityReport:
    """Run every check on an estimated transfer matrix.

    Parameters
    ----------
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Estimate, m/V.
    coherence : ndarray, shape (n_freqs, n_points, n_actuators)
        In [0, 1]; NaN where not assessable.
    freqs : ndarray, shape (n_freqs,)
        Hz.
    band : (float, float)
        Calibrated band, Hz.
    layout : ArrayLayout
    snr_db, noise_rms_m : ndarray, shape (n_points, n_actuators)
        From :func:`vibrofocus.calibration.estimate.noise_and_snr`.
    clipped : ndarray of bool, shape (n_points, n_actuators)
        Any recording of the pair clipped.
    repeats_used : ndarray of int, shape (n_points, n_actuators)
        Recordings kept per pair.
    dropouts : ndarray of int, shape (n_points, n_actuators)
        Recordings left out per pair because of dropouts.
    drive_peak_v, peak_limit_v : float
        Sweep peak and the rig's peak limit, V.
    thresholds : QualityThresholds, optional

    Returns
    -------
    QualityReport
    """
    t = thresholds or QualityThresholds()
    names, labels = layout.actuator_names, layout.point_labels
    in_band = (freqs >= band[0]) & (freqs <= band[1])
    band_gain = np.sqrt(np.mean(np.abs(H[in_band]) ** 2, axis=0))  # (P, A)
    issues: list[QualityIssue] = []

    # Dead actuators: compared with the others, or never above the noise floor.
    best = band_gain.max(axis=0)
    reference = np.median(best)
    dead = (best < t.dead_ratio * reference) | (np.nanmax(snr_db, axis=0) < t.snr_min_db / 2)
    for a in np.flatnonzero(dead):
        ratio_db = 20 * np.log10(max(best[a], 1e-300) / reference) if reference > 0 else -np.inf
        issues.append(QualityIssue(
            "dead_actuator", "error",
            f"actuator {names[a]} looks dead: its strongest response anywhere is {ratio_db:.0f} dB "
            f"relative to the median actuator and its best SNR is {np.nanmax(snr_db[:, a]):.0f} dB; "
            "check its cable, amplifier channel and contact with the skin",
            actuator=int(a)))

    # Reversed actuators.
    polarity, corr, nearest = _polarity(H, in_band, layout, ~dead)
    live = np.flatnonzero(~dead)
    reversed_ = np.flatnonzero(polarity < 0)
    if live.size == 2 and reversed_.size:
        a, b = live
        issues.append(QualityIssue(
            "reversed_actuator", "warning",
            f"actuators {names[a]} and {names[b]} have opposite polarity (near-field correlation "
            f"{corr[a, b]:+.2f}); with two actuators vibrofocus cannot tell which is reversed",
            actuator=None))
        polarity[:] = 0
    elif live.size >= 3:
        for a in reversed_:
            others = [b for b in live if polarity[b] > 0]
            mean_corr = float(np.mean(corr[a, others])) if others else float("nan")
            d_mm = np.linalg.norm(layout.points_xy[nearest[a]] - layout.actuators_xy[a]) * 1e3
            issues.append(QualityIssue(
                "reversed_actuator", "error",
                f"actuator {names[a]} is reversed: its near-field response (point {labels[nearest[a]]}, "
                f"{d_mm:.1f} mm away) has the opposite sign to {', '.join(names[b] for b in others)} "
                f"(mean correlation {mean_corr:+.2f}); swap its wires. The inverse filter compensates "
                "a measured reversal, funneling does not",
                actuator=int(a)))

    # Points that barely move.
    point_best = band_gain.max(axis=1)
    point_ref = np.median(point_best)
    for p in np.flatnonzero(point_best < t.still_ratio * point_ref):
        ratio_db = 20 * np.log10(max(point_best[p], 1e-300) / point_ref)
        xy = layout.points_xy[p] * 1e3
        issues.append(QualityIssue(
            "still_point", "warning",
            f"point {labels[p]} ({xy[0]:+.1f}, {xy[1]:+.1f} mm) barely moves: its strongest response is "
            f"{ratio_db:.0f} dB relative to the median point; check the vibrometer aim and the "
            "reflective patch there",
            point=int(p)))

    # Clipping.
    for p, a in np.argwhere(clipped):
        issues.append(QualityIssue(
            "clipping", "error",
            f"point {labels[p]} / {names[a]}: the recording is clipped (flat top or sensor range); "
            "lower amplitude_v or the vibrometer's sensitivity and calibrate again",
            point=int(p), actuator=int(a)))
    if drive_peak_v >= 0.99 * peak_limit_v:
        issues.append(QualityIssue(
            "drive_at_limit", "warning",
            f"the sweep peak {drive_peak_v:.2f} V is at the rig's peak limit of {peak_limit_v:g} V; "
            "the amplifier may clip, lower amplitude_v"))

    # Low SNR, one issue per actuator listing its points.
    for a in np.flatnonzero(~dead):
        low = np.flatnonzero(snr_db[:, a] < t.snr_min_db)
        if low.size:
            listing = ", ".join(f"{labels[p]} ({snr_db[p, a]:.0f} dB)" for p in low)
            issues.append(QualityIssue(
                "low_snr", "warning",
                f"actuator {names[a]}: in-band SNR below {t.snr_min_db:g} dB at point(s) {listing}; "
                "more repeats or a longer sweep help",
                actuator=int(a)))

    # Low coherence.
    f_band = freqs[in_band]
    coh = coherence[in_band]  # (n_band, P, A)
    assessable = np.isfinite(coh).all(axis=0)
    low_mask = np.where(np.isfinite(coh), coh < t.coherence_min, False)
    share = np.where(assessable, low_mask.mean(axis=0), np.nan)
    flagged = assessable & (share >= t.coherence_share) & ~dead[None, :]
    coherent_to = np.where(assessable, band[1], np.nan)
    wide: dict[int, list[str]] = {}
    top_limited: dict[int, list[str]] = {}
    for p, a in np.argwhere(flagged):
        ranges = _ranges(f_band, low_mask[:, p, a], min_gap=max(3, int(0.02 * f_band.size)))
        last_lo, last_hi = ranges[-1]
        in_last = low_mask[:, p, a][f_band >= last_lo].sum()
        if last_hi >= f_band[-1] and in_last >= 0.8 * low_mask[:, p, a].sum():
            coherent_to[p, a] = last_lo
            top_limited.setdefault(a, []).append(f"{labels[p]} (to {last_lo:.0f} Hz)")
        else:
            wide.setdefault(a, []).append(f"{labels[p]} ({share[p, a]:.0%}: {_format_ranges(ranges)})")
    for a, parts in sorted(wide.items()):
        issues.append(QualityIssue(
            "low_coherence", "warning",
            f"actuator {names[a]}: coherence below {t.coherence_min:g} over at least {t.coherence_share:.0%} "
            f"of the band at point(s) {'; '.join(parts)}; check the actuator's contact and the vibrometer "
            "signal there, or add repeats"
            + (f" (with {int(repeats_used.max())} repeats the coherence estimate itself is coarse: pure noise "
               f"gives {1 / max(int(repeats_used.max()), 1):.2g} on average)" if repeats_used.max() < 4 else ""),
            actuator=int(a)))
    for a, parts in sorted(top_limited.items()):
        issues.append(QualityIssue(
            "coherence_limit", "info",
            f"actuator {names[a]}: coherent only up to a frequency at point(s) {', '.join(parts)}; above it the "
            "skin damps the response below the sensor noise (expected far from an actuator)",
            actuator=int(a)))

    # Dropouts.
    missing = np.asarray(dropouts, int)
    if (missing > 0).any():
        pairs = ", ".join(f"{labels[p]}/{names[a]} ({missing[p, a]})" for p, a in np.argwhere(missing > 0)[:8])
        more = int((missing > 0).sum()) - 8
        issues.append(QualityIssue(
            "dropouts", "info",
            f"{int(missing[missing > 0].sum())} recording(s) with vibrometer dropouts (NaN samples) were "
            f"left out: point/actuator {pairs}{f' and {more} more' if more > 0 else ''}"))

    return QualityReport(
        issues=issues, snr_db=np.asarray(snr_db, float), noise_rms_m=np.asarray(noise_rms_m, float),
        band_gain=band_gain, low_coherence_share=share, coherent_to_hz=coherent_to, clipped=np.asarray(clipped, bool),
        repeats_used=np.asarray(repeats_used, int), dropouts=missing, polarity=polarity, thresholds=t,
    )
