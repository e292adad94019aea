"""Wrap-around (causality) check of a frequency-domain design.

A drive designed per frequency on an ``n``-point FFT grid reproduces its target under
*circular* convolution with the medium. Played once from silence, the medium convolves
it *linearly*: whatever the circular design folded back from past the window's end (the
medium's ring-down of a late target, or the acausal pre-ringing of a drive that wrapped
to the window's end) then appears after the window instead of inside it. The design is
only valid when that spill-over is negligible.

How it is computed: the drives played once from silence give the linear convolution
``y`` (``2 n`` samples) of each path's impulse response ``h = irfft(H, n)`` with its
drive. On the ``2 n``-point grid, the even bins of ``y``'s spectrum are ``H @ D`` on the
design grid itself, and the odd bins are ``H_odd @ D_odd``, where
``H_odd = FFT_n(h exp(-i pi t / n))`` (the half-bin shifted spectra of the impulse
responses) depend only on ``H``. :class:`WraparoundCheck` computes ``H_odd`` once per
transfer matrix and keeps it; each check then costs one transform of each drive, the
products and one inverse transform per point, and gives the same energies as playing
the drives by linear convolution at every point (single precision: the share past the
window is exact to about 1e-6 of the response energy, against a tolerance of 1e-3).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import scipy.fft

from .._validation import as_array, check_choice, check_in_range
from ..errors import CausalityError, ValidationError
from ._pinv import _single_threaded_blas

__all__ = ["wraparound_fraction", "check_wraparound", "WraparoundCheck", "CausalityWarning", "DEFAULT_WRAPAROUND_TOL"]

#: Largest tolerated share of the response energy that falls past the window (-30 dB).
DEFAULT_WRAPAROUND_TOL = 1e-3
#: Memory budget of one chunk of zero-padded transfer functions, bytes.
_CHUNK_BYTES = 64 * 2**20
#: Odd bins whose summed contribution to the response energy is provably below this
#: share of it are skipped by a cached check (they change the share past the window by
#: at most ``2 sqrt(_SKIP_SHARE * fraction)``, 6e-8 absolute at a fraction of 1e-3).
_SKIP_SHARE = 1e-12


class CausalityWarning(UserWarning):
    """The design window is too short (issued instead of CausalityError on request)."""


def _as_drives_and_transfer(drives: Any, H: Any) -> tuple[np.ndarray, np.ndarray]:
    drives = as_array(drives, "drives", ndim=2)
    H = as_array(H, "H", ndim=3, dtype="complex")
    n = drives.shape[1]
    if H.shape[0] != n // 2 + 1 or H.shape[2] != drives.shape[0]:
        raise ValidationError(
            f"H must have shape (n // 2 + 1, n_points, n_actuators) = ({n // 2 + 1}, any, {drives.shape[0]}) "
            f"to match drives of shape {drives.shape}, got {H.shape}"
        )
    return drives, H


def _point_chunks(H: np.ndarray):
    """Slices of points whose zero-padded transfer functions fit in _CHUNK_BYTES."""
    n_freqs, n_points, n_act = H.shape
    per_point = max(1, _CHUNK_BYTES // (16 * n_freqs * max(n_act, 1)))
    return [slice(start, start + per_point) for start in range(0, n_points, per_point)]


def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    return (a @ x[:, :, None])[:, :, 0]


def _energy_bound(norms: np.ndarray, drives: np.ndarray) -> np.ndarray:
    """Bound ``||H||_F^2 |D|^2`` of each bin's ``sum_p |(H D)_p|^2``; drives (F, n_act)."""
    flat = np.ascontiguousarray(drives).view(drives.real.dtype)
    return norms * np.einsum("fa,fa->f", flat, flat, dtype=np.float64)


def _bins_within(bound: np.ndarray, budget: float) -> slice:
    """The shortest run of bins outside which ``bound`` sums to at most ``budget`` (half
    of it at each end)."""
    low = int(np.searchsorted(np.cumsum(bound), 0.5 * budget, side="right"))
    high = len(bound) - int(np.searchsorted(np.cumsum(bound[::-1]), 0.5 * budget, side="right"))
    return slice(low, max(low, high))


class WraparoundCheck:
    """The single-playback (linear convolution) check of drives through one ``H``.

    Keeps the half-bin shifted spectra ``H_odd`` of the impulse responses (module notes),
    computed on first use: build it once per transfer matrix and reuse it for every
    design through that matrix (an :class:`~vibrofocus.rendering.InverseOperator` and a
    :class:`~vibrofocus.calibration.Calibration` keep theirs).

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)``.
    n_samples : int, optional
        Window length ``n``; default ``2 (n_freqs - 1)``. Give it for odd ``n``.
    keep : bool
        Compute ``H_odd`` at the first check and keep it (default); False transforms the
        impulse responses at every check and keeps nothing (a single check).

    Notes
    -----
    ``H_odd`` takes ``8 (n // 2 + 1) n_points n_actuators`` bytes (single precision), half
    of ``H``.
    """

    def __init__(self, H: Any, n_samples: int | None = None, *, keep: bool = True) -> None:
        H = as_array(H, "H", ndim=3, dtype="complex")
        self.n = 2 * (H.shape[0] - 1) if n_samples is None else int(n_samples)
        if H.shape[0] != self.n // 2 + 1:
            raise ValidationError(f"H has {H.shape[0]} frequencies, which does not match n_samples={n_samples!r}")
        self.H = H
        self.keep = bool(keep)
        self._odd: np.ndarray | None = None
        self._odd_norms: np.ndarray | None = None
        self._even_norms: np.ndarray | None = None

    def _odd_chunk(self, points: slice) -> np.ndarray:
        """``H_odd`` of some points, complex64, shape (n_odd, n_chunk, n_actuators)."""
        impulse = scipy.fft.irfft(self.H[:, points, :].astype(np.complex64), self.n, axis=0)
        return scipy.fft.rfft(impulse, 2 * self.n, axis=0)[1::2]

    @property
    def odd_spectra(self) -> np.ndarray:
        """``H_odd``, complex64, shape ((n + 1) // 2, n_points, n_actuators) (computed once)."""
        if self._odd is None:
            odd = np.empty(((self.n + 1) // 2,) + self.H.shape[1:], np.complex64)
            for points in _point_chunks(self.H):
                odd[:, points] = self._odd_chunk(points)
            flat = odd.reshape(odd.shape[0], -1).view(np.float32)
            self._odd_norms = np.einsum("fi,fi->f", flat, flat, dtype=np.float64)  # ||H_odd||_F^2 per bin
            self._odd = odd
        return self._odd

    def _even_response(self, even: np.ndarray) -> np.ndarray:
        """``H @ D`` on the design grid, (n_freqs, n_points), skipping the bins whose summed
        contribution to the response energy is provably below ``_SKIP_SHARE`` of it."""
        H = self.H
        if self._even_norms is None:
            flat = H.reshape(H.shape[0], -1).view(np.float64)
            self._even_norms = np.einsum("fi,fi->f", flat, flat)
        bound = _energy_bound(self._even_norms, even)
        out = np.zeros(H.shape[:2], complex)
        core = _bins_within(bound, 1e-6 * float(np.sum(bound)))  # nearly all of it
        out[core] = _matvec(H[core], even[core])
        kept = _bins_within(bound, _SKIP_SHARE * float(np.vdot(out[core], out[core]).real))
        for part in (slice(kept.start, min(kept.stop, core.start)), slice(max(kept.start, core.stop), kept.stop)):
            out[part] = _matvec(H[part], even[part])
        return out

    def fraction(self, drives: Any, spectra: np.ndarray | None = None) -> float:
        """Share of the response energy that one playback of ``drives`` puts past the window.

        Parameters
        ----------
        drives : ndarray, shape (n_actuators, n)
            Drive signals, in the input unit of ``H`` (V).
        spectra : ndarray, complex, shape (n // 2 + 1, n_actuators), optional
            ``rfft(drives)`` if known; its zero bins (outside a design's band) are skipped.

        Returns
        -------
        float
            As :func:`wraparound_fraction`.
        """
        drives, H = _as_drives_and_transfer(drives, self.H)
        n = self.n
        padded = scipy.fft.rfft(drives.astype(np.float32), 2 * n, axis=-1).T  # (n + 1, n_act)
        response = np.zeros((H.shape[1], n + 1), np.complex64)  # (points, 2n-grid bins)
        odd = padded[1::2]
        with _single_threaded_blas():
            if spectra is not None:  # exact zeros outside the design's band
                used = np.flatnonzero(np.any(spectra != 0, axis=1))
                bins = slice(int(used[0]), int(used[-1]) + 1) if used.size else slice(0, 0)
                even_response = _matvec(H[bins], spectra[bins])
                response[:, 0::2][:, bins] = even_response.T
            else:
                even_response = self._even_response(padded[0::2].astype(complex))
                response[:, 0::2] = even_response.T
            if self.keep:
                self.odd_spectra
                # The even bins' energy is a lower bound of the response's (Parseval).
                bound = _energy_bound(2 * self._odd_norms, odd)  # mirrored bins counted
                kept = _bins_within(bound, _SKIP_SHARE * float(np.vdot(even_response, even_response).real))
                response[:, 1::2][:, kept] = _matvec(self._odd[kept], odd[kept]).T
            else:  # one-shot: no need to keep H_odd
                for points in _point_chunks(H):
                    response[points, 1::2] = _matvec(self._odd_chunk(points), odd).T
        played = scipy.fft.irfft(response, 2 * n, axis=-1)
        head = float(np.einsum("pt,pt->", played[:, :n], played[:, :n], dtype=np.float64))
        tail = float(np.einsum("pt,pt->", played[:, n:], played[:, n:], dtype=np.float64))
        return tail / (head + tail) if head + tail > 0 else 0.0

    def check(self, drives: Any, *, tol: float = DEFAULT_WRAPAROUND_TOL, action: str = "raise",
              spectra: np.ndarray | None = None) -> float:
        """:func:`check_wraparound` through this check's cached spectra."""
        return _verdict(self.fraction(drives, spectra), drives, tol, action)


def wraparound_fraction(drives: np.ndarray, H: np.ndarray) -> float:
    """Share of the response energy that a single playback puts past the window's end.

    The drives are played once from silence through the linear medium whose impulse
    responses are ``irfft(H, n)``; the response is the linear convolution (``2 n``
    samples, no wrap-around), computed as in the module notes. To check many designs
    through one ``H``, build a :class:`WraparoundCheck` once instead.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n)
        Drive signals, in the input unit of ``H`` (V).
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators) or WraparoundCheck
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
    if isinstance(H, WraparoundCheck):
        return H.fraction(drives)
    drives, H = _as_drives_and_transfer(drives, H)
    return WraparoundCheck(H, drives.shape[1], keep=False).fraction(drives)


def _playback_wraparound_fraction(drives: np.ndarray, H: np.ndarray) -> float:
    """The former implementation, kept as the tests' reference: every path's impulse
    response zero-padded to ``2 n``, played by linear convolution at every point."""
    drives, H = _as_drives_and_transfer(drives, H)
    n = drives.shape[1]
    n_fft = 2 * n
    drive_spectra = scipy.fft.rfft(drives.astype(np.float32), n_fft, axis=-1).T  # (n+1, n_act)
    tail = 0.0
    total = 0.0
    for points in _point_chunks(H):
        impulse = scipy.fft.irfft(H[:, points, :].astype(np.complex64), n, axis=0)
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
    return _verdict(wraparound_fraction(drives, H), drives, tol, action)


def _verdict(fraction: float, drives: np.ndarray, tol: float, action: str) -> float:
    check_choice(action, "action", ("raise", "warn"))
    tol = check_in_range(tol, "tol", 0.0, 1.0, inclusive=False)
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
        warnings.warn(message, CausalityWarning, stacklevel=4)
    return fraction
