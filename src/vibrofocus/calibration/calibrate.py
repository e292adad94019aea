"""Measure the skin's transfer matrix on a rig: :func:`calibrate` and :class:`Calibration`."""

from __future__ import annotations

import datetime as _dt
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .._validation import check_band, check_choice
from ..defaults import BAND_HZ, N_SAMPLES
from ..errors import SafetyError, ValidationError, VibrofocusError
from ..io.calibration_nc import SCHEMA_VERSION
from ..layout import ArrayLayout
from ..signals.taper import band_taper
from ..rigs.base import Rig
from .estimate import (
    estimate_repeats,
    h1_average,
    mimo_h1,
    noise_and_snr,
    resize_impulse_response,
    split_snr,
)
from .excitation import METHODS, SweepSettings, default_settings, hadamard_codes, make_excitation
from .quality import QualityReport, QualityThresholds, assess_quality, detect_clipping

__all__ = ["SCHEMA_VERSION", "DEFAULT_METHOD", "Calibration", "CalibrationPlan", "calibrate", "plan_calibration"]

# SCHEMA_VERSION: version of the calibration data model and of its file layout
# (vibrofocus.io.calibration_nc, its home). Version 2 added the ``mimo`` method's
# variables; version 1 files still load.

#: Method of :func:`calibrate` when none is given.
DEFAULT_METHOD = "mimo"

log = logging.getLogger(__name__)

#: Extra recordings tried for a point whose every repeat had a dropout.
MAX_RETRIES = 3

PromptFn = Callable[[str, np.ndarray], None]
ProgressFn = Callable[[int, int, str], None]


@dataclass(eq=False)
class Calibration:
    """A measured transfer matrix with everything needed to trust and reproduce it.

    Attributes
    ----------
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Transfer matrix, m/V, on ``freqs``; point ``i`` is ``layout.points_xy[i]``.
    freqs : ndarray, shape (n_freqs,)
        ``numpy.fft.rfftfreq(n_fft, 1 / fs)``, Hz.
    fs : float
        Sample rate, Hz.
    coherence : ndarray, shape (n_freqs, n_points, n_actuators)
        Coherence over repeats, in [0, 1]; NaN where not assessable (one repeat). For
        ``mimo`` the partial coherence of each actuator given the others
        (:class:`.estimate.MimoEstimate`); NaN with no more takes than actuators.
    layout : ArrayLayout
        The actuators and points calibrated.
    band : (float, float)
        Calibrated band, Hz; outside it ``H`` is not to be trusted.
    participant_id : str
    method : {"h1", "paper", "mimo"}
    quality : QualityReport
    drives : ndarray, shape (n_actuators, n_drive)
        Voltage on actuator ``a``'s channel while ``a`` was measured (all other channels
        were zero), as played after the rig's fades, V. For ``mimo``, every take played
        ``codes[r, a] * drives[a]`` on every actuator ``a`` at once.
    recordings : ndarray, float32
        Raw displacement, m; NaN marks a dropout. Shape (n_actuators, n_repeats,
        n_points, n_rec) for ``h1``/``paper`` (one actuator per take); (n_repeats,
        n_points, n_rec) for ``mimo`` (all actuators in every take). Stored in single
        precision (about 0.1 ppm of the signal, far below sensor noise).
    rig : dict
        ``rig.describe()`` at calibration time.
    straps : dict or None
        Strap force reading taken just before the sweeps (``StrapReading.to_dict()``:
        forces in N against the 1 N target), for rigs with strap sensors; else None.
    sweep : SweepSettings
    created : str
        ISO 8601 time (UTC) of the calibration.
    software_version : str
        ``vibrofocus.__version__`` that measured it.
    schema_version : int
    codes : ndarray of int8, shape (n_repeats, n_actuators), or None
        ``mimo`` only: the sign of each actuator's sweep in each take
        (:func:`.excitation.hadamard_codes`).
    multiple_coherence : ndarray, shape (n_freqs, n_points), or None
        ``mimo`` only: share of each point's response the actuators together explain,
        in [0, 1] (NaN where not assessable); pure noise gives ``n_actuators / n_repeats``.
    recorded_s : float
        Real duration of the takes recorded, re-recordings included, s (NaN when not
        known, e.g. a file written before it was stored).
    fit : FittedSkin or None
        The skin model fitted to ``H`` (``cal.fit = fit_model(cal)``), stored with the
        calibration file when set; None otherwise.
    """

    H: np.ndarray
    freqs: np.ndarray
    fs: float
    coherence: np.ndarray
    layout: ArrayLayout
    band: tuple[float, float]
    participant_id: str
    method: str
    quality: QualityReport
    drives: np.ndarray
    recordings: np.ndarray
    rig: dict
    sweep: SweepSettings
    created: str = field(default_factory=lambda: _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    software_version: str = field(default_factory=lambda: _software_version())
    schema_version: int = SCHEMA_VERSION
    straps: dict | None = None
    codes: np.ndarray | None = None
    multiple_coherence: np.ndarray | None = None
    recorded_s: float = float("nan")
    fit: Any = None

    @property
    def n_fft(self) -> int:
        """Length of the time window whose real-FFT grid ``freqs`` is."""
        return 2 * (len(self.freqs) - 1)

    @property
    def n_points(self) -> int:
        return self.H.shape[1]

    @property
    def n_actuators(self) -> int:
        return self.H.shape[2]

    def impulse_responses(self) -> np.ndarray:
        """Impulse responses of ``H``, m/V per sample, time zero at index 0 (negative times
        wrap to the end), shape (n_points, n_actuators, n_fft)."""
        return np.fft.irfft(np.moveaxis(self.H, 0, -1), self.n_fft, axis=-1)

    def wraparound_check(self, n: int, *, taper_octaves: float = 0.5):
        """The :class:`~vibrofocus.rendering.WraparoundCheck` of ``transfer_for(n)``, built
        once per ``(n, taper_octaves)`` and kept: its ``H`` is the design's transfer matrix
        and the spectra it caches make every later check of a design cheap."""
        from ..rendering.causality import WraparoundCheck

        cache = self.__dict__.setdefault("_wraparound_checks", {})
        key = (n, float(taper_octaves))
        if key not in cache:
            cache[key] = WraparoundCheck(self.transfer_for(n, taper_octaves=taper_octaves), n)
        return cache[key]

    def transfer_for(self, n: int, *, taper_octaves: float = 0.5) -> np.ndarray:
        """The transfer matrix on the design grid ``rfftfreq(n, 1 / fs)``.

        The stored ``H`` (on ``rfftfreq(n_fft, 1/fs)``) is taken to the time domain; its
        impulse responses are zero-padded (``n > n_fft``) or cut with half-Hann fades
        (``n < n_fft``), keeping the causal part at the start and a short acausal part
        (1/16 of the window) at the end (:func:`.estimate.resize_impulse_response`), and
        transformed back. Outside the calibrated band, where nothing was measured
        reliably, the values are tapered to zero with a raised cosine over
        ``taper_octaves`` octaves beyond each band edge (the designs band-limit to the
        calibrated band anyway, with the same half-octave taper by default); beyond the
        taper they are exactly zero.

        Parameters
        ----------
        n : int
            Window length, samples (even, >= 16).
        taper_octaves : float
            Width of the out-of-band taper, octaves.

        Returns
        -------
        ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
            m/V.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 16 or n % 2:
            raise ValidationError(f"n must be an even integer >= 16 (samples), got {n!r}")
        n = int(n)
        if n == self.n_fft:
            H = self.H.copy()
        else:
            h = resize_impulse_response(self.impulse_responses(), n)
            H = np.moveaxis(np.fft.rfft(h, axis=-1), -1, 0)
        freqs = np.fft.rfftfreq(n, 1 / self.fs)
        with np.errstate(over="ignore", divide="ignore"):  # band_taper at 0 Hz
            taper = band_taper(freqs, self.band, taper_octaves)
        return H * taper[:, None, None]

    def summary_table(self, title: str | None = None):
        """Rich table with a verdict per point and actuator (see :class:`QualityReport`)."""
        title = title or f"Calibration of {self.participant_id} ({self.method}, {self.band[0]:g}-{self.band[1]:g} Hz)"
        return self.quality.table(self.layout, title=title)

    def __repr__(self) -> str:
        return (
            f"Calibration(participant_id={self.participant_id!r}, method={self.method!r}, "
            f"n_points={self.n_points}, n_actuators={self.n_actuators}, n_fft={self.n_fft}, "
            f"fs={self.fs:g}, band={self.band}, quality_ok={self.quality.ok})"
        )


def _software_version() -> str:
    from .. import __version__

    return __version__


def _sub_layout(layout: ArrayLayout, points: Sequence[int] | None, actuators: Sequence[int] | None):
    """The layout restricted to chosen point and actuator indices (order kept)."""
    p_idx = _indices(points, layout.n_points, "points", "points of the layout")
    a_idx = _indices(actuators, layout.n_actuators, "actuators", "actuators of the layout")
    if points is None and actuators is None:
        return layout, p_idx, a_idx
    loc = p_idx[p_idx < layout.n_locations]
    grd = p_idx[p_idx >= layout.n_locations] - layout.n_locations
    if loc.size == 0:
        raise ValidationError("points must include at least one location (not only guard points)")
    sub = ArrayLayout(
        layout.actuators_xy[a_idx], layout.locations_xy[loc], layout.guards_xy[grd],
        spacing_xy=layout.spacing_xy, actuator_names=tuple(layout.actuator_names[i] for i in a_idx),
        guard_names=tuple(layout.guard_names[i] for i in grd), name=f"{layout.name} (subset)",
    )
    # Locations come first in a layout, so keep that order for the recordings too.
    return sub, np.concatenate([loc, grd + layout.n_locations]), a_idx


def _indices(sel: Sequence[int] | None, n: int, name: str, what: str) -> np.ndarray:
    if sel is None:
        return np.arange(n)
    idx = np.asarray(list(sel))
    if idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
        raise ValidationError(f"{name} must be a non-empty sequence of integer indices, got {sel!r}")
    if idx.min() < 0 or idx.max() >= n:
        raise ValidationError(f"{name} holds an index outside the {n} {what} (valid: 0..{n - 1}): {sel!r}")
    if len(np.unique(idx)) != idx.size:
        raise ValidationError(f"{name} lists an index twice: {sel!r}")
    return np.sort(idx)


@dataclass(frozen=True)
class CalibrationPlan:
    """What a calibration will play and how long the takes last (:func:`plan_calibration`).

    Attributes
    ----------
    method : {"h1", "paper", "mimo"}
    settings : SweepSettings
    point_indices : tuple of int
        Points of the rig's layout calibrated, in recording order.
    actuator_indices : tuple of int
        Actuators of the rig's layout calibrated.
    positions : int
        Vibrometer positions: 1 for a rig that records every point in each take, else
        one per group of points it can record at once (the operator aims at each).
    """

    method: str
    settings: SweepSettings
    point_indices: tuple[int, ...]
    actuator_indices: tuple[int, ...]
    positions: int

    @property
    def takes_per_position(self) -> int:
        """Takes at each vibrometer position: ``repeats`` per actuator, or ``repeats`` for
        all actuators at once (``mimo``)."""
        n_a = 1 if self.method == "mimo" else len(self.actuator_indices)
        return n_a * self.settings.repeats

    @property
    def takes(self) -> int:
        """Takes in all (without re-recordings after dropouts)."""
        return self.positions * self.takes_per_position

    @property
    def duration_s(self) -> float:
        """Real duration of the takes (silence, sweep and tail each), s; aiming the
        vibrometer and re-recordings after dropouts come on top."""
        return self.takes * self.settings.take_s

    def describe(self) -> str:
        """The plan in one line, e.g. ``"mimo: 8 takes of 2.4 s (...) = 19.2 s of sweeps"``."""
        n_a, n_r = len(self.actuator_indices), self.settings.repeats
        who = (f"all {n_a} actuators at once, {n_r} Hadamard-coded repeats" if self.method == "mimo"
               else f"{n_a} actuator(s) one at a time x {n_r} repeat(s)")
        where = ("every point in each take" if self.positions == 1
                 else f"at each of {self.positions} vibrometer positions")
        text = (f"{self.method}: {self.takes} takes of {self.settings.take_s:.3g} s ({who}, {where}) = "
                f"{_format_duration(self.duration_s)} of sweeps")
        if self.positions > 1:
            text += f", plus aiming the vibrometer {self.positions} times"
        return text


def _format_duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.1f} s"
    minutes, rest = divmod(int(round(seconds)), 60)
    return f"{minutes} min {rest:02d} s"


def plan_calibration(
    rig: Rig,
    *,
    method: str = DEFAULT_METHOD,
    points: Sequence[int] | None = None,
    actuators: Sequence[int] | None = None,
    band: tuple[float, float] = BAND_HZ,
    sweep_s: float | None = None,
    repeats: int | None = None,
    amplitude_v: float = 5.0,
) -> CalibrationPlan:
    """The takes :func:`calibrate` will record with these arguments, and their real duration.

    Parameters
    ----------
    rig, method, points, actuators, band, sweep_s, repeats, amplitude_v
        As for :func:`calibrate`.

    Returns
    -------
    CalibrationPlan
        ``plan.duration_s`` (s) and ``plan.describe()`` say how long the sweeps take.

    Raises
    ------
    ValidationError
        Bad arguments (nothing is played).
    """
    if not isinstance(rig, Rig):
        raise ValidationError(f"rig must be a vibrofocus Rig, got {type(rig).__name__}")
    check_choice(method, "method", METHODS)
    band = check_band(band, rig.fs)
    settings = default_settings(method, rig.fs, band, sweep_s=sweep_s, repeats=repeats, amplitude_v=amplitude_v)
    _, p_idx, a_idx = _sub_layout(rig.layout, points, actuators)
    if method == "mimo":
        hadamard_codes(len(a_idx), settings.repeats)  # refuses repeats that cannot separate them
    limit = rig.max_points_per_recording
    positions = 1 if limit is None else -(-len(p_idx) // limit)
    return CalibrationPlan(method=method, settings=settings, point_indices=tuple(int(i) for i in p_idx),
                           actuator_indices=tuple(int(i) for i in a_idx), positions=positions)


def calibrate(
    rig: Rig,
    *,
    participant_id: str,
    method: str = DEFAULT_METHOD,
    points: Sequence[int] | None = None,
    actuators: Sequence[int] | None = None,
    band: tuple[float, float] = BAND_HZ,
    sweep_s: float | None = None,
    repeats: int | None = None,
    amplitude_v: float = 5.0,
    n_fft: int = N_SAMPLES,
    prompt: PromptFn | None = None,
    progress: ProgressFn | None = None,
    checkpoint: str | os.PathLike | None = None,
    resume: bool = False,
    thresholds: QualityThresholds | None = None,
) -> Calibration:
    """Measure the transfer matrix from every actuator to every skin point.

    With ``mimo`` (the default) all actuators play at once, each with its own Hadamard
    signs over the takes, and the MIMO H1 estimate separates them; with ``h1`` and
    ``paper`` one actuator plays at a time (all other channels at zero) while the skin
    is recorded. Before
    the first take, the plan and its real duration (:func:`plan_calibration`) are
    reported through ``progress(0, total, plan)`` and logged (``logging``, INFO).
    Vibrometer dropouts (NaN samples, or samples flagged in the rig's
    ``last_dropout_mask`` when it has one) exclude that recording of that point from the
    estimate, never patched over; a point that dropped out in every take (``mimo``: in
    so many takes that the kept ones cannot separate the actuators) is recorded again
    (up to three times). The quality report says how many were left out.
    Clipping is detected in the recordings (a flat top, or the rig's ``sensor_range_m``)
    and taken from the rig's ``last_clipped`` (bool, per recorded point or for all) when
    it reports one. A rig that records any number of points at once (the simulated forearm)
    records all points in each take; a single-spot vibrometer
    (``rig.max_points_per_recording == 1``) is aimed by the operator at each point in
    turn, after ``prompt(point_label, point_xy)`` returns.

    Parameters
    ----------
    rig : Rig
        The rig; its ``layout`` and ``fs`` define the points, actuators and sample rate.
    participant_id : str
        Who is calibrated; stored in the result.
    method : {"mimo", "h1", "paper"}
        ``"mimo"`` (default): the ``h1`` sweep on all actuators at once with Hadamard
        signs, MIMO H1 estimate, partial and multiple coherence, input conditioning;
        with 4 actuators about 30 % of ``h1``'s time for a lower H error
        (benchmarks/bench_mimo_calibration.py). ``"h1"``: one actuator at a time,
        exponential sweep with half an octave of margin beyond the band, repeated, H1
        estimate and coherence. ``"paper"``: one linear sweep over the band, FFT of the
        response over FFT of the drive. See
        :mod:`vibrofocus.calibration.excitation` and :mod:`.estimate`.
    points : sequence of int, optional
        Indices into ``rig.layout.points_xy`` to calibrate; default all. The result's
        layout then holds only these points (locations renumbered 1..k in order).
    actuators : sequence of int, optional
        Indices of the actuators to calibrate; default all.
    band : (float, float)
        Calibrated band, Hz.
    sweep_s : float, optional
        Sweep length, s; default 2 s (2.5 s for ``mimo``).
    repeats : int, optional
        Recordings per point and actuator; default 8 (``h1``, ``mimo``) or 1
        (``paper``). For ``mimo`` each recording serves every actuator, and ``repeats``
        must be a multiple of the Hadamard block (4 for 3-4 actuators, 8 for 5-8).
    amplitude_v : float
        Sweep peak, V (default 5 V: under the default 4 V RMS limit).
    n_fft : int
        Length of the design grid: ``H`` is stored on ``rfftfreq(n_fft, 1/fs)``.
    prompt : callable ``(point_label: str, point_xy: ndarray (2,) in m) -> None``, optional
        Called before each point on a rig that must be aimed; it returns when the sensor
        is on the point. Required for such rigs.
    progress : callable ``(done: int, total: int, message: str) -> None``, optional
        Called once with ``done = 0`` and the plan (:meth:`CalibrationPlan.describe`)
        before the first take, then as each take starts (its message ends in
        "playing") and after every take.
    checkpoint : path-like, optional
        A partial file (:func:`~vibrofocus.calibration.checkpoint.partial_path`) that
        receives the takes of each completed point group as it is measured, so an
        interruption loses at most the point being measured. Delete it once the
        calibration is saved (the CLI does).
    resume : bool
        Continue from ``checkpoint``: its completed points are not measured again. It
        must come from the same plan on the same rig, or it is refused.
    thresholds : QualityThresholds, optional
        Thresholds of the quality verdicts.

    Returns
    -------
    Calibration

    Raises
    ------
    ValidationError
        Bad arguments, or a single-spot rig without ``prompt``.
    SafetyError
        The sweep breaks the rig's limits (nothing is played).
    VibrofocusError
        A point kept dropping out in every recording.
    """
    if not isinstance(rig, Rig):
        raise ValidationError(f"rig must be a vibrofocus Rig, got {type(rig).__name__}")
    if not isinstance(participant_id, str) or not participant_id.strip():
        raise ValidationError(f"participant_id must be a non-empty string, got {participant_id!r}")
    check_choice(method, "method", METHODS)
    fs = rig.fs
    band = check_band(band, fs)
    if isinstance(n_fft, bool) or not isinstance(n_fft, (int, np.integer)) or n_fft < 256 or n_fft % 2:
        raise ValidationError(f"n_fft must be an even integer >= 256, got {n_fft!r}")
    if fs / n_fft > band[0]:
        raise ValidationError(
            f"n_fft={n_fft} gives a frequency step of {fs / n_fft:.3g} Hz, coarser than the band's low "
            f"edge {band[0]:g} Hz; use n_fft >= {int(np.ceil(fs / band[0]))}"
        )
    plan = plan_calibration(rig, method=method, points=points, actuators=actuators, band=band, sweep_s=sweep_s,
                            repeats=repeats, amplitude_v=amplitude_v)
    settings = plan.settings
    thresholds = thresholds or QualityThresholds()
    layout, p_idx, a_idx = _sub_layout(rig.layout, points, actuators)
    mimo = method == "mimo"
    excitation = make_excitation(settings)
    # Refuse an unsafe sweep before the first recording, not halfway through.
    probe = np.zeros((rig.layout.n_actuators, excitation.size))
    probe[a_idx if mimo else a_idx[:1]] = excitation
    try:
        played = rig.check(probe)[a_idx[0]]
    except SafetyError as exc:
        raise SafetyError(
            f"the calibration sweep ({settings.amplitude_v:g} V peak, {settings.amplitude_v / np.sqrt(2):.3g} V RMS) "
            f"breaks the {rig.kind} rig's limits, nothing was played: {exc}; "
            + ("shorten sweep_s" if "longer than the limit" in str(exc) else "lower amplitude_v")
        ) from exc

    points_xy = rig.layout.points_xy[p_idx]
    labels = layout.point_labels
    limit = rig.max_points_per_recording
    if limit is None:
        groups = [np.arange(len(p_idx))]
    else:
        if prompt is None:
            raise ValidationError(
                f"the {rig.kind} rig records {limit} point(s) at a time and its sensor must be aimed at each "
                "point: pass prompt=callable(point_label, point_xy) (the CLI asks on the terminal)"
            )
        groups = [np.arange(s, min(s + limit, len(p_idx))) for s in range(0, len(p_idx), limit)]

    n_p, n_a, n_r = len(p_idx), len(a_idx), settings.repeats
    n_rec = settings.n_drive + settings.n_tail
    log.info("calibration plan for %s: %s", participant_id, plan.describe())
    if progress is not None:
        progress(0, plan.takes, plan.describe())
    session = _Takes(rig, points_xy, limit is not None, n_rec, settings.tail_s, (n_p, n_a), progress, plan.takes)
    if checkpoint is not None:
        from .checkpoint import CalibrationCheckpoint

        described = {k: v for k, v in rig.describe().items() if k != "last_latency_samples"}
        session.checkpoint = CalibrationCheckpoint(checkpoint, {
            "participant": participant_id, "method": method, "points": p_idx.tolist(), "actuators": a_idx.tolist(),
            "settings": asdict(settings), "n_fft": n_fft, "rig": described}, resume=resume)
    # Single precision from the start (what the file keeps): 0.1 ppm of the signal, far
    # below sensor noise, and half the memory for dense arrays and long sweeps.
    if mimo:
        codes = hadamard_codes(n_a, n_r)
        recordings, dropouts = _record_mimo(session, excitation, a_idx, codes, groups, labels, layout,
                                            thresholds, prompt)
    else:
        codes = None
        recordings, dropouts = _record_one_at_a_time(session, excitation, a_idx, n_r, groups, labels, layout,
                                                     prompt)

    freqs = np.fft.rfftfreq(n_fft, 1 / fs)
    multiple = condition = correlation = None
    if mimo:
        y = recordings.astype(float)  # (R, P, n_rec)
        # Each take deconvolved by the common sweep: sum_a codes[r, a] H_a on the design grid.
        composite, ok = estimate_repeats(y, played, fs, band, n_fft)  # (R, P, F), (R, P)
        est = mimo_h1(codes[:, :, None], composite, ok)
        H, coherence, multiple = est.H, est.partial_coherence, est.multiple_coherence
        condition, correlation = est.condition_number, est.input_correlation
        n_used = np.repeat(est.n_used[:, None], n_a, axis=1)
        noise_p, snr_p = noise_and_snr(y, ok, settings.n_pre, fs, band)
        noise = np.repeat(noise_p[:, None], n_a, axis=1)
        snr = split_snr(snr_p, H, freqs, band, played, fs)
        clip_rec = detect_clipping(recordings, clip_samples=thresholds.clip_samples,
                                   sensor_range_m=getattr(rig, "sensor_range_m", None)).any(axis=0)  # (P,)
        clipped = clip_rec[:, None] | session.adc_clipped
    else:
        # Estimation, one actuator at a time (a handful), vectorised over repeats, points
        # and frequencies; only the averages are kept, so memory does not grow with repeats.
        H = np.zeros((n_fft // 2 + 1, n_p, n_a), complex)
        coherence = np.zeros(H.shape)
        n_used = np.zeros((n_p, n_a), int)
        noise, snr = np.zeros((n_p, n_a)), np.zeros((n_p, n_a))
        for a in range(n_a):
            y = recordings[a].astype(float)
            Hr, ok = estimate_repeats(y, played, fs, band, n_fft)  # (R, P, F), (R, P)
            H_a, coh_a, n_used[:, a] = h1_average(Hr, ok)
            H[:, :, a], coherence[:, :, a] = H_a.T, coh_a.T
            noise[:, a], snr[:, a] = noise_and_snr(y, ok, settings.n_pre, fs, band)
        clipped = detect_clipping(recordings, clip_samples=thresholds.clip_samples,
                                  sensor_range_m=getattr(rig, "sensor_range_m", None)).any(axis=1).T
        clipped = clipped | session.adc_clipped  # (P, A)

    quality = assess_quality(
        H, coherence, freqs, band, layout,
        snr_db=snr, noise_rms_m=noise, clipped=clipped,
        repeats_used=n_used, dropouts=dropouts, drive_peak_v=float(np.abs(played).max()),
        peak_limit_v=rig.limits.peak_v, thresholds=thresholds,
        multiple_coherence=multiple, input_condition=condition, input_correlation=correlation,
    )
    drives = np.repeat(played[None, :], n_a, axis=0)
    return Calibration(
        H=H, freqs=freqs, fs=fs, coherence=coherence, layout=layout, band=band,
        participant_id=participant_id, method=method, quality=quality, drives=drives,
        recordings=recordings, rig=rig.describe(), sweep=settings, straps=_read_straps(rig),
        codes=codes, multiple_coherence=multiple, recorded_s=session.n_takes * settings.take_s,
    )


class _Takes:
    """Records takes on a rig and keeps what a take tells besides the displacement.

    Also the progress of the takes (``done`` of ``total``) and the optional checkpoint of
    completed point groups.
    """

    def __init__(self, rig: Rig, points_xy: np.ndarray, aimed: bool, n_rec: int, tail_s: float,
                 shape: tuple[int, int], progress: ProgressFn | None = None, total: int = 0) -> None:
        self.rig, self.points_xy, self.aimed = rig, points_xy, aimed
        self.n_rec, self.tail_s = n_rec, tail_s
        self.adc_clipped = np.zeros(shape, dtype=bool)  # (P, A): the rig's converter clipped
        self.n_takes = 0
        self.progress, self.total, self.done = progress, total, 0
        self.checkpoint = None

    def tell(self, message: str, *, took: int = 0) -> None:
        self.done += took
        if self.progress is not None:
            self.progress(self.done, self.total, message)

    def restored(self, index: int, group: np.ndarray, labels) -> dict | None:
        """The saved takes of point group ``index`` from the checkpoint, if it was completed."""
        saved = None if self.checkpoint is None else self.checkpoint.restore(index)
        if saved is not None:
            self.adc_clipped[group] = saved["adc_clipped"]
            self.n_takes += int(saved["n_takes"])
            self.tell(f"point {', '.join(labels[p] for p in group)}: kept from the partial file",
                      took=int(saved["n_planned"]))
        return saved

    def completed(self, index: int, group: np.ndarray, n_planned: int, n_takes_before: int, **arrays) -> None:
        if self.checkpoint is not None:
            self.checkpoint.save(index, adc_clipped=self.adc_clipped[group], n_takes=self.n_takes - n_takes_before,
                                 n_planned=n_planned, **arrays)

    def record(self, drive: np.ndarray, group: np.ndarray, actuator: int | None) -> np.ndarray:
        """One take at the points ``group``; ``actuator`` None when all of them played.

        Returns
        -------
        ndarray, shape (len(group), n_rec)
            Displacement, m; NaN where the rig flagged a dropout.
        """
        rig = self.rig
        y = rig.play_and_record(drive, self.points_xy[group] if self.aimed else self.points_xy, tail_s=self.tail_s)
        self.n_takes += 1
        if y.shape != (len(group), self.n_rec):
            raise VibrofocusError(
                f"the {rig.kind} rig returned a recording of shape {y.shape}, expected {(len(group), self.n_rec)}"
            )
        # A rig may flag dropout samples instead of (or besides) writing NaN into them.
        flagged = getattr(rig, "last_dropout_mask", None)
        if isinstance(flagged, np.ndarray) and flagged.shape == y.shape and flagged.any():
            y = np.where(flagged, np.nan, y)
        # Clipping at the sensor's converter may be invisible after the rig converts to
        # displacement (a velocity decoder is integrated): a rig can report it.
        rig_clipped = getattr(rig, "last_clipped", None)
        if rig_clipped is not None:
            hit = np.broadcast_to(np.asarray(rig_clipped, bool), (len(group),))
            if actuator is None:
                self.adc_clipped[group] |= hit[:, None]
            else:
                self.adc_clipped[group, actuator] |= hit
        return y


def _where(layout: ArrayLayout, group: np.ndarray, aimed: bool) -> str:
    return "point " + ", ".join(layout.point_labels[p] for p in group) if aimed else "all points"


def _record_one_at_a_time(session, excitation, a_idx, n_r, groups, labels, layout, prompt):
    """The takes of ``h1``/``paper``: one actuator at a time.

    Returns recordings (n_actuators, n_repeats, n_points, n_rec) float32 and the dropouts
    per (point, actuator)."""
    rig = session.rig
    n_a, n_p = len(a_idx), len(session.points_xy)
    recordings = np.full((n_a, n_r, n_p, session.n_rec), np.nan, dtype=np.float32)
    dropouts = np.zeros((n_p, n_a), dtype=int)
    for gi, group in enumerate(groups):
        saved = session.restored(gi, group, labels)
        if saved is not None:
            recordings[:, :, group], dropouts[group] = saved["recordings"], saved["dropouts"]
            continue
        takes_before = session.n_takes
        if session.aimed:
            for p in group:
                prompt(labels[p], session.points_xy[p].copy())
        for a, channel in enumerate(a_idx):
            drive = np.zeros((rig.layout.n_actuators, excitation.size))
            drive[channel] = excitation
            for r in range(n_r):
                what = f"{layout.actuator_names[a]}, {_where(layout, group, session.aimed)}, take {r + 1}/{n_r}"
                session.tell(what + ": playing")
                recordings[a, r, group] = session.record(drive, group, a)
                session.tell(what, took=1)
            bad = ~np.isfinite(recordings[a][:, group]).all(axis=-1)  # (R, len(group))
            dropouts[group, a] = bad.sum(axis=0)
            # A point that dropped out in every take is re-recorded into its first slot.
            for _ in range(MAX_RETRIES):
                lost = group[bad.all(axis=0)]
                if lost.size == 0:
                    break
                y = session.record(drive, group, a)
                ok_now = np.isfinite(y).all(axis=-1)
                fill = bad.all(axis=0) & ok_now
                recordings[a, 0, group[fill]] = y[fill]
                bad[0, fill] = False
            lost = group[bad.all(axis=0)]
            if lost.size:
                raise VibrofocusError(
                    f"the vibrometer dropped out in every recording of point(s) "
                    f"{', '.join(labels[p] for p in lost)} with actuator {layout.actuator_names[a]} "
                    f"({n_r + MAX_RETRIES} tries); check its aim and signal level"
                )
        session.completed(gi, group, n_a * n_r, takes_before, recordings=recordings[:, :, group],
                          dropouts=dropouts[group])
    return recordings, dropouts


def _separable(codes: np.ndarray, kept: np.ndarray, condition_max: float) -> np.ndarray:
    """Whether the takes kept at each point still tell the actuators apart.

    Parameters
    ----------
    codes : ndarray, shape (n_takes, n_actuators)
    kept : ndarray of bool, shape (n_takes, n_points)
    condition_max : float

    Returns
    -------
    ndarray of bool, shape (n_points,)
        The condition number of ``codes[kept].T @ codes[kept]`` is at most ``condition_max``.
    """
    c = codes.astype(float)
    gram = np.einsum("rp,ra,rb->pab", kept.astype(float), c, c)
    eig = np.linalg.eigvalsh(gram)
    return eig[:, 0] * condition_max >= eig[:, -1] * (1 - 1e-12)


def _record_mimo(session, excitation, a_idx, codes, groups, labels, layout, thresholds, prompt):
    """The takes of ``mimo``: every actuator at once, with the signs ``codes[r]`` in take ``r``.

    Returns recordings (n_takes, n_points, n_rec) float32 and the dropouts per (point,
    actuator) (the same for every actuator of a point)."""
    rig = session.rig
    n_r, n_a = codes.shape
    n_p = len(session.points_xy)
    recordings = np.full((n_r, n_p, session.n_rec), np.nan, dtype=np.float32)
    dropouts = np.zeros((n_p, n_a), dtype=int)

    def take(r: int) -> np.ndarray:
        drive = np.zeros((rig.layout.n_actuators, excitation.size))
        drive[a_idx] = codes[r].astype(float)[:, None] * excitation[None, :]
        return drive

    for gi, group in enumerate(groups):
        saved = session.restored(gi, group, labels)
        if saved is not None:
            recordings[:, group], dropouts[group] = saved["recordings"], saved["dropouts"]
            continue
        takes_before = session.n_takes
        if session.aimed:
            for p in group:
                prompt(labels[p], session.points_xy[p].copy())
        for r in range(n_r):
            what = f"all {n_a} actuators, {_where(layout, group, session.aimed)}, take {r + 1}/{n_r}"
            session.tell(what + ": playing")
            recordings[r, group] = session.record(take(r), group, None)
            session.tell(what, took=1)
        bad = ~np.isfinite(recordings[:, group]).all(axis=-1)  # (R, len(group))
        dropouts[group] = bad.sum(axis=0)[:, None]
        # Too many takes lost at a point to separate the actuators: record the first of
        # its lost takes again (same signs) into that slot.
        for _ in range(MAX_RETRIES):
            lost = np.flatnonzero(~_separable(codes, ~bad, thresholds.condition_max))
            if lost.size == 0:
                break
            r = int(np.flatnonzero(bad[:, lost[0]])[0])
            y = session.record(take(r), group, None)
            fill = bad[r] & np.isfinite(y).all(axis=-1)
            recordings[r, group[fill]] = y[fill]
            bad[r, fill] = False
        lost = group[~_separable(codes, ~bad, thresholds.condition_max)]
        if lost.size:
            raise VibrofocusError(
                f"the vibrometer dropped out in so many takes of point(s) {', '.join(labels[p] for p in lost)} "
                f"that the {n_a} actuators cannot be told apart ({n_r + MAX_RETRIES} tries); check its aim and "
                "signal level"
            )
        session.completed(gi, group, n_r, takes_before, recordings=recordings[:, group], dropouts=dropouts[group])
    return recordings, dropouts


def _read_straps(rig: Rig) -> dict | None:
    """The strap force reading of rigs that have strap sensors (stored with the calibration)."""
    from ..rigs.force import check_straps, has_strap_sensors

    if not has_strap_sensors(rig):
        return None

    return check_straps(rig).to_dict()

