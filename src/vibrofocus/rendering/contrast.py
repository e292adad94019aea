"""Contrast designs of SPEC §2: acoustic contrast control (ACC), a constrained
fidelity-contrast design, and the contrast bound of an array.

Notation, per frequency ``f`` of ``rfftfreq(n, 1/fs)``: ``h`` (row, ``n_actuators``) is the
transfer to the target, ``H_q`` (``n_quiet x n_actuators``) the transfer to the quiet
points, ``s`` the drive spectra. The target's energy is ``|h s|^2 = s^H A s`` with
``A = a a^H``, ``a = h^H``; the quiet points' energy is ``s^H G s`` with
``G = H_q^H H_q``. Acoustic contrast control maximizes the Rayleigh quotient
``s^H A s / s^H B s`` with ``B = G + delta I`` (a small regularization ``delta``, relative
to the mean eigenvalue of ``G``, that keeps the drives finite where ``G`` is
ill-conditioned). ``A`` has rank one, so the maximizing generalized eigenvector is
``w = B^-1 a`` with eigenvalue ``lambda = a^H B^-1 a`` (one batched linear solve over all
frequencies), and ``h w = lambda`` is real and positive.

Phase alignment: an eigenvector is only defined up to a complex factor per frequency,
which left free makes the drives a noise burst. The designs here choose it so that the
target receives the band-limited tap: ``s = w U / lambda`` gives ``h s = U`` exactly, ``U``
the spectrum of the desired waveform (the Ricker tap through the band taper). Among all
drives that put exactly ``U`` at the target, this ``s`` has the least regularized quiet
energy ``s^H B s = |U|^2 / lambda``: with ``delta = 0`` that is the *exact-tap bound* of
SPEC §2.

The constrained design trades fidelity for contrast: ``s = w V / lambda`` puts
``V = g U`` at the target, ``g`` proportional to ``lambda / (lambda + mu)``. It solves
``maximize corr(u_t, tap)`` subject to ``energy contrast >= C``: with ``x_f = |V_f|^2``
that is a concave objective over linear constraints, whose KKT conditions give this
``g`` (``mu >= 0``, or ``mu < -max lambda`` for contrasts beyond ``mu = inf``); fidelity and
contrast do not change when all drives are scaled, so the peak-voltage constraint is met
by scaling the drives to the limit, which also gives the largest target amplitude that
design can reach within it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal

from .._validation import as_array, check_band, check_in_range, check_index, check_positive
from ..defaults import BAND_HZ, SIGMA_S
from ..errors import ValidationError
from ..signals.ricker import ricker
from ._checks import as_indices, as_transfer, check_grid, check_transfer_energy
from ._pinv import _single_threaded_blas, gram_matrix
from .taper import design_grid

__all__ = [
    "ContrastBound",
    "contrast_bound",
    "generalized_eigh_max",
    "acc_filters",
    "contrast_drives",
    "constrained_drives",
    "energy_contrast_db",
    "exact_target_spectra",
    "taper_drive_ends",
    "DRIVE_WINDOW_TAPER",
    "DEFAULT_ACC_REG",
]

#: Default regularization ``delta`` of the contrast designs, relative to the mean
#: eigenvalue ``trace(G) / n_actuators`` of the quiet points' Gram matrix at each frequency.
DEFAULT_ACC_REG = 1e-3

#: Share of the design window that ``render`` tapers (half at each end, a Tukey window
#: centred on the tap) in the drives of a contrast design that would otherwise not fit
#: the window. These designs divide by the array's gain to the target, which is small
#: where the array focuses poorly; from a measured (noisy) calibration that spreads a
#: little drive energy over the whole window, which played once from silence rings past
#: its end (up to 0.16 % of the response energy on simulated forearms, above the 0.1 %
#: the wrap-around check tolerates). The taper brings it to about 6e-6 and changed the
#: medians of fidelity and energy contrast by less than 0.002 and 0.4 dB there.
DRIVE_WINDOW_TAPER = 0.25


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


@dataclass(frozen=True)
class ContrastBound:
    """The most energy contrast an array can give at one target (SPEC §2).

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


def _exact_lambda(h: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Unregularized ``lambda_max = a^H G^+ a`` (inf where ``a`` leaves ``G``'s range)."""
    with _single_threaded_blas():
        mu, V = np.linalg.eigh(G)
    proj = np.abs(np.einsum("fqk,fq->fk", np.conj(V), np.conj(h))) ** 2  # |v_k^H a|^2
    mu_max = mu[:, -1:]
    tol = G.shape[-1] * 1e3 * np.finfo(float).eps * np.where(mu_max > 0, mu_max, 1.0)
    null = mu <= tol
    a2 = np.sum(np.abs(h) ** 2, axis=1, keepdims=True)
    escapes = np.any(null & (proj > 1e-12 * np.maximum(a2, 1e-300)), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.sum(np.where(null, 0.0, proj / np.where(null, 1.0, mu)), axis=1)
    return np.where(escapes, np.inf, lam)


def _runs(indices: np.ndarray) -> list[tuple[int, int]]:
    """``indices`` as runs ``[start, stop)`` of consecutive values, in their order."""
    breaks = np.flatnonzero(np.diff(indices) != 1) + 1
    starts, ends = np.r_[0, breaks], np.r_[breaks, len(indices)]
    return [(int(indices[s]), int(indices[e - 1]) + 1) for s, e in zip(starts, ends)]


def _quiet_gram(H: np.ndarray, target_index: int, quiet_indices: Any, quiet_H: Any,
                bins: slice = slice(None)) -> np.ndarray:
    """Gram matrix ``H_q^H H_q`` of the quiet points at ``bins``, (F_bins, n_act, n_act),
    from indices and/or a field H. Runs of consecutive quiet points (every other point,
    the default, is two) are read from ``H`` in place, summing their Gram matrices: no
    copy of the quiet points' transfer."""
    parts = []
    if quiet_indices is not None:
        q = as_indices(quiet_indices, "quiet_indices", H.shape[1])
        if np.any(q == target_index):
            raise ValidationError(f"quiet_indices holds the target point {target_index}; a quiet point cannot be the target")
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
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)``, m/V.
    target_index : int
        Row of ``H`` of the target.
    quiet_indices : sequence of int, optional
        Rows of ``H`` whose summed energy is the denominator; default every other row
        (unless ``quiet_H`` is given, then only its points).
    band : (float, float)
        Band of the tap, Hz; the tap is band-limited with :func:`band_taper`.
    fs : float
        Sample rate, Hz.
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
    G = _quiet_gram(H, target_index, quiet_indices, quiet_H)
    taper, U = _tap(n, fs, sigma, t0, band, taper_octaves, waveform)
    active = taper > 0
    # Over every bin (not only the band's), so that bound_db_for can weigh any waveform.
    lam = _exact_lambda(H[:, target_index, :], G)
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


def _design(H, target_index, fs, quiet_indices, quiet_H, band, sigma, t0, waveform, target_peak, taper_octaves,
            reg_param):
    """Validate, then the ACC eigenpairs over the band; ``waveform=None`` asks for
    ``target_peak`` times the Ricker centred at ``t0`` (default mid-window). ``H``'s values
    are checked where used, the target and quiet points in the band, through the Gram
    matrix (no pass of its own over a large ``H``)."""
    H = as_transfer(H, values=False)
    fs = check_positive(fs, "fs")
    n = 2 * (H.shape[0] - 1) if waveform is None else as_array(waveform, "waveform", ndim=1).size
    check_grid(H.shape[0], n, "waveform (n,)")
    target_index = check_index(target_index, "target_index", H.shape[1], what="points of H")
    band = check_band(band, fs)
    taper_octaves = check_positive(taper_octaves, "taper_octaves", allow_zero=True)
    reg_param = check_positive(reg_param, "reg_param", allow_zero=True)
    taper, U = _tap(n, fs, check_positive(sigma, "sigma"), t0, band, taper_octaves, waveform)
    if waveform is None:
        U = check_positive(target_peak, "target_peak") * U
    active = slice(int(np.flatnonzero(taper > 0)[0]), int(np.flatnonzero(taper > 0)[-1]) + 1)
    G = _quiet_gram(H, target_index, quiet_indices, quiet_H, active)
    h = H[active, target_index, :]
    with np.errstate(over="ignore", invalid="ignore"):
        # The Gram matrix's trace and |h|^2 hold the energy of every part of H in use.
        used = np.trace(G, axis1=1, axis2=2).real.sum() + np.vdot(h, h).real
        check_transfer_energy(used, H[active], "H", " in the design band")
    if np.any(np.all(h == 0, axis=1) & (np.abs(U[active]) > 0)):
        raise ValidationError(
            f"H is zero from every actuator to the target (point {target_index}) at frequencies inside the band: "
            "no drive moves it there; recalibrate or narrow the band"
        )
    lam, w = acc_filters(h, G, reg_param)
    return H, n, U, active, lam, w, G


def _to_drives(spectra_active: np.ndarray, active: slice, F: int, n: int) -> np.ndarray:
    spectra = np.zeros((F, spectra_active.shape[1]), complex)
    spectra[active] = spectra_active
    return np.fft.irfft(spectra, n, axis=0).T


def taper_drive_ends(drives: Any, centre: int, taper: float = DRIVE_WINDOW_TAPER) -> np.ndarray:
    """Drives times a Tukey window centred (circularly) on sample ``centre``.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n)
        Drives, V.
    centre : int
        Sample the window is centred on (the tap's peak).
    taper : float
        Share of the window tapered, half at each end, in [0, 1].

    Returns
    -------
    ndarray, shape (n_actuators, n)
    """
    drives = as_array(drives, "drives", ndim=2)
    n = drives.shape[1]
    window = np.roll(scipy.signal.windows.tukey(n, check_in_range(taper, "taper", 0.0, 1.0)), int(centre) - n // 2)
    return drives * window


def contrast_drives(
    H: Any,
    target_index: int,
    fs: float,
    *,
    quiet_indices: Any = None,
    quiet_H: Any = None,
    band: tuple[float, float] = BAND_HZ,
    sigma: float = SIGMA_S,
    t0: float | None = None,
    waveform: Any = None,
    target_peak: float = 1.0,
    reg_param: float = DEFAULT_ACC_REG,
    taper_octaves: float = 0.5,
) -> np.ndarray:
    """Acoustic contrast control, phase-aligned into the desired tap at the target.

    Per frequency ``s = w U / lambda`` (module notes): the ACC eigenvector scaled so that
    the target receives exactly the band-limited tap spectrum ``U``; batched over
    frequency.

    Parameters
    ----------
    H : ndarray, complex, shape (n // 2 + 1, n_points, n_actuators)
        Transfer matrix on ``rfftfreq(n, 1 / fs)``, m/V.
    target_index : int
        Row of ``H`` of the target.
    fs : float
        Sample rate, Hz.
    quiet_indices : sequence of int, optional
        Rows of ``H`` to keep quiet; default every other row (unless ``quiet_H``).
    quiet_H : ndarray, complex, shape (n // 2 + 1, n_grid, n_actuators), optional
        Transfer to further quiet points (a dense skin grid).
    band : (float, float)
        Design band, Hz.
    sigma, t0
        Ricker spread and centre, s (t0 default: mid-window).
    waveform : ndarray, shape (n,), optional
        Desired target waveform instead of ``target_peak`` times the Ricker, m.
    target_peak : float
        Peak of the Ricker before band-limiting, m.
    reg_param : float
        ``delta`` relative to the mean eigenvalue of the quiet Gram matrix.
    taper_octaves : float

    Returns
    -------
    ndarray, real, shape (n_actuators, n)
        Drives, V, unscaled (the rendering layer applies the drive limit).
    """
    H, n, U, active, lam, w, _ = _design(H, target_index, fs, quiet_indices, quiet_H, band, sigma, t0, waveform,
                                         target_peak, taper_octaves, reg_param)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(lam > 0, U[active] / np.where(lam > 0, lam, 1.0), 0.0)
    return _to_drives(w * gain[:, None], active, H.shape[0], n)


def constrained_drives(
    H: Any,
    target_index: int,
    fs: float,
    *,
    contrast_weight: float | None = None,
    min_contrast_db: float | None = None,
    quiet_indices: Any = None,
    quiet_H: Any = None,
    band: tuple[float, float] = BAND_HZ,
    sigma: float = SIGMA_S,
    t0: float | None = None,
    waveform: Any = None,
    target_peak: float = 1.0,
    reg_param: float = DEFAULT_ACC_REG,
    taper_octaves: float = 0.5,
    full_output: bool = False,
) -> np.ndarray | tuple[np.ndarray, dict[str, float]]:
    """Best target fidelity for a required energy contrast (or a weighted trade-off).

    Per frequency ``s = w U / (lambda + mu)`` (module notes), which puts
    ``V = U lambda / (lambda + mu)`` at the target: ``mu = 0`` is the exact tap of
    :func:`contrast_drives`; a larger ``mu`` gives up the frequencies where the array
    focuses poorly, so the energy contrast rises and the fidelity falls. Give exactly one
    of ``contrast_weight`` and ``min_contrast_db`` (neither: ``contrast_weight=1``).

    Parameters
    ----------
    H, target_index, fs, quiet_indices, quiet_H, band, sigma, t0, waveform, target_peak, reg_param, taper_octaves
        As in :func:`contrast_drives`.
    contrast_weight : float, optional
        ``mu`` relative to the broadband exact-tap contrast ``lambda_ref`` (linear) of the
        regularized design, ``mu = contrast_weight * lambda_ref``, >= 0 (0: the exact tap).
    min_contrast_db : float, optional
        Required energy contrast, dB: target energy over the summed energy of the quiet
        points (the exact, unregularized prediction through ``H``). The design takes the
        least trade-off (the best fidelity) that meets it, searching ``mu`` from 0 to
        infinity and then the branch beyond (module notes), which ends with all the
        energy in the band's best bin (contrast ``lambda_max`` there, fidelity near 0).
    full_output : bool
        Also return ``{"tradeoff", "energy_contrast_db", "predicted_fidelity"}``
        (``tradeoff`` in [0, 2]: ``mu / (mu + lambda_ref)`` below 1, the branch beyond above).

    Notes
    -----
    The target gets ``V = g U`` with ``g`` normalized so that its energy is the exact
    tap's; for the best fidelity at a given contrast the KKT conditions of the convex
    problem in ``|V|^2`` give ``g`` proportional to ``lambda / (lambda + mu)`` for
    ``mu >= 0`` or to ``lambda / (|mu| - lambda)`` for ``|mu| > lambda_top`` (the branch
    beyond).

    Returns
    -------
    drives : ndarray, real, shape (n_actuators, n)
        V, unscaled (scale them to the drive limit: neither fidelity nor contrast change).
    info : dict
        Only with ``full_output=True``.

    Raises
    ------
    ValidationError
        If ``min_contrast_db`` is beyond what any ``mu`` reaches (the message gives the
        most reachable).
    """
    if contrast_weight is not None and min_contrast_db is not None:
        raise ValidationError("give contrast_weight or min_contrast_db, not both")
    if min_contrast_db is None:
        contrast_weight = 1.0 if contrast_weight is None else check_positive(contrast_weight, "contrast_weight",
                                                                             allow_zero=True)
    else:
        try:
            min_contrast_db = float(min_contrast_db)
        except (TypeError, ValueError) as exc:
            raise ValidationError(f"min_contrast_db must be a number of dB, got {min_contrast_db!r}") from exc
        if not np.isfinite(min_contrast_db):
            raise ValidationError(f"min_contrast_db must be finite, got {min_contrast_db!r}")
    H, n, U, active, lam, w, G = _design(H, target_index, fs, quiet_indices, quiet_H, band, sigma, t0, waveform,
                                         target_peak, taper_octaves, reg_param)
    Ua = U[active]
    weight = _parseval_weights(n)[active] * np.abs(Ua) ** 2  # target energy per bin of the exact tap
    ok = lam > 0
    safe = np.where(ok, lam, 1.0)
    # Exact quiet energy per unit target energy along the ACC direction: w^H G w / lambda^2.
    ratio = np.where(ok, np.einsum("fq,fqk,fk->f", np.conj(w), G, w).real / safe**2, 0.0)
    weight = np.where(ok, weight, 0.0)
    lam_ref = float(np.sum(weight) / np.sum(weight / safe))  # broadband exact-tap contrast (regularized)

    lam_top = float(np.max(np.where(weight > 0, safe, 0.0)))
    towards_ref = lam_ref - safe  # p < 1: lambda / (lambda + p (lam_ref - lambda))
    beyond_num = safe * lam_top / lam_ref  # the branch beyond: beyond_num / (beyond_den + q lambda)
    beyond_den = lam_top - np.minimum(safe, lam_top)

    def shape(p: np.ndarray) -> np.ndarray:
        """Target gain ``V / U`` up to a factor, per trade-off parameter ``p`` (M,) -> (M, F),
        all ``p`` on one branch: ``p`` in [0, 1): ``lambda / (lambda + mu)`` with
        ``mu = lam_ref p / (1 - p)``; ``p`` in [1, 2]: the branch beyond ``mu = inf``,
        ``lambda / (1 - (1 - q) lambda / lambda_top)`` with ``q = 10^(-30 (p - 1))``, which
        ends on the best bin alone."""
        if np.all(p < 1):
            return safe / (safe + p[:, None] * towards_ref)
        return beyond_num / (beyond_den + 10.0 ** (-30.0 * np.minimum(p[:, None] - 1.0, 1.0)) * safe)

    def gains(p: float) -> np.ndarray:
        """:func:`shape` at one ``p``, normalized to the exact tap's target energy, 0 where
        ``lambda <= 0``, shape (F,)."""
        g = shape(np.array([p]))[0]
        g = g * np.sqrt(np.sum(weight) / max(float(np.sum(g**2 * weight)), 1e-300))
        return np.where(ok, g, 0.0)

    # Target and quiet energy per bin of a unit gain (zero where lambda <= 0): the contrast
    # of a gain g is (g^2 . weight) / (g^2 . weight ratio), independent of g's scale.
    energies = np.stack([weight, weight * ratio], axis=1)  # (F, 2)

    def contrast_at(p: np.ndarray) -> np.ndarray:
        """Energy contrast (linear) for each p, shape (M,): one product over the bins per
        branch."""
        out = np.empty(p.size)
        for branch in (p < 1, p >= 1):
            if branch.any():
                g = shape(p[branch])
                target, quiet = ((g * g) @ energies).T
                out[branch] = target / np.maximum(quiet, 1e-300 * target)
        return out

    if min_contrast_db is None:
        p_opt = contrast_weight / (contrast_weight + 1.0)
    else:
        goal = 10 ** (min_contrast_db / 10)
        grid = np.linspace(0.0, 2.0, 301)
        values = contrast_at(grid)
        meets = np.flatnonzero(values >= goal * (1 + 1e-9))
        if meets.size == 0:
            raise ValidationError(
                f"min_contrast_db={min_contrast_db:g} dB is beyond this array: the constrained design reaches at most "
                f"{10 * np.log10(values.max()):.2f} dB of energy contrast at point {target_index} over these quiet points"
            )
        k = int(meets[0])
        if k == 0:
            p_opt = 0.0
        else:
            # Contrast below the goal at lo, at or above it at hi (p = 1 is a grid point: the
            # bracket lies in one branch). Regula falsi with the Illinois step narrows it to
            # rounding (what 60 bisection steps gave) in a few evaluations; a step that
            # would not land strictly inside the bracket bisects instead.
            lo, hi = grid[k - 1], grid[k]
            f_lo, f_hi = values[k - 1] - goal * (1 + 1e-9), values[k] - goal * (1 + 1e-9)
            side = 0
            for _ in range(200):
                if hi - lo <= 4 * np.finfo(float).eps * hi:
                    break
                mid = hi - f_hi * (hi - lo) / (f_hi - f_lo)
                if not lo < mid < hi:
                    mid = 0.5 * (lo + hi)
                f_mid = contrast_at(np.array([mid]))[0] - goal * (1 + 1e-9)
                if f_mid >= 0:
                    hi, f_hi = mid, f_mid
                    f_lo = 0.5 * f_lo if side == 1 else f_lo
                    side = 1
                else:
                    lo, f_lo = mid, f_mid
                    f_hi = 0.5 * f_hi if side == -1 else f_hi
                    side = -1
            p_opt = hi
    g = gains(p_opt)
    drives = _to_drives(w * np.where(ok, g * Ua / safe, 0.0)[:, None], active, H.shape[0], n)
    if not full_output:
        return drives
    V = g * Ua
    pw = _parseval_weights(n)[active]
    fidelity = float(np.sum(pw * (np.conj(Ua) * V).real) / np.sqrt(np.sum(pw * np.abs(Ua) ** 2) * np.sum(pw * np.abs(V) ** 2)))
    info = {"tradeoff": float(p_opt), "energy_contrast_db": float(10 * np.log10(contrast_at(np.array([p_opt]))[0])),
            "predicted_fidelity": fidelity}
    return drives, info


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
    from ._pinv import SpectralPinv

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
