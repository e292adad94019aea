"""Smooth band-limiting taper shared by the designs and the deconvolution."""

from __future__ import annotations

import numpy as np

from .._validation import as_array, check_positive
from ..errors import ValidationError

__all__ = ["band_taper"]


def band_taper(freqs: np.ndarray, band: tuple[float, float], taper_octaves: float = 0.5) -> np.ndarray:
    """Weights in [0, 1]: 1 inside ``band``, a raised-cosine roll-off over ``taper_octaves``
    octaves outside each edge, 0 beyond.

    Tapering outside rather than inside keeps the full calibrated band at unit gain while
    avoiding the long time-domain ringing of a brick-wall band limit.

    Parameters
    ----------
    freqs : ndarray, shape (n_freqs,)
        Frequencies, Hz (>= 0).
    band : (float, float)
        Pass band ``(low, high)``, Hz.
    taper_octaves : float
        Roll-off width, octaves; 0 gives a brick wall.

    Returns
    -------
    ndarray, shape (n_freqs,)
    """
    f = as_array(freqs, "freqs")
    try:
        low, high = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"band must be a pair (low_hz, high_hz), got {band!r}") from exc
    if not 0 < low < high < np.inf:
        raise ValidationError(f"band must satisfy 0 < low < high, got ({low:g}, {high:g}) Hz")
    taper_octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
    w = ((f >= low) & (f <= high)).astype(float)
    if taper_octaves > 0:
        # log2(0) = -inf puts DC infinitely many octaves below the band (weight 0).
        with np.errstate(divide="ignore"):
            log_f = np.log2(f)
        octaves_below = np.log2(low) - log_f
        octaves_above = log_f - np.log2(high)
        for dist in (octaves_below, octaves_above):
            ramp = (dist > 0) & (dist < taper_octaves)
            w[ramp] = 0.5 + 0.5 * np.cos(np.pi * dist[ramp] / taper_octaves)
    return w
