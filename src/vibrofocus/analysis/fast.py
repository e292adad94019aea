"""Vectorized statistics of docs/method.md (Analysis) for many simulated studies at once (power analysis).

The report's statistics go through pingouin one study at a time; for power analysis that
is the bottleneck. These functions compute the same numbers on arrays of cell means,
batched over studies, with numpy: the two-way repeated-measures ANOVA with the
Greenhouse–Geisser epsilon and Mauchly's test (as :func:`pingouin.rm_anova`, two-way,
which is what :func:`~vibrofocus.analysis.study1_anova` wraps) and the Friedman test
corrected for ties (as :func:`pingouin.friedman`, ``method="chisq"``, on per-subject
means rounded as :func:`~vibrofocus.analysis.friedman_tests` does). The tests check
equality with pingouin to 1e-8.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from ..errors import ValidationError

__all__ = ["rm_anova2_batch", "friedman_batch", "orthonormal_contrasts"]


def _sf(function, lower: float, x, *df) -> np.ndarray | float:
    """A survival function as ``scipy.stats``' generic ``sf`` evaluates it, without its
    per-call overhead: ``function(x, *df)`` where ``x`` is inside the support
    (``lower``, inf) and every ``df`` is positive; 1 at or below ``lower``; 0 at +inf; NaN
    where ``x`` is NaN or a ``df`` is not positive."""
    arrays = np.broadcast_arrays(np.asarray(x, dtype=float), *(np.asarray(d, dtype=float) for d in df))
    x, df = arrays[0], arrays[1:]
    valid = np.ones(x.shape, dtype=bool)
    for d in df:
        valid &= d > 0
    inside = valid & (x > lower) & (x < np.inf)
    out = np.zeros(x.shape)
    out[~valid | np.isnan(x)] = np.nan
    out[valid & (x <= lower)] = 1.0
    if inside.any():
        out[inside] = function(x[inside], *(d[inside] for d in df))
    return out[()] if out.ndim == 0 else out


def chi2_sf(x, df) -> np.ndarray | float:
    """``scipy.stats.chi2.sf(x, df)``, bit for bit, at a fraction of its overhead (about
    0.3 ms a call; the power simulation makes tens of thousands)."""
    return _sf(lambda x, df: special.chdtrc(df, x), 0.0, x, df)


def f_sf(x, dfn, dfd) -> np.ndarray | float:
    """``scipy.stats.f.sf(x, dfn, dfd)``, bit for bit (as :func:`chi2_sf`)."""
    return _sf(lambda x, dfn, dfd: special.fdtrc(dfn, dfd, x), 0.0, x, dfn, dfd)


def t_sf(x, df) -> np.ndarray | float:
    """``scipy.stats.t.sf(x, df)``, bit for bit (as :func:`chi2_sf`)."""
    return _sf(lambda x, df: special.stdtr(df, -x), -np.inf, x, df)


def orthonormal_contrasts(k: int) -> np.ndarray:
    """(k, k - 1) orthonormal contrasts (orthogonal to the grand mean)."""
    q, _ = np.linalg.qr(np.column_stack([np.ones(k), np.eye(k)[:, :-1]]))
    return q[:, 1:]


def _eps_mauchly(piv: np.ndarray, C: np.ndarray, k_total: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GG epsilon, Mauchly's W and p from wide data ``piv`` (S, n, c) and contrasts C (c, d)."""
    n = piv.shape[1]
    z = piv @ C  # (S, n, d)
    z = z - z.mean(axis=1, keepdims=True)
    M = np.einsum("sni,snj->sij", z, z) / (n - 1)
    d = M.shape[-1]
    tr = np.trace(M, axis1=1, axis2=2)
    if d <= 1:
        one = np.ones(len(piv))
        return one, np.full(len(piv), np.nan), one
    tr2 = np.einsum("sij,sji->s", M, M)
    with np.errstate(invalid="ignore", divide="ignore"):
        eps = np.minimum(tr**2 / (d * tr2), 1.0)
        sign, logdet = np.linalg.slogdet(M)
        logW = np.where(sign > 0, logdet - d * np.log(tr / d), -np.inf)
    df_resid = n - 1
    ddof = d * (d + 1) / 2 - 1
    f = 1 - (2 * d**2 + d + 2) / (6 * d * df_resid)
    w2 = (d + 2) * (d - 1) * (d - 2) * (2 * d**3 + 6 * d**2 + 3 * k_total + 2) / (288 * (df_resid * d * f) ** 2)
    chi = -df_resid * f * logW
    p1, p2 = chi2_sf(chi, ddof), chi2_sf(chi, ddof + 4)
    return eps, np.exp(logW), p1 + w2 * (p2 - p1)


def rm_anova2_batch(Y: np.ndarray) -> dict[str, np.ndarray]:
    """Two-way repeated-measures ANOVA of many studies at once.

    Parameters
    ----------
    Y : ndarray, shape (n_studies, n_subjects, n_a, n_b)
        One value per subject and cell (no missing values), e.g. the mean error (mm) with
        ``a`` = location and ``b`` = method.

    Returns
    -------
    dict of ndarray
        Each of shape (n_studies, 3), effects in the order ``a``, ``b``, ``a * b``: ``F``,
        ``p_unc``, ``eps`` (Greenhouse–Geisser), ``p_gg``, ``W_mauchly``, ``p_mauchly``;
        and ``ddof1``, ``ddof2`` of shape (3,).
    """
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 3:
        Y = Y[None]
    if Y.ndim != 4 or min(Y.shape[1:]) < 2 or Y.shape[1] < 3:
        raise ValidationError(f"Y must have shape (n_studies, n_subjects >= 3, n_a >= 2, n_b >= 2), got {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise ValidationError("Y must be finite (complete cases only)")
    _, n, na, nb = Y.shape
    mu = Y.mean(axis=(1, 2, 3))[:, None]
    g_s = Y.mean(axis=(2, 3))
    g_a = Y.mean(axis=(1, 3))
    g_b = Y.mean(axis=(1, 2))
    g_ab = Y.mean(axis=1)
    g_as = Y.mean(axis=3)
    g_bs = Y.mean(axis=2)
    ss_tot = np.sum((Y - mu[:, :, None, None]) ** 2, axis=(1, 2, 3))
    ss_s = na * nb * np.sum((g_s - mu) ** 2, axis=1)
    ss_a = nb * n * np.sum((g_a - mu) ** 2, axis=1)
    ss_b = na * n * np.sum((g_b - mu) ** 2, axis=1)
    ss_ab = n * np.sum((g_ab - mu[:, :, None]) ** 2, axis=(1, 2)) - ss_a - ss_b
    ss_as = nb * np.sum((g_as - mu[:, :, None]) ** 2, axis=(1, 2)) - ss_s - ss_a
    ss_bs = na * np.sum((g_bs - mu[:, :, None]) ** 2, axis=(1, 2)) - ss_s - ss_b
    ss_abs = ss_tot - ss_a - ss_b - ss_s - ss_ab - ss_as - ss_bs
    df_a, df_b, df_s = na - 1, nb - 1, n - 1
    df_ab = na * nb - 1 - df_a - df_b
    df_as = na * n - 1 - df_s - df_a
    df_bs = nb * n - 1 - df_s - df_b
    df_abs = na * nb * n - 1 - df_a - df_b - df_s - df_ab - df_as - df_bs
    ss = np.stack([ss_a, ss_b, ss_ab], axis=1)
    err = np.stack([ss_as, ss_bs, ss_abs], axis=1)
    ddof1 = np.array([df_a, df_b, df_ab], dtype=float)
    ddof2 = np.array([df_as, df_bs, df_abs], dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        F = (ss / ddof1) / (err / ddof2)
    p_unc = f_sf(F, ddof1, ddof2)
    Ca, Cb = orthonormal_contrasts(na), orthonormal_contrasts(nb)
    # Interaction contrasts: Kronecker product, columns ordered a-major as in the pivot.
    Cab = np.einsum("ai,bj->abij", Ca, Cb).reshape(na * nb, -1)
    res = [
        _eps_mauchly(Y.mean(axis=3), Ca, na * nb),
        _eps_mauchly(Y.mean(axis=2), Cb, na * nb),
        _eps_mauchly(Y.reshape(len(Y), n, na * nb), Cab, na * nb),
    ]
    eps = np.stack([r[0] for r in res], axis=1)
    W = np.stack([r[1] for r in res], axis=1)
    p_m = np.stack([r[2] for r in res], axis=1)
    p_gg = f_sf(F, np.maximum(ddof1 * eps, 1.0), np.maximum(ddof2 * eps, 1.0))
    return {"F": F, "p_unc": p_unc, "eps": eps, "p_gg": p_gg, "W_mauchly": W, "p_mauchly": p_m,
            "ddof1": ddof1, "ddof2": ddof2}


def _denoise(values: np.ndarray) -> np.ndarray:
    # Same rounding as analysis.study2._denoise, per study (so equal fractions tie).
    finite = np.where(np.isfinite(values), np.abs(values), 0.0)
    scale = np.maximum(finite.reshape(len(values), -1).max(axis=1), 1.0)
    decimals = 9 - np.ceil(np.log10(scale)).astype(int)
    out = np.empty_like(values)
    for i, dec in enumerate(decimals):
        out[i] = np.round(values[i], int(dec))
    return out


def _average_ranks(X: np.ndarray, eq: np.ndarray) -> np.ndarray:
    """``scipy.stats.rankdata(X, axis=-1)`` (average ranks of ties; a row with a NaN is all
    NaN), bit for bit (the ranks are integers and halves: exact), given ``eq``, the size of
    each value's tie group; for the few levels of a study, without rankdata's per-call
    overhead."""
    less = (X[..., None, :] < X[..., :, None]).sum(axis=-1)
    ranked = less + (eq + 1) / 2.0
    ranked[np.isnan(X).any(axis=-1)] = np.nan
    return ranked


def friedman_batch(X: np.ndarray, *, denoise: bool = True) -> dict[str, np.ndarray]:
    """Friedman test (chi-square, corrected for ties) of many studies at once.

    Parameters
    ----------
    X : ndarray, shape (n_studies, n_subjects, k)
        One value per subject and level (e.g. per-subject mean counts per location).
    denoise : bool
        Round as :func:`~vibrofocus.analysis.friedman_tests` does before ranking.

    Returns
    -------
    dict of ndarray, each shape (n_studies,)
        ``chi2``, ``p``, ``kendall_w``; and ``dof`` (int). A study whose subjects are all
        tied gets chi2 0, p 1 (as ``friedman_tests``).
    """
    X = np.asarray(X, dtype=float)
    if X.ndim == 2:
        X = X[None]
    if X.ndim != 3 or X.shape[1] < 2 or X.shape[2] < 2:
        raise ValidationError(f"X must have shape (n_studies, n_subjects >= 2, k >= 2), got {X.shape}")
    if denoise:
        X = _denoise(X)
    _, n, k = X.shape
    eq = (X[:, :, :, None] == X[:, :, None, :]).sum(axis=3)  # (S, n, k): size of each value's tie group
    ranked = _average_ranks(X, eq)
    ssbn = np.sum(ranked.sum(axis=1) ** 2, axis=1)
    ties = np.sum(eq**2 - 1, axis=(1, 2)).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        W = (12 * ssbn - 3 * n**2 * k * (k + 1) ** 2) / (n**2 * k * (k - 1) * (k + 1) - n * ties)
    all_tied = np.ptp(X, axis=2).max(axis=1) == 0
    W = np.where(all_tied, 0.0, W)
    Q = n * (k - 1) * W
    p = np.where(all_tied, 1.0, chi2_sf(Q, k - 1))
    return {"chi2": Q, "p": p, "kendall_w": W, "dof": k - 1}
