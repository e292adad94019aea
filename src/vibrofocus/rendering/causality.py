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
responses) depend only on ``H``. :class:`WraparoundCheck` computes these spectra ``H2``
(all ``n + 1`` bins of the ``2 n`` grid) once per transfer matrix and keeps them; each
check then costs one transform of each drive, the products over the bins where the
response has energy and one inverse transform per point, and gives the same energies as
playing the drives by linear convolution at every point (single precision: the share
past the window is exact to about 1e-6 of the response energy, against a tolerance of
1e-3). Without the kept spectra (a single check) every path's impulse response is
transformed, which costs more than the design itself on a large array.
"""

from __future__ import annotations

import warnings
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.fft

from .._docs import fill_doc
from .._validation import as_array, check_choice, check_finite, check_in_range
from ..errors import CausalityError, ValidationError
from ._pinv import _single_threaded_blas

__all__ = ["wraparound_fraction", "check_wraparound", "WraparoundCheck", "CausalityWarning", "DEFAULT_WRAPAROUND_TOL"]

#: Largest tolerated share of the response energy that falls past the window (-30 dB).
DEFAULT_WRAPAROUND_TOL = 1e-3
#: Memory budget of one chunk of zero-padded transfer functions, bytes.
_CHUNK_BYTES = 64 * 2**20
#: Bins whose summed contribution to the response energy is provably below this share of
#: it are skipped by a cached check. They change the share past the window by at most
#: ``2 sqrt(_SKIP_SHARE * fraction) + _SKIP_SHARE``, 6e-7 absolute at a fraction of 1e-3
#: (below the single-precision error); a check whose verdict that margin could change
#: plays every bin. (The drives' spectra on the ``2 n`` grid fall off only like ``1 / f``
#: past the band, from their values at the window's ends, so a much smaller share would
#: keep nearly every bin.)
_SKIP_SHARE = 1e-10
#: Share of the bound ``||H2[k]||_F^2 |D2[k]|^2`` outside the bins whose energy a cached
#: check computes first, to set the budget of the bins skipped.
_CORE_SHARE = 1e-6


class CausalityWarning(UserWarning):
    """The design window is too short (issued instead of CausalityError on request)."""


def _as_drives_and_transfer(drives: Any, H: Any) -> tuple[np.ndarray, np.ndarray]:
    drives = as_array(drives, "drives", ndim=2)
    H = as_array(H, "H", ndim=3, dtype="complex")
    _check_shapes(drives, H)
    return drives, H


def _check_shapes(drives: np.ndarray, H: np.ndarray) -> None:
    n = drives.shape[1]
    if H.shape[0] != n // 2 + 1 or H.shape[2] != drives.shape[0]:
        raise ValidationError(
            f"H must have shape (n // 2 + 1, n_points, n_actuators) = ({n // 2 + 1}, any, {drives.shape[0]}) "
            f"to match drives of shape {drives.shape}, got {H.shape}"
        )


def _point_chunks(H: np.ndarray, bytes_per_value: int = 16):
    """Slices of points whose zero-padded transfer functions fit in _CHUNK_BYTES."""
    n_freqs, n_points, n_act = H.shape
    per_point = max(1, _CHUNK_BYTES // (bytes_per_value * n_freqs * max(n_act, 1)))
    return [slice(start, start + per_point) for start in range(0, n_points, per_point)]


def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    return (a @ x[:, :, None])[:, :, 0]


@lru_cache(maxsize=8)
def _probe(n_points: int, n_actuators: int) -> np.ndarray:
    """Fixed pseudo-random complex weights, (n_points, n_actuators), of the fingerprint."""
    rng = np.random.default_rng(0x5EED)
    probe = rng.standard_normal((n_points, n_actuators)) + 1j * rng.standard_normal((n_points, n_actuators))
    probe.setflags(write=False)
    return probe


def _fingerprint(H: np.ndarray) -> np.ndarray:
    """One random projection of each frequency's matrix, (n_freqs,) complex: a change of
    ``H`` changes it (but for a change orthogonal to a random vector). One BLAS pass over a
    contiguous ``H``, no copy of a strided one, which also validates its values: a NaN or
    infinity in ``H`` makes the projection non-finite, and then
    :class:`~vibrofocus.errors.ValidationError` says where (a mere overflow passes)."""
    probe = _probe(*H.shape[1:])
    if H.flags.c_contiguous:
        fingerprint = H.reshape(H.shape[0], -1) @ probe.reshape(-1)
    else:
        fingerprint = np.einsum("fpa,pa->f", H, probe)
    if not np.all(np.isfinite(fingerprint)):
        check_finite(H, "H")
    return fingerprint


def _parseval_weights_2n(n: int) -> np.ndarray:
    """Weight of each bin of ``rfft(y, 2 n)`` in ``sum y^2`` (times ``2 n``): 1 for the
    first and last bins, 2 for the others (counted with their mirror)."""
    w = np.full(n + 1, 2.0)
    w[[0, -1]] = 1.0
    return w


class _BinRuns:
    """Shortest runs of bins outside which ``bound`` sums to at most a budget (half of it
    at each end), for several budgets: the cumulative sums are formed once."""

    def __init__(self, bound: np.ndarray) -> None:
        self.rising, self.falling = np.cumsum(bound), np.cumsum(bound[::-1])

    def within(self, budget: float) -> slice:
        low = int(np.searchsorted(self.rising, 0.5 * budget, side="right"))
        high = len(self.rising) - int(np.searchsorted(self.falling, 0.5 * budget, side="right"))
        return slice(low, max(low, high))


def _response(H2: np.ndarray, drives2: np.ndarray, bins: slice) -> np.ndarray:
    """Spectra of the linear responses at ``bins`` of the ``2 n`` grid, (n_bins, n_points)
    complex64. H2 : (n + 1, n_points, n_act) spectra of the impulse responses on that grid;
    drives2 : (n + 1, n_act) complex64 spectra of the drives on it. Call it with one BLAS
    thread (:func:`~vibrofocus.rendering._pinv._single_threaded_blas`): thousands of
    small products gain nothing from threads and lose much to their hand-offs."""
    return _matvec(H2[bins], drives2[bins])


def _head_and_tail(rows: np.ndarray, bins: slice, n: int) -> tuple[float, float]:
    """Energies ``sum_p sum_{k < n} y_p[k]^2`` and ``sum_p sum_{k >= n} y_p[k]^2`` of the
    linear responses ``y_p = irfft(rows[p], 2 n)``; ``rows`` (n_points, n + 1) complex64,
    zero outside ``bins``. The total comes from the spectra (Parseval, double precision),
    the tail from the signals."""
    if bins.stop <= bins.start:
        return 0.0, 0.0
    flat = rows[:, bins].view(np.float32)
    power = np.einsum("pk,pk->k", flat, flat, dtype=np.float64).reshape(-1, 2).sum(axis=1)
    total = float(_parseval_weights_2n(n)[bins] @ power) / (2 * n)
    played = scipy.fft.irfft(rows, 2 * n, axis=-1)[:, n:]
    tail = float(np.einsum("pt,pt->", played, played, dtype=np.float64))
    return total - tail, tail


def _placed(response: np.ndarray, bins: slice, n: int) -> np.ndarray:
    """``response`` (n_bins, n_points) at ``bins`` of an otherwise zero (n_points, n + 1)
    complex64 array."""
    rows = np.zeros((response.shape[1], n + 1), np.complex64)
    rows[:, bins] = response.T
    return rows


@fill_doc
class WraparoundCheck:
    """The single-playback (linear convolution) check of drives through one ``H``.

    Keeps the spectra ``H2`` of the impulse responses on the ``2 n``-point grid (module
    notes; complex64), computed on first use: build it once per transfer matrix and
    reuse it for every design through that matrix (an
    :class:`~vibrofocus.rendering.InverseOperator` and a
    :class:`~vibrofocus.calibration.Calibration` keep theirs). A check through the kept
    spectra then plays only the bins where the response has energy: the bins left out
    hold, by the bound ``||H2[k]||_F^2 |D2[k]|^2``, at most ``_SKIP_SHARE`` of the
    response energy, and where that margin could change the verdict the check plays every
    bin (so the verdict is the one of the full playback).

    Parameters
    ----------
    %(H)s
    n_samples : int, optional
        Window length ``n``; default ``2 (n_freqs - 1)``. Give it for odd ``n``.
    keep : bool
        Compute ``H2`` at the first check and keep it (default); False transforms the
        impulse responses at every check and keeps nothing (a single check).

    Notes
    -----
    ``H2`` takes ``8 (n + 1) n_points n_actuators`` bytes (single precision), about as
    much as ``H`` in double precision.

    The check keeps a reference to ``H``, not a copy, and a fingerprint of its values
    taken when it is built: a check of an ``H`` changed in place since then refuses to
    build its spectra, and :func:`~vibrofocus.rendering.inverse_filter` refuses it.
    """

    def __init__(self, H: Any, n_samples: int | None = None, *, keep: bool = True) -> None:
        # A kept check validates H's values with its fingerprint: one pass, not two.
        H = as_array(H, "H", ndim=3, dtype="complex", finite=not keep)
        self.n = 2 * (H.shape[0] - 1) if n_samples is None else int(n_samples)
        if H.shape[0] != self.n // 2 + 1:
            raise ValidationError(f"H has {H.shape[0]} frequencies, which does not match n_samples={n_samples!r}")
        self._set(H, keep)
        self._fingerprint = _fingerprint(H) if keep else None

    def matches(self, H: np.ndarray) -> bool:
        """Whether ``H`` (validated, complex) holds the values this check was built from
        (its fingerprint: a fixed random projection of each frequency's matrix, equal to
        about 1e-12 of its largest value; one pass over ``H``).

        Raises
        ------
        ValidationError
            If ``H`` holds NaN or infinite values (they also fail the comparison).
        """
        if H.shape != self.H.shape:
            return False
        fingerprint = _fingerprint(H)
        reference = self._fingerprint if self._fingerprint is not None else _fingerprint(self.H)
        scale = float(np.max(np.abs(reference), initial=0.0)) or 1.0
        with np.errstate(invalid="ignore"):
            return bool(np.all(np.abs(fingerprint - reference) <= 1e-12 * scale))

    @classmethod
    def _trusted(cls, H: np.ndarray, n: int, keep: bool) -> "WraparoundCheck":
        """A check of a transfer matrix the caller has validated (no pass over its values)."""
        check = cls.__new__(cls)
        check.n = n
        check._set(H, keep)
        return check

    def _set(self, H: np.ndarray, keep: bool) -> None:
        self._fingerprint: np.ndarray | None = None  # of H's values when built (a public check)
        self.H = H
        self.keep = bool(keep)
        self._padded: np.ndarray | None = None
        self._weighted_norms: np.ndarray | None = None  # ||H2[k]||_F^2 per bin of the 2n grid, Parseval-weighted

    def _padded_rows(self, points: slice) -> np.ndarray:
        """``H2`` of some points as rows, complex64, shape (n_chunk, n_actuators, n + 1)
        (transformed along the last axis, several times faster than along the first)."""
        rows = np.ascontiguousarray(np.moveaxis(self.H[:, points, :], 0, -1), dtype=np.complex64)
        return scipy.fft.rfft(scipy.fft.irfft(rows, self.n, axis=-1), 2 * self.n, axis=-1)

    @property
    def padded_spectra(self) -> np.ndarray:
        """``H2``, complex64, shape (n + 1, n_points, n_actuators): the spectra of the
        impulse responses zero-padded to ``2 n`` (even bins: ``H``; computed once)."""
        if self._padded is None:
            if self._fingerprint is not None and not self.matches(self.H):
                raise ValidationError(
                    "H was changed in place after this WraparoundCheck was built: its spectra would judge "
                    "drives through a medium that is no longer H; build a new WraparoundCheck(H)"
                )
            padded = np.empty((self.n + 1,) + self.H.shape[1:], np.complex64)
            for points in _point_chunks(self.H):
                padded[:, points] = np.moveaxis(self._padded_rows(points), -1, 0)
            flat = padded.reshape(padded.shape[0], -1).view(np.float32)
            self._weighted_norms = _parseval_weights_2n(self.n) * np.einsum("fi,fi->f", flat, flat, dtype=np.float64)
            self._padded = padded
        return self._padded

    @property
    def odd_spectra(self) -> np.ndarray:
        """``H_odd``, complex64, shape ((n + 1) // 2, n_points, n_actuators): the odd bins
        of :attr:`padded_spectra` (a view)."""
        return self.padded_spectra[1::2]

    def _validated(self, drives: Any) -> np.ndarray:
        drives = as_array(drives, "drives", ndim=2)
        _check_shapes(drives, self.H)
        return drives

    def _padded_drives(self, drives: np.ndarray, spectra: np.ndarray | None) -> np.ndarray:
        """``rfft(drives, 2 n)``, (n + 1, n_act), complex128 (single precision would leave a
        rounding floor in every bin, which the bins skipped must then cover); a design's
        exact zeros (its ``spectra`` on the ``n`` grid) are kept exact in the even bins."""
        padded = np.ascontiguousarray(scipy.fft.rfft(drives, 2 * self.n, axis=-1).T)
        if spectra is not None:
            padded[0::2][~np.any(spectra != 0, axis=1)] = 0
        return padded

    def _played(self, drives: np.ndarray, spectra: np.ndarray | None, full: bool) -> tuple[float, float, float]:
        """(head, tail, skipped): energies before and past the window's end and a bound of
        the energy in the bins left out (0 when ``full`` or for a single check)."""
        padded = self._padded_drives(drives, spectra)
        flat = padded.view(np.float64)
        power = np.einsum("ki,ki->k", flat, flat)  # sum |D2[k]|^2 over actuators
        padded = padded.astype(np.complex64)
        n = self.n
        if not self.keep:  # one-shot: every bin of every point, no need to keep H2
            head = tail = 0.0
            drives_rows = np.ascontiguousarray(padded.T)  # (n_act, n + 1)
            for points in _point_chunks(self.H):
                paths = self._padded_rows(points)  # (n_chunk, n_act, n + 1)
                rows = paths[:, 0] * drives_rows[0]
                for a in range(1, paths.shape[1]):  # over actuators: contiguous passes
                    rows += paths[:, a] * drives_rows[a]
                part = _head_and_tail(rows, slice(0, n + 1), n)
                head, tail = head + part[0], tail + part[1]
            return head, tail, 0.0
        H2 = self.padded_spectra
        bound = self._weighted_norms * power  # >= the bin's energy
        if full:
            every = _BinRuns(bound).within(0.0)  # the bins left out are exact zeros
            return (*_head_and_tail(_placed(_response(H2, padded, every), every, n), every, n), 0.0)
        # The energy of the bins holding all but _CORE_SHARE of the bound is a lower bound
        # of the response's: the bins outside `kept` (a superset) hold at most _SKIP_SHARE
        # of it.
        runs = _BinRuns(bound)
        core = runs.within(_CORE_SHARE * float(runs.rising[-1]))
        core_response = _response(H2, padded, core)
        flat = core_response.view(np.float32)
        core_energy = _parseval_weights_2n(n)[core] @ np.einsum("kp,kp->k", flat, flat, dtype=np.float64)
        kept = runs.within(_SKIP_SHARE * float(core_energy))
        kept = slice(min(kept.start, core.start), max(kept.stop, core.stop))
        if (kept.start, kept.stop) == (core.start, core.stop):
            response = core_response
        else:
            response = np.concatenate([_response(H2, padded, slice(kept.start, core.start)), core_response,
                                       _response(H2, padded, slice(core.stop, kept.stop))])
        skipped = (float(runs.rising[-1]) - float(np.sum(bound[kept]))) / (2 * n)
        return (*_head_and_tail(_placed(response, kept, n), kept, n), max(skipped, 0.0))

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
        with _single_threaded_blas():
            head, tail, _ = self._played(self._validated(drives), spectra, full=False)
        return _share(head, tail)

    def _exceeds(self, drives: Any, tol: float = DEFAULT_WRAPAROUND_TOL,
                 spectra: np.ndarray | None = None) -> tuple[bool, float]:
        """Whether the share past the window exceeds ``tol``, with that share.

        The verdict is the one of playing every bin: where the bins a cached check leaves
        out could change it, they are played too.

        Parameters
        ----------
        drives, spectra
            As in :meth:`fraction`.
        tol : float
            Largest tolerated share, in (0, 1).

        Returns
        -------
        exceeded : bool
            ``fraction > tol``.
        fraction : float
            As :meth:`fraction`.
        """
        drives = self._validated(drives)
        tol = check_in_range(tol, "tol", 0.0, 1.0, inclusive=False)
        with _single_threaded_blas():
            head, tail, skipped = self._played(drives, spectra, full=False)
            # The bins left out change the tail's root-energy by at most sqrt(skipped) and
            # add at most `skipped` to the total: play them all where that could matter.
            root = np.sqrt(skipped)
            low = max(np.sqrt(tail) - root, 0.0) ** 2 / (head + tail + skipped) if head + tail > 0 else 0.0
            high = (np.sqrt(tail) + root) ** 2 / (head + tail) if head + tail > 0 else 0.0
            if skipped > 0 and (low > tol) != (high > tol):
                head, tail, _ = self._played(drives, spectra, full=True)
        fraction = _share(head, tail)
        return fraction > tol, fraction

    def check(self, drives: Any, *, tol: float = DEFAULT_WRAPAROUND_TOL, action: str = "raise",
              spectra: np.ndarray | None = None) -> float:
        """:func:`check_wraparound` through this check's cached spectra."""
        return _verdict(self._exceeds(drives, tol, spectra)[1], drives, tol, action)


def _share(head: float, tail: float) -> float:
    return tail / (head + tail) if head + tail > 0 else 0.0


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
    return WraparoundCheck._trusted(H, drives.shape[1], keep=False).fraction(drives)


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
            f"Use a longer window (try n_samples={2 * drives.shape[1]}), or move the target waveform away from "
            "the window's ends "
            "(it needs room before it for the drive's pre-ringing and after it for the medium's ring-down)."
        )
        if action == "raise":
            raise CausalityError(message)
        warnings.warn(message, CausalityWarning, stacklevel=4)
    return fraction
