"""The band taper of the designs: :func:`vibrofocus.signals.band_taper`, re-exported
here for the rendering modules (signals sit below rendering; nothing flows back up), and
the design grid with its taper, kept for repeated designs."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._docs import fill_doc
from ..signals.taper import band_taper

__all__ = ["band_taper", "design_grid"]


@lru_cache(maxsize=16)
def _grid(n: int, fs: float, low: float, high: float, taper_octaves: float) -> tuple[np.ndarray, np.ndarray]:
    freqs = np.fft.rfftfreq(n, 1 / fs)
    taper = band_taper(freqs, (low, high), taper_octaves)
    freqs.setflags(write=False)  # shared by every design on this grid
    taper.setflags(write=False)
    return freqs, taper


@fill_doc
def design_grid(n: int, fs: float, band: tuple[float, float], taper_octaves: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and band taper of an ``n``-sample design at ``fs``.

    The pair is computed once per grid and shared (read-only): a design repeated on the
    same grid, the usual case, does not recompute the taper's logarithms.

    Parameters
    ----------
    n : int
        Window length, samples.
    %(fs)s
    band : (float, float)
        Pass band, Hz (validated by the caller).
    taper_octaves : float
        Roll-off width, octaves.

    Returns
    -------
    freqs : ndarray, shape (n // 2 + 1,)
        ``rfftfreq(n, 1 / fs)``, Hz, read-only.
    taper : ndarray, shape (n // 2 + 1,)
        :func:`band_taper` on ``freqs``, read-only.
    """
    return _grid(int(n), float(fs), float(band[0]), float(band[1]), float(taper_octaves))
