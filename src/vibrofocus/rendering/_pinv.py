"""Regularized pseudo-inverses of a stack of matrices, batched over the frequency axis.

A transfer matrix ``H`` of shape ``(n_freqs, n_rows, n_cols)`` is factorized once for all
frequencies. Where a frequency is well conditioned the design works on the small Gram
matrix ``A`` (``H^H H`` or ``H H^H``), which is several times cheaper than a full SVD of a
tall matrix. Its rounding error grows like ``eps * cond(H)^2``, so frequencies whose
condition number exceeds :data:`GRAM_MAX_CONDITION` are re-factorized by a (batched) SVD
of ``H`` itself. The result therefore matches ``numpy.linalg.pinv`` to about ``1e-10``
relative everywhere.

- The plain pseudo-inverse (no regularization, the default) needs no eigenvalues: a
  batched inverse of ``A + delta I`` (``delta`` a rounding-level shift that keeps it
  positive definite, undone by one refinement step) gives ``A^-1`` and the bound
  ``cond2(A) <= ||A||_F ||A^-1||_F`` that routes frequencies to the SVD. Singular values
  are computed only when asked for.
- The regularized designs take the eigenvalues of ``A`` (``eigvalsh``: they set ``lam``
  and the conditioning test), then a linear solve (Tikhonov) or the eigenvectors (TSVD).

Regularization acts on the singular values ``s`` of each frequency through a filter
``g(s)`` that replaces ``1/s``:

- ``None``: plain pseudo-inverse, ``g = 1/s`` above ``max(n_rows, n_cols) * eps * s_max``
  (the cutoff ``numpy.linalg.pinv`` uses), else 0.
- ``"tikhonov"``: ``g = s / (s^2 + (lam * s_max)^2)``, ``lam = reg_param``.
- ``"tsvd"``: ``g = 1/s`` where ``s >= reg_param * s_max``, else 0.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from threadpoolctl import ThreadpoolController

__all__ = ["REGULARIZATIONS", "GRAM_MAX_CONDITION", "SMALL_GRAM", "SpectralPinv", "filter_factors", "gram_matrix",
           "hpd_inverse", "small_gram"]

REGULARIZATIONS = (None, "tikhonov", "tsvd")
#: Above this condition number a frequency is factorized by SVD instead of the Gram
#: matrix (the Gram route loses about ``eps * cond^2`` relative accuracy).
GRAM_MAX_CONDITION = 1e3
#: Gram matrices up to this size are formed by a complex product and inverted by a
#: Gauss-Jordan sweep vectorized over frequency: batched LAPACK and BLAS calls cost about
#: a microsecond each in overhead, more than the arithmetic of a small matrix (measured on
#: 577 frequencies: 4 x 4 inverse 0.20 ms against 0.38 ms, 12 x 12 1.9 ms against 2.9 ms;
#: at 32 x 32 LAPACK is four times faster).
SMALL_GRAM = 12


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


_blas_depth = threading.local()


@contextmanager
def _single_threaded_blas():
    """Run LAPACK on thousands of small matrices with one BLAS thread: each matrix is too
    small to gain from threads, and on a busy machine the per-call thread hand-offs made
    a batched 32 x 32 eigendecomposition over 20 times slower. Re-entrant: only the
    outermost use sets and restores the limit (each costs about 0.1 ms)."""
    depth = getattr(_blas_depth, "value", 0)
    if depth:
        _blas_depth.value = depth + 1
        try:
            yield
        finally:
            _blas_depth.value = depth
        return
    with _controller().limit(limits=1, user_api="blas"):
        _blas_depth.value = 1
        try:
            yield
        finally:
            _blas_depth.value = 0


def _herm(a: np.ndarray) -> np.ndarray:
    return np.conj(np.swapaxes(a, -1, -2))


def _matvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a @ x`` per frequency: a (F, m, n), x (F, n) -> (F, m)."""
    return (a @ x[:, :, None])[:, :, 0]


def _hmatvec(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``a^H @ x`` per frequency without copying ``a``: a (F, m, n), x (F, m) -> (F, n)."""
    return np.conj((np.conj(x)[:, None, :] @ a)[:, 0, :])


def gram_matrix(H: np.ndarray) -> np.ndarray:
    """``H^H H`` per frequency, shape (F, k, k), exactly Hermitian, without copying ``H``.

    A complex128 ``H`` whose last axis is contiguous is read as real (``F, m, 2 k``) and
    multiplied by its own transpose, which numpy hands to BLAS ``dsyrk`` (half the work of
    a complex product and no conjugated copy of ``H``); the four real blocks make up the
    complex Gram matrix.

    Up to :data:`SMALL_GRAM` columns a complex product is faster (fewer, larger BLAS
    calls per frequency).
    """
    if H.dtype != np.complex128 or H.strides[-1] != H.itemsize or H.shape[-1] <= SMALL_GRAM:
        G = _herm(H) @ H
        G += _herm(G)
        G *= 0.5
        return G
    X = H.view(np.float64)  # columns Re h_0, Im h_0, Re h_1, ...
    R = np.swapaxes(X, -1, -2) @ X  # symmetric, (F, 2k, 2k)
    G = np.empty(R.shape[:-2] + (R.shape[-1] // 2,) * 2, complex)
    np.add(R[..., ::2, ::2], R[..., 1::2, 1::2], out=G.real)  # out=: no temporaries
    np.subtract(R[..., ::2, 1::2], R[..., 1::2, ::2], out=G.imag)
    return G


def small_gram(H: np.ndarray) -> np.ndarray:
    """The smaller Gram matrix of each frequency: ``H^H H`` (tall ``H``) or ``H H^H``."""
    with _single_threaded_blas():
        return gram_matrix(H) if H.shape[-2] >= H.shape[-1] else gram_matrix(np.swapaxes(H, -1, -2)).conj()


def _frobenius2(a: np.ndarray) -> np.ndarray:
    """Squared Frobenius norm of each matrix of a complex stack (F, m, n) -> (F,)."""
    flat = a.reshape(a.shape[0], -1).view(np.float64)
    return np.einsum("fi,fi->f", flat, flat)


def hpd_inverse(a: np.ndarray) -> np.ndarray:
    """Inverse of each Hermitian positive definite matrix of a stack.

    Parameters
    ----------
    a : ndarray, complex, shape (F, k, k)

    Returns
    -------
    ndarray, complex, shape (F, k, k)
        Up to :data:`SMALL_GRAM` a Gauss-Jordan sweep without pivoting, one numpy operation
        per row over all frequencies (stable for positive definite matrices: the pivots are
        their Schur complements, all > 0); LAPACK above. A matrix that is not positive
        definite gives non-finite or meaningless entries, not an error: callers test the
        result (:func:`_plain_factor` bounds the condition number with it).
    """
    k = a.shape[-1]
    if k > SMALL_GRAM:
        try:
            with _single_threaded_blas():
                return np.linalg.inv(a)
        except np.linalg.LinAlgError:  # an exactly singular matrix stops the whole batch
            pass  # the sweep leaves it non-finite and inverts the others
    work = np.moveaxis(a, 0, -1).copy(order="C")  # (k, k, F): each entry a contiguous row; never a view of a
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for i in range(k):
            inv_pivot = 1.0 / work[i, i]
            row = work[i] * inv_pivot
            row[i] = inv_pivot
            column = work[:, i].copy()
            column[i] = 0.0
            work[:, i] = 0.0  # becomes -column * inv_pivot below
            work -= column[:, None, :] * row[None, :, :]
            work[i] = row
    return np.ascontiguousarray(np.moveaxis(work, -1, 0))


def _plain_factor(gram: np.ndarray, inner: int):
    """Inverse-Gram route of the plain pseudo-inverse.

    Returns ``(zero, good, bad, inverse, shift)``: the frequencies where ``H`` vanishes,
    those solved through the Gram matrix and those left to the SVD; ``(A + delta I)^-1``
    and ``delta`` at the good ones.
    """
    n_freqs, k = gram.shape[0], gram.shape[-1]
    trace = np.trace(gram, axis1=-2, axis2=-1).real
    zero = trace == 0
    # A shift well above the rounding of the computed Gram matrix (about inner * eps *
    # trace) keeps it positive definite even where H is singular; those frequencies fail
    # the condition bound below and go to the SVD. Elsewhere it changes A^-1 by about
    # delta ||A^-1|| (below 1e-5 relative under the bound), and one refinement step in
    # _gram_inverse_apply takes that to its square.
    shift = 2 * (inner + k) * np.finfo(float).eps * trace
    scale = np.where(zero, 1.0, trace)  # inverted at unit trace: no overflow
    system = gram / scale[:, None, None]
    system.reshape(n_freqs, k * k)[:, :: k + 1] += (shift / scale)[:, None]  # the diagonal, in place
    if zero.any():
        system[zero] = np.eye(k)
    inverse = hpd_inverse(system)
    with np.errstate(over="ignore", invalid="ignore"):
        # cond2(A) <= ||A||_F ||A^-1||_F
        ill = ~zero & ~(_frobenius2(system) * _frobenius2(inverse) <= GRAM_MAX_CONDITION**4)
    if not ill.any() and not zero.any():  # the common case: no copies
        return zero, np.arange(n_freqs), np.arange(0), inverse / scale[:, None, None], shift
    good = np.flatnonzero(~zero & ~ill)
    return zero, good, np.flatnonzero(ill), inverse[good] / scale[good, None, None], shift[good]


@dataclass
class SpectralPinv:
    """Factorized regularized pseudo-inverse of ``H`` at every frequency.

    Build with :meth:`factorize`; apply with :meth:`apply` (one right-hand side per
    frequency) or form the matrices with :meth:`matrix`.

    Well-conditioned frequencies use the Gram matrix ``A = H^H H`` (``H H^H`` when ``H``
    is wide): the plain design applies ``(A + delta I)^-1`` and one refinement step
    (module notes), Tikhonov solves
    ``(A + lam^2 I) x = b``, truncated SVD uses the eigenvectors of ``A``. The other
    frequencies use an SVD of ``H``.
    """

    H: np.ndarray
    tall: bool
    gram: np.ndarray  # (F, k, k) Gram matrix of every frequency
    zero_freqs: np.ndarray  # (F,) bool: H vanishes there (zero drives)
    gram_freqs: np.ndarray  # indices of the frequencies on the Gram route
    inverse: np.ndarray | None  # (n_gram, k, k) (A + delta I)^-1 ("inverse" route, plain)
    shift: np.ndarray | None  # (n_gram,) delta
    system: np.ndarray | None  # (n_gram, k, k) A + lam^2 I ("solve" route, tikhonov)
    basis: np.ndarray | None  # (n_gram, k, k) eigenvectors of A ("eig" route, tsvd)
    coef: np.ndarray | None  # (n_gram, k) g(s) / s ("eig" route)
    svd_freqs: np.ndarray  # indices of frequencies factorized by SVD
    svd_u: np.ndarray  # (n_svd, n_rows, k)
    svd_s: np.ndarray  # (n_svd, k)
    svd_vh: np.ndarray  # (n_svd, k, n_cols)
    svd_g: np.ndarray  # (n_svd, k)
    _singular_values: np.ndarray | None = None

    @classmethod
    def factorize(cls, H: np.ndarray, regularization: str | None = None, reg_param: float | None = None,
                  gram: np.ndarray | None = None) -> "SpectralPinv":
        """Factorize ``H`` (complex, shape ``(n_freqs, n_rows, n_cols)``); ``gram``: its
        :func:`small_gram`, if already computed."""
        n_freqs, n_rows, n_cols = H.shape
        tall = n_rows >= n_cols
        k = min(n_rows, n_cols)
        max_dim = max(n_rows, n_cols)
        gram = small_gram(H) if gram is None else gram
        plain = _plain_factor(gram, max_dim) if regularization is None else None
        inverse = shift = system = basis = coef = s = None
        if plain is not None:
            zero, good, bad, inverse, shift = plain
        else:
            with _single_threaded_blas():
                eigvals = np.linalg.eigvalsh(gram)  # ascending
            s = np.sqrt(np.clip(eigvals[:, ::-1], 0.0, None))
            s_max, s_min = s[:, 0], s[:, -1]
            zero = s_max == 0
            # Frequencies where the Gram route loses accuracy (about eps * cond^2): use a
            # true SVD of H there, batched over just those frequencies. Frequencies where
            # H vanishes entirely get zero drives.
            ill = ~zero & (s_min * GRAM_MAX_CONDITION < s_max)
            good = np.flatnonzero(~zero & ~ill)
            bad = np.flatnonzero(ill)
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
        else:  # no call into LAPACK for nothing
            u, s_bad, vh, g_bad = (np.zeros((0, n_rows, k), complex), np.zeros((0, k)),
                                   np.zeros((0, k, n_cols), complex), np.zeros((0, k)))
        if s is not None:
            s[bad] = s_bad
        return cls(H, tall, gram, zero, good, inverse, shift, system, basis, coef, bad, u, s_bad, vh, g_bad, s)

    @property
    def singular_values(self) -> np.ndarray:
        """Singular values of ``H`` at each frequency, (n_freqs, k), descending (computed
        on first use on the plain route)."""
        if self._singular_values is None:
            s = np.zeros(self.gram.shape[:2])
            with _single_threaded_blas():
                eigvals = np.linalg.eigvalsh(self.gram[self.gram_freqs])
            s[self.gram_freqs] = np.sqrt(np.clip(eigvals[:, ::-1], 0.0, None))
            s[self.svd_freqs] = self.svd_s
            self._singular_values = s
        return self._singular_values

    def _gram_inverse_apply(self, x: np.ndarray) -> np.ndarray:
        """``A^-1 x`` at the Gram-route frequencies; x (n_gram, k) or (n_gram, k, m)."""
        vec = x.ndim == 2
        x = x[:, :, None] if vec else x
        with _single_threaded_blas():
            if self.inverse is not None:
                y = self.inverse @ x  # (A + delta I)^-1 x
                y = y + self.inverse @ (self.shift[:, None, None] * y)  # refined: A^-1 x
            else:
                y = np.linalg.solve(self.system, x)
        return y[:, :, 0] if vec else y

    def _gram_apply(self, H: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """Pseudo-inverse applied at the Gram-route frequencies (H, rhs restricted)."""
        if self.basis is None:
            if self.tall:
                return self._gram_inverse_apply(_hmatvec(H, rhs))
            return _hmatvec(H, self._gram_inverse_apply(rhs))
        V = self.basis
        if self.tall:
            return _matvec(V, self.coef * _hmatvec(V, _hmatvec(H, rhs)))
        return _hmatvec(H, _matvec(V, self.coef * _hmatvec(V, rhs)))

    def apply(self, rhs: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """``H^+ rhs`` per frequency; ``rhs`` shape (n_freqs, n_rows) -> (n_freqs, n_cols).

        With ``rows`` (indices), ``rhs`` holds only those rows, shape (n_freqs, len(rows)):
        the others are zero and cost nothing.
        """
        n_freqs, n_rows, n_cols = self.H.shape
        H, u = self.H, self.svd_u
        if rows is not None:
            if not self.tall:
                full = np.zeros((n_freqs, n_rows), complex)
                full[:, rows] = rhs
                return self.apply(full)
            H, u = H[:, rows, :], u[:, rows, :]
        out = np.zeros((n_freqs, n_cols), complex)
        good = self.gram_freqs
        if good.size == n_freqs:  # the common case: no copies of H
            out = self._gram_apply(H, rhs)
        elif good.size:
            out[good] = self._gram_apply(H[good], rhs[good])
        if self.svd_freqs.size:
            b = self.svd_freqs
            out[b] = _hmatvec(self.svd_vh, self.svd_g * _hmatvec(u, rhs[b]))
        return out

    def matrix(self) -> np.ndarray:
        """The pseudo-inverse matrices, shape (n_freqs, n_cols, n_rows)."""
        n_freqs, n_rows, n_cols = self.H.shape
        out = np.zeros((n_freqs, n_cols, n_rows), complex)
        good = self.gram_freqs
        if good.size:
            H = self.H if good.size == n_freqs else self.H[good]
            if self.basis is None:
                if self.tall:
                    out[good] = self._gram_inverse_apply(_herm(H))
                else:
                    eye = np.broadcast_to(np.eye(n_rows, dtype=complex), (good.size, n_rows, n_rows))
                    out[good] = _herm(H) @ self._gram_inverse_apply(eye)
            else:
                V = self.basis
                if self.tall:
                    out[good] = (V * self.coef[:, None, :]) @ (_herm(V) @ _herm(H))
                else:
                    out[good] = _herm(H) @ ((V * self.coef[:, None, :]) @ _herm(V))
        if self.svd_freqs.size:
            out[self.svd_freqs] = (_herm(self.svd_vh) * self.svd_g[:, None, :]) @ _herm(self.svd_u)
        return out
