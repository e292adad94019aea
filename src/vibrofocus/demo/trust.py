"""Where a calibration of the simulated forearm can be trusted: its coherent band and H error."""

from __future__ import annotations

import numpy as np

from ..defaults import SIGMA_S

__all__ = ["tap_band", "calibration_trust"]


def tap_band(sigma: float = SIGMA_S, dynamic_range_db: float = 20.0) -> tuple[float, float]:
    """Band (Hz) where the base tap's spectrum is within ``dynamic_range_db`` of its peak.

    The zero-mean Ricker of spread ``sigma`` has the amplitude spectrum
    ``f^2 exp(-(2 pi f sigma)^2 / 2)`` (up to a constant), which peaks at
    ``1 / (sqrt(2) pi sigma)`` (about 225 Hz for 1 ms).

    Parameters
    ----------
    sigma : float
        Ricker spread, s.
    dynamic_range_db : float
        How far under its peak the spectrum may fall inside the band, dB.

    Returns
    -------
    (float, float)
        Lowest and highest frequency of the band, Hz (on a grid of ``0.5e-3 / sigma`` Hz).
    """
    f = np.linspace(1.0, 10.0 / sigma, 20001)
    spec = f**2 * np.exp(-((2 * np.pi * f * sigma) ** 2) / 2)
    keep = f[spec >= spec.max() * 10 ** (-dynamic_range_db / 20)]
    return float(keep.min()), float(keep.max())


def _longest_run(mask: np.ndarray) -> tuple[int, int] | None:
    """First and last index of the longest run of True, or None."""
    if not mask.any():
        return None
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])


def calibration_trust(calibration, truth: np.ndarray, *, min_coherence: float | None = None) -> dict:
    """The calibrated band over which every point is coherent, and the H error in and out of it.

    Parameters
    ----------
    calibration : vibrofocus.calibration.Calibration
        A measured calibration (``freqs``, ``band``, ``coherence`` and, for ``mimo``,
        ``multiple_coherence``).
    truth : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        The true transfer on ``calibration.freqs`` (a simulator knows it), m/V.
    min_coherence : float, optional
        Coherence a bin needs at every point (multiple coherence for ``mimo``, the
        least over actuators otherwise); default
        :data:`~vibrofocus.calibration.quality.TRUSTED_COHERENCE` (0.9).

    Returns
    -------
    dict
        ``coherent_band_hz`` ((low, high) or None: the longest run of such bins inside
        the calibrated band), ``tap_band_hz`` (:func:`tap_band`), ``covers_tap_band``,
        ``error_inside`` and ``error_outside`` (median relative H error, NaN where no
        bins), ``min_coherence``.
    """
    from ..calibration import TRUSTED_COHERENCE, transfer_error

    if min_coherence is None:
        min_coherence = TRUSTED_COHERENCE

    f = np.asarray(calibration.freqs, dtype=float)
    low, high = calibration.band
    in_band = (f >= low) & (f <= high)
    coh = calibration.multiple_coherence
    coh = np.asarray(calibration.coherence).min(axis=2) if coh is None else np.asarray(coh)
    good = in_band & np.all(coh >= min_coherence, axis=1)
    run = _longest_run(good)
    inside = np.zeros_like(good)
    if run is not None:
        inside[run[0]:run[1] + 1] = True
    outside = in_band & ~inside

    def error(mask: np.ndarray) -> float:
        if not mask.any():
            return float("nan")
        return float(transfer_error(np.asarray(calibration.H)[mask], truth[mask])["median_relative_error"])

    band = None if run is None else (float(f[run[0]]), float(f[run[1]]))
    tap = tap_band()
    return {
        "coherent_band_hz": band,
        "tap_band_hz": tap,
        "covers_tap_band": bool(band is not None and band[0] <= tap[0] and band[1] >= tap[1]),
        "error_inside": error(inside),
        "error_outside": error(outside),
        "min_coherence": float(min_coherence),
    }
