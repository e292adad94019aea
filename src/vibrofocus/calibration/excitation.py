"""Calibration excitations: the sweep one actuator plays while the skin is recorded.

Two methods (docs/method.md, calibration):

``"h1"`` (default)
    An exponential sine sweep that covers the calibrated band with half an octave of
    margin on each side (so the band edges are not where the sweep starts and stops),
    played ``repeats`` times; the transfer function is the H1 estimate averaged over the
    repeats, with coherence per frequency.
``"paper"``
    The method of the paper vibrofocus follows: one linear sine sweep over exactly the
    band, the transfer function being the FFT of the response divided by the FFT of the
    drive.

Every drive starts with ``pre_s`` of silence: the recording over that stretch holds only
sensor noise (the skin cannot respond before it is driven), which gives the noise floor
for the SNR verdicts.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._validation import check_band, check_choice, check_positive
from ..errors import ValidationError
from ..signals import exponential_sweep, linear_sweep

__all__ = ["METHODS", "SweepSettings", "default_settings", "make_excitation"]

#: Estimation methods of :func:`vibrofocus.calibration.calibrate`.
METHODS = ("h1", "paper")

#: Margin of the exponential sweep beyond each band edge, octaves.
_MARGIN_OCTAVES = 0.5


@dataclass(frozen=True)
class SweepSettings:
    """Everything that defines the excitation of one calibration.

    Parameters
    ----------
    method : {"h1", "paper"}
        Estimation method (see the module docstring).
    kind : {"exponential", "linear"}
        Sweep law.
    f_start, f_stop : float
        Sweep start and stop frequencies, Hz.
    sweep_s : float
        Sweep duration, s.
    amplitude_v : float
        Sweep peak voltage at the actuator, V.
    repeats : int
        Recordings per (point, actuator).
    pre_s : float
        Silence before the sweep, s (noise floor).
    tail_s : float
        Recording after the drive ends, s (decay of the response).
    fade_s : float
        Raised-cosine fade at both sweep ends, s.
    fs : float
        Sample rate, Hz.
    """

    method: str
    kind: str
    f_start: float
    f_stop: float
    sweep_s: float
    amplitude_v: float
    repeats: int
    pre_s: float
    tail_s: float
    fade_s: float
    fs: float

    @property
    def n_pre(self) -> int:
        """Samples of silence before the sweep."""
        return int(round(self.pre_s * self.fs))

    @property
    def n_drive(self) -> int:
        """Samples in one drive (silence + sweep)."""
        return self.n_pre + int(round(self.sweep_s * self.fs))

    @property
    def n_tail(self) -> int:
        """Samples recorded after the drive."""
        return int(round(self.tail_s * self.fs))

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "SweepSettings":
        """Inverse of :meth:`to_dict`."""
        return cls(**data)


def default_settings(
    method: str,
    fs: float,
    band: tuple[float, float],
    *,
    sweep_s: float | None = None,
    repeats: int | None = None,
    amplitude_v: float = 5.0,
    pre_s: float = 0.1,
    tail_s: float = 0.3,
) -> SweepSettings:
    """Sweep settings for ``method`` with its defaults filled in.

    Parameters
    ----------
    method : {"h1", "paper"}
    fs : float
        Sample rate, Hz.
    band : (float, float)
        Calibrated band, Hz.
    sweep_s : float, optional
        Sweep duration, s. Default 2 s for both methods.
    repeats : int, optional
        Default 8 (``h1``) or 1 (``paper``: one sweep, as in the paper).
    amplitude_v : float
        Sweep peak, V. The default 5 V stays under the default RMS limit of 4 V
        (a sine of 5 V peak is 3.5 V RMS).
    pre_s, tail_s : float
        Silence before the sweep and recording after the drive, s.

    Returns
    -------
    SweepSettings
    """
    check_choice(method, "method", METHODS)
    fs = check_positive(fs, "fs")
    low, high = check_band(band, fs)
    if method == "h1":
        f_start = low * 2.0 ** -_MARGIN_OCTAVES
        # Stay clear of Nyquist: the sweep's top must be a tone the DAC can render.
        f_stop = min(high * 2.0**_MARGIN_OCTAVES, 0.45 * fs)
        f_stop = max(f_stop, high)
        kind = "exponential"
        sweep_s = 2.0 if sweep_s is None else sweep_s
        repeats = 8 if repeats is None else repeats
    else:
        f_start, f_stop, kind = low, high, "linear"
        sweep_s = 2.0 if sweep_s is None else sweep_s
        repeats = 1 if repeats is None else repeats
    sweep_s = check_positive(sweep_s, "sweep_s")
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise ValidationError(f"repeats must be a positive integer, got {repeats!r}")
    amplitude_v = check_positive(amplitude_v, "amplitude_v")
    pre_s = check_positive(pre_s, "pre_s")
    tail_s = check_positive(tail_s, "tail_s")
    if sweep_s * f_start < 2:
        raise ValidationError(
            f"sweep_s={sweep_s:g} s is too short to sweep from {f_start:g} Hz (needs at least "
            f"{2 / f_start:.3g} s, two periods of the lowest frequency)"
        )
    return SweepSettings(
        method=method, kind=kind, f_start=float(f_start), f_stop=float(f_stop), sweep_s=float(sweep_s),
        amplitude_v=float(amplitude_v), repeats=int(repeats), pre_s=float(pre_s), tail_s=float(tail_s),
        fade_s=0.01, fs=float(fs),
    )


def make_excitation(settings: SweepSettings) -> np.ndarray:
    """The single-channel drive of one recording: silence then the sweep.

    Parameters
    ----------
    settings : SweepSettings

    Returns
    -------
    ndarray, shape (settings.n_drive,)
        Voltage, V.
    """
    law = exponential_sweep if settings.kind == "exponential" else linear_sweep
    sweep = law(settings.fs, settings.f_start, settings.f_stop, settings.sweep_s,
                amplitude=settings.amplitude_v, fade_s=settings.fade_s)
    return np.concatenate([np.zeros(settings.n_pre), sweep])
