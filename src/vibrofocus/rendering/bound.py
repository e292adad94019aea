"""The energy-contrast bound of an array (docs/method.md, "Rendering methods"): :func:`contrast_bound` and
:func:`energy_contrast_db`. Notation: :mod:`.contrast`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_band, check_index, check_positive
from ..defaults import BAND_HZ, SIGMA_S
from ._acc import _parseval_weights, _quiet_gram, _quiet_indices, _tap
from ._checks import as_transfer, check_grid
from ._pinv import _single_threaded_blas

__all__ = ["ContrastBound", "contrast_bound", "energy_contrast_db"]


@dataclass(frozen=True)
class ContrastBound:
    """The most energy contrast an array can give at one target (docs/method.md, "Rendering methods").

    Attributes
    ----------
    freqs : ndarray, shape (F,)
        Frequencies, Hz (``rfftfreq(n, 1 / fs)``).
    lambda_max : ndarray, shape (F,)
        Largest ratio of target energy over summed quiet-point energy any drive reaches
        at each frequency (inf where the quiet points leave a direction free).
    tap_spectrum : ndarray, complex, shape (F,)
        Spectrum ``U`` of the desired target waveform, m (rfft of it).
    quiet_energy_min : ndarray, shape (F,)
        Exact-tap bound per frequency: the least summed quiet-point energy ``|U|^2 /
        lambda_max`` for the tap's spectrum at the target (rfft units, m^2).
    bound_db : float
        Broadband energy contrast of the exact tap at its best,
        ``10 log10(sum w |U|^2 / sum w |U|^2 / lambda_max)`` (Parseval weights ``w``): no
        drive that puts this waveform at the target does better.
    best_db : float
        ``10 log10(max lambda_max)`` over the band's bins: no drive at all does better.
    n_samples : int
    """

    freqs: np.ndarray
    lambda_max: np.ndarray
    tap_spectrum: np.ndarray
    quiet_energy_min: np.ndarray
    bound_db: float
    best_db: float
    n_samples: int

    def bound_db_for(self, waveform: Any) -> float:
        """Exact-tap bound for another target waveform, dB.

        Parameters
        ----------
        waveform : ndarray, shape (n,)
            Waveform at the target (any real signal), m. The energy contrast of any drive
            that produces it there through the same ``H`` is at most this.
        """
        waveform = as_array(waveform, "waveform", ndim=1, shape=(self.n_samples,))
        return _bound_db(np.fft.rfft(waveform), self.lambda_max, self.n_samples)


def _bound_db(U: np.ndarray, lam: np.ndarray, n: int) -> float:
    w = _parseval_weights(n) * np.abs(U) ** 2
    target = float(np.sum(w))
    if target == 0:
        return float("nan")
    # Bins carrying a negligible share of the energy (rounding where H vanishes) are left out.
    reach = w > 1e-15 * target
    if np.any(reach & (lam <= 0)):
        return float("-inf")  # the waveform asks for energy where the target cannot move
    with np.errstate(divide="ignore"):
        quiet = float(np.sum(np.where(reach, w / np.where(reach, lam, 1.0), 0.0)))
    return float("inf") if quiet == 0 else float(10 * np.log10(target / quiet))


def _null_tol(mu: np.ndarray, n_act: int) -> np.ndarray:
    """Eigenvalues of ``G`` (F, k) at or below this are its null space (relative to the largest)."""
    mu_max = mu[:, -1:]
    return n_act * 1e3 * np.finfo(float).eps * np.where(mu_max > 0, mu_max, 1.0)


def _exact_lambda(h: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Unregularized ``lambda_max = a^H G^+ a`` (inf where ``a`` leaves ``G``'s range)."""
    with _single_threaded_blas():
        mu, V = np.linalg.eigh(G)
    proj = np.abs(np.einsum("fqk,fq->fk", np.conj(V), np.conj(h))) ** 2  # |v_k^H a|^2
    null = mu <= _null_tol(mu, G.shape[-1])
    a2 = np.sum(np.abs(h) ** 2, axis=1, keepdims=True)
    escapes = np.any(null & (proj > 1e-12 * np.maximum(a2, 1e-300)), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.sum(np.where(null, 0.0, proj / np.where(null, 1.0, mu)), axis=1)
    return np.where(escapes, np.inf, lam)


def _exact_lambda_rows(h: np.ndarray, Hq: np.ndarray) -> np.ndarray:
    """:func:`_exact_lambda` of ``G = Hq^H Hq`` from the quiet rows ``Hq`` (F, q, n_act), for
    fewer quiet rows than actuators: ``G``'s non-zero eigenpairs from the small Gram
    ``Hq Hq^H`` (q x q; same eigenvalues ``mu_k``, ``G``'s eigenvectors ``Hq^H u_k / sqrt(mu_k)``),
    so ``|v_k^H a|^2 = |u_k^H Hq a|^2 / mu_k``; ``a`` leaves ``G``'s range where the part of its
    energy outside those eigenvectors exceeds ``1e-12`` of it (the whole null space's share,
    where :func:`_exact_lambda` tests each null direction's)."""
    with _single_threaded_blas():
        K = Hq @ np.conj(np.swapaxes(Hq, -1, -2))
        mu, U = np.linalg.eigh(0.5 * (K + np.conj(np.swapaxes(K, -1, -2))))
        c = (Hq @ np.conj(h)[:, :, None])[:, :, 0]  # Hq a, a = conj(h)
    num = np.abs(np.einsum("fqk,fq->fk", np.conj(U), c)) ** 2  # |u_k^H Hq a|^2 = mu_k |v_k^H a|^2
    null = mu <= _null_tol(mu, h.shape[-1])
    a2 = np.sum(np.abs(h) ** 2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.where(null, 1.0, mu)
        inside = np.sum(np.where(null, 0.0, num / safe), axis=1)
        lam = np.sum(np.where(null, 0.0, num / safe**2), axis=1)
    escapes = a2 - inside > 1e-12 * np.maximum(a2, 1e-300)
    return np.where(escapes, np.inf, lam)


@fill_doc
def contrast_bound(
    H: Any,
    target_index: int,
    quiet_indices: Any = None,
    band: tuple[float, float] = BAND_HZ,
    *,
    fs: float,
    sigma: float = SIGMA_S,
    t0: float | None = None,
    waveform: Any = None,
    quiet_H: Any = None,
    taper_octaves: float = 0.5,
) -> ContrastBound:
    """Acoustic-contrast bound: the most target energy over quiet-point energy possible.

    Parameters
    ----------
    %(H)s
    target_index : int
        Row of ``H`` of the target.
    quiet_indices : sequence of int, optional
        Rows of ``H`` whose summed energy is the denominator; default every other row
        (unless ``quiet_H`` is given, then only its points).
    band : (float, float)
        Band of the tap, Hz; the tap is band-limited with :func:`band_taper`.
    %(fs)s
    sigma, t0
        Ricker spread and centre of the tap, s (t0 default: mid-window; the bound does
        not depend on it).
    waveform : ndarray, shape (n,), optional
        Desired target waveform instead of the Ricker (band-limited here), m.
    quiet_H : ndarray, complex, shape (n // 2 + 1, n_grid, n_actuators), optional
        Transfer to further quiet points, e.g. a dense model-predicted skin grid.
    taper_octaves : float
        Taper roll-off, octaves.

    Returns
    -------
    ContrastBound
        ``lambda_max`` per frequency, the exact-tap bound per frequency and broadband.
    """
    H = as_transfer(H)
    fs = check_positive(fs, "fs")
    n = 2 * (H.shape[0] - 1) if waveform is None else as_array(waveform, "waveform", ndim=1).size
    check_grid(H.shape[0], n, "waveform (n,)")
    target_index = check_index(target_index, "target_index", H.shape[1], what="points of H")
    band = check_band(band, fs)
    taper_octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
    sigma = check_positive(sigma, "sigma")
    rows = _quiet_rows(H, target_index, quiet_indices, quiet_H)
    taper, U = _tap(n, fs, sigma, t0, band, taper_octaves, waveform)
    active = taper > 0
    # Over every bin (not only the band's), so that bound_db_for can weigh any waveform;
    # with fewer quiet rows than actuators, from the rows' small Gram (q x q, not n_act x n_act).
    lam = (_exact_lambda_rows(H[:, target_index, :], rows) if rows is not None else
           _exact_lambda(H[:, target_index, :], _quiet_gram(H, target_index, quiet_indices, quiet_H)))
    with np.errstate(divide="ignore", invalid="ignore"):
        quiet_min = np.where(active & (lam > 0), np.abs(U) ** 2 / np.where(lam > 0, lam, 1.0), 0.0)
    quiet_min = np.where(active & (lam <= 0) & (np.abs(U) > 0), np.inf, quiet_min)
    best = float(np.max(lam[active])) if active.any() else 0.0
    return ContrastBound(
        freqs=np.fft.rfftfreq(n, 1 / fs),
        lambda_max=lam,
        tap_spectrum=U,
        quiet_energy_min=quiet_min,
        bound_db=_bound_db(U, lam, n),
        best_db=float(10 * np.log10(best)) if best > 0 else float("-inf"),
        n_samples=n,
    )


def _quiet_rows(H: np.ndarray, target_index: int, quiet_indices: Any, quiet_H: Any) -> np.ndarray | None:
    """The quiet points' rows of ``H`` (and of ``quiet_H``), (F, q, n_act), when they are fewer
    than the actuators; ``None`` otherwise (the Gram, n_act x n_act, is then the smaller)."""
    if quiet_H is not None:
        return None  # a field grid: many rows (and checked where its Gram is formed)
    q = _quiet_indices(H.shape[1], target_index, quiet_indices)
    if q.size >= H.shape[2] or q.size == 0:
        return None  # the Gram path (and, with no quiet point, its error)
    return H[:, q, :]


def energy_contrast_db(response: Any, target_index: int, compare_indices: Any = None) -> float:
    """``10 log10(E_target / sum of E at the compared rows)``, dB (what ACC maximizes).

    Parameters
    ----------
    response : ndarray, shape (n_points, n)
        Displacement, m.
    target_index : int
    compare_indices : sequence of int, optional
        Rows summed in the denominator (the target skipped); default every other row.
    """
    response = as_array(response, "response", ndim=2)
    target_index = check_index(target_index, "target_index", response.shape[0], what="points of response")
    compare = np.delete(np.arange(response.shape[0]), target_index) if compare_indices is None else \
        np.asarray(compare_indices, int)
    compare = compare[compare != target_index]
    energy = np.sum(response**2, axis=1)
    return _energy_db(energy[target_index], energy[compare])


def _energy_db(target: float, others: np.ndarray) -> float:
    if others.size == 0 or target == 0:
        return float("nan")
    total = float(np.sum(others))
    return float("inf") if total == 0 else float(10 * np.log10(target / total))
