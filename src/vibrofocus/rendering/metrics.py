"""Focus metrics (docs/method.md, "Rendering methods"), one function used everywhere."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_in_range, check_index, check_positive
from ..defaults import SIGMA_S
from ..errors import ValidationError
from .bound import _energy_db
from .taper import design_grid

__all__ = ["focus_metrics", "zero_lag_fidelity"]


@fill_doc
def focus_metrics(
    response: Any,
    target_index: int,
    desired: Any,
    fs: float,
    *,
    t0: float | None = None,
    sigma: float = SIGMA_S,
    band: tuple[float, float] | None = None,
    drives: Any = None,
    taper_octaves: float = 0.5,
    compare_indices: Any = None,
    field: Any = None,
    bound: Any = None,
) -> dict[str, float]:
    """How well a response focuses a tap at one point.

    Parameters
    ----------
    response : ndarray, shape (n_points, n)
        Displacement at every point (predicted or measured), m.
    target_index : int
        Row of ``response`` of the target point.
    desired : ndarray, shape (n_desired,)
        Desired target waveform, m, ``n_desired <= n``. A shorter waveform (the design
        window, when ``response`` is a recording with a decay tail) is zero-padded at
        the end.
    %(fs)s
    t0 : float, optional
        Centre of the tap, s; default the time of the largest ``|desired|``.
    sigma : float
        Ricker spread, s; the compactness window is ``t0 +- 2 sigma``.
    band : (float, float), optional
        If given, ``desired`` is band-limited with :func:`band_taper` first (Hz);
        otherwise it is used as given (pass an already band-limited waveform).
    drives : ndarray, shape (n_actuators, n) or (n_actuators, n_desired), optional
        Drives that produced the response, V; for ``peak_drive_v``.
    taper_octaves : float
        Taper width used with ``band``.
    compare_indices : sequence of int, optional
        Rows of ``response`` the contrast compares the target against (the target itself
        is skipped if listed); default every other row.
    field : ndarray, shape (n_grid, n) or (n_grid, n_desired), optional
        Displacement over a dense skin grid (e.g. ``SimulatedForearm.field`` or a
        prediction through a grid transfer), m; adds the contrast against it.
    bound : ContrastBound, optional
        The array's energy-contrast bound at this target against the compared points
        (:func:`~vibrofocus.rendering.contrast_bound`); adds ``bound_db`` and
        ``bound_own_db``.

    Returns
    -------
    dict
        ``fidelity``: zero-lag normalized correlation of the target displacement with
        the band-limited desired waveform, in [-1, 1] (NaN if either is silent).
        ``contrast_db``: 20 log10 of the peak ``|u|`` at the target over the largest peak
        at any other (compared) point (inf if all others are silent, NaN with one point or silence).
        ``peak_drive_v``: peak ``|drives|`` (NaN without drives).
        ``target_peak_m``: peak ``|u|`` at the target.
        ``compactness``: share of the target's energy within ``t0 +- 2 sigma`` (NaN if silent).
        ``peak_time_s``: time of the peak ``|u|`` at the target; ``timing_error_s``: that
        minus ``t0``.
        ``relative_error``: ``||u_t - d|| / ||d||`` (NaN if ``d`` is silent).
        ``shape_fidelity``: the largest normalized cross-correlation of ``u_t`` with
        ``d`` over all lags, and ``shape_lag_s`` the lag where it occurs (positive when
        ``u_t`` is late). Zero-lag ``fidelity`` scores a waveform that arrives late as
        poor even when its shape is right (funneling travels from the actuators and
        arrives several ms after ``t0``); this pair tells shape and timing apart.
        ``contrast_all_db``: peak contrast against every other row (all calibrated
        points, guards included), whatever ``compare_indices``.
        ``energy_contrast_db``: ``10 log10`` of the target's energy over the summed
        energy of the compared points (what acoustic contrast control maximizes);
        ``energy_contrast_all_db``: the same against every other row.
        With ``field``: ``contrast_field_db`` (peak ``|u|`` at the target over the largest
        peak anywhere on the grid) and ``energy_contrast_field_db`` (over the summed
        energy of the grid points).
        With ``bound``: ``bound_db``, its exact-tap bound (dB; comparable with
        ``energy_contrast_db`` when ``bound`` was computed over the same compared
        points), and ``bound_own_db``, the bound for the waveform the target actually
        receives (no drive producing that waveform does better; NaN if ``bound`` is on
        another window).
    """
    response = as_array(response, "response", ndim=2, finite=False)
    bad = ~np.isfinite(response)
    if bad.any():
        rows = np.flatnonzero(bad.any(axis=1))
        raise ValidationError(
            f"response contains {int(bad.sum())} NaN/Inf sample(s), at point(s) {', '.join(map(str, rows[:8]))}"
            f"{' ...' if rows.size > 8 else ''}: a recording with vibrometer dropouts (NaN runs); repeat the "
            "recording rather than patch it"
        )
    n_points, n = response.shape
    target_index = check_index(target_index, "target_index", n_points, what="points of response")
    desired = as_array(desired, "desired", ndim=1)
    if desired.size == 0:
        raise ValidationError("desired holds no samples; pass the desired target waveform, m")
    if desired.size > n:
        raise ValidationError(
            f"desired has {desired.size} samples, more than the {n} of response; pass the whole response"
        )
    n_design = desired.size
    desired = np.pad(desired, (0, n - n_design))
    fs = check_positive(fs, "fs")
    sigma = check_positive(sigma, "sigma")
    if band is not None:
        taper = design_grid(n, fs, check_band(band, fs),
                            check_positive(taper_octaves, "taper_octaves", allow_zero=True))[1]
        desired = np.fft.irfft(np.fft.rfft(desired) * taper, n)
    if t0 is None:
        t0 = float(np.argmax(np.abs(desired))) / fs
    else:
        t0 = check_in_range(t0, "t0", 0.0, n / fs)
    if drives is None:
        peak_drive = float("nan")
    else:
        drives = as_array(drives, "drives", ndim=2)
        if drives.shape[1] not in (n, n_design):
            raise ValidationError(
                f"drives must have {n_design} samples like desired (or {n} like response), got shape {drives.shape}"
            )
        peak_drive = float(np.max(np.abs(drives)))

    achieved = response[target_index]
    peaks = np.max(np.abs(response), axis=1)
    target_peak = float(peaks[target_index])
    if compare_indices is None:
        compare = np.delete(np.arange(n_points), target_index)
    else:
        compare = np.atleast_1d(np.asarray(compare_indices))
        if compare.size == 0 and compare.ndim == 1:
            compare = compare.astype(int)  # an empty list comes out as float64
        if compare.ndim != 1 or (compare.size and not np.issubdtype(compare.dtype, np.integer)):
            raise ValidationError(f"compare_indices must be a sequence of integer point indices, got {compare_indices!r}")
        if compare.size and (compare.min() < 0 or compare.max() >= n_points):
            raise ValidationError(f"compare_indices holds indices outside the {n_points} points of response")
        compare = compare[compare != target_index]
    others = peaks[compare]
    if others.size == 0 or target_peak == 0:
        contrast = float("nan")
    elif others.max() == 0:
        contrast = float("inf")
    else:
        contrast = float(20 * np.log10(target_peak / others.max()))

    every = np.delete(np.arange(n_points), target_index)
    if every.size == 0 or target_peak == 0:
        contrast_all = float("nan")
    else:
        top = peaks[every].max()
        contrast_all = float("inf") if top == 0 else float(20 * np.log10(target_peak / top))
    energies = np.sum(response**2, axis=1)
    energy_contrast = _energy_db(energies[target_index], energies[compare])
    energy_contrast_all = _energy_db(energies[target_index], energies[every])
    extra: dict[str, float] = {}
    if field is not None:
        field = as_array(field, "field", ndim=2)
        if field.shape[1] not in (n, n_design) or field.shape[0] == 0:
            raise ValidationError(
                f"field must have shape (n_grid, {n}) like response (or {n_design} samples like desired), got {field.shape}"
            )
        top = float(np.max(np.abs(field)))
        extra["contrast_field_db"] = (float("nan") if target_peak == 0 else
                                      float("inf") if top == 0 else float(20 * np.log10(target_peak / top)))
        extra["energy_contrast_field_db"] = _energy_db(energies[target_index], np.sum(field**2, axis=1))
    if bound is not None:
        extra["bound_db"] = float(bound.bound_db)
        extra["bound_own_db"] = (float(bound.bound_db_for(achieved)) if bound.n_samples == n else float("nan"))

    norm_achieved = float(np.linalg.norm(achieved))
    norm_desired = float(np.linalg.norm(desired))
    silent = norm_achieved == 0 or norm_desired == 0
    fidelity = zero_lag_fidelity(achieved, desired)
    # In samples, with a little slack so that a window edge falling on a sample is kept
    # whatever the rounding of t0 * fs.
    window = np.abs(np.arange(n) - t0 * fs) <= 2 * sigma * fs * (1 + 1e-9)
    energy = float(np.sum(achieved**2))
    compactness = float(np.sum(achieved[window] ** 2) / energy) if energy > 0 else float("nan")
    if silent:
        shape_fidelity, shape_lag = float("nan"), float("nan")
    else:
        # Linear cross-correlation through a 2n FFT (no wrap); lag k of u_t against d sits
        # at index k for k >= 0 and at 2n + k for k < 0.
        xcorr = np.fft.irfft(np.fft.rfft(achieved, 2 * n) * np.conj(np.fft.rfft(desired, 2 * n)), 2 * n)
        best = int(np.argmax(xcorr))
        shape_fidelity = float(xcorr[best] / (norm_achieved * norm_desired))
        shape_lag = (best if best < n else best - 2 * n) / fs
    peak_time = float(np.argmax(np.abs(achieved))) / fs
    error = float(np.linalg.norm(achieved - desired) / norm_desired) if norm_desired > 0 else float("nan")
    return {
        "fidelity": fidelity,
        "contrast_db": contrast,
        "peak_drive_v": peak_drive,
        "target_peak_m": target_peak,
        "compactness": compactness,
        "peak_time_s": peak_time,
        "timing_error_s": peak_time - t0,
        "relative_error": error,
        "shape_fidelity": shape_fidelity,
        "shape_lag_s": shape_lag,
        "contrast_all_db": contrast_all,
        "energy_contrast_db": energy_contrast,
        "energy_contrast_all_db": energy_contrast_all,
        **extra,
    }


def zero_lag_fidelity(achieved: np.ndarray, desired: np.ndarray) -> float:
    """Zero-lag normalized correlation of two waveforms (the focus metrics' ``fidelity``).

    Parameters
    ----------
    achieved, desired : ndarray, shape (n,)
        The target's displacement and the desired one (any common unit).

    Returns
    -------
    float
        In [-1, 1]; NaN when either waveform is silent.
    """
    norm = float(np.linalg.norm(achieved)) * float(np.linalg.norm(desired))
    return float("nan") if norm == 0 else float(np.dot(achieved, desired) / norm)
