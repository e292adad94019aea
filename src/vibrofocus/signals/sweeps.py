"""Sine sweeps for calibration and their inverses for deconvolution (docs/method.md, calibration)."""

from __future__ import annotations

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_positive
from ..errors import ValidationError
from .taper import band_taper

__all__ = [
    "linear_sweep",
    "exponential_sweep",
    "exponential_sweep_inverse",
    "spectral_inverse",
    "apply_fades",
]


@fill_doc
def apply_fades(signal: np.ndarray, fs: float, fade_in_s: float, fade_out_s: float | None = None) -> np.ndarray:
    """Raised-cosine fade-in and fade-out along the last axis (returns a copy).

    Parameters
    ----------
    signal : ndarray, shape (..., n_samples)
    %(fs)s
    fade_in_s, fade_out_s : float
        Fade lengths, s; ``fade_out_s`` defaults to ``fade_in_s``.
    """
    out = as_array(signal, "signal").copy()
    fs = check_positive(fs, "fs")
    fade_in_s = check_positive(fade_in_s, "fade_in_s", allow_zero=True)
    fade_out_s = fade_in_s if fade_out_s is None else check_positive(fade_out_s, "fade_out_s", allow_zero=True)
    n = out.shape[-1]
    m_in = min(int(round(fade_in_s * fs)), n // 2)
    m_out = min(int(round(fade_out_s * fs)), n // 2)
    if m_in > 0:
        out[..., :m_in] *= 0.5 - 0.5 * np.cos(np.pi * np.arange(m_in) / m_in)
    if m_out > 0:
        out[..., n - m_out:] *= (0.5 - 0.5 * np.cos(np.pi * np.arange(m_out) / m_out))[::-1]
    return out


def _check_sweep_args(fs: float, f_start: float, f_stop: float, duration: float) -> tuple[float, float, float, int]:
    fs = check_positive(fs, "fs")
    f_start, f_stop = check_band((f_start, f_stop), fs, name="(f_start, f_stop)")
    duration = check_positive(duration, "duration")
    return fs, f_start, f_stop, int(round(duration * fs))


@fill_doc
def linear_sweep(
    fs: float,
    f_start: float = 10.0,
    f_stop: float = 1000.0,
    duration: float = 1.0,
    *,
    amplitude: float = 1.0,
    fade_s: float = 0.01,
) -> np.ndarray:
    """Linear sine sweep, instantaneous frequency ``f_start + (f_stop - f_start) t / T``.

    Parameters
    ----------
    %(sweep)s
    amplitude : float
        Peak value.
    %(sweep_fade_s)s

    Returns
    -------
    ndarray, shape (round(duration * fs),)
    """
    fs, f1, f2, n = _check_sweep_args(fs, f_start, f_stop, duration)
    t = np.arange(n) / fs
    phase = 2 * np.pi * (f1 * t + (f2 - f1) * t**2 / (2 * duration))
    return apply_fades(amplitude * np.sin(phase), fs, fade_s)


@fill_doc
def exponential_sweep(
    fs: float,
    f_start: float = 10.0,
    f_stop: float = 1000.0,
    duration: float = 1.0,
    *,
    amplitude: float = 1.0,
    fade_s: float = 0.01,
) -> np.ndarray:
    """Exponential (logarithmic) sine sweep, ``f(t) = f_start (f_stop/f_start)^(t/T)``.

    Spends equal time per octave, so low frequencies, where skin is most damped at the
    vibrometer, get more energy than in a linear sweep.

    Parameters
    ----------
    %(sweep)s
    amplitude : float
        Peak value.
    %(sweep_fade_s)s

    Returns
    -------
    ndarray, shape (round(duration * fs),)
    """
    fs, f1, f2, n = _check_sweep_args(fs, f_start, f_stop, duration)
    t = np.arange(n) / fs
    rate = duration / np.log(f2 / f1)
    phase = 2 * np.pi * f1 * rate * (np.exp(t / rate) - 1)
    return apply_fades(amplitude * np.sin(phase), fs, fade_s)


@fill_doc
def exponential_sweep_inverse(
    fs: float, f_start: float = 10.0, f_stop: float = 1000.0, duration: float = 1.0, *, fade_s: float = 0.01
) -> np.ndarray:
    """Time-domain inverse of :func:`exponential_sweep` (the classic reversed sweep).

    The sweep reversed in time, with an envelope falling 6 dB per octave that undoes the
    sweep's pink spectrum, normalised so that the sweep convolved with it has unit gain
    at the band centre (geometric mean of the band).

    Parameters
    ----------
    %(sweep)s
    %(sweep_fade_s)s

    Returns
    -------
    ndarray, shape (round(duration * fs),)
    """
    fs, f1, f2, n = _check_sweep_args(fs, f_start, f_stop, duration)
    sweep = exponential_sweep(fs, f1, f2, duration, fade_s=fade_s)
    t = np.arange(n) / fs
    rate = duration / np.log(f2 / f1)
    inverse = sweep[::-1] * np.exp(-t / rate)
    n_fft = 2 * n
    freqs = np.fft.rfftfreq(n_fft, 1 / fs)
    gain = np.abs(np.fft.rfft(sweep, n_fft) * np.fft.rfft(inverse, n_fft))
    centre = np.argmin(np.abs(freqs - np.sqrt(f1 * f2)))
    return inverse / gain[centre]


@fill_doc
def spectral_inverse(
    excitation: np.ndarray,
    fs: float,
    n_fft: int,
    band: tuple[float, float],
    *,
    regularization: float = 1e-6,
    taper_octaves: float = 0.5,
) -> np.ndarray:
    """Regularised spectral inverse of an excitation, band-limited with a smooth taper.

    ``X_inv(f) = T(f) conj(X(f)) / (|X(f)|^2 + eps max|X|^2)`` on ``rfftfreq(n_fft, 1/fs)``,
    with ``T`` the band taper. Works for any excitation (linear or exponential sweep).

    Parameters
    ----------
    excitation : ndarray, shape (n_samples,)
    %(fs)s
    n_fft : int
        FFT length, >= n_samples (use >= recording length for linear deconvolution).
    band : (float, float)
        Band kept, Hz.
    regularization : float
        ``eps`` relative to the largest ``|X|^2``.
    taper_octaves : float
        Width of the raised-cosine taper outside each band edge, octaves.

    Returns
    -------
    ndarray, complex, shape (n_fft // 2 + 1,)
    """
    x = as_array(excitation, "excitation", ndim=1)
    fs = check_positive(fs, "fs")
    band = check_band(band, fs)
    if isinstance(n_fft, bool) or not isinstance(n_fft, (int, np.integer)) or n_fft < x.size:
        raise ValidationError(f"n_fft={n_fft!r} must be an integer >= the excitation length {x.size}")
    regularization = check_positive(regularization, "regularization", allow_zero=True)
    taper_octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
    spectrum = np.fft.rfft(x, n_fft)
    power = np.abs(spectrum) ** 2
    freqs = np.fft.rfftfreq(n_fft, 1 / fs)
    return band_taper(freqs, band, taper_octaves) * np.conj(spectrum) / (power + regularization * power.max())
