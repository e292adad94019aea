"""Contrast designs (docs/method.md, "Rendering methods"): acoustic contrast control (ACC), a constrained
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
energy ``s^H B s = |U|^2 / lambda``: with ``delta = 0`` that is the *exact-tap bound*
(docs/method.md, "Rendering methods").

The constrained design trades fidelity for contrast: ``s = w V / lambda`` puts
``V = g U`` at the target, ``g`` proportional to ``lambda / (lambda + mu)``. It solves
``maximize corr(u_t, tap)`` subject to ``energy contrast >= C``: with ``x_f = |V_f|^2``
that is a concave objective over linear constraints, whose KKT conditions give this
``g`` (``mu >= 0``, or ``mu < -max lambda`` for contrasts beyond ``mu = inf``); fidelity and
contrast do not change when all drives are scaled, so the peak-voltage constraint is met
by scaling the drives to the limit, which also gives the largest target amplitude that
design can reach within it.

The designs are here; the bound is in :mod:`.bound`, the shared algebra in :mod:`._acc`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.signal

from .._docs import fill_doc
from .._validation import as_array, check_band, check_in_range, check_index, check_positive
from ..defaults import BAND_HZ, SIGMA_S
from ..errors import ValidationError
from ._acc import DEFAULT_ACC_REG, _parseval_weights, _quiet_gram, _tap, acc_filters, generalized_eigh_max
from ._checks import as_transfer, check_grid, check_transfer_energy
from .bound import ContrastBound, contrast_bound, energy_contrast_db
from .exact_target import exact_target_spectra

# The bound, the ACC algebra and the exact-target inverse design live in modules of their
# own (.bound, ._acc, .exact_target); their public names stay importable from here.
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


#: Share of the design window that ``render`` tapers (half at each end, a Tukey window
#: centred on the tap) in the drives of a contrast design that would otherwise not fit
#: the window. These designs divide by the array's gain to the target, which is small
#: where the array focuses poorly; from a measured (noisy) calibration that spreads a
#: little drive energy over the whole window, which played once from silence rings past
#: its end (up to 0.16 % of the response energy on simulated forearms, above the 0.1 %
#: the wrap-around check tolerates). The taper brings it to about 6e-6 and changed the
#: medians of fidelity and energy contrast by less than 0.002 and 0.4 dB there.
DRIVE_WINDOW_TAPER = 0.25


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


@fill_doc
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
    %(H)s
    target_index : int
        Row of ``H`` of the target.
    %(fs)s
    quiet_indices : sequence of int, optional
        Rows of ``H`` to keep quiet; default every other row (unless ``quiet_H``).
    quiet_H : ndarray, complex, shape (n // 2 + 1, n_grid, n_actuators), optional
        Transfer to further quiet points (a dense skin grid).
    %(band)s
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
