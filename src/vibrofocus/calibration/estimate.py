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

With several actuators playing at once (method ``mimo``) step 3 becomes the MIMO H1
estimate (:func:`mimo_h1`) per point and frequency, over the takes: with input spectra
``X_r`` (n_actuators,) and output ``Y_r``, ``G_xx = sum_r X_r X_r^H``,
``G_yx = sum_r Y_r X_r^H`` and ``H = G_yx G_xx^-1``. When every actuator plays the same
sweep ``x`` with a sign ``s_ra``, ``X_r(f) = s_r X(f)``; since the H1 estimate does not
change when all inputs are divided by the same ``X(f)``, steps 1-2 deconvolve each take
by ``x`` (giving ``sum_a s_ra H_a`` plus noise on the design grid) and step 3 uses the
signs as the inputs. Its single-input case (one actuator, ``X_r = 1``) is step 3 above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
import scipy.signal

from .._docs import fill_doc
from .._validation import as_array, check_band, check_positive
from ..errors import ValidationError
from ..signals.taper import band_taper

__all__ = [
    "resize_impulse_response",
    "estimate_repeats",
    "h1_average",
    "MimoEstimate",
    "mimo_h1",
    "noise_and_snr",
    "split_snr",
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


@fill_doc
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
    %(fs)s
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


@dataclass(frozen=True)
class MimoEstimate:
    """The MIMO H1 estimate of :func:`mimo_h1` and its diagnostics.

    Attributes
    ----------
    H : ndarray, complex, shape (n_freqs, n_outputs, n_inputs)
        ``G_yx G_xx^-1`` per output and frequency (output units per input unit).
    multiple_coherence : ndarray, shape (n_freqs, n_outputs)
        ``G_yx G_xx^-1 G_xy / G_yy`` in [0, 1]: the share of the output's power that the
        inputs together explain linearly. NaN where not assessable (no more blocks than
        inputs, or no output power). For pure noise its expected value is
        ``n_inputs / n_blocks``.
    partial_coherence : ndarray, shape (n_freqs, n_outputs, n_inputs)
        Coherence of each input with the output once the other inputs' linear
        contributions are removed: ``|H_a|^2 / [G_xx^-1]_aa`` over itself plus the
        residual power. With one input it is the ordinary coherence; for pure noise
        its expected value is ``1 / (n_blocks - n_inputs + 1)``. NaN where not
        assessable.
    condition_number : ndarray, shape (n_freqs, n_outputs)
        2-norm condition number of ``G_xx`` (largest over smallest eigenvalue); inf
        where it is singular.
    input_correlation : ndarray, shape (n_freqs, n_outputs)
        Largest ``|G_xx[a, b]| / sqrt(G_xx[a, a] G_xx[b, b])`` over input pairs
        ``a != b``: 0 for uncorrelated inputs, 1 for inputs that cannot be told apart.
        0 with one input.
    n_used : ndarray of int, shape (n_outputs,)
        Blocks kept per output.
    """

    H: np.ndarray
    multiple_coherence: np.ndarray
    partial_coherence: np.ndarray
    condition_number: np.ndarray
    input_correlation: np.ndarray
    n_used: np.ndarray


def mimo_h1(inputs: np.ndarray, outputs: np.ndarray, valid: np.ndarray | None = None) -> MimoEstimate:
    """MIMO H1 estimate ``H = G_yx G_xx^-1``, batched over outputs and frequencies.

    Every output is estimated separately (its own weights, so a block with a dropout
    at one output leaves only that output's sums), with the cross-spectral matrices
    summed over the blocks kept: ``G_xx = sum_r w_r X_r X_r^H`` (n_inputs, n_inputs),
    ``G_yx = sum_r w_r Y_r X_r^H`` (1, n_inputs), ``G_yy = sum_r w_r |Y_r|^2``. The
    inverse is a pseudo-inverse (Hermitian, relative cut-off 1e-12), so a singular
    ``G_xx`` gives the minimum-norm estimate instead of overflow; ``condition_number``
    says where that happened.

    Parameters
    ----------
    inputs : array_like, shape (n_blocks, n_inputs, n_freqs)
        Input spectra ``X_r`` per block (e.g. V); any shape that broadcasts to it
        (``(n_blocks, n_inputs, 1)`` for inputs that are the same at every frequency).
    outputs : array_like, complex, shape (n_blocks, n_outputs, n_freqs)
        Output spectra ``Y_r`` per block (e.g. m).
    valid : array_like of bool, shape (n_blocks, n_outputs), optional
        Which blocks to keep for each output (default all).

    Returns
    -------
    MimoEstimate
    """
    Y = as_array(outputs, "outputs", ndim=3, dtype="complex", finite=False)
    n_blocks, n_out, n_freqs = Y.shape
    X = np.asarray(inputs)
    if X.ndim != 3 or X.shape[0] != n_blocks or X.shape[2] not in (1, n_freqs):
        raise ValidationError(
            f"inputs must have shape (n_blocks={n_blocks}, n_inputs, n_freqs={n_freqs} or 1), got {X.shape}"
        )
    X = as_array(X, "inputs", ndim=3, dtype="complex")
    n_in = X.shape[1]
    w = np.ones((n_blocks, n_out)) if valid is None else as_array(valid, "valid", shape=(n_blocks, n_out))
    kept = w[..., None] > 0
    if not np.isfinite(Y[np.broadcast_to(kept, Y.shape)]).all():
        raise ValidationError("outputs holds NaN/Inf in a block marked valid")
    Y = np.where(kept, Y, 0.0)  # a dropped block may hold garbage (NaN)
    Xf = np.broadcast_to(X, (n_blocks, n_in, n_freqs))
    # Cross-spectral sums, frequencies batched: (P, F, A, A), (P, F, A), (P, F).
    Gxx = np.einsum("rp,raf,rbf->pfab", w, Xf, Xf.conj(), optimize=True)
    Gyx = np.einsum("rp,rpf,raf->pfa", w, Y, Xf.conj(), optimize=True)
    Gyy = np.einsum("rp,rpf->pf", w, np.abs(Y) ** 2)
    inv = np.linalg.pinv(Gxx, rcond=1e-12, hermitian=True)
    H = np.einsum("pfa,pfab->pfb", Gyx, inv)
    explained = np.einsum("pfa,pfa->pf", H, Gyx.conj()).real  # G_yx G_xx^-1 G_xy
    residual = np.maximum(Gyy - explained, 0.0)
    n_used = w.sum(axis=0)
    assessable = (n_used > n_in)[:, None] & (Gyy > 0)
    multiple = np.full(Gyy.shape, np.nan)
    np.divide(explained, Gyy, out=multiple, where=assessable)
    # Adding input a to the others lowers the residual by |H_a|^2 / [G_xx^-1]_aa.
    inv_diag = np.einsum("pfaa->pfa", inv).real
    gain = np.divide(np.abs(H) ** 2, inv_diag, out=np.zeros(H.shape), where=inv_diag > 0)
    total = gain + residual[..., None]
    partial = np.full(H.shape, np.nan)
    np.divide(gain, total, out=partial, where=assessable[..., None] & (total > 0))
    eig = np.linalg.eigvalsh(Gxx)  # ascending, (P, F, A)
    tiny = np.finfo(float).tiny
    cond = np.divide(eig[..., -1], eig[..., 0], out=np.full(eig.shape[:-1], np.inf),
                     where=eig[..., 0] > tiny * np.maximum(eig[..., -1], 1.0))
    power = np.einsum("pfaa->pfa", Gxx).real
    norm = np.sqrt(power[..., :, None] * power[..., None, :])
    corr = np.divide(np.abs(Gxx), norm, out=np.zeros(Gxx.shape), where=norm > 0)
    corr[..., np.arange(n_in), np.arange(n_in)] = 0.0
    return MimoEstimate(
        H=np.moveaxis(H, 0, 1), multiple_coherence=np.minimum(multiple, 1.0).T,
        partial_coherence=np.minimum(np.moveaxis(partial, 0, 1), 1.0),
        condition_number=np.moveaxis(cond, 0, 1), input_correlation=corr.max(axis=(-2, -1)).T,
        n_used=n_used.astype(int),
    )


@fill_doc
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
    %(fs)s
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
    # The silence without its mean and linear trend: a velocity decoder's recording,
    # integrated to displacement over the whole take, drifts linearly there, and that
    # drift (not noise) would leak into the band through the window's edges.
    p_noise_each = _band_power(scipy.signal.detrend(y[..., :n_pre], axis=-1, type="linear"), fs, band)
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


@fill_doc
def split_snr(
    snr_db: np.ndarray, H: np.ndarray, freqs: np.ndarray, band: tuple[float, float], drive: np.ndarray, fs: float
) -> np.ndarray:
    """Per-actuator SNR of takes in which all actuators played the same sweep at once.

    Over a block of Hadamard-coded takes the cross terms between actuators cancel, so a
    point's mean in-band response power is the sum of what each actuator alone gives.
    That power over the noise floor (``snr_db`` of :func:`noise_and_snr`) is shared
    among the actuators in proportion to ``sum_band |H_pa(f)|^2 |X(f)|^2``, the in-band
    power actuator ``a`` gives at point ``p`` with the sweep's spectrum ``X``. The result
    reads like the ``h1`` SNR of that pair: what the pair alone would have given.

    Parameters
    ----------
    snr_db : ndarray, shape (n_points,)
        In-band SNR of all actuators together, dB (:func:`noise_and_snr`).
    H : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        Estimated transfer matrix, m/V.
    freqs : ndarray, shape (n_freqs,)
        Frequencies of ``H``, Hz.
    band : (float, float)
        Calibrated band, Hz.
    drive : ndarray, shape (n_drive,)
        The sweep each actuator played (up to its sign), V.
    %(fs)s

    Returns
    -------
    ndarray, shape (n_points, n_actuators)
        dB, floored at -60 dB and capped at 300 dB like :func:`noise_and_snr`.
    """
    n = scipy.fft.next_fast_len(max(drive.size, 2 * (len(freqs) - 1)), real=True)
    sweep_power = np.interp(freqs, scipy.fft.rfftfreq(n, 1 / fs), np.abs(scipy.fft.rfft(drive, n)) ** 2)
    in_band = (freqs >= band[0]) & (freqs <= band[1])
    power = np.einsum("fpa,f->pa", np.abs(H[in_band]) ** 2, sweep_power[in_band])
    total = power.sum(axis=1, keepdims=True)
    share = np.divide(power, total, out=np.zeros(power.shape), where=total > 0)
    ratio = 10.0 ** (np.asarray(snr_db, float)[:, None] / 10.0) * share
    with np.errstate(divide="ignore"):
        out = 10.0 * np.log10(np.maximum(ratio, 1e-6))
    return np.where(np.isnan(snr_db)[:, None], np.nan, np.minimum(out, 300.0))


def _band_power(y: np.ndarray, fs: float, band: tuple[float, float]) -> np.ndarray:
    """Mean power of ``y`` (..., n) within ``band``: ``2 sum_band |Y_k|^2 / n^2``."""
    n = y.shape[-1]
    freqs = scipy.fft.rfftfreq(n, 1 / fs)
    keep = (freqs >= band[0]) & (freqs <= band[1])
    spectrum = scipy.fft.rfft(y, axis=-1)[..., keep]
    return 2.0 * np.sum(np.abs(spectrum) ** 2, axis=-1) / n**2
