"""Inverse designs that meet the target exactly: :func:`exact_target_spectra` (the other
control points in least squares, by the null-space method)."""

from __future__ import annotations

import numpy as np

from ._pinv import SpectralPinv

__all__ = ["exact_target_spectra"]


def exact_target_spectra(H_active: np.ndarray, target_index: int, others: np.ndarray, U: np.ndarray,
                         regularization: str | None = None, reg_param: float | None = None) -> np.ndarray:
    """Drive spectra meeting the target exactly, other control points in least squares.

    ``minimize sum_c |H_c s|^2 subject to h s = U`` per frequency by the null-space
    method: ``s = s0 + N z`` with ``s0 = h^H U / |h|^2`` (so ``h s0 = U``), ``N`` an
    orthonormal basis of the null space of ``h`` and ``z = -(H_c N)^+ H_c s0`` the
    (regularized) batched pseudo-inverse of
    :class:`~vibrofocus.rendering._pinv.SpectralPinv`. ``H_c N`` has full column rank
    where the array can act: working in the null-space basis, rather than with the
    rank-deficient projection ``H_c P``, keeps a numerically zero singular value from
    being inverted into a tone that fills the window.

    Parameters
    ----------
    H_active : ndarray, complex, shape (F, n_points, n_actuators)
        Transfer matrix at the design's frequencies.
    target_index : int
    others : ndarray of int
        Control points held at zero in least squares.
    U : ndarray, complex, shape (F,)
        Target spectrum.
    regularization, reg_param
        Of the least-squares fit of the others (see :class:`InverseOperator`).

    Returns
    -------
    ndarray, complex, shape (F, n_actuators)
    """
    h = H_active[:, target_index, :]
    h2 = np.sum(np.abs(h) ** 2, axis=1)
    ok = h2 > 0
    a = np.conj(h) / np.where(ok, h2, 1.0)[:, None]  # h a = 1
    s0 = a * np.where(ok, U, 0.0)[:, None]
    if len(others) == 0 or h.shape[1] < 2:
        return s0
    # Rows 2.. of V^H of the 1 x A matrix h span its null space (orthonormal).
    _, _, vh = np.linalg.svd(h[:, None, :], full_matrices=True)
    null_basis = np.conj(np.swapaxes(vh[:, 1:, :], 1, 2))  # (F, A, A - 1)
    Hc = H_active[:, others, :]
    factors = SpectralPinv.factorize(Hc @ null_basis, regularization, reg_param)
    z = factors.apply((Hc @ s0[:, :, None])[:, :, 0])
    return s0 - (null_basis @ z[:, :, None])[:, :, 0]
