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
    (default 0.1, -20 dB) of that figure for the strongest actuator, or it never rises
    ``snr_min_db`` above the noise floor at any point. (The strongest, not the median: with
    most actuators unconnected the median is zero and would condemn the one that works.)
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
predicted points
    A calibration that measures a subset of the points (``calibrate(..., measure=K)``)
    predicts ``H`` at the others from the skin model fitted to the measured ones: each
    is reported as info (``predicted``), every other check reads the measured points
    only, and a fit whose residual at a measured point exceeds ``fit_residual_max``
    (default 0.05) is a warning (``fit_residual``): the model does not describe that
    arm well, so its predictions are not to be trusted.

With all actuators at once (``mimo``) the per-pair checks read the same figures (the
coherence is each actuator's partial coherence, the SNR each actuator's share of the
response over the noise floor), plus three checks of the separation:

ill-conditioned inputs
    Per point, the condition number of the input spectral matrix of the takes kept
    exceeds ``condition_max`` (default 10) somewhere in the band: the actuators cannot
    be told apart reliably there (too many takes lost to dropouts). An error.
correlated inputs
    Per point, the largest normalised input cross-spectrum ``|G_ab| / sqrt(G_aa G_bb)``
    in the band exceeds ``input_correlation_max`` (default 0.5). The Hadamard signs make
    it 0; dropouts raise it (1/7 after losing one take of eight). A warning.
low multiple coherence
    Per point, the share of the response that the actuators together explain is below
    ``coherence_min`` over at least ``coherence_share`` of the band, not only at its top
    (nonlinearity, a moving arm, noise); read against the pure-noise value
    ``n_actuators / n_takes``. A warning; at the top of the band only, info.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .._docs import fill_doc
from ..errors import ValidationError
from ..layout import ArrayLayout

__all__ = ["TRUSTED_COHERENCE", "QualityThresholds", "QualityIssue", "QualityReport", "assess_quality",
           "detect_clipping"]

#: Largest relative fit residual at a measured point (:attr:`~.fitmodel.FittedSkin.residual`) of a
#: model that describes the skin (an assumption: the simulated arms give about 0.005 with
#: the default noise, in the model's family; a layered fit of the ``voigt-fit`` arm
#: misses by more). Over it, :attr:`~.fitmodel.FittedSkin.verdict` says so, and so does the
#: calibration's quality (``fit_residual_max``).
FIT_RESIDUAL_MAX = 0.05

SEVERITIES = ("info", "warning", "error")

#: Coherence a frequency needs at every point for the calibration to be trusted there: the
#: demo's "coherent band" and the line drawn on the calibration figure. Stricter than the
#: quality check's ``coherence_min`` (0.5), which flags a path only where noise is as large
#: as the response.
TRUSTED_COHERENCE = 0.9


@dataclass(frozen=True)
class QualityThresholds:
    """Thresholds of the quality checks (see the module docstring).

    Attributes
    ----------
    coherence_min : float
        Coherence below which a frequency counts as incoherent.
    coherence_share : float
        Share of the band's frequencies that may be incoherent before a path is flagged.
    dead_ratio : float
        An actuator whose band gain is below this fraction of the strongest actuator's is dead.
    still_ratio : float
        A point whose response is below this fraction of the median point's barely moves.
    snr_min_db : float
        Lowest acceptable signal-to-noise ratio in the band, dB.
    clip_samples : int
        Samples at full scale that make a recording clipped.
    condition_max : float
        ``mimo``: largest condition number of the input spectral matrix at which the
        actuators are still separated (above it the calibration is an error).
    input_correlation_max : float
        ``mimo``: largest normalised cross-spectrum between two actuators' inputs before
        a warning (0 when every take is kept: the Hadamard signs are orthogonal).
    fit_residual_max : float
        A calibration with predicted points: largest relative residual of the skin-model
        fit at a measured point before a warning (:attr:`FittedSkin.residual`; the
        simulated arms give about 0.005 with the default noise).
    """

    coherence_min: float = 0.5
    coherence_share: float = 0.1
    dead_ratio: float = 0.1
    still_ratio: float = 0.1
    snr_min_db: float = 10.0
    clip_samples: int = 4
    condition_max: float = 10.0
    input_correlation_max: float = 0.5
    fit_residual_max: float = FIT_RESIDUAL_MAX

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class QualityIssue:
    """One verdict.

    Parameters
    ----------
    check : str
        ``low_coherence``, ``coherence_limit``, ``dead_actuator``, ``reversed_actuator``, ``clipping``,
        ``drive_at_limit``, ``low_snr``, ``still_point``, ``dropouts``, for ``mimo``
        ``ill_conditioned``, ``input_correlation``, ``low_multiple_coherence`` and
        ``multiple_coherence_limit``, and for a calibration of a subset of the points
        ``predicted`` and ``fit_residual``.
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
    input_condition : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only: condition number of the input spectral matrix per frequency and
        point (1: perfectly separable; inf: singular).
    input_correlation : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only: largest normalised input cross-spectrum per frequency and point
        (0: uncorrelated inputs).
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
    input_condition: np.ndarray | None = None
    input_correlation: np.ndarray | None = None

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
            elif issue.check == "ill_conditioned":
                for a in range(n_a):
                    tags[issue.point][a].append("not separable")
            elif issue.check == "predicted":
                for a in range(n_a):
                    tags[issue.point][a].append("predicted")
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
        cell with the SNR (in-band response over the noise floor before the sweep, dB)."""
        from rich.table import Table

        verdicts = self.verdicts()
        table = Table(title=title, caption="ok (dB): the in-band signal-to-noise ratio, the response over the "
                                           "noise floor measured before each sweep")
        table.add_column("point")
        table.add_column("x, y (mm)", justify="right", no_wrap=True)
        for name in layout.actuator_names:
            table.add_column(f"{name} (SNR)")
        for p, (label, xy) in enumerate(zip(layout.point_labels, layout.points_xy)):
            cells = []
            for a in range(layout.n_actuators):
                v = verdicts[p, a]
                style = "green" if v == "ok" else ("red" if _is_error(v) else
                                                   "cyan" if v.startswith(("to ", "predicted")) else "yellow")
                snr = self.snr_db[p, a]
                cells.append(f"[{style}]{v}[/] ({snr:.0f} dB)" if v == "ok" and np.isfinite(snr)
                             else f"[{style}]{v}[/]")
            table.add_row(label, f"{xy[0] * 1e3:+.1f}, {xy[1] * 1e3:+.1f}", *cells)
        return table

    def lines(self) -> list[str]:
        """The issues as ``severity: message`` lines (errors first)."""
        order = {s: i for i, s in enumerate(reversed(SEVERITIES))}
        lines = [f"{i.severity}: {i.message}" for i in sorted(self.issues, key=lambda i: order[i.severity])
                 if i.check != "predicted"]
        predicted = [i.message.split(" was not measured")[0].removeprefix("point ") for i in self.by_check("predicted")]
        if predicted:  # one line for all of them
            first = self.by_check("predicted")[0].message
            lines.append(f"info: point(s) {', '.join(predicted)} were not measured" + first.split(" was not measured")[1])
        return lines


def _is_error(verdict: str) -> bool:
    return any(tag in verdict for tag in ("dead", "reversed", "clipped", "not separable"))


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
    H: np.ndarray, in_band: np.ndarray, layout: ArrayLayout, live: np.ndarray, measured: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative polarity from the near-field transfer functions (module docstring), at
    the nearest measured point."""
    points = layout.points_xy
    dist = np.linalg.norm(points[:, None, :] - layout.actuators_xy[None, :, :], axis=-1)
    dist[~measured] = np.inf
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


@fill_doc
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
    multiple_coherence: np.ndarray | None = None,
    input_condition: np.ndarray | None = None,
    input_correlation: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    fit_residual: np.ndarray | None = None,
) -> QualityReport:
    """Run every check on an estimated transfer matrix.

    Parameters
    ----------
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Estimate, m/V.
    coherence : ndarray, shape (n_freqs, n_points, n_actuators)
        In [0, 1]; NaN where not assessable (``mimo``: partial coherence).
    freqs : ndarray, shape (n_freqs,)
        Hz.
    band : (float, float)
        Calibrated band, Hz.
    %(layout)s
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
    multiple_coherence, input_condition, input_correlation : ndarray, shape (n_freqs, n_points), optional
        ``mimo`` only (:class:`vibrofocus.calibration.estimate.MimoEstimate`): given
        together, they add the separation checks and are kept in the report.
    measured : ndarray of bool, shape (n_points,), optional
        Which rows of ``H`` were measured (default all); the others were predicted by a
        fitted skin model and hold NaN in the figures of the recordings. Each predicted
        point is reported (``predicted``, info) and the other checks read the measured
        points only.
    fit_residual : ndarray, shape (n_points,), optional
        With ``measured``: the fit's relative residual per point
        (:attr:`FittedSkin.residual`); above ``fit_residual_max`` at a measured point, a
        warning.

    Returns
    -------
    QualityReport
    """
    t = thresholds or QualityThresholds()
    names, labels = layout.actuator_names, layout.point_labels
    in_band = (freqs >= band[0]) & (freqs <= band[1])
    band_gain = np.sqrt(np.mean(np.abs(H[in_band]) ** 2, axis=0))  # (P, A)
    issues: list[QualityIssue] = []
    m = np.ones(layout.n_points, bool) if measured is None else np.asarray(measured, bool).reshape(layout.n_points)
    if not m.any():
        raise ValidationError("measured must mark at least one point as measured")

    # Dead actuators: compared with the strongest one (not the median, which is zero when
    # most are unconnected and would then call every actuator dead), or never above the
    # noise floor.
    best = band_gain[m].max(axis=0)
    strongest = int(np.argmax(best))
    reference = best[strongest]
    dead = (best < t.dead_ratio * reference) | (np.nanmax(snr_db, axis=0) < t.snr_min_db / 2)
    for a in np.flatnonzero(dead):
        ratio_db = 20 * np.log10(max(best[a], 1e-300) / reference) if reference > 0 else -np.inf
        relative = (f"{ratio_db:.0f} dB relative to the strongest actuator ({names[strongest]})"
                    if reference > 0 and a != strongest else "no response above zero" if reference == 0
                    else "the strongest of all")
        issues.append(QualityIssue(
            "dead_actuator", "error",
            f"actuator {names[a]} looks dead: its strongest response anywhere is {relative} "
            f"and its best SNR is {np.nanmax(snr_db[:, a]):.0f} dB; "
            "check its cable, amplifier channel and contact with the skin",
            actuator=int(a)))

    # Reversed actuators.
    polarity, corr, nearest = _polarity(H, in_band, layout, ~dead, m)
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
    point_ref = np.median(point_best[m])
    for p in np.flatnonzero(m & (point_best < t.still_ratio * point_ref)):
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

    # Low coherence (partial coherence of each actuator for mimo).
    f_band = freqs[in_band]
    share, coherent_to, wide, top_limited = _low_coherence(f_band, coherence[in_band], band[1], t, ~dead)
    n_inputs = H.shape[2] if multiple_coherence is not None else 1
    dof = int(repeats_used.max()) - n_inputs + 1  # pure noise gives 1/dof on average
    for a, parts in sorted(wide.items()):
        issues.append(QualityIssue(
            "low_coherence", "warning",
            f"actuator {names[a]}: coherence below {t.coherence_min:g} over at least {t.coherence_share:.0%} "
            f"of the band at point(s) {'; '.join(f'{labels[p]} {d}' for p, d in parts)}; check the actuator's "
            "contact and the vibrometer "
            "signal there, or add repeats"
            + (f" (with {int(repeats_used.max())} repeats the coherence estimate itself is coarse: pure noise "
               f"gives {1 / max(dof, 1):.2g} on average)" if dof < 4 else ""),
            actuator=int(a)))
    for a, parts in sorted(top_limited.items()):
        issues.append(QualityIssue(
            "coherence_limit", "info",
            f"actuator {names[a]}: coherent only up to a frequency at point(s) "
            f"{', '.join(f'{labels[p]} {d}' for p, d in parts)}; above it the "
            "skin damps the response below the sensor noise (expected far from an actuator)",
            actuator=int(a)))
    if multiple_coherence is not None:
        issues += _separation_issues(multiple_coherence[in_band], input_condition[in_band],
                                     input_correlation[in_band], f_band, band[1], layout, repeats_used, t)

    # Dropouts.
    missing = np.asarray(dropouts, int)
    if (missing > 0).any():
        pairs = ", ".join(f"{labels[p]}/{names[a]} ({missing[p, a]})" for p, a in np.argwhere(missing > 0)[:8])
        more = int((missing > 0).sum()) - 8
        issues.append(QualityIssue(
            "dropouts", "info",
            f"{int(missing[missing > 0].sum())} recording(s) with vibrometer dropouts (NaN samples) were "
            f"left out: point/actuator {pairs}{f' and {more} more' if more > 0 else ''}"))

    if not m.all():
        issues = [i for i in issues if i.point is None or m[i.point]]  # no figures of a recording there
        issues += _predicted_issues(layout, m, fit_residual, t)

    return QualityReport(
        issues=issues, snr_db=np.asarray(snr_db, float), noise_rms_m=np.asarray(noise_rms_m, float),
        band_gain=band_gain, low_coherence_share=share, coherent_to_hz=coherent_to, clipped=np.asarray(clipped, bool),
        repeats_used=np.asarray(repeats_used, int), dropouts=missing, polarity=polarity, thresholds=t,
        input_condition=None if input_condition is None else np.asarray(input_condition, float),
        input_correlation=None if input_correlation is None else np.asarray(input_correlation, float),
    )


def _predicted_issues(layout: ArrayLayout, measured: np.ndarray, fit_residual: np.ndarray | None,
                      t: QualityThresholds) -> list[QualityIssue]:
    """One ``predicted`` info per point not measured, and ``fit_residual`` warnings."""
    labels = layout.point_labels
    k = int(measured.sum())
    issues = [QualityIssue(
        "predicted", "info",
        f"point {labels[p]} was not measured: its H is predicted by the skin model fitted to the {k} measured "
        "point(s)", point=int(p)) for p in np.flatnonzero(~measured)]
    if fit_residual is not None:
        res = np.asarray(fit_residual, float).reshape(layout.n_points)
        for p in np.flatnonzero(measured & (res > t.fit_residual_max)):
            issues.append(QualityIssue(
                "fit_residual", "warning",
                f"point {labels[p]}: the skin model fitted to the measured points misses its H by {res[p]:.1%} "
                f"(limit {t.fit_residual_max:.0%}), so the predicted points are not to be trusted; measure every "
                "point", point=int(p)))
    return issues


def _low_coherence(f_band: np.ndarray, coh: np.ndarray, band_top: float, t: QualityThresholds,
                   live: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    """Pairs whose coherence is low over a share of the band, and how.

    Parameters
    ----------
    f_band : ndarray, shape (n_band,)
        In-band frequencies, Hz.
    coh : ndarray, shape (n_band, n_points, n_columns)
        Coherence in the band (NaN: not assessable).
    band_top : float
        Top of the band, Hz.
    t : QualityThresholds
    live : ndarray of bool, shape (n_columns,)
        Columns to judge.

    Returns
    -------
    share, coherent_to : ndarray, shape (n_points, n_columns)
        Share of low-coherence frequencies and frequency up to which the pair is coherent
        (NaN: not assessable).
    wide, top_limited : dict of column -> list of (int, str)
        Flagged points per column with a note: low coherence spread over the band, or
        only at its top.
    """
    assessable = np.isfinite(coh).all(axis=0)
    low_mask = np.where(np.isfinite(coh), coh < t.coherence_min, False)
    share = np.where(assessable, low_mask.mean(axis=0), np.nan)
    flagged = assessable & (share >= t.coherence_share) & live[None, :]
    coherent_to = np.where(assessable, band_top, np.nan)
    wide: dict[int, list[tuple[int, str]]] = {}
    top_limited: dict[int, list[tuple[int, str]]] = {}
    for p, a in np.argwhere(flagged):
        gap = max(3, int(0.02 * f_band.size))
        ranges = _ranges(f_band, low_mask[:, p, a], min_gap=gap)
        last_lo, last_hi = ranges[-1]
        in_last = low_mask[:, p, a][f_band >= last_lo].sum()
        # "At the top": the last range ends within a merge gap of the band's top (one
        # noisy bin above the threshold there does not make it a mid-band problem).
        if last_hi >= f_band[max(f_band.size - gap, 0)] and in_last >= 0.8 * low_mask[:, p, a].sum():
            coherent_to[p, a] = last_lo
            top_limited.setdefault(a, []).append((p, f"(to {last_lo:.0f} Hz)"))
        else:
            wide.setdefault(a, []).append((p, f"({share[p, a]:.0%}: {_format_ranges(ranges)})"))
    return share, coherent_to, wide, top_limited


def _separation_issues(multiple: np.ndarray, condition: np.ndarray, correlation: np.ndarray, f_band: np.ndarray,
                       band_top: float, layout: ArrayLayout, repeats_used: np.ndarray,
                       t: QualityThresholds) -> list[QualityIssue]:
    """The ``mimo`` checks (module docstring) on in-band figures of shape (n_band, n_points)."""
    labels = layout.point_labels
    issues = []
    worst_cond = condition.max(axis=0)
    for p in np.flatnonzero(~(worst_cond <= t.condition_max)):
        f_worst = f_band[int(np.argmax(condition[:, p]))]
        issues.append(QualityIssue(
            "ill_conditioned", "error",
            f"point {labels[p]}: the takes kept cannot separate the actuators reliably (input condition number "
            f"{worst_cond[p]:.3g} at {f_worst:.0f} Hz, limit {t.condition_max:g}); too many takes were lost to "
            "dropouts: calibrate this point again", point=int(p)))
    worst_corr = correlation.max(axis=0)
    for p in np.flatnonzero(worst_corr > t.input_correlation_max):
        issues.append(QualityIssue(
            "input_correlation", "warning",
            f"point {labels[p]}: the actuators' excitations in the takes kept are correlated up to "
            f"{worst_corr[p]:.2f} (limit {t.input_correlation_max:g}; 0 with every take); the estimate separates "
            "them but with more noise", point=int(p)))
    _, _, wide, top_limited = _low_coherence(f_band, multiple[:, :, None], band_top, t, np.ones(1, bool))
    n_inputs = layout.n_actuators
    floor = n_inputs / max(int(repeats_used.max()), 1)
    for check, severity, found, what in (
        ("low_multiple_coherence", "warning", wide.get(0, []),
         "check the contact of the actuators and the vibrometer signal there; nonlinearity or a moving arm "
         "also lower it"),
        ("multiple_coherence_limit", "info", top_limited.get(0, []),
         "above it the skin damps every actuator's response below the sensor noise"),
    ):
        for p, detail in found:
            issues.append(QualityIssue(
                check, severity,
                f"point {labels[p]}: the actuators together explain less than {t.coherence_min:g} of the response "
                f"{detail} (multiple coherence; pure noise gives {floor:.2g}); {what}", point=int(p)))
    return issues
