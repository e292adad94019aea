"""Transfer-function estimation from sweep recordings, batched over repeats and points.

The estimate of one (point, actuator) pair from ``R`` recordings ``y_r`` of the same
drive ``x``:

1. **Linear deconvolution.** Each recording holds the drive convolved *linearly* with
   the skin's impulse response plus noise, so both are transformed with an FFT length
   ``N >= len(y)`` (no wrap-around) and ``H_r(f) = Y_r(f) X_inv(f)`` with
   ``X_inv = T(f) conj(X) / (|X|^2 + eps (1 - T(f)))``: ``T`` is the band taper (1 in
   the calibrated band, a raised cosine to 0 over half an octave beyond each edge, which
   is where the default sweep stops) and ``eps`` the smallest ``|X|^2`` in the band. In
   the band this is the exact inverse (no bias); in the taper zone, where a sweep that
   stops at the band edge (the paper's) has almost no energy, the regularisation grows
   smoothly and keeps the noise gain within a few times its in-band worst case.
2. **Onto the design grid.** ``H_r`` lives on the fine grid ``rfftfreq(N, 1/fs)``. Its
   impulse response is cut to the design length ``n`` (:func:`resize_impulse_response`:
   the causal part with a half-Hann fade-out, plus a short acausal part) and transformed
   back, giving ``H_r`` on ``rfftfreq(n, 1/fs)``. Cutting the impulse response averages
   neighbouring fine bins, which lowers the noise by about ``sqrt(N / n)``.
3. **H1 over repeats.** ``H = sum_r conj(X_r) Y_r / sum_r |X_r|^2``; with the same drive in
   every repeat this is the mean of the per-repeat estimates over the repeats kept, and
   the coherence ``|S_xy|^2 / (S_xx S_yy)`` reduces to
   ``|sum_r H_r|^2 / (R sum_r |H_r|^2)``. It is 1 for a noise-free linear response; for
   pure noise its expected value is ``1/R``. With one repeat it cannot be assessed and is
   NaN.

Recordings with dropouts (NaN or Inf samples) are excluded from the average for the
point they affect (weight 0).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from .._validation import as_array, check_band, check_positive
from ..errors import ValidationError
from ..signals.taper import band_taper

__all__ = [
    "resize_impulse_response",
    "estimate_repeats",
    "h1_average",
    "noise_and_snr",
]

#: Share of an impulse-response buffer kept for negative times (acausal part), e.g. the
#: pre-ringing a band limit causes. 1/16 of 4096 samples at 10 kHz is 25.6 ms.
ACAUSAL_FRACTION = 1 / 16
#: Share of the kept causal part over which a truncated response fades out.
FADE_FRACTION = 1 / 8
#: Regularisation of the drive's spectral inverse outside the band, relative to the
#: drive's smallest power in the calibrated band.
REGULARIZATION = 1.0
#: Width of the taper of the inverse beyond each band edge, octaves.
TAPER_OCTAVES = 0.5


def resize_impulse_response(h: np.ndarray, n_out: int) -> np.ndarray:
    """Change the length of circular impulse responses, keeping time zero at index 0.

    A buffer of length ``n`` holds causal samples at ``[0, n - n//16)`` and acausal
    (negative-time) samples at ``[n - n//16, n)``. Lengthening zero-pads between the two
    parts; shortening keeps what fits and fades the cut ends with half-Hann windows
    (over 1/8 of the kept causal part, and over half of the kept acausal part), so the
    truncation does not ring in frequency.

    Parameters
    ----------
    h : ndarray, shape (..., n_in)
        Impulse responses, real.
    n_out : int
        New length, samples.

    Returns
    -------
    ndarray, shape (..., n_out)
    """
    h = np.asarray(h, dtype=float)
    n_in = h.shape[-1]
    if n_out == n_in:
        return h.copy()
    a_in = int(n_in * ACAUSAL_FRACTION)
    a_out = int(n_out * ACAUSAL_FRACTION)
    n_causal = min(n_in - a_in, n_out - a_out)
    n_acausal = min(a_in, a_out)
    out = np.zeros(h.shape[:-1] + (n_out,))
    causal = h[..., :n_causal].copy()
    if n_causal < n_in - a_in:  # truncated: fade the end out
        m = max(int(n_causal * FADE_FRACTION), 1)
        causal[..., n_causal - m:] *= 0.5 + 0.5 * np.cos(np.pi * (np.arange(m) + 1) / m)
    out[..., :n_causal] = causal
    if n_acausal:
        acausal = h[..., n_in - n_acausal:].copy()
        if n_acausal < a_in:  # truncated at its early (most negative) end
            m = max(n_acausal // 2, 1)
            acausal[..., :m] *= 0.5 - 0.5 * np.cos(np.pi * np.arange(m) / m)
        out[..., n_out - n_acausal:] = acausal
    return out


def estimate_repeats(
    recordings: np.ndarray,
    drive: np.ndarray,
    fs: float,
    band: tuple[float, float],
    n_fft: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-recording transfer estimates on the design grid.

    Parameters
    ----------
    recordings : ndarray, shape (..., n_rec)
        Displacement recorded while ``drive`` played, m. Non-finite samples mark a
        dropout; such recordings come back with ``valid`` False (and an estimate of 0).
    drive : ndarray, shape (n_drive,)
        The voltage actually played on the actuator (after the rig's fades), V;
        ``n_drive <= n_rec``.
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Calibrated band, Hz; the inverse is tapered to zero over half an octave beyond
        each edge.
    n_fft : int
        Length of the design grid: the estimate is on ``rfftfreq(n_fft, 1/fs)``.

    Returns
    -------
    H : ndarray, complex, shape (..., n_fft // 2 + 1)
        Transfer function per recording, m/V.
    valid : ndarray of bool, shape (...)
        False where the recording holds a dropout.
    """
    y = np.asarray(recordings, dtype=float)
    x = as_array(drive, "drive", ndim=1)
    fs = check_positive(fs, "fs")
    band = check_band(band, fs)
    n_rec = y.shape[-1]
    valid = np.isfinite(y).all(axis=-1)
    y = np.where(np.isfinite(y), y, 0.0)
    # At least the recording length: linear, not circular, deconvolution.
    n_long = scipy.fft.next_fast_len(max(n_rec, x.size, n_fft), real=True)
    spectrum = scipy.fft.rfft(x, n_long)
    power = np.abs(spectrum) ** 2
    freqs = scipy.fft.rfftfreq(n_long, 1 / fs)
    in_band = (freqs >= band[0]) & (freqs <= band[1])
    eps = REGULARIZATION * power[in_band].min()
    if not eps > 0:
        raise ValidationError(f"the drive has no energy at some frequency of the band {band[0]:g}-{band[1]:g} Hz")
    with np.errstate(over="ignore", divide="ignore"):  # band_taper divides by f; 0 Hz is harmless
        taper = band_taper(freqs, band, TAPER_OCTAVES)
    x_inv = taper * np.conj(spectrum) / (power + eps * (1.0 - taper))
    h_long = scipy.fft.irfft(scipy.fft.rfft(y, n_long, axis=-1) * x_inv, n_long, axis=-1)
    H = scipy.fft.rfft(resize_impulse_response(h_long, n_fft), axis=-1)
    H[~valid] = 0.0
    return H, valid


def h1_average(H_repeats: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 estimate and coherence over the repeats kept.

    Parameters
    ----------
    H_repeats : ndarray, complex, shape (n_repeats, ..., n_freqs)
        Per-repeat estimates of the same drive (:func:`estimate_repeats`), m/V.
    valid : ndarray of bool, shape (n_repeats, ...)
        Which repeats to keep.

    Returns
    -------
    H : ndarray, complex, shape (..., n_freqs)
        Mean over the valid repeats, m/V (0 where none is valid).
    coherence : ndarray, shape (..., n_freqs)
        ``|sum H_r|^2 / (R sum |H_r|^2)`` in [0, 1]; NaN where fewer than two repeats
        are valid (not assessable).
    n_used : ndarray of int, shape (...)
        Repeats kept.
    """
    w = np.asarray(valid, dtype=float)[..., None]
    n_used = w.sum(axis=0)
    s_xy = (w * H_repeats).sum(axis=0)
    s_yy = (w * np.abs(H_repeats) ** 2).sum(axis=0)
    H = np.divide(s_xy, n_used, out=np.zeros_like(s_xy), where=n_used > 0)
    denom = n_used * s_yy
    ok = (n_used >= 2) & (denom > 0)
    coherence = np.full(denom.shape, np.nan)
    np.divide(np.abs(s_xy) ** 2, denom, out=coherence, where=ok)
    coherence = np.minimum(coherence, 1.0)  # rounding can exceed 1 by an ulp; NaN stays
    return H, coherence, n_used[..., 0].astype(int)


def noise_and_snr(
    recordings: np.ndarray, valid: np.ndarray, n_pre: int, fs: float, band: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """In-band noise floor (from the pre-sweep silence) and SNR of each recording set.

    Both the silence ``[0, n_pre)`` and the response ``[n_pre, n_rec)`` are measured in
    the calibrated band only (mean power from the FFT bins in the band, by Parseval), so
    out-of-band sensor noise does not count against the signal.

    Parameters
    ----------
    recordings : ndarray, shape (n_repeats, n_points, n_rec)
        Displacement, m (non-finite where ``valid`` is False).
    valid : ndarray of bool, shape (n_repeats, n_points)
    n_pre : int
        Samples of silence at the start of each drive.
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Calibrated band, Hz.

    Returns
    -------
    noise_rms : ndarray, shape (n_points,)
        In-band RMS of the silence, m (NaN where no repeat is valid).
    snr_db : ndarray, shape (n_points,)
        ``10 log10((P_response - P_noise) / P_noise)``, dB, floored at -60 dB and capped
        at 300 dB.
    """
    y = np.where(np.isfinite(recordings), recordings, 0.0)
    p_noise_each = _band_power(y[..., :n_pre], fs, band)
    p_total_each = _band_power(y[..., n_pre:], fs, band)
    w = np.asarray(valid, dtype=float)
    n_used = w.sum(axis=0)
    p_noise = (w * p_noise_each).sum(axis=0)
    p_total = (w * p_total_each).sum(axis=0)
    has = n_used > 0
    p_noise = np.divide(p_noise, n_used, out=np.full(n_used.shape, np.nan), where=has)
    p_total = np.divide(p_total, n_used, out=np.full(n_used.shape, np.nan), where=has)
    tiny = np.finfo(float).tiny
    ratio = np.divide(p_total - p_noise, p_noise, out=np.full(n_used.shape, np.inf),
                      where=has & (p_noise > tiny))
    snr_db = np.full(n_used.shape, np.nan)
    np.log10(np.maximum(ratio, 1e-6), out=snr_db, where=has)
    # A noise-free recording (simulation without noise) has an infinite SNR; cap it so
    # the figure stays a finite number in files and tables.
    snr_db = np.minimum(10.0 * snr_db, 300.0)
    return np.sqrt(p_noise), snr_db


def _band_power(y: np.ndarray, fs: float, band: tuple[float, float]) -> np.ndarray:
    """Mean power of ``y`` (..., n) within ``band``: ``2 sum_band |Y_k|^2 / n^2``."""
    n = y.shape[-1]
    freqs = scipy.fft.rfftfreq(n, 1 / fs)
    keep = (freqs >= band[0]) & (freqs <= band[1])
    spectrum = scipy.fft.rfft(y, axis=-1)[..., keep]
    return 2.0 * np.sum(np.abs(spectrum) ** 2, axis=-1) / n**2
