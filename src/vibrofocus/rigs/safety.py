"""The one safety layer every drive passes through before any rig plays it.

Three parts (docs/hardware.md, "What the software guarantees"):

- :class:`SafetyLimits` and :func:`check_drive`: a stateless check of one drive (type,
  shape, NaN/Inf, duration, peak, RMS over every 1 s window) that returns the faded copy
  to play;
- :class:`EnergyBudget`: the same windowed RMS across consecutive plays of one rig, so
  neither zero padding nor back-to-back plays can dilute it, and a second, sustained
  limit over a long window (60 s by default) for the heat a coil builds up over minutes;
- the hard ceilings (``*_CEILING``, ``MIN_FADE_S``): no configuration may loosen the
  limits beyond them.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._validation import check_in_range, check_positive
from ..defaults import DRIVE_LIMIT_V
from ..errors import CoolingError, SafetyError, ValidationError
from ..signals.sweeps import apply_fades

__all__ = [
    "SafetyLimits",
    "EnergyBudget",
    "PlanLevels",
    "plan_levels",
    "plan_pause_s",
    "play_paced",
    "check_drive",
    "check_sustained_alone",
    "check_on_rig",
    "windowed_rms",
    "PEAK_V_CEILING",
    "RMS_V_CEILING",
    "SUSTAINED_RMS_V_CEILING",
    "ASSUMED_RATED_POWER_W",
    "ASSUMED_COIL_OHMS",
    "DURATION_S_CEILING",
    "MIN_FADE_S",
    "MAX_FADE_S",
]

# Hard ceilings. Assumptions, not measurements: the reference setup drives 8 ohm
# TEAX14C02-8 exciters (de Vlam et al., IEEE ToH 2023) at up to 10 V peak; their power
# rating is taken as 2 W (we could not check a data sheet: an assumption). A lab with
# other actuators changes these constants in code, on purpose, not in a file.
#: The continuous power an exciter is assumed to take, W (assumption, see above).
ASSUMED_RATED_POWER_W = 2.0
#: The coil's impedance the power figures assume, ohm (the TEAX14C02-8 is an 8 ohm part).
ASSUMED_COIL_OHMS = 8.0
#: Largest peak limit any configuration may set, V at the actuator (twice the reference).
PEAK_V_CEILING = 20.0
#: Largest RMS limit over the short window any configuration may set, V at the actuator:
#: twice the assumed rating in power, sqrt(2 * 2 W * 8 ohm) = 5.65685 V, written 5.66 V (a limit
#: set to 5.66 is accepted and taken as this value: :func:`written_ceiling`).
RMS_V_CEILING = math.sqrt(2 * ASSUMED_RATED_POWER_W * ASSUMED_COIL_OHMS)
#: Largest sustained RMS limit (the long window), V: the assumed rating itself, 4 V = 2 W.
SUSTAINED_RMS_V_CEILING = math.sqrt(ASSUMED_RATED_POWER_W * ASSUMED_COIL_OHMS)
#: Resolution of the long window's energy history, s (a conservative bin: see EnergyBudget).
SUSTAINED_BIN_S = 0.01
#: Largest mean voltage over any RMS window, V: a voice coil is not made for DC (it heats
#: without moving, and pushes the cone off centre). Assumption: 0.5 V; the calibration
#: sweeps' means stay under 0.06 V and the taps' under 0.01 V.
DC_V_LIMIT = 0.5
#: Below this frequency a drive is "slow", Hz (the paper's band starts at 10 Hz)...
SLOW_HZ = 10.0
#: ...and may hold at most this RMS there, V. Assumption: 2 V; the default calibration
#: sweeps hold 0.8 V (band from 10 Hz) to 1.4 V (from 5 Hz) below 10 Hz, the taps < 0.01 V.
SLOW_RMS_V_LIMIT = 2.0
#: Longest drive any configuration may allow, s.
DURATION_S_CEILING = 60.0
#: Shortest fade at each end of a drive, s: no drive starts or stops with a step.
MIN_FADE_S = 0.1e-3
#: Longest fade, s (a fade longer than a tap would erase it).
MAX_FADE_S = 50e-3
#: Window of the RMS limit, s: about the thermal time scale of a small voice coil.
RMS_WINDOW_S = 1.0


def written_ceiling(ceiling: float) -> float:
    """A hard ceiling as the docs and messages write it: 3 significant digits (5.66 for 5.65685...).

    A limit set to the ceiling as written is accepted, and taken as the ceiling itself.
    """
    return float(f"{ceiling:.3g}")


@dataclass(frozen=True)
class SafetyLimits:
    """Limits at the actuator terminals.

    Parameters
    ----------
    peak_v : float
        Largest instantaneous voltage magnitude, V, in (0, 20]. Default 10 V: a 1 V DAQ
        output through a 20 dB amplifier (docs/method.md, reference setup).
    rms_v : float
        Largest RMS voltage per channel over any window of ``rms_window_s``, V, in (0, 5.66]
        (the ceiling, sqrt(32) = 5.65685 V; 5.66 as written is taken as it).
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
    sustained_rms_v : float
        Largest RMS voltage per channel over any window of ``sustained_window_s``, V, in
        (0, 4]: the heat a coil pressed against skin builds up over minutes. Default 4 V
        (2 W into 8 ohm, the assumed rating); a lab sets it from its exciters' rating
        and a housing-temperature check (docs/hardware.md).
    sustained_window_s : float
        The long window, s, in [10, 600]; default 60 s.
    """

    peak_v: float = DRIVE_LIMIT_V
    rms_v: float = 4.0
    max_duration_s: float = 30.0
    fade_s: float = 0.5e-3
    rms_window_s: float = RMS_WINDOW_S
    sustained_rms_v: float = SUSTAINED_RMS_V_CEILING
    sustained_window_s: float = 60.0

    def __post_init__(self) -> None:
        for name, ceiling in (("peak_v", PEAK_V_CEILING), ("rms_v", RMS_V_CEILING),
                              ("max_duration_s", DURATION_S_CEILING),
                              ("sustained_rms_v", SUSTAINED_RMS_V_CEILING)):
            value = check_positive(getattr(self, name), name)
            if value > written_ceiling(ceiling):
                raise ValidationError(
                    f"{name} = {value:g} is above the hard ceiling of {ceiling:.3g} that no configuration may "
                    "exceed (docs/hardware.md, limits)")
            # The ceiling as written (5.66 V RMS) is the ceiling itself (5.65685... V).
            object.__setattr__(self, name, min(float(value), ceiling))
        check_in_range(self.fade_s, "fade_s", MIN_FADE_S, MAX_FADE_S)
        check_in_range(self.rms_window_s, "rms_window_s", 0.1, 10.0)
        check_in_range(self.sustained_window_s, "sustained_window_s", 10.0, 600.0)

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
    energy = _window_sums(squares, n_window).max(axis=-1)
    return np.sqrt(np.maximum(energy, 0.0) / n_window)


def _window_sums(values: np.ndarray, span: int) -> np.ndarray:
    """Sums of ``values`` over every window of ``span`` entries along the last axis.

    A signal no longer than the window gives its one total (as followed by silence).
    Shape (..., n - span + 1), or (..., 1).
    """
    n = values.shape[-1]
    csum = np.concatenate([np.zeros(values.shape[:-1] + (1,)), np.cumsum(values, axis=-1)], axis=-1)
    return csum[..., -1:] if n <= span else csum[..., span:] - csum[..., :-span]


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
    n_window = max(1, int(round(limits.rms_window_s * fs)))
    rms = windowed_rms(arr**2, n_window)
    if rms.max() > limits.rms_v * (1 + 1e-9):
        raise SafetyError("drive refused: " + _channel_message(
            rms, limits.rms_v, "V RMS", f" over {limits.rms_window_s:g} s"))
    _check_slow_content(arr, fs, n_window, limits.rms_window_s)
    # At least one sample of fade at each end (ceil: a fade shorter than a sample at a low
    # rate must not round to none), and a drive long enough to hold both fades.
    n_fade = max(1, math.ceil(limits.fade_s * fs - 1e-9))
    if arr.shape[1] < 2 * n_fade:
        raise SafetyError(f"drive refused: {arr.shape[1]} sample(s) cannot hold its fades ({n_fade} sample(s) at "
                          f"each end at {fs:g} Hz); make it at least {2 * n_fade} samples long")
    return apply_fades(arr, fs, n_fade / fs)


def check_sustained_alone(drive: np.ndarray, fs: float, limits: SafetyLimits) -> None:
    """Refuse a drive that breaks the sustained limit played alone, from silence.

    :func:`check_drive` holds every limit a drive has by itself but this one, which
    :class:`EnergyBudget` applies across plays; a drive whose own energy over
    ``limits.sustained_window_s`` exceeds ``limits.sustained_rms_v`` is refused by the
    budget whatever the wait before it. A plan (a study's stimuli) checks each drive with
    :func:`check_drive` and this, so such a drive is refused when it is planned.

    Parameters
    ----------
    drive : ndarray, shape (n_actuators, n_samples)
        Voltages at the actuators, V (e.g. :func:`check_drive`'s faded copy).
    fs : float
        Sample rate, Hz.
    limits : SafetyLimits

    Raises
    ------
    SafetyError
        Over ``limits.sustained_rms_v``, naming the channel and the value.
    """
    arr = np.asarray(drive, dtype=float)
    rms = windowed_rms(arr**2, max(1, int(round(limits.sustained_window_s * fs))))
    if rms.max() > limits.sustained_rms_v * (1 + 1e-9):
        raise SafetyError("drive refused: played alone, " + _channel_message(
            rms, limits.sustained_rms_v, "V RMS", f" over {limits.sustained_window_s:g} s")
            + " (sustained_rms_v); no wait before it would admit it")


def check_on_rig(drives: np.ndarray, rig: Any) -> np.ndarray:
    """Every limit of ``rig`` that a drive has by itself; the faded copy to play.

    The rig's own check (:meth:`~vibrofocus.rigs.Rig.check`: shape, peak, RMS over the
    short window, DC and slow content, the level at its outputs) and the sustained limit
    played alone (:func:`check_sustained_alone`). What the drive adds to the plays before
    it is the energy budget's, when it plays.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n_samples)
        V.
    rig : Rig

    Returns
    -------
    ndarray, shape (n_actuators, n_samples)

    Raises
    ------
    SafetyError
        The first limit it breaks.
    """
    safe = rig.check(drives)
    check_sustained_alone(safe, rig.fs, rig.limits)
    return safe


def _check_slow_content(arr: np.ndarray, fs: float, n_window: int, window_s: float) -> None:
    """Refuse DC and slow drives: a mean over any window above DC_V_LIMIT, or RMS below SLOW_HZ above SLOW_RMS_V_LIMIT."""
    n = arr.shape[1]
    # A drive shorter than the window counts as followed by silence, as for the RMS.
    mean = np.abs(_window_sums(arr, n_window)).max(axis=1) / n_window
    if mean.max() > DC_V_LIMIT:
        raise SafetyError("drive refused: DC, " + _channel_message(
            mean, DC_V_LIMIT, "V", f" mean over {window_s:g} s") + " (a voice coil is not driven with DC)")
    spectrum = np.fft.rfft(arr, axis=1)
    spectrum[:, np.fft.rfftfreq(n, 1 / fs) >= SLOW_HZ] = 0
    slow = np.sqrt(np.mean(np.fft.irfft(spectrum, n, axis=1) ** 2, axis=1))
    if slow.max() > SLOW_RMS_V_LIMIT:
        raise SafetyError("drive refused: " + _channel_message(
            slow, SLOW_RMS_V_LIMIT, "V RMS", f" below {SLOW_HZ:g} Hz") + " (too slow for a vibrotactile actuator)")


class _RmsWindow:
    """One RMS limit over a sliding window, across plays: the energy history of one window.

    The history is kept in bins of ``bin_samples`` samples (1 for the short window: exact).
    With wider bins, a window of ``n_bins`` bins is checked over ``n_bins + 1`` bins
    (any window of the samples lies inside that many bins) and gaps are rounded down: the
    check can only be stricter than the exact one, never looser.
    """

    def __init__(self, rms_v: float, window_s: float, fs: float, n_channels: int, bin_samples: int, label: str):
        self.rms_v, self.window_s, self.label = rms_v, window_s, label
        self.bin = max(1, int(bin_samples))
        self.n_window = max(1, int(round(window_s * fs)))
        self.n_bins = max(1, -(-self.n_window // self.bin))
        self.tail = np.zeros((n_channels, self.n_bins))

    def history(self, squares: np.ndarray, gap_samples: int | None) -> np.ndarray:
        n = squares.shape[1]
        binned = squares if self.bin == 1 else np.pad(
            squares, ((0, 0), (0, (-n) % self.bin))).reshape(len(squares), -1, self.bin).sum(axis=2)
        gap = self.n_bins if gap_samples is None else gap_samples // self.bin
        keep = max(0, self.n_bins - gap)
        return np.concatenate([self.tail[:, self.n_bins - keep:], np.zeros((len(squares), min(gap, self.n_bins))),
                               binned], axis=1)

    def worst_rms(self, history: np.ndarray) -> np.ndarray:
        span = self.n_bins + (1 if self.bin > 1 else 0)
        energy = _window_sums(history, span).max(axis=1)
        return np.sqrt(np.maximum(energy, 0.0) / self.n_window)

    def commit(self, history: np.ndarray) -> None:
        self.tail = history[:, -self.n_bins:] if history.shape[1] >= self.n_bins else np.concatenate(
            [np.zeros((len(history), self.n_bins - history.shape[1])), history], axis=1)


class EnergyBudget:
    """The RMS limits across consecutive plays of one rig (thread-safe).

    Keeps the squared drive of the last ``rms_window_s`` seconds (exactly, at the drive's
    sample rate) and of the last ``sustained_window_s`` seconds (in 10 ms bins, checked
    conservatively), with the time the last play ends. A new drive is admitted only if no
    window over what was played before and the new drive, placed at the time it starts,
    holds more than ``rms_v`` RMS (short window) or ``sustained_rms_v`` RMS (long window)
    on any channel.

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
        self._windows = (
            _RmsWindow(limits.rms_v, limits.rms_window_s, self.fs, n_channels, 1, "rms_v"),
            _RmsWindow(limits.sustained_rms_v, limits.sustained_window_s, self.fs, n_channels,
                       int(round(SUSTAINED_BIN_S * self.fs)), "sustained_rms_v"),
        )
        self.n_window = self._windows[0].n_window
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
        CoolingError
            If it would exceed an RMS limit together with the plays before it; the
            budget is then left as it was, and ``wait_s`` says how long to wait.
        SafetyError
            If it exceeds an RMS limit played alone, from silence: no wait would admit it.
        """
        squares = drive**2
        with self._lock:
            measured = self._measure(squares, start_s)
            for window, history, rms in measured:
                if rms.max() > window.rms_v * (1 + 1e-9):
                    over = _channel_message(rms, window.rms_v, "V RMS", f" over {window.window_s:g} s")
                    alone = window.worst_rms(window.history(squares, None))
                    if alone.max() > window.rms_v * (1 + 1e-9):
                        raise SafetyError(
                            "drive refused: played alone, " + _channel_message(
                                alone, window.rms_v, "V RMS", f" over {window.window_s:g} s")
                            + f" ({window.label}); no wait will ever admit it: lower its level or shorten it")
                    wait = window.window_s if self._end_s is None else max(
                        0.0, self._end_s + window.window_s - start_s)
                    raise CoolingError(
                        f"drive refused: together with the plays before it, {over} ({window.label}); wait "
                        f"{wait:.1f} s for the actuators to cool, or play less", wait_s=wait)
            self._commit(measured, drive.shape[1], start_s)

    def record(self, drive: np.ndarray, start_s: float) -> np.ndarray:
        """Record a drive whatever its level; return the worst RMS it makes in each window.

        What a plan uses (:func:`plan_levels`): it never refuses.

        Parameters
        ----------
        drive : ndarray, shape (n_channels, n_samples)
            Voltages, V.
        start_s : float
            When it starts, s, on the budget's clock.

        Returns
        -------
        ndarray, shape (2,)
            The largest RMS over any channel in the short window (``rms_window_s``) and in
            the long one (``sustained_window_s``), V.
        """
        with self._lock:
            measured = self._measure(np.asarray(drive, dtype=float) ** 2, start_s)
            self._commit(measured, drive.shape[1], start_s)
        return np.array([float(rms.max()) for _, _, rms in measured])

    @property
    def end_s(self) -> float | None:
        """When the last play admitted ends, s, on the budget's clock; None before the first."""
        return self._end_s

    def _measure(self, squares: np.ndarray, start_s: float) -> list:
        """Each window's history with ``squares`` placed at ``start_s``, and its worst RMS per channel."""
        gap = None if self._end_s is None else int(np.floor(max(0.0, start_s - self._end_s) * self.fs))
        out = []
        for window in self._windows:
            history = window.history(squares, gap)
            out.append((window, history, window.worst_rms(history)))
        return out

    def _commit(self, measured: list, n_samples: int, start_s: float) -> None:
        for window, history, _ in measured:
            window.commit(history)
        begin = start_s if self._end_s is None else max(start_s, self._end_s)
        self._end_s = begin + n_samples / self.fs

    def delay_last(self, delay_s: float) -> None:
        """The last admitted play began ``delay_s`` later than it was admitted at: end it as much later.

        What the plays after it are placed against moves later; the history keeps it where
        it was admitted, nearer the plays before it, which can only make the check stricter.

        Parameters
        ----------
        delay_s : float
            How much later it began, s (>= 0; a negative delay is ignored).
        """
        with self._lock:
            if self._end_s is not None and delay_s > 0:
                self._end_s += float(delay_s)


@dataclass(frozen=True)
class PlanLevels:
    """The levels a sequence of plays reaches, against a rig's limits (:func:`plan_levels`).

    Attributes
    ----------
    peak_v, rms_v, sustained_rms_v : float
        Largest instantaneous voltage, RMS over ``limits.rms_window_s`` and RMS over
        ``limits.sustained_window_s`` on any channel, V.
    limits : SafetyLimits
    pause_s : float
        The silence between plays assumed, s.
    """

    peak_v: float
    rms_v: float
    sustained_rms_v: float
    limits: SafetyLimits
    pause_s: float = 0.0

    def ratios(self) -> dict[str, float]:
        """Each level over its limit (1 is at the limit), keyed by the limit's name."""
        lim = self.limits
        return {"peak_v": self.peak_v / lim.peak_v, "rms_v": self.rms_v / lim.rms_v,
                "sustained_rms_v": self.sustained_rms_v / lim.sustained_rms_v}

    @property
    def fits(self) -> bool:
        """Every level within its limit."""
        return max(self.ratios().values()) <= 1 + 1e-9

    @property
    def scale_to_fit(self) -> float:
        """The largest factor on every drive's level (<= 1) that fits, rounded down to 3 digits."""
        worst = max(self.ratios().values())
        if worst <= 1 + 1e-9:
            return 1.0
        return math.floor(1e3 / worst) / 1e3

    def broken(self) -> str:
        """The limits broken, as people read them ("" when it fits)."""
        lim, parts = self.limits, []
        for name, value, window in (("peak_v", self.peak_v, ""), ("rms_v", self.rms_v, f" RMS over {lim.rms_window_s:g} s"),
                                    ("sustained_rms_v", self.sustained_rms_v,
                                     f" RMS over {lim.sustained_window_s:g} s")):
            if self.ratios()[name] > 1 + 1e-9:
                limit = getattr(lim, name)
                parts.append(f"{value:.3g} V{window or ' peak'}, over {name} = {limit:g} V")
        return "; ".join(parts)


def plan_levels(drives: Sequence[np.ndarray], fs: float, limits: SafetyLimits, *, pause_s: float = 0.0) -> PlanLevels:
    """The peak, 1 s RMS and sustained RMS of drives played one after the other.

    The drives are placed back to back with ``pause_s`` of silence between them (a rig
    cannot play them closer), through an :class:`EnergyBudget` of ``limits``: the same
    windows and the same sums the rig's budget applies when they play.

    Parameters
    ----------
    drives : sequence of ndarray, shape (n_channels, n_samples)
        The plays in order, V (the same array may appear many times).
    fs : float
        Sample rate, Hz.
    limits : SafetyLimits
    pause_s : float
        Silence after each play, s.

    Returns
    -------
    PlanLevels
    """
    check_positive(pause_s, "pause_s", allow_zero=True)
    if not drives:
        raise ValidationError("plan_levels needs at least one drive")
    budget = EnergyBudget(limits, np.shape(drives[0])[0], fs)
    peak, worst = 0.0, np.zeros(2)
    start = 0.0
    for drive in drives:
        drive = np.asarray(drive, dtype=float)
        peak = max(peak, float(np.abs(drive).max()))
        worst = np.maximum(worst, budget.record(drive, start))
        start = budget.end_s + pause_s
    return PlanLevels(peak, float(worst[0]), float(worst[1]), limits, float(pause_s))


def plan_pause_s(drives: Sequence[np.ndarray], fs: float, limits: SafetyLimits, *,
                 resolution_s: float = 0.1) -> float | None:
    """The shortest pause between plays (to ``resolution_s``, rounded up) for which they fit the RMS limits.

    Parameters
    ----------
    drives : sequence of ndarray, shape (n_channels, n_samples)
        The plays in order, V.
    fs : float
        Sample rate, Hz.
    limits : SafetyLimits
    resolution_s : float
        Step of the pause searched, s.

    Returns
    -------
    float or None
        0 when they fit back to back; None when no pause makes them fit (a play alone
        breaks a limit).
    """
    if plan_levels(drives, fs, limits).fits:
        return 0.0
    lo, hi = 0, int(math.ceil((limits.sustained_window_s + limits.rms_window_s) / resolution_s))
    if not plan_levels(drives, fs, limits, pause_s=hi * resolution_s).fits:
        return None
    while hi - lo > 1:  # lo does not fit, hi fits: the levels only fall as the pause grows
        mid = (lo + hi) // 2
        if plan_levels(drives, fs, limits, pause_s=mid * resolution_s).fits:
            hi = mid
        else:
            lo = mid
    return hi * resolution_s


#: Most waits :func:`play_paced` makes for one drive (the first wait named suffices).
MAX_COOLING_WAITS = 3


def play_paced(rig: Any, drive: np.ndarray, on_wait: Callable[[float, str], None] | None = None, *,
               sleep: Callable[[float], None] | None = None) -> Any:
    """``rig.play(drive)``; when a limit over time refuses it, wait the time it names and play it then.

    A drive that breaks a limit played alone is refused at once (no wait would admit it),
    and a ``rig.stop()`` during the wait ends it (:class:`~vibrofocus.rigs.devices.StoppedError`):
    the drive is never played after a stop.

    Parameters
    ----------
    rig : Rig
        The rig that plays.
    drive : ndarray, shape (n_actuators, n_samples)
        Voltages at the actuators, V.
    on_wait : callable ``(wait_s: float, message: str) -> None``, optional
        Told before each wait (the refusal's message and the wait, s).
    sleep : callable, optional
        Waits a number of seconds (default :func:`time.sleep`; a test's clock).

    Returns
    -------
    What ``rig.play`` returns (a :class:`~vibrofocus.rigs.base.DeviceOnset`).
    """
    from .devices import StoppedError

    sleep = time.sleep if sleep is None else sleep
    for attempt in range(MAX_COOLING_WAITS + 1):
        try:
            return rig.play(drive)
        except CoolingError as exc:
            if attempt == MAX_COOLING_WAITS:
                raise
            if on_wait is not None:
                on_wait(exc.wait_s, str(exc))
            epoch, left = rig._stop_epoch, exc.wait_s
            while left > 0:
                sleep(min(0.05, left))
                left -= 0.05
                if rig._stop_epoch != epoch:
                    raise StoppedError("play") from None
