"""Frequency-domain building blocks of the skin model: wavenumber, source, exciter.

Sign convention. The physics is written, as usual for waves, with ``exp(-i omega t)``
time dependence, where an outgoing, decaying wave is ``H0^(1)(k r)`` with
``k = 2 pi f / c(f) + i alpha(f)`` from a causal viscoelastic law (:mod:`.viscoelastic`). NumPy's FFT uses ``exp(+i omega t)``, in
which a delay is ``exp(-i omega tau)``; :func:`surface_green` returns the complex
conjugate so that everything handed out is in NumPy's convention.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from .viscoelastic import ViscoelasticLaw

__all__ = ["wavenumber", "surface_green", "exciter_response", "hankel0"]

# Beyond this many nepers of decay an image path adds less than exp(-40) ~ 4e-18 of the
# direct wave and is skipped.
_MAX_NEPERS = 40.0


def wavenumber(freqs: np.ndarray, law: ViscoelasticLaw) -> np.ndarray:
    """Complex wavenumber ``k(f) = 2 pi f / c(f) + i alpha(f)`` (physics convention).

    Parameters
    ----------
    freqs : ndarray
        Frequencies, Hz, > 0.
    law : ViscoelasticLaw
        The medium's constitutive law; speed and attenuation both follow from it.

    Returns
    -------
    ndarray, complex, same shape as ``freqs``
        rad/m (real part) and Np/m (imaginary part).
    """
    return law.wavenumber(freqs)


# Hankel's asymptotic expansion H0(z) ~ sqrt(2/(pi z)) e^{i(z - pi/4)} sum_j i^j a_j / z^j
# (Abramowitz & Stegun 9.2.7), a_j = prod_{l<=j} (-(2l-1)^2) / (j! 8^j). With 7 terms it is
# accurate to about 1e-10 relative for |z| >= 30 and cheaper than AMOS. The playback
# tables' scaled function takes 14 (_hankel0_scaled).
_ASYMPTOTIC_FROM = 30.0
_SERIES_COEFFS = []  # i^j a_j, j = 1..14
_c = 1.0
for _j in range(1, 15):
    _c *= -((2 * _j - 1) ** 2) / (_j * 8.0)
    _SERIES_COEFFS.append(_c * 1j**_j)
del _c, _j


def _asymptotic_sum(inv: np.ndarray, n_terms: int) -> np.ndarray:
    """``1 + sum_{j<=n_terms} i^j a_j / z^j`` from ``inv = 1 / z``, by Horner in ``1/z`` (in place)."""
    series = np.full_like(inv, _SERIES_COEFFS[n_terms - 1])
    series *= inv
    for coeff in reversed(_SERIES_COEFFS[: n_terms - 1]):
        series += coeff
        series *= inv
    series += 1.0
    return series


def hankel0(z: np.ndarray) -> np.ndarray:
    """``H0^(1)(z)`` for complex ``z`` with ``Im z >= 0``: scipy for small ``|z|``,
    Hankel's asymptotic series (7 terms, ~1e-11 relative) for ``|z| >= 25``."""
    z = np.asarray(z, dtype=complex)
    out = np.empty_like(z)
    far = np.abs(z) >= _ASYMPTOTIC_FROM
    near = ~far
    if near.any():
        out[near] = special.hankel1(0, z[near])
    if far.any():
        zf = z[far]
        out[far] = np.sqrt(2 / (np.pi * zf)) * np.exp(1j * (zf - np.pi / 4)) * _asymptotic_sum(1.0 / zf, 7)
    return out


# The same series to 14 terms for the scaled ``H0(z) exp(-i z)`` of the playback tables:
# for |z| >= 30 its truncation error is below 3e-16 and it agrees with scipy's AMOS to
# about 1e-15 relative (tests/skin/test_propagation.py), at half the cost or less; 8 terms
# do as well from |z| >= 100.
_SCALED_RANGES = ((_ASYMPTOTIC_FROM, 100.0, 14), (100.0, np.inf, 8))


def _hankel0_scaled(z: np.ndarray) -> np.ndarray:
    """``H0^(1)(z) exp(-i z)`` (scipy's ``hankel1e(0, z)``) for ``Im z >= 0``, to about 1e-15
    relative: scipy below ``|z| = 30``, Hankel's asymptotic series from there."""
    z = np.asarray(z, dtype=complex)
    out = np.empty_like(z)
    size = np.abs(z)
    near = size < _ASYMPTOTIC_FROM
    if near.any():
        out[near] = special.hankel1e(0, z[near])
    for lo, hi, n_terms in _SCALED_RANGES:
        sel = (size >= lo) & (size < hi)
        if not sel.any():
            continue
        inv = 1.0 / z[sel]
        series = _asymptotic_sum(inv, n_terms)
        series *= np.sqrt(inv * (2 / np.pi))
        series *= np.exp(-0.25j * np.pi)
        out[sel] = series
    return out


def _tabulated_hankel0(k: np.ndarray, d: np.ndarray, step: float) -> np.ndarray:
    """``H0(k d)`` for every ``k`` (n_freqs,) and ``d`` (n_paths,) through a distance table.

    ``H0(z) exp(-i z)`` (scipy's ``hankel1e``) is smooth and slowly varying in ``log d``
    (about ``d^-1/2``), so it is tabulated on nodes ``d_min (1 + step)^j`` and
    interpolated linearly; the fast phase ``exp(i k d)`` is applied exactly. Only the nodes
    next to some path are evaluated (a third of them for the simulated forearm's playback
    responses, whose table has more nodes than paths): the complex Hankel function is the
    costly part, and each value is the one the whole table would hold.
    """
    lo, hi = float(d.min()), float(d.max())
    ratio = np.log1p(step)
    n_nodes = max(int(np.ceil(np.log(hi / lo) / ratio)) + 2, 2)
    nodes = lo * np.exp(ratio * np.arange(n_nodes))
    u = np.log(d / lo) / ratio
    i = np.clip(np.floor(u).astype(int), 0, n_nodes - 2)
    w = u - i
    used, at = np.unique(np.concatenate([i, i + 1]), return_inverse=True)
    table = _hankel0_scaled(k[:, None] * nodes[None, used])  # (n_freqs, n_used)
    # In place: each (n_freqs, n_paths) array is large, and making it is most of the cost.
    g = table[:, at[:d.size]]
    g *= 1 - w
    upper = table[:, at[d.size:]]
    upper *= w
    g += upper
    phase = np.multiply(1j * k[:, None], d[None, :], out=upper)
    g *= np.exp(phase, out=phase)
    return g


def _disc_factor(ka: np.ndarray) -> np.ndarray:
    # 2 J1(ka) / (ka): the Graf addition theorem turns the area average of H0(k|r - r'|)
    # over a uniform disc into H0(k r) times this factor for r outside the disc.
    return 2 * special.jv(1, ka) / ka


def surface_green(k: np.ndarray, distance: np.ndarray, radius: np.ndarray, *,
                  max_nepers: float = _MAX_NEPERS, disc_factor: np.ndarray | None = None,
                  table_step: float | None = None) -> np.ndarray:
    """2-D Green's function of a uniform disc source, in NumPy's sign convention.

    The out-of-plane displacement of a membrane-like skin layer under a unit force
    spread evenly over a disc of radius ``a`` is the area average of the point-source
    Green's function ``(i/4) H0^(1)(k |r - r'|)``:

    - outside the disc (``d >= a``): ``(i/4) H0(k d) * 2 J1(k a) / (k a)``;
    - inside (``d < a``): ``(i/4) (2 / (k a^2)) [2i / (pi k) + a J0(k d) H1(k a)]``,

    which follow from Graf's addition theorem and the Wronskian
    ``J1 H0 - J0 H1 = 2i / (pi z)``; they meet continuously at ``d = a`` and the
    inside form stays finite at the centre (a finite contact has no singularity).
    Far away, ``|H0(k d)| ~ sqrt(2 / (pi |k| d)) exp(-alpha d)``: cylindrical spreading
    (-3 dB per doubling of distance) times attenuation.

    Parameters
    ----------
    k : ndarray, complex, shape (n_freqs,)
        Wavenumbers (physics convention, ``Im k > 0``), rad/m; none zero.
    distance : ndarray, shape (n_points, n_sources)
        Path lengths, m.
    radius : ndarray, shape (n_sources,)
        Contact radius of each source, m.
    max_nepers : float
        Paths attenuated by more than this (``alpha d``) are left out (set to 0).
    disc_factor : ndarray, complex, shape (n_freqs, 1, n_sources), optional
        ``2 J1(k a) / (k a)`` if already computed (it does not depend on the distance,
        so callers summing several paths compute it once; complex Bessel functions
        are the costly part).
    table_step : float, optional
        For many paths: evaluate the scaled Hankel function ``H0(z) exp(-i z)``, which
        varies slowly with distance, on a geometric distance grid of this relative
        step, interpolate it linearly in log-distance and multiply by ``exp(i k d)``.
        A step of 0.005 keeps the relative error near 1e-6 and is several times faster
        than evaluating ``H0`` at every path. Default: exact evaluation.

    Returns
    -------
    ndarray, complex, shape (n_freqs, n_points, n_sources)
        Displacement per unit force and unit membrane tension (dimensionless), NumPy
        convention (the conjugate of the physics expression).
    """
    k = np.asarray(k, dtype=complex)[:, None, None]
    d = np.asarray(distance, dtype=float)
    a = np.asarray(radius, dtype=float)
    ka = k * a[None, None, :]
    factor = _disc_factor(ka) if disc_factor is None else disc_factor
    out = np.zeros((k.shape[0],) + d.shape, dtype=complex)
    outside = d[None] >= a[None, None, :]
    pairs = outside[0]
    if table_step is not None and pairs.sum() > 64:
        # Prune whole frequencies at which even the shortest path is attenuated beyond
        # max_nepers (the far images at all but low frequencies).
        rows = np.flatnonzero(k[:, 0, 0].imag * d[pairs].min() < max_nepers)
        if rows.size:
            cols = np.nonzero(pairs)[1]
            vals = _tabulated_hankel0(k[rows, 0, 0], d[pairs], table_step)
            vals *= factor[rows, 0][:, cols]
            vals *= 0.25j
            if pairs.all() and rows.size == out.shape[0]:
                out = vals.reshape(out.shape)  # every value set: no copy
            elif pairs.all():
                out[rows] = vals.reshape((rows.size,) + d.shape)
            else:
                sub = out[rows]
                sub[:, pairs] = vals
                out[rows] = sub
        sel = None
    else:
        # Skip frequency/path pairs attenuated beyond max_nepers: their Hankel values
        # underflow anyway, and this keeps dense grids with far images cheap.
        sel = ((k.imag * d[None]) < max_nepers) & outside
    if sel is not None and sel.any():
        kd = (k * d[None])[sel]
        out[sel] = 0.25j * hankel0(kd) * np.broadcast_to(factor, out.shape)[sel]
    inside = np.broadcast_to(~outside, out.shape)
    if inside.any():
        kk = np.broadcast_to(k, out.shape)[inside]
        dd = np.broadcast_to(d[None], out.shape)[inside]
        aa = np.broadcast_to(a[None, None, :], out.shape)[inside]
        bracket = 2j / (np.pi * kk) + aa * special.jv(0, kk * dd) * special.hankel1(1, kk * aa)
        out[inside] = 0.25j * (2 / (kk * aa**2)) * bracket
    return np.conjugate(out, out=out)


def exciter_response(freqs: np.ndarray, f0_hz: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Force of an inertial exciter per unit drive, normalised to 1 far above resonance.

    A voice coil drives a suspended mass; the force on the skin is the mass times its
    acceleration, a second-order high-pass:
    ``E(f) = -(f/f0)^2 / (1 - (f/f0)^2 + i (f/f0) / Q)`` (NumPy convention, causal).

    Parameters
    ----------
    freqs : ndarray, shape (n_freqs,)
        Hz, >= 0.
    f0_hz, q : ndarray, shape (n_actuators,)
        Loaded resonance frequency (Hz) and quality factor of each exciter.

    Returns
    -------
    ndarray, complex, shape (n_freqs, n_actuators)
    """
    r = np.asarray(freqs, dtype=float)[:, None] / np.asarray(f0_hz, dtype=float)[None, :]
    return -(r**2) / (1 - r**2 + 1j * r / np.asarray(q, dtype=float)[None, :])
