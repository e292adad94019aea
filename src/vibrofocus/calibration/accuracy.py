"""How close a measured transfer matrix is to a known one (simulator checks, benchmarks)."""

from __future__ import annotations

import numpy as np

from .._validation import as_array, check_positive
from ..errors import ValidationError

__all__ = ["transfer_error"]


def transfer_error(measured: np.ndarray, truth: np.ndarray, *, dynamic_range_db: float = 40.0) -> dict:
    """Median relative error of a measured transfer where the true response is measurable.

    Realistic skin damps a 1 kHz wave by tens of dB over a few centimetres, so far from an
    actuator the true response falls below any vibrometer's noise and no method can
    measure it; a median over every bin would mostly count those. This compares only the
    bins whose true magnitude is within ``dynamic_range_db`` of the largest magnitude of
    the same (point, actuator) pair over frequency, and reports how many bins that is.

    Parameters
    ----------
    measured, truth : ndarray, complex, shape (n_freqs, n_points, n_actuators)
        The estimate and the true transfer on the same frequencies, m/V.
    dynamic_range_db : float
        Bins more than this below their pair's peak are left out, dB.

    Returns
    -------
    dict
        ``median_relative_error`` (``|measured - truth| / |truth|``, median over the kept
        bins), ``coverage`` (share of bins kept, 0-1) and ``dynamic_range_db``.
    """
    h = as_array(measured, "measured", ndim=3, dtype="complex")
    t = as_array(truth, "truth", ndim=3, shape=h.shape, dtype="complex")
    check_positive(dynamic_range_db, "dynamic_range_db")
    mag = np.abs(t)
    keep = mag >= mag.max(axis=0, keepdims=True) * 10 ** (-dynamic_range_db / 20)
    keep &= mag > 0
    if not keep.any():
        raise ValidationError("truth is zero at every bin: nothing to compare")
    rel = np.abs(h[keep] - t[keep]) / mag[keep]
    return {"median_relative_error": float(np.median(rel)), "coverage": float(keep.mean()),
            "dynamic_range_db": float(dynamic_range_db)}
