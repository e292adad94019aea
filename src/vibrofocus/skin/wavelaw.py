"""What every wave law derives from its complex wavenumber: phase speed and attenuation."""

from __future__ import annotations

import numpy as np

__all__ = ["WaveNumberMixin"]


class WaveNumberMixin:
    """Wavenumber, phase speed and attenuation of a law that provides ``_wavenumber(f)``."""

    def _wavenumber(self, f: np.ndarray) -> np.ndarray:  # pragma: no cover - provided by the law
        raise NotImplementedError

    def wavenumber(self, freqs: np.ndarray) -> np.ndarray:
        """Complex surface wavenumber in the physics convention, ``k = omega / c + i alpha``.

        Parameters
        ----------
        freqs : ndarray
            Frequencies, Hz, > 0.

        Returns
        -------
        ndarray, complex, same shape as ``freqs``
            rad/m (real part, ``2 pi f / c(f)``) and Np/m (imaginary part,
            ``alpha(f)`` >= 0).
        """
        return self._wavenumber(np.asarray(freqs, dtype=float))

    def phase_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Phase speed ``c(f) = 2 pi f / Re k``, m/s, for ``freqs`` > 0 Hz."""
        f = np.asarray(freqs, dtype=float)
        return 2 * np.pi * f / self.wavenumber(f).real

    def attenuation(self, freqs: np.ndarray) -> np.ndarray:
        """Attenuation ``alpha(f) = Im k``, Np/m (amplitude falls as ``exp(-alpha r)``)."""
        return self.wavenumber(freqs).imag
