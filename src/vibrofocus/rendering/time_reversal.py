"""Time reversal (docs/method.md, "Rendering methods"): ``S(f) = H_c(f)^H U_c(f)``, normalized to the drive limit."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_positive
from ..defaults import BAND_HZ
from ..errors import ValidationError
from ._checks import as_transfer, check_grid
from .inverse import scale_to_peak
from .taper import design_grid

__all__ = ["time_reversal_drives"]


@fill_doc
def time_reversal_drives(
    H: Any,
    targets: Any,
    fs: float,
    *,
    max_drive: float | None = None,
    band: tuple[float, float] = BAND_HZ,
    taper_octaves: float = 0.5,
) -> np.ndarray:
    """Time-reversal drives ``irfft(T(f) H(f)^H U(f))``.

    For a single non-zero target this is each actuator playing the time-reversed impulse
    response to the target, convolved with the target waveform: the classic focusing by
    phase conjugation, with no inversion of ``H`` (so no control of the other points).

    Parameters
    ----------
    %(H)s
    targets : ndarray, real, shape (n_points, n)
        Desired displacements at the points of ``H`` (zeros for quiet points).
    %(fs)s
    max_drive : float, optional
        If given, the drives are scaled so that their peak equals it (V); else they are
        returned in the unit of ``H^H U``.
    band, taper_octaves
        As in :func:`inverse_filter`.

    Returns
    -------
    ndarray, real, shape (n_actuators, n)
    """
    H = as_transfer(H)
    fs = check_positive(fs, "fs")
    targets = as_array(targets, "targets", ndim=2)
    check_grid(H.shape[0], targets.shape[1], "targets (n_points, n)")
    if targets.shape[0] != H.shape[1]:
        raise ValidationError(f"targets has {targets.shape[0]} rows but H has {H.shape[1]} points")
    n = targets.shape[1]
    taper = design_grid(n, fs, check_band(band, fs), check_positive(taper_octaves, "taper_octaves", allow_zero=True))[1]
    rhs = np.fft.rfft(targets, axis=-1).T * taper[:, None]  # (F, n_points)
    spectra = np.conj((np.conj(rhs)[:, None, :] @ H)[:, 0, :])  # H^H u per frequency
    drives = np.fft.irfft(spectra, n, axis=0).T
    if max_drive is not None:
        max_drive = check_positive(max_drive, "max_drive")
        peak = np.max(np.abs(drives))
        if peak == 0:
            raise ValidationError("time reversal gives silent drives (targets zero in band, or H zero there)")
        drives = scale_to_peak(drives, max_drive)
    return drives
