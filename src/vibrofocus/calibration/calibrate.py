"""Measure the skin's transfer matrix on a rig: :func:`calibrate`.

The calibration's record is :class:`~.result.Calibration`, its plan
:func:`~.plan.plan_calibration` and its takes :mod:`.recording`; their names are
re-exported here (``vibrofocus.calibration.calibrate.Calibration`` keeps working).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict

import numpy as np

from .._validation import check_band, check_choice
from ..defaults import BAND_HZ, N_SAMPLES
from ..errors import SafetyError, ValidationError
from ..io.calibration_nc import SCHEMA_VERSION
from ..rigs.base import Rig
from .estimate import estimate_repeats, h1_average, mimo_h1, noise_and_snr, split_snr
from .excitation import METHODS, hadamard_codes, make_excitation
from .quality import QualityThresholds, assess_quality, detect_clipping
from .plan import DEFAULT_METHOD, CalibrationPlan, _sub_layout, measured_indices, plan_calibration, plan_for_arguments
from .recording import ProgressFn, _read_straps, _record_mimo, _record_one_at_a_time, _Takes
from .result import Calibration

__all__ = ["SCHEMA_VERSION", "DEFAULT_METHOD", "Calibration", "CalibrationPlan", "calibrate", "plan_calibration"]

# SCHEMA_VERSION: version of the calibration data model and of its file layout
# (vibrofocus.io.calibration_nc, its home). Version 2 added the ``mimo`` method's
# variables; version 1 files still load.

log = logging.getLogger(__name__)

PromptFn = Callable[[str, np.ndarray], None]


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
    measure: int | Sequence[int] | None = None,
    fit_law: str = "layered",
    plan: CalibrationPlan | None = None,
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
    measure : int or sequence of int, optional
        Measure only some points and predict the others: a count ``K`` (the points
        :func:`~.plan.subset_points` spreads over the array) or the indices of the
        points to measure. The skin model is fitted to the measured points
        (:func:`~.fitmodel.fit_model`, kept as ``cal.fit``) and predicts ``H`` at the
        rest; the result still holds every point of the layout, ``cal.measured`` says
        which rows were measured, and the quality report names the predicted ones.
        Default: measure every point. Not with ``points``.
    fit_law : {"layered", "homogeneous"}
        With ``measure``: the wave law of the fitted model (:func:`~.fitmodel.fit_model`).
    plan : CalibrationPlan, optional
        What :func:`plan_calibration` gave for the same rig and arguments (a caller that
        showed the plan first): used as it is instead of checking the limits again.

    Returns
    -------
    Calibration

    Raises
    ------
    ValidationError
        Bad arguments, a ``plan`` made for other arguments, or a single-spot rig without ``prompt``.
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
    plan = plan_for_arguments(rig, plan, method=method, points=points, actuators=actuators, band=band,
                              sweep_s=sweep_s, repeats=repeats, amplitude_v=amplitude_v, measure=measure)
    settings = plan.settings
    thresholds = thresholds or QualityThresholds()
    layout, p_idx, a_idx = _sub_layout(rig.layout, points, actuators)
    rows = None  # rows of the layout measured, when the rest are predicted
    if measure is not None:
        from .fitmodel import _check_law

        _check_law(fit_law)
        rows = measured_indices(layout, measure)
        p_idx = p_idx[rows]
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
    labels = layout.point_labels if rows is None else tuple(layout.point_labels[i] for i in rows)
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
    session.pause_s = plan.pause_s  # what the rig's limits over time need between sweeps
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

    measured = fit = None
    if rows is not None:
        # Every figure of a recording gets the layout's rows, NaN (nothing) where not measured.
        measured = np.zeros(layout.n_points, bool)
        measured[rows] = True
        H, coherence, multiple, condition, correlation = (
            None if x is None else _rows(x, rows, layout.n_points, axis=1, fill=np.nan)
            for x in (H, coherence, multiple, condition, correlation))
        snr, noise = (_rows(x, rows, layout.n_points, axis=0, fill=np.nan) for x in (snr, noise))
        n_used, dropouts = (_rows(x, rows, layout.n_points, axis=0, fill=0) for x in (n_used, dropouts))
        clipped = _rows(clipped, rows, layout.n_points, axis=0, fill=False)
        recordings = _rows(recordings, rows, layout.n_points, axis=recordings.ndim - 2, fill=np.nan)
        fit, H = _predict_rows(H, coherence, freqs, fs, band, layout, rows, fit_law, participant_id, method,
                               settings, recordings, played, n_a, rig)
    quality = assess_quality(
        H, coherence, freqs, band, layout,
        snr_db=snr, noise_rms_m=noise, clipped=clipped,
        repeats_used=n_used, dropouts=dropouts, drive_peak_v=float(np.abs(played).max()),
        peak_limit_v=rig.limits.peak_v, thresholds=thresholds,
        multiple_coherence=multiple, input_condition=condition, input_correlation=correlation,
        measured=measured, fit_residual=None if fit is None else fit.residual,
    )
    drives = np.repeat(played[None, :], n_a, axis=0)
    return Calibration(
        H=H, freqs=freqs, fs=fs, coherence=coherence, layout=layout, band=band,
        participant_id=participant_id, method=method, quality=quality, drives=drives,
        recordings=recordings, rig=rig.describe(), sweep=settings, straps=_read_straps(rig),
        codes=codes, multiple_coherence=multiple, recorded_s=session.n_takes * settings.take_s,
        fit=fit, measured=measured,
    )


def _rows(x: np.ndarray, rows: np.ndarray, n_points: int, *, axis: int, fill) -> np.ndarray:
    """``x`` (the measured rows along ``axis``) spread to all ``n_points`` rows, ``fill`` elsewhere."""
    x = np.asarray(x)
    shape = list(x.shape)
    shape[axis] = n_points
    out = np.full(shape, fill, dtype=x.dtype)  # NaN for float and complex, 0 / False otherwise
    index = [slice(None)] * x.ndim
    index[axis] = rows
    out[tuple(index)] = x
    return out


def _predict_rows(H, coherence, freqs, fs, band, layout, rows, law, participant_id, method, settings, recordings,
                  played, n_a, rig):
    """The skin model fitted to the measured rows of ``H``, and ``H`` with the others predicted by it."""
    from .fitmodel import fit_model
    from .quality import QualityReport

    n_p = layout.n_points
    empty = np.full((n_p, n_a), np.nan)
    placeholder = QualityReport(issues=[], snr_db=empty, noise_rms_m=empty, band_gain=empty,
                                low_coherence_share=empty, coherent_to_hz=empty, clipped=np.zeros((n_p, n_a), bool),
                                repeats_used=np.zeros((n_p, n_a), int), dropouts=np.zeros((n_p, n_a), int),
                                polarity=np.zeros(n_a, int))
    partial = Calibration(H=H, freqs=freqs, fs=fs, coherence=coherence, layout=layout, band=band,
                          participant_id=participant_id, method=method, quality=placeholder,
                          drives=np.repeat(played[None, :], n_a, axis=0), recordings=recordings,
                          rig=rig.describe(), sweep=settings)
    fit = fit_model(partial, law=law, points=rows)
    predicted = np.setdiff1d(np.arange(n_p), rows)
    H = H.copy()
    H[:, predicted] = fit.transfer(layout.points_xy[predicted], freqs)
    return fit, H
