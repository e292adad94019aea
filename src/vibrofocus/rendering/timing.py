"""When a transfer matrix's waves arrive and when they have died away: :func:`response_timing`.

The design defaults that depend on the setup come from here, not from the reference
setup's numbers: the minimax drives' support (they must start at least as long before the
tap as the waves take to reach it) and the design window (long enough for the responses'
ring-down on both sides of a tap set mid-window).

Both times are read from the band-limited impulse responses ``irfft(T H)`` (``T`` the
designs' band taper) through their cumulative energy: the **arrival** is where an impulse
response has gathered ``onset`` of its energy, the **ring-down** where all but ``tol`` of
it has come. The band taper is zero phase, so its pulse rings a little before ``t = 0``:
on the circular window those samples sit at its end; the last eighth of the window counts
as negative time here (as in :func:`~vibrofocus.rendering.minimax_filter`'s
``ir_tail_energy``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import check_in_range, check_positive
from ..defaults import BAND_HZ
from ._checks import as_transfer
from .inverse import _prepare_design

__all__ = ["ResponseTiming", "response_timing", "DEFAULT_SUPPORT_S"]

#: The minimax drives' support of the reference setup, s before and after the tap: the
#: least a default support from H may be (its designs stay as they were).
DEFAULT_SUPPORT_S = (0.01, 0.005)


@dataclass(frozen=True)
class ResponseTiming:
    """Arrival and ring-down of every impulse response of a transfer matrix.

    Attributes
    ----------
    arrival_s : ndarray, shape (n_points, n_actuators)
        Time at which each band-limited impulse response has gathered ``onset`` of its
        energy, s (0 or more): where its wave arrives.
    centre_s : ndarray, shape (n_points, n_actuators)
        Time at which it has gathered half its energy, s: its energy's group delay.
    ringdown_s : ndarray, shape (n_points, n_actuators)
        Time after which at most ``tol`` of its energy is left, s.
    fs : float
        Sample rate, Hz.
    n_samples : int
        Window the times were read on, samples (no time exceeds it).
    onset, tol : float
        The energy shares that define the arrival and the ring-down.
    """

    arrival_s: np.ndarray
    centre_s: np.ndarray
    ringdown_s: np.ndarray
    fs: float
    n_samples: int
    onset: float
    tol: float

    def support_s(self, target_index: int, *, least: tuple[float, float] = DEFAULT_SUPPORT_S) -> tuple[float, float]:
        """The minimax drives' default support around a tap at one point, s.

        Before the tap: twice the latest arrival of an actuator's wave at the target
        (``arrival_s``), so that every actuator's wave reaches the target with room to
        shape it, rounded to a millisecond and at least ``least[0]``. After the tap:
        ``least[1]``.

        Parameters
        ----------
        target_index : int
            Row of the target point.
        least : (float, float)
            The shortest support, s before and after the tap (the reference setup's).

        Returns
        -------
        (float, float)
            Seconds before and after the tap.
        """
        pre = np.round(2.0 * float(np.max(self.arrival_s[int(target_index)])), 3)
        return (max(float(least[0]), float(pre)), float(least[1]))

    def window(self, minimum: int = 16) -> int:
        """A design window for these responses, samples.

        The tap sits mid-window: before it the inverse drives' pre-ringing, after it the
        ring-down, each about as long as the latest ring-down. The window is four times
        that, rounded up to a power of two, and at least ``minimum``.

        Parameters
        ----------
        minimum : int
            Shortest window, samples.
        """
        need = 4 * float(np.max(self.ringdown_s)) * self.fs
        return int(max(int(minimum), 2 ** int(np.ceil(np.log2(max(need, 2.0))))))


@fill_doc
def response_timing(H: Any, fs: float, *, band: tuple[float, float] = BAND_HZ, taper_octaves: float = 0.5,
                    onset: float = 0.01, tol: float = 1e-4) -> ResponseTiming:
    """Arrival, energy group delay and ring-down of each impulse response of ``H``.

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)`` (m/V), or a
        :class:`~vibrofocus.rendering.TransferMatrix`.
    %(fs)s
    band : (float, float)
        Design band, Hz: the impulse responses are band-limited with the designs' taper.
    taper_octaves : float
        Taper roll-off outside each band edge, octaves.
    onset : float
        Share of each response's energy gathered at its arrival, in (0, 0.5).
    tol : float
        Share of each response's energy left after its ring-down, in (0, 0.5).

    Returns
    -------
    ResponseTiming
        Times in s, shape (n_points, n_actuators) each. A response with no energy in the
        band arrives and rings down at 0 s.
    """
    onset = check_in_range(onset, "onset", 0.0, 0.5, inclusive=False)
    tol = check_in_range(tol, "tol", 0.0, 0.5, inclusive=False)
    n = getattr(H, "n_samples", None)
    H = as_transfer(getattr(H, "H", H))
    H, fs, n, band, taper, _, _ = _prepare_design(H, check_positive(fs, "fs"), n, band, taper_octaves)
    g = np.fft.irfft(H * taper[:, None, None], n, axis=0)  # (n, n_points, n_actuators)
    lead = n // 8  # the taper's pulse rings before t = 0: the window's last eighth is negative time
    g = np.roll(g, lead, axis=0)
    energy = np.cumsum(g**2, axis=0)
    total = energy[-1]
    safe = np.where(total > 0, total, 1.0)
    share = energy / safe

    def first_at(level: float) -> np.ndarray:
        idx = np.argmax(share >= level, axis=0)
        return np.where(total > 0, np.maximum(idx - lead, 0) / fs, 0.0)

    return ResponseTiming(arrival_s=first_at(onset), centre_s=first_at(0.5), ringdown_s=first_at(1 - tol),
                          fs=float(fs), n_samples=int(n), onset=float(onset), tol=float(tol))
