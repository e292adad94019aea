"""The combination method (docs/method.md, "Rendering methods"): an inverse filter whose target waveform is what
funneling would produce at the target, predicted through ``H``."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_index, check_positive
from ..defaults import BAND_HZ
from ..errors import ValidationError
from ._checks import as_transfer, check_grid
from .taper import design_grid

__all__ = ["combination_target"]


@fill_doc
def combination_target(
    H: Any,
    target_index: int,
    gains: Any,
    stimulus: Any,
    fs: float,
    *,
    band: tuple[float, float] | None = BAND_HZ,
    taper_octaves: float = 0.5,
) -> np.ndarray:
    """Band-limited displacement funneling would produce at one point.

    ``u_t = irfft(T(f) sum_q H_tq(f) A_q S(f))`` with ``S`` the spectrum of the stimulus
    every actuator plays (scaled by its gain ``A_q``) and ``T`` the band taper. Use it
    as the target row of an inverse filter, with zeros at the guards.

    Parameters
    ----------
    %(H)s
    target_index : int
        Row of ``H`` of the target point.
    gains : ndarray, shape (n_actuators,)
        Funneling amplitudes ``A_q``, V (see :func:`funneling_gains`).
    stimulus : ndarray, shape (n,)
        Base stimulus, unit peak (see :func:`~vibrofocus.signals.ricker`).
    %(fs)s
    band, taper_octaves
        As in :func:`inverse_filter`; ``band=None`` skips the band limit (``T = 1``), for
        callers whose design applies the taper itself (:class:`InverseOperator` does).

    Returns
    -------
    ndarray, shape (n,)
        Target displacement, m.

    Raises
    ------
    ValidationError
        If the predicted funneling displacement at the target is zero (nothing to render).
    """
    H = as_transfer(H)
    fs = check_positive(fs, "fs")
    target_index = check_index(target_index, "target_index", H.shape[1], what="points of H")
    gains = as_array(gains, "gains", ndim=1, shape=(H.shape[2],))
    stimulus = as_array(stimulus, "stimulus", ndim=1)
    check_grid(H.shape[0], stimulus.size, "stimulus (n,)")
    if band is None:
        taper = 1.0
    else:
        taper = design_grid(stimulus.size, fs, check_band(band, fs),
                            check_positive(taper_octaves, "taper_octaves", allow_zero=True))[1]
    spectrum = (H[:, target_index, :] @ gains) * np.fft.rfft(stimulus) * taper
    target = np.fft.irfft(spectrum, stimulus.size)
    if not np.any(np.abs(target) > 0):
        raise ValidationError(
            f"funneling predicts no displacement at point {target_index} inside the band "
            "(zero gains, silent stimulus or H zero there): the combination has no target waveform"
        )
    return target
