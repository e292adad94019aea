"""What every wave law derives from its complex wavenumber: phase speed and attenuation."""

from __future__ import annotations

import numpy as np

__all__ = ["WaveNumberMixin"]


class WaveNumberMixin:
    """Phase speed and attenuation of a law with a physics-convention ``wavenumber(freqs)``."""

    def wavenumber(self, freqs: np.ndarray) -> np.ndarray:  # pragma: no cover - provided by the law
        raise NotImplementedError

    def phase_speed(self, freqs: np.ndarray) -> np.ndarray:
        """Phase speed ``c(f) = 2 pi f / Re k``, m/s, for ``freqs`` > 0 Hz."""
        f = np.asarray(freqs, dtype=float)
        return 2 * np.pi * f / self.wavenumber(f).real

    def attenuation(self, freqs: np.ndarray) -> np.ndarray:
        """Attenuation ``alpha(f) = Im k``, Np/m (amplitude falls as ``exp(-alpha r)``)."""
        return self.wavenumber(freqs).imag
