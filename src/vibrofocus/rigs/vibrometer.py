"""The laser Doppler vibrometer as a sensor: recorded volts -> skin displacement.

A vibrometer decoder puts out a voltage proportional to the velocity (most decoders) or
the displacement of the spot. Both hardware rigs record that voltage and hand it to
:meth:`Vibrometer.to_displacement`.

Velocity is integrated in the frequency domain: the mean of the recording is removed
(a decoder offset), the spectrum of the zero-padded recording is divided by ``j 2 pi f``
and multiplied by the magnitude of a 4th-order Butterworth high-pass at ``highpass_hz``. Using the magnitude only makes the high-pass
zero-phase, so the phase of a transfer function estimated from the result is that of the
skin, not of the filter; the high-pass removes the DC offset and low-frequency drift that
plain integration would turn into a ramp (at 3 Hz it changes the magnitude at 10 Hz by
less than 1e-4). Zero-padding to twice the length keeps the circular wrap of the
integration away from the samples returned. A recording should start and end at rest
(the rigs record a tail after every drive for that).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from .._validation import as_array, check_choice, check_positive

__all__ = ["Vibrometer"]

_HP_ORDER = 4


@dataclass(frozen=True)
class Vibrometer:
    """A vibrometer decoder output read through an analog input.

    Parameters
    ----------
    decoder : {"velocity", "displacement"}
        What the analog output is proportional to.
    sensitivity : float
        (m/s)/V for a velocity decoder, m/V for a displacement decoder.
    highpass_hz : float or None
        Corner of the zero-phase high-pass, Hz (see module notes); None disables it
        (then a velocity recording is integrated with only its DC bin removed).
    """

    decoder: str
    sensitivity: float
    highpass_hz: float | None = 3.0

    def __post_init__(self) -> None:
        check_choice(self.decoder, "decoder", ("velocity", "displacement"))
        check_positive(self.sensitivity, "sensitivity")
        if self.highpass_hz is not None:
            check_positive(self.highpass_hz, "highpass_hz")

    def _highpass(self, freqs: np.ndarray) -> np.ndarray:
        if self.highpass_hz is None:
            gain = np.ones_like(freqs)
        else:
            with np.errstate(divide="ignore"):
                ratio = np.where(freqs > 0, self.highpass_hz / np.where(freqs > 0, freqs, 1.0), np.inf)
            gain = 1.0 / np.sqrt(1.0 + ratio ** (2 * _HP_ORDER))
        gain[freqs == 0] = 0.0
        return gain

    def _filter(self, x: np.ndarray, fs: float, integrate: bool) -> np.ndarray:
        n = x.shape[-1]
        nfft = scipy.fft.next_fast_len(2 * n, real=True)
        # The mean goes first: a decoder offset would otherwise be a step at the ends of
        # the zero-padded record, which leaks into the band and integrates into a ramp.
        spec = scipy.fft.rfft(x - x.mean(axis=-1, keepdims=True), nfft, axis=-1)
        freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
        resp = self._highpass(freqs).astype(complex)
        if integrate:
            nz = freqs > 0
            resp[nz] /= 2j * np.pi * freqs[nz]
        return scipy.fft.irfft(spec * resp, nfft, axis=-1)[..., :n]

    def to_displacement(self, volts: np.ndarray, fs: float) -> np.ndarray:
        """Convert decoder volts to displacement.

        Parameters
        ----------
        volts : ndarray, shape (..., n_samples)
            Recorded decoder output, V.
        fs : float
            Sample rate, Hz.

        Returns
        -------
        ndarray, shape (..., n_samples)
            Displacement, m; DC and drift below ``highpass_hz`` removed (a
            displacement decoder with ``highpass_hz=None`` is only scaled).
        """
        v = as_array(volts, "volts")
        fs = check_positive(fs, "fs")
        if v.shape[-1] == 0:
            return v.copy()
        scaled = v * self.sensitivity
        if self.decoder == "velocity":
            return self._filter(scaled, fs, integrate=True)
        if self.highpass_hz is None:
            return scaled
        return self._filter(scaled, fs, integrate=False)

    def describe(self) -> dict:
        """Settings to store beside a recording (JSON-serialisable)."""
        unit = "(m/s)/V" if self.decoder == "velocity" else "m/V"
        return {"decoder": self.decoder, "sensitivity": self.sensitivity, "sensitivity_unit": unit,
                "highpass_hz": self.highpass_hz}
