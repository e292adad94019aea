"""The linear algebra of acoustic contrast control, shared by the contrast designs and the
contrast bound (:mod:`.contrast`, :mod:`.bound`): the generalized eigenproblem, the ACC
filters, the quiet points' Gram matrix and the tap's spectrum. Notation: :mod:`.contrast`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import as_array
from ..errors import ValidationError
from ..signals.ricker import ricker
from ._checks import as_indices, as_transfer
from ._pinv import _single_threaded_blas, gram_matrix
from .taper import design_grid

#: Default regularization ``delta`` of the contrast designs, relative to the mean
#: eigenvalue ``trace(G) / n_actuators`` of the quiet points' Gram matrix at each frequency.
DEFAULT_ACC_REG = 1e-3


def _parseval_weights(n: int) -> np.ndarray:
    """Weight of each ``rfft`` bin in the signal energy: ``sum x^2 = sum w |X|^2 / n``."""
    w = np.full(n // 2 + 1, 2.0)
    w[0] = 1.0
    if n % 2 == 0:
        w[-1] = 1.0
    return w


def generalized_eigh_max(A: Any, B: Any) -> tuple[np.ndarray, np.ndarray]:
    """Largest generalized eigenpair of Hermitian pencils ``A v = lambda B v``, batched.

    Parameters
    ----------
    A : ndarray, complex, shape (..., m, m)
        Hermitian matrices.
    B : ndarray, complex, shape (..., m, m)
        Hermitian positive definite matrices.

    Returns
    -------
    lam : ndarray, shape (...)
        Largest generalized eigenvalue of each pencil.
    vec : ndarray, complex, shape (..., m)
        Its eigenvector, normalized ``v^H B v = 1`` (phase arbitrary).

    Raises
    ------
    ValidationError
        If a ``B`` is not positive definite (Cholesky fails).
    """
    A = as_array(A, "A", dtype="complex")
    B = as_array(B, "B", dtype="complex")
    if A.ndim < 2 or A.shape != B.shape or A.shape[-1] != A.shape[-2]:
        raise ValidationError(f"A and B must be stacks of square matrices of one shape, got {A.shape} and {B.shape}")
    with _single_threaded_blas():
        try:
            L = np.linalg.cholesky(B)
        except np.linalg.LinAlgError as exc:
            raise ValidationError("B is not positive definite: regularize the quiet points' Gram matrix") from exc
        Linv = np.linalg.inv(L)
        C = Linv @ A @ np.conj(np.swapaxes(Linv, -1, -2))
        C = 0.5 * (C + np.conj(np.swapaxes(C, -1, -2)))
        w, v = np.linalg.eigh(C)
    vec = (np.conj(np.swapaxes(Linv, -1, -2)) @ v[..., :, -1:])[..., 0]
    return w[..., -1], vec


def _gram(Hq: np.ndarray) -> np.ndarray:
    """``H_q^H H_q`` per frequency, shape (F, n_act, n_act), exactly Hermitian (a real
    ``dsyrk`` over ``H_q`` read as real, :func:`~vibrofocus.rendering._pinv.gram_matrix`)."""
    with _single_threaded_blas():
        return gram_matrix(Hq)


def acc_filters(h: np.ndarray, G: np.ndarray, reg_param: float) -> tuple[np.ndarray, np.ndarray]:
    """ACC eigenpair per frequency for a single target row.

    Parameters
    ----------
    h : ndarray, complex, shape (F, n_actuators)
        Transfer to the target.
    G : ndarray, complex, shape (F, n_actuators, n_actuators)
        Gram matrix ``H_q^H H_q`` of the quiet points.
    reg_param : float
        ``delta`` relative to ``trace(G) / n_actuators`` (>= 0).

    Returns
    -------
    lam : ndarray, shape (F,)
        Largest eigenvalue ``a^H B^-1 a`` (0 where ``h`` vanishes).
    w : ndarray, complex, shape (F, n_actuators)
        Eigenvector ``B^-1 a``, scaled so that ``h w = lam``.
    """
    n_act = h.shape[1]
    delta = reg_param * np.trace(G, axis1=1, axis2=2).real / n_act
    # Frequencies where the quiet points vanish entirely: only the regularization is left.
    delta = np.where(delta > 0, delta, max(reg_param, 1e-300) * np.maximum(np.sum(np.abs(h) ** 2, axis=1), 1e-300))
    B = G + delta[:, None, None] * np.eye(n_act)
    a = np.conj(h)
    with _single_threaded_blas():
        w = np.linalg.solve(B, a[:, :, None])[:, :, 0]
    lam = np.einsum("fq,fq->f", h, w).real
    return lam, w


def _runs(indices: np.ndarray) -> list[tuple[int, int]]:
    """``indices`` as runs ``[start, stop)`` of consecutive values, in their order."""
    breaks = np.flatnonzero(np.diff(indices) != 1) + 1
    starts, ends = np.r_[0, breaks], np.r_[breaks, len(indices)]
    return [(int(indices[s]), int(indices[e - 1]) + 1) for s, e in zip(starts, ends)]


def _quiet_indices(n_points: int, target_index: int, quiet_indices: Any) -> np.ndarray:
    """The quiet points: ``quiet_indices`` checked (never the target), or every point but the target."""
    if quiet_indices is None:
        return np.delete(np.arange(n_points), target_index)
    q = as_indices(quiet_indices, "quiet_indices", n_points)
    if np.any(q == target_index):
        raise ValidationError(f"quiet_indices holds the target point {target_index}; a quiet point cannot be the target")
    return q


def _quiet_gram(H: np.ndarray, target_index: int, quiet_indices: Any, quiet_H: Any,
                bins: slice = slice(None)) -> np.ndarray:
    """Gram matrix ``H_q^H H_q`` of the quiet points at ``bins``, (F_bins, n_act, n_act),
    from indices and/or a field H. Runs of consecutive quiet points (every other point,
    the default, is two) are read from ``H`` in place, summing their Gram matrices: no
    copy of the quiet points' transfer."""
    parts = []
    if quiet_indices is not None:
        q = _quiet_indices(H.shape[1], target_index, quiet_indices)
        runs = _runs(q)
        parts += [H[bins, start:stop] for start, stop in runs] if len(runs) <= 8 else [H[bins][:, q, :]]
    if quiet_H is not None:
        Hf = as_transfer(quiet_H, "quiet_H")
        if Hf.shape[0] != H.shape[0] or Hf.shape[2] != H.shape[2]:
            raise ValidationError(
                f"quiet_H has shape {Hf.shape} but H has {H.shape}: it must have shape "
                f"({H.shape[0]}, n_grid, {H.shape[2]}) (same frequencies and actuators)"
            )
        parts.append(Hf[bins])
    if not parts:
        if H.shape[1] == 1:
            raise ValidationError("H has a single point: there are no quiet points to compare the target with")
        parts += [H[bins, :target_index], H[bins, target_index + 1:]]
    grams = [_gram(part) for part in parts if part.shape[1]]
    return grams[0] if len(grams) == 1 else np.sum(grams, axis=0)


def _tap(n: int, fs: float, sigma: float, t0: float | None, band: tuple[float, float], taper_octaves: float,
         waveform: Any) -> tuple[np.ndarray, np.ndarray]:
    """(taper, U): the band taper and the spectrum of the band-limited desired waveform."""
    taper = design_grid(n, fs, band, taper_octaves)[1]
    if waveform is None:
        t0 = n / fs / 2 if t0 is None else t0
        waveform = ricker(fs, sigma, n / fs, t0)
    else:
        waveform = as_array(waveform, "waveform", ndim=1, shape=(n,))
    return taper, np.fft.rfft(waveform) * taper
