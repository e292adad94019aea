"""The spectrum of a response's precursor, to take it out of a transfer function.

A single surface mode whose phase speed rises with frequency at little loss is not
causal on its own (Kramers-Kronig: a causal mode with the measured dispersion would
lose about 190 Np/m at 250 Hz). A layered arm is causal as a whole wave field: the
near-field and non-modal parts of its response cancel the mode's precursor. The
layered presets of the simulated forearm stand in for those parts with the minimal
correction: the response before ``t = 0`` is computed on a fine time grid and its
spectrum subtracted, so that the transfer is the Fourier transform of a response that
starts at ``t = 0`` (its *causal part*).
"""

from __future__ import annotations

import numpy as np

__all__ = ["precursor_spectrum"]

# Frequencies per block of the direct sum (bounds memory to a few tens of MB).
_BLOCK = 512


def precursor_spectrum(samples: np.ndarray, rate: float, freqs: np.ndarray) -> np.ndarray:
    """Fourier transform of the ``n_pre`` samples just before ``t = 0``.

    Parameters
    ----------
    samples : ndarray, shape (n_pre, ...)
        Response times the sample interval (the ``irfft`` of a transfer) at times
        ``t_j = (j - n_pre) / rate``, m/V.
    rate : float
        Sample rate of ``samples``, Hz.
    freqs : ndarray, shape (n_freqs,)
        Frequencies, Hz.

    Returns
    -------
    ndarray, complex, shape (n_freqs, ...)
        ``sum_j samples[j] exp(-2 pi i f t_j)`` in NumPy's sign convention, m/V.

    Notes
    -----
    On a uniform grid ``f_k = k df`` with ``rate / df = N`` an integer (every
    ``rfftfreq`` grid whose sample rate divides ``rate``'s multiples), one FFT of length
    ``N`` gives the sum exactly; other frequencies are summed directly, in blocks.
    """
    x = np.asarray(samples)
    f = np.asarray(freqs, dtype=float)
    n_pre = x.shape[0]
    if f.size > 1 and f[0] == 0.0:
        df = f[1] - f[0]
        n_fft = rate / df
        uniform = np.allclose(np.diff(f), df, rtol=0, atol=1e-9 * df)
        if uniform and abs(n_fft - round(n_fft)) < 1e-6 * n_fft and round(n_fft) >= max(n_pre, 2 * (f.size - 1)):
            n_fft = int(round(n_fft))
            buf = np.zeros((n_fft,) + x.shape[1:], dtype=x.dtype)
            buf[n_fft - n_pre:] = x  # negative times wrap to the end of the FFT window
            return np.fft.rfft(buf, axis=0)[: f.size]
    t = (np.arange(n_pre) - n_pre) / rate
    flat = x.reshape(n_pre, -1)
    out = np.empty((f.size, flat.shape[1]), dtype=complex)
    for start in range(0, f.size, _BLOCK):
        fb = f[start:start + _BLOCK]
        out[start:start + _BLOCK] = np.exp(-2j * np.pi * fb[:, None] * t[None, :]) @ flat
    return out.reshape((f.size,) + x.shape[1:])
