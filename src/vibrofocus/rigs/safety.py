"""The one safety layer every drive passes through before any rig plays it (docs/method.md, rigs and safety)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._validation import check_positive
from ..defaults import DRIVE_LIMIT_V
from ..errors import SafetyError
from ..signals.sweeps import apply_fades

__all__ = ["SafetyLimits", "check_drive"]


@dataclass(frozen=True)
class SafetyLimits:
    """Limits at the actuator terminals.

    Parameters
    ----------
    peak_v : float
        Largest instantaneous voltage magnitude, V. Default 10 V: a 1 V DAQ output
        through a 20 dB amplifier (docs/method.md, reference setup).
    rms_v : float
        Largest RMS voltage per channel over the drive, V. Default 4 V, i.e. 2 W into the
        8 ohm coil of a 14 mm exciter, which such exciters stand for seconds; a 10 V peak
        sine (7.1 V RMS) is refused.
    max_duration_s : float
        Longest drive, s.
    fade_s : float
        Raised-cosine fade applied at both ends so no drive starts or stops with a step, s.
    """

    peak_v: float = DRIVE_LIMIT_V
    rms_v: float = 4.0
    max_duration_s: float = 30.0
    fade_s: float = 0.5e-3

    def __post_init__(self) -> None:
        for name in ("peak_v", "rms_v", "max_duration_s"):
            check_positive(getattr(self, name), name)
        check_positive(self.fade_s, "fade_s", allow_zero=True)

    def to_dict(self) -> dict:
        return asdict(self)


def check_drive(drive: np.ndarray, fs: float, n_actuators: int, limits: SafetyLimits) -> np.ndarray:
    """Validate a drive against the limits and return the faded copy to play.

    Parameters
    ----------
    drive : ndarray, shape (n_actuators, n_samples)
        Voltages at the actuators, V.
    fs : float
        Sample rate, Hz.
    n_actuators : int
        Number of actuator channels of the rig.
    limits : SafetyLimits

    Returns
    -------
    ndarray, shape (n_actuators, n_samples)
        The drive with fades applied; never larger than the input.

    Raises
    ------
    SafetyError
        Wrong type or shape, NaN/Inf, empty, too long, over the peak or RMS limit. The
        message names the channel, numbered from 1 as people read them (channel 1 is
        the first actuator, A1 in the reference layout), and the value.
    """
    try:
        arr = np.asarray(drive)
    except Exception as exc:
        raise SafetyError(f"drive refused: not an array ({exc})") from exc
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise SafetyError(f"drive refused: must be real numbers, got dtype {arr.dtype}")
    arr = arr.astype(float)
    if arr.ndim != 2 or arr.shape[0] != n_actuators:
        raise SafetyError(f"drive refused: shape must be (n_actuators={n_actuators}, n_samples), got {arr.shape}")
    if arr.shape[1] == 0:
        raise SafetyError("drive refused: it holds no samples")
    bad = ~np.isfinite(arr)
    if bad.any():
        ch, k = np.argwhere(bad)[0]
        raise SafetyError(f"drive refused: {int(bad.sum())} NaN/Inf sample(s), first on channel {ch + 1} at sample {k}")
    duration = arr.shape[1] / fs
    if duration > limits.max_duration_s:
        raise SafetyError(f"drive refused: {duration:.3f} s is longer than the limit of {limits.max_duration_s:g} s")
    peaks = np.abs(arr).max(axis=1)
    if peaks.max() > limits.peak_v * (1 + 1e-9):
        ch = int(peaks.argmax())
        raise SafetyError(
            f"drive refused: channel {ch + 1} reaches {peaks[ch]:.3g} V peak, over the limit of {limits.peak_v:g} V"
        )
    rms = np.sqrt(np.mean(arr**2, axis=1))
    if rms.max() > limits.rms_v * (1 + 1e-9):
        ch = int(rms.argmax())
        raise SafetyError(f"drive refused: channel {ch + 1} has {rms[ch]:.3g} V RMS, over the limit of {limits.rms_v:g} V")
    return apply_fades(arr, fs, limits.fade_s)
