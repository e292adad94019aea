"""Calibration excitations: the sweeps the actuators play while the skin is recorded.

Three methods (docs/method.md, calibration):

``"h1"`` (default)
    An exponential sine sweep that covers the calibrated band with half an octave of
    margin on each side (so the band edges are not where the sweep starts and stops),
    played ``repeats`` times; the transfer function is the H1 estimate averaged over the
    repeats, with coherence per frequency.
``"paper"``
    The method of the paper vibrofocus follows: one linear sine sweep over exactly the
    band, the transfer function being the FFT of the response divided by the FFT of the
    drive.
``"mimo"``
    All actuators play at once. Every take plays the same exponential sweep as ``h1`` on
    every actuator, each with its own sign from a Hadamard code (:func:`hadamard_codes`):
    over a block of takes the actuators' drives are exactly uncorrelated, so the MIMO H1
    estimator (:func:`vibrofocus.calibration.estimate.mimo_h1`) separates their
    contributions exactly, while every take excites every actuator. For the same
    number of repeats this measures ``n_actuators`` pairs in the time of one.

Every drive starts with ``pre_s`` of silence: the recording over that stretch holds only
sensor noise (the skin cannot respond before it is driven), which gives the noise floor
for the SNR verdicts.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._docs import fill_doc
from .._validation import check_band, check_choice, check_positive
from ..errors import ValidationError
from ..signals import exponential_sweep, linear_sweep

__all__ = ["METHODS", "SweepSettings", "default_settings", "make_excitation", "hadamard_codes"]

#: Estimation methods of :func:`vibrofocus.calibration.calibrate`.
METHODS = ("h1", "paper", "mimo")

#: Default repeats per method (recordings of each point in which each actuator plays).
DEFAULT_REPEATS = {"h1": 8, "paper": 1, "mimo": 8}
#: Default sweep length per method, s. ``mimo`` spends part of the time it saves on
#: longer sweeps: 8 takes of 2.5 s give every actuator 25 % more sweep than ``h1``'s
#: 8 x 2 s, in 30 % of its time with four actuators (benchmarks/bench_mimo_calibration.py).
DEFAULT_SWEEP_S = {"h1": 2.0, "paper": 2.0, "mimo": 2.5}

#: Margin of the exponential sweep beyond each band edge, octaves.
_MARGIN_OCTAVES = 0.5


@dataclass(frozen=True)
@fill_doc
class SweepSettings:
    """Everything that defines the excitation of one calibration.

    Parameters
    ----------
    method : {"h1", "paper", "mimo"}
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
        Recordings of each point in which each actuator plays: per actuator for
        ``h1``/``paper`` (one actuator per take), for all actuators at once for ``mimo``.
    pre_s : float
        Silence before the sweep, s (noise floor).
    tail_s : float
        Recording after the drive ends, s (decay of the response).
    fade_s : float
        Raised-cosine fade at both sweep ends, s.
    %(fs)s
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

    @property
    def take_s(self) -> float:
        """Real duration of one take (silence, sweep and the recorded tail), s."""
        return (self.n_drive + self.n_tail) / self.fs

    def to_dict(self) -> dict:
        """JSON-serialisable form."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "SweepSettings":
        """Inverse of :meth:`to_dict`."""
        return cls(**data)


@fill_doc
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
    method : {"h1", "paper", "mimo"}
    %(fs)s
    band : (float, float)
        Calibrated band, Hz.
    sweep_s : float, optional
        Sweep duration, s. Default 2 s (``h1``, ``paper``) or 2.5 s (``mimo``).
    repeats : int, optional
        Default 8 (``h1``, ``mimo``) or 1 (``paper``: one sweep, as in the paper). For
        ``mimo`` a multiple of the Hadamard block (:func:`hadamard_codes`): 4 for 3 or 4
        actuators, 8 for 5 to 8, ...
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
    if method in ("h1", "mimo"):
        f_start = low * 2.0 ** -_MARGIN_OCTAVES
        # Stay clear of Nyquist: the sweep's top must be a tone the DAC can render.
        f_stop = min(high * 2.0**_MARGIN_OCTAVES, 0.45 * fs)
        f_stop = max(f_stop, high)
        kind = "exponential"
    else:
        f_start, f_stop, kind = low, high, "linear"
    sweep_s = DEFAULT_SWEEP_S[method] if sweep_s is None else sweep_s
    repeats = DEFAULT_REPEATS[method] if repeats is None else repeats
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


def hadamard_codes(n_actuators: int, repeats: int) -> np.ndarray:
    """Signs of each actuator's sweep in each take of a ``mimo`` calibration.

    The columns come from a Sylvester Hadamard matrix of order ``K``, the largest power
    of two dividing ``repeats``; the block of ``K`` takes is played ``repeats / K``
    times. When ``K > n_actuators`` the all-ones column is skipped, so every actuator's
    signs sum to zero (a response common to all takes, e.g. a drift, cancels from every
    estimate). Any two columns are orthogonal: ``codes.T @ codes = repeats * I``, the
    drives are exactly uncorrelated and the input spectral matrix of the MIMO H1
    estimate is ``repeats |X(f)|^2 I`` (condition number 1).

    Parameters
    ----------
    n_actuators : int
        Actuators playing at once (>= 1).
    repeats : int
        Takes; a multiple of the smallest power of two >= ``n_actuators``.

    Returns
    -------
    ndarray of int8, shape (repeats, n_actuators)
        +1 or -1.

    Raises
    ------
    ValidationError
        ``repeats`` too small or not a multiple of the block.
    """
    for value, name in ((n_actuators, "n_actuators"), (repeats, "repeats")):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValidationError(f"{name} must be a positive integer, got {value!r}")
    block = 1 << max(int(n_actuators) - 1, 0).bit_length()  # smallest power of two >= n_actuators
    if repeats % block:
        lower, upper = (repeats // block) * block, (repeats // block + 1) * block
        hint = f"{lower} or {upper}" if lower else f"{upper}"
        raise ValidationError(
            f"repeats={repeats} cannot separate {n_actuators} actuators playing at once: the mimo method "
            f"needs a multiple of {block} takes (Hadamard codes); use {hint}"
        )
    order = repeats & -repeats  # largest power of two dividing repeats
    sylvester = np.ones((1, 1), dtype=np.int8)
    while sylvester.shape[0] < order:
        sylvester = np.block([[sylvester, sylvester], [sylvester, -sylvester]])
    first = 1 if order > n_actuators else 0
    return np.tile(sylvester[:, first:first + n_actuators], (repeats // order, 1))
