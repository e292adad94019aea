"""Regularized pseudo-inverses of a stack of matrices, batched over the frequency axis.

A transfer matrix ``H`` of shape ``(n_freqs, n_rows, n_cols)`` is factorized once for all
frequencies. Where a frequency is well conditioned the design works on the small Gram
matrix (``H^H H`` or ``H H^H``): its eigenvalues (``eigvalsh``) give the singular values,
and a batched linear solve gives the (Tikhonov-damped) pseudo-inverse, which is several
times cheaper than a full SVD of a tall matrix. Its rounding error grows like
``eps * cond(H)^2``, so frequencies whose condition number exceeds
:data:`GRAM_MAX_CONDITION` are re-factorized by a (batched) SVD of ``H`` itself. The
result therefore matches ``numpy.linalg.pinv`` to about ``1e-10`` relative everywhere.

Regularization acts on the singular values ``s`` of each frequency through a filter
``g(s)`` that replaces ``1/s``:

- ``None``: plain pseudo-inverse, ``g = 1/s`` above ``max(n_rows, n_cols) * eps * s_max``
  (the cutoff ``numpy.linalg.pinv`` uses), else 0.
- ``"tikhonov"``: ``g = s / (s^2 + (lam * s_max)^2)``, ``lam = reg_param``.
- ``"tsvd"``: ``g = 1/s`` where ``s >= reg_param * s_max``, else 0.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from threadpoolctl import ThreadpoolController

__all__ = ["REGULARIZATIONS", "GRAM_MAX_CONDITION", "SpectralPinv", "filter_factors"]

REGULARIZATIONS = (None, "tikhonov", "tsvd")
#: Above this condition number a frequency is factorized by SVD instead of the Gram
#: matrix (the Gram route loses about ``eps * cond^2`` relative accuracy).
GRAM_MAX_CONDITION = 1e3


def filter_factors(s: np.ndarray, regularization: str | None, reg_param: float | None, max_dim: int) -> np.ndarray:
    """Regularized reciprocal ``g(s)`` of singular values.

    Parameters
    ----------
    s : ndarray, shape (n_freqs, k)
        Singular values (>= 0) of each frequency.
    regularization : {None, "tikhonov", "tsvd"}
    reg_param : float or None
        Relative to the largest singular value at each frequency.
    max_dim : int
        ``max(n_rows, n_cols)``, for the plain pseudo-inverse cutoff.

    Returns
    -------
    ndarray, shape (n_freqs, k)
        ``g(s)``; 0 for singular values that are dropped.
    """
    s_max = s.max(axis=-1, keepdims=True)
    safe = np.where(s > 0, s, 1.0)
    if regularization is None:
        keep = s > max_dim * np.finfo(float).eps * s_max
        return np.where(keep, 1.0 / safe, 0.0)
    if regularization == "tikhonov":
        lam2 = (reg_param * s_max) ** 2
        denom = s**2 + lam2
        return np.where(denom > 0, s / np.where(denom > 0, denom, 1.0), 0.0)
    if regularization == "tsvd":
        keep = (s >= reg_param * s_max) & (s > 0)
        return np.where(keep, 1.0 / safe, 0.0)
    raise ValueError(f"unknown regularization {regularization!r}")  # pragma: no cover


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


@contextmanager
def _single_threaded_blas():
    """Run LAPACK on thousands of small matrices with one BLAS thread: each matrix is too
    small to gain from threads, and on a busy machine the per-call thread hand-offs made
    a batched 32 x 32 eigendecomposition over 20 times slower."""
    with _controller().limit(limits=1, user_api="blas"):
        yield


def _herm(a: np.ndarray) -> np.ndarray:
    return np.conj(np.swapaxes(a, -1, -2))


def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a @ x`` per frequency: a (F, m, n), x (F, n) -> (F, m)."""
    return (a @ x[:, :, None])[:, :, 0]


def _hmatvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a^H @ x`` per frequency without copying ``a``: a (F, m, n), x (F, m) -> (F, n)."""
    return np.conj((np.conj(x)[:, None, :] @ a)[:, 0, :])


@dataclass
class SpectralPinv:
    """Factorized regularized pseudo-inverse of ``H`` at every frequency.

    Build with :meth:`factorize`; apply with :meth:`apply` (one right-hand side per
    frequency) or form the matrices with :meth:`matrix`.

    Well-conditioned frequencies use the Gram matrix ``A = H^H H`` (``H H^H`` when ``H``
    is wide): the plain and Tikhonov designs solve ``(A + lam^2 I) x = b`` (the singular
    values, from ``eigvalsh``, only set ``lam`` and the conditioning test), truncated SVD
    uses the eigenvectors of ``A``. The other frequencies use an SVD of ``H``.
    """

    H: np.ndarray
    tall: bool
    gram_freqs: np.ndarray  # indices of the frequencies on the Gram route
    system: np.ndarray | None  # (n_gram, k, k) A + lam^2 I ("solve" route)
    basis: np.ndarray | None  # (n_gram, k, k) eigenvectors of A ("eig" route, tsvd)
    coef: np.ndarray | None  # (n_gram, k) g(s) / s ("eig" route)
    singular_values: np.ndarray  # (F, k), descending
    svd_freqs: np.ndarray  # indices of frequencies factorized by SVD
    svd_u: np.ndarray  # (n_svd, n_rows, k)
    svd_vh: np.ndarray  # (n_svd, k, n_cols)
    svd_g: np.ndarray  # (n_svd, k)

    @classmethod
    def factorize(cls, H: np.ndarray, regularization: str | None = None, reg_param: float | None = None) -> "SpectralPinv":
        """Factorize ``H`` (complex, shape ``(n_freqs, n_rows, n_cols)``)."""
        n_freqs, n_rows, n_cols = H.shape
        tall = n_rows >= n_cols
        k = min(n_rows, n_cols)
        max_dim = max(n_rows, n_cols)
        gram = _herm(H) @ H if tall else H @ _herm(H)
        with _single_threaded_blas():
            eigvals = np.linalg.eigvalsh(gram)  # ascending
        s = np.sqrt(np.clip(eigvals[:, ::-1], 0.0, None))
        s_max, s_min = s[:, 0], s[:, -1]
        # Frequencies where the Gram route loses accuracy (about eps * cond^2): use a
        # true SVD of H there, batched over just those frequencies. Frequencies where H
        # vanishes entirely get zero drives.
        ill = (s_max > 0) & (s_min * GRAM_MAX_CONDITION < s_max)
        good = np.flatnonzero((s_max > 0) & ~ill)
        bad = np.flatnonzero(ill)
        system = basis = coef = None
        if regularization == "tsvd":
            with _single_threaded_blas():
                w, vecs = np.linalg.eigh(gram[good])
            s_good = np.sqrt(np.clip(w[:, ::-1], 0.0, None))
            basis = vecs[:, :, ::-1]
            g = filter_factors(s_good, regularization, reg_param, max_dim)
            coef = np.where(s_good > 0, g / np.where(s_good > 0, s_good, 1.0), 0.0)
        else:
            # cond <= GRAM_MAX_CONDITION here, far above the plain pseudo-inverse cutoff,
            # so the plain design is the exact inverse of the Gram matrix.
            lam = 0.0 if regularization is None else reg_param * s_max[good]
            system = gram[good]
            if regularization is not None:
                system = system + (lam**2)[:, None, None] * np.eye(k)
        if bad.size:
            with _single_threaded_blas():
                u, s_bad, vh = np.linalg.svd(H[bad], full_matrices=False)
            g_bad = filter_factors(s_bad, regularization, reg_param, max_dim)
            s[bad] = s_bad
        else:
            u = np.zeros((0, n_rows, k), complex)
            vh = np.zeros((0, k, n_cols), complex)
            g_bad = np.zeros((0, k))
        return cls(H, tall, good, system, basis, coef, s, bad, u, vh, g_bad)

    def _gram_apply(self, H: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Pseudo-inverse applied at the Gram-route frequencies (H, rhs restricted)."""
        if self.system is not None:
            with _single_threaded_blas():
                if self.tall:
                    return np.linalg.solve(self.system, _hmatvec(H, rhs)[:, :, None])[:, :, 0]
                return _hmatvec(H, np.linalg.solve(self.system, rhs[:, :, None])[:, :, 0])
        V = self.basis
        if self.tall:
            return _matvec(V, self.coef * _hmatvec(V, _hmatvec(H, rhs)))
        return _hmatvec(H, _matvec(V, self.coef * _hmatvec(V, rhs)))

    def apply(self, rhs: np.ndarray) -> np.ndarray:
        """``H^+ rhs`` per frequency; ``rhs`` shape (n_freqs, n_rows) -> (n_freqs, n_cols)."""
        n_freqs, _, n_cols = self.H.shape
        out = np.zeros((n_freqs, n_cols), complex)
        good = self.gram_freqs
        if good.size == n_freqs:  # the common case: no copies of H
            out = self._gram_apply(self.H, rhs)
        elif good.size:
            out[good] = self._gram_apply(self.H[good], rhs[good])
        if self.svd_freqs.size:
            b = self.svd_freqs
            out[b] = _hmatvec(self.svd_vh, self.svd_g * _hmatvec(self.svd_u, rhs[b]))
        return out

    def matrix(self) -> np.ndarray:
        """The pseudo-inverse matrices, shape (n_freqs, n_cols, n_rows)."""
        n_freqs, n_rows, n_cols = self.H.shape
        out = np.zeros((n_freqs, n_cols, n_rows), complex)
        good = self.gram_freqs
        if good.size:
            H = self.H if good.size == n_freqs else self.H[good]
            if self.system is not None:
                with _single_threaded_blas():
                    if self.tall:
                        out[good] = np.linalg.solve(self.system, _herm(H))
                    else:
                        out[good] = _herm(H) @ np.linalg.inv(self.system)
            else:
                V = self.basis
                if self.tall:
                    out[good] = (V * self.coef[:, None, :]) @ (_herm(V) @ _herm(H))
                else:
                    out[good] = _herm(H) @ ((V * self.coef[:, None, :]) @ _herm(V))
        if self.svd_freqs.size:
            out[self.svd_freqs] = (_herm(self.svd_vh) * self.svd_g[:, None, :]) @ _herm(self.svd_u)
        return out
