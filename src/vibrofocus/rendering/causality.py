"""Wrap-around (causality) check of a frequency-domain design.

A drive designed per frequency on an ``n``-point FFT grid reproduces its target under
*circular* convolution with the medium. Played once from silence, the medium convolves
it *linearly*: whatever the circular design folded back from past the window's end (the
medium's ring-down of a late target, or the acausal pre-ringing of a drive that wrapped
to the window's end) then appears after the window instead of inside it. The design is
only valid when that spill-over is negligible.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.fft

from .._validation import as_array, check_choice, check_in_range
from ..errors import CausalityError, ValidationError

__all__ = ["wraparound_fraction", "check_wraparound", "CausalityWarning", "DEFAULT_WRAPAROUND_TOL"]

#: Largest tolerated share of the response energy that falls past the window (-30 dB).
DEFAULT_WRAPAROUND_TOL = 1e-3
#: Memory budget of one chunk of zero-padded transfer functions, bytes.
_CHUNK_BYTES = 64 * 2**20


class CausalityWarning(UserWarning):
    """The design window is too short (issued instead of CausalityError on request)."""


def wraparound_fraction(drives: np.ndarray, H: np.ndarray) -> float:
    """Share of the response energy that a single playback puts past the window's end.

    The drives are played once from silence through the linear medium whose impulse
    responses are ``irfft(H, n)``; the response is computed by linear convolution (FFT of
    length ``2 n``, i.e. zero-padded, no wrap-around).

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n)
        Drive signals, in the input unit of ``H`` (V).
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)``.

    Returns
    -------
    float
        ``sum_p sum_{k >= n} y_p[k]^2 / sum_p sum_k y_p[k]^2`` in [0, 1]; 0 for a silent
        response. Values above about 1e-3 mean the window is too short for this design.

    Notes
    -----
    The impulse responses are those ``H`` implies on the ``n``-point grid. A medium whose
    true impulse response is longer than the window is already time-aliased in ``H`` and
    cannot be detected here; sample ``H`` on a long enough grid.
    """
    drives = as_array(drives, "drives", ndim=2)
    H = as_array(H, "H", ndim=3, dtype="complex")
    n = drives.shape[1]
    if H.shape[0] != n // 2 + 1 or H.shape[2] != drives.shape[0]:
        raise ValidationError(
            f"H must have shape (n // 2 + 1, n_points, n_actuators) = ({n // 2 + 1}, any, {drives.shape[0]}) "
            f"to match drives of shape {drives.shape}, got {H.shape}"
        )
    n_points = H.shape[1]
    n_fft = 2 * n
    # Single precision is ample for an energy share compared with ~1e-3 and halves the
    # cost of transforming every path's impulse response.
    drive_spectra = scipy.fft.rfft(drives.astype(np.float32), n_fft, axis=-1).T  # (n+1, n_act)
    per_point = max(1, _CHUNK_BYTES // (8 * (n + 1) * max(H.shape[2], 1)))
    tail = 0.0
    total = 0.0
    for start in range(0, n_points, per_point):  # chunks of points bound the memory
        chunk = H[:, start:start + per_point, :].astype(np.complex64)
        impulse = scipy.fft.irfft(chunk, n, axis=0)
        padded = scipy.fft.rfft(impulse, n_fft, axis=0)  # (n+1, chunk, n_act)
        response = scipy.fft.irfft((padded @ drive_spectra[:, :, None])[:, :, 0], n_fft, axis=0)
        tail += float(np.sum(np.square(response[n:], dtype=np.float64)))
        total += float(np.sum(np.square(response, dtype=np.float64)))
    return tail / total if total > 0 else 0.0


def check_wraparound(
    drives: np.ndarray,
    H: np.ndarray,
    *,
    tol: float = DEFAULT_WRAPAROUND_TOL,
    action: str = "raise",
) -> float:
    """Raise :class:`~vibrofocus.errors.CausalityError` (or warn) if the window is too short.

    Parameters
    ----------
    drives, H
        As in :func:`wraparound_fraction`.
    tol : float
        Largest tolerated :func:`wraparound_fraction`, in (0, 1).
    action : {"raise", "warn"}
        Raise CausalityError or issue a :class:`CausalityWarning`.

    Returns
    -------
    float
        The wrap-around fraction.
    """
    check_choice(action, "action", ("raise", "warn"))
    tol = check_in_range(tol, "tol", 0.0, 1.0, inclusive=False)
    fraction = wraparound_fraction(drives, H)
    if fraction > tol:
        message = (
            f"the design window of {drives.shape[1]} samples is too short: played once from silence, "
            f"{100 * fraction:.2g}% of the response energy falls past the window's end "
            f"(tolerance {100 * tol:.2g}%), so the circular design would not be reproduced. "
            "Use a longer window (n_samples), or move the target waveform away from the window's ends "
            "(it needs room before it for the drive's pre-ringing and after it for the medium's ring-down)."
        )
        if action == "raise":
            raise CausalityError(message)
        warnings.warn(message, CausalityWarning, stacklevel=3)
    return fraction
