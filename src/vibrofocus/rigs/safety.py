"""The one safety layer every drive passes through before any rig plays it.

Three parts (docs/hardware.md, "What the software guarantees"):

- :class:`SafetyLimits` and :func:`check_drive`: a stateless check of one drive (type,
  shape, NaN/Inf, duration, peak, RMS over every 1 s window) that returns the faded copy
  to play;
- :class:`EnergyBudget`: the same windowed RMS across consecutive plays of one rig, so
  neither zero padding nor back-to-back plays can dilute it;
- the hard ceilings (``*_CEILING``, ``MIN_FADE_S``): no configuration may loosen the
  limits beyond them.
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass

import numpy as np

from .._validation import check_in_range, check_positive
from ..defaults import DRIVE_LIMIT_V
from ..errors import SafetyError, ValidationError
from ..signals.sweeps import apply_fades

__all__ = [
    "SafetyLimits",
    "EnergyBudget",
    "check_drive",
    "windowed_rms",
    "PEAK_V_CEILING",
    "RMS_V_CEILING",
    "DURATION_S_CEILING",
    "MIN_FADE_S",
    "MAX_FADE_S",
]

# Hard ceilings. Assumption, not a measurement: twice the reference setup's limits (10 V
# peak into the 8 ohm TEAX14C02-8 exciters of de Vlam et al., IEEE ToH 2023; 4 V RMS = 2 W).
# A lab with larger actuators changes these constants in code, on purpose, not in a file.
#: Largest peak limit any configuration may set, V at the actuator.
PEAK_V_CEILING = 20.0
#: Largest RMS limit any configuration may set, V at the actuator.
RMS_V_CEILING = 8.0
#: Longest drive any configuration may allow, s.
DURATION_S_CEILING = 60.0
#: Shortest fade at each end of a drive, s: no drive starts or stops with a step.
MIN_FADE_S = 0.1e-3
#: Longest fade, s (a fade longer than a tap would erase it).
MAX_FADE_S = 50e-3
#: Window of the RMS limit, s: about the thermal time scale of a small voice coil.
RMS_WINDOW_S = 1.0


@dataclass(frozen=True)
class SafetyLimits:
    """Limits at the actuator terminals.

    Parameters
    ----------
    peak_v : float
        Largest instantaneous voltage magnitude, V, in (0, 20]. Default 10 V: a 1 V DAQ
        output through a 20 dB amplifier (docs/method.md, reference setup).
    rms_v : float
        Largest RMS voltage per channel over any window of ``rms_window_s``, V, in (0, 8].
        Default 4 V, i.e. 2 W into the 8 ohm coil of a 14 mm exciter. The window slides
        over the drive and over the plays before it (:class:`EnergyBudget`), and a drive
        shorter than the window counts as followed by silence: a 10 V peak sine (7.1 V
        RMS) for 1 s is refused however many zeros follow it.
    max_duration_s : float
        Longest drive, s, in (0, 60].
    fade_s : float
        Raised-cosine fade applied at both ends so no drive starts or stops with a step,
        s, in [0.1 ms, 50 ms].
    rms_window_s : float
        Window of the RMS limit, s, in [0.1, 10]; default 1 s.
    """

    peak_v: float = DRIVE_LIMIT_V
    rms_v: float = 4.0
    max_duration_s: float = 30.0
    fade_s: float = 0.5e-3
    rms_window_s: float = RMS_WINDOW_S

    def __post_init__(self) -> None:
        for name, ceiling in (("peak_v", PEAK_V_CEILING), ("rms_v", RMS_V_CEILING),
                              ("max_duration_s", DURATION_S_CEILING)):
            value = check_positive(getattr(self, name), name)
            if value > ceiling:
                raise ValidationError(
                    f"{name} = {value:g} is above the hard ceiling of {ceiling:g} that no configuration may "
                    "exceed (docs/hardware.md, limits)")
        check_in_range(self.fade_s, "fade_s", MIN_FADE_S, MAX_FADE_S)
        check_in_range(self.rms_window_s, "rms_window_s", 0.1, 10.0)

    def to_dict(self) -> dict:
        return asdict(self)


def windowed_rms(squares: np.ndarray, n_window: int) -> np.ndarray:
    """Largest RMS over any window of ``n_window`` samples, per channel.

    Parameters
    ----------
    squares : ndarray, shape (n_channels, n_samples)
        Squared voltages, V².
    n_window : int
        Window length, samples. A signal shorter than the window counts as followed by
        silence (its energy over the whole window).

    Returns
    -------
    ndarray, shape (n_channels,)
        V.
    """
    n = squares.shape[-1]
    csum = np.concatenate([np.zeros(squares.shape[:-1] + (1,)), np.cumsum(squares, axis=-1)], axis=-1)
    if n <= n_window:
        energy = csum[..., -1]
    else:
        energy = (csum[..., n_window:] - csum[..., :-n_window]).max(axis=-1)
    return np.sqrt(np.maximum(energy, 0.0) / n_window)


def _channel_message(values: np.ndarray, limit: float, unit: str, over: str = "") -> str:
    ch = int(values.argmax())
    value = f"{values[ch]:.4g}"
    if float(value) <= limit:  # enough digits that a value just over the limit never reads as the limit
        value = f"{values[ch]:.12g}"
    return f"channel {ch + 1} reaches {value} {unit}{over}, over the limit of {limit:g} {unit}"


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
        Wrong type or shape, NaN/Inf, empty, too long, over the peak limit or over the
        RMS limit in any window of ``limits.rms_window_s``. The message names the
        channel, numbered from 1 as people read them (channel 1 is the first actuator,
        A1 in the reference layout), and the value.
    """
    try:
        arr = np.asarray(drive)
    except Exception as exc:
        raise SafetyError(f"drive refused: not an array ({exc})") from exc
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise SafetyError(f"drive refused: must be real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[0] != n_actuators:
        raise SafetyError(f"drive refused: shape must be (n_actuators={n_actuators}, n_samples), got {arr.shape}")
    if arr.shape[1] == 0:
        raise SafetyError("drive refused: it holds no samples")
    duration = arr.shape[1] / fs
    if duration > limits.max_duration_s:
        raise SafetyError(f"drive refused: {duration:.3f} s is longer than the limit of {limits.max_duration_s:g} s")
    arr = arr.astype(float)
    bad = ~np.isfinite(arr)
    if bad.any():
        ch, k = np.argwhere(bad)[0]
        raise SafetyError(f"drive refused: {int(bad.sum())} NaN/Inf sample(s), first on channel {ch + 1} at sample {k}")
    peaks = np.abs(arr).max(axis=1)
    if peaks.max() > limits.peak_v * (1 + 1e-9):
        raise SafetyError("drive refused: " + _channel_message(peaks, limits.peak_v, "V peak"))
    rms = windowed_rms(arr**2, max(1, int(round(limits.rms_window_s * fs))))
    if rms.max() > limits.rms_v * (1 + 1e-9):
        raise SafetyError("drive refused: " + _channel_message(
            rms, limits.rms_v, "V RMS", f" over {limits.rms_window_s:g} s"))
    return apply_fades(arr, fs, limits.fade_s)


class EnergyBudget:
    """The RMS limit across consecutive plays of one rig (thread-safe).

    Keeps the squared drive of the last ``rms_window_s`` seconds, at the drive's sample
    rate, with the time the last play ends. A new drive is admitted only if no window of
    ``rms_window_s`` over what was played before and the new drive, placed at the time it
    starts, holds more than ``rms_v`` RMS on any channel.

    Parameters
    ----------
    limits : SafetyLimits
    n_channels : int
    fs : float
        Sample rate of the drives, Hz.
    """

    def __init__(self, limits: SafetyLimits, n_channels: int, fs: float):
        self.limits = limits
        self.fs = float(fs)
        self.n_window = max(1, int(round(limits.rms_window_s * self.fs)))
        self._tail = np.zeros((n_channels, self.n_window))
        self._end_s: float | None = None
        self._lock = threading.Lock()

    def admit(self, drive: np.ndarray, start_s: float) -> None:
        """Record a checked drive that starts playing at ``start_s``, or refuse it.

        Parameters
        ----------
        drive : ndarray, shape (n_channels, n_samples)
            The faded drive about to play, V.
        start_s : float
            When it starts, s, on the rig's clock (monotonic).

        Raises
        ------
        SafetyError
            If it would exceed the RMS limit together with the plays before it; the
            budget is then left as it was.
        """
        squares = drive**2
        with self._lock:
            if self._end_s is None:
                gap = self.n_window
            else:
                gap = int(np.floor(max(0.0, start_s - self._end_s) * self.fs))
            keep = max(0, self.n_window - gap)
            history = np.concatenate(
                [self._tail[:, self.n_window - keep:], np.zeros((len(squares), min(gap, self.n_window))), squares],
                axis=1)
            rms = windowed_rms(history, self.n_window)
            if rms.max() > self.limits.rms_v * (1 + 1e-9):
                wait = self.limits.rms_window_s if self._end_s is None else max(
                    0.0, self._end_s + self.limits.rms_window_s - start_s)
                raise SafetyError(
                    "drive refused: together with the plays before it, "
                    + _channel_message(rms, self.limits.rms_v, "V RMS", f" over {self.limits.rms_window_s:g} s")
                    + f"; wait {wait:.1f} s for the actuators to cool, or play less"
                )
            self._tail = history[:, -self.n_window:]  # history always holds the window and the drive
            begin = start_s if self._end_s is None else max(start_s, self._end_s)
            self._end_s = begin + drive.shape[1] / self.fs
