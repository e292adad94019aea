"""The vectorized statistics equal the report's (pingouin) statistics on the same data."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from vibrofocus.analysis import fast
from vibrofocus.analysis.study1 import study1_anova
from vibrofocus.analysis.study2 import friedman_tests
from vibrofocus.errors import ValidationError


def _long(Y: np.ndarray, dv: str) -> pd.DataFrame:
    n, na, nb = Y.shape
    methods = ["funneling", "inverse", "combination", "time_reversal"][:nb]
    rows = [
        {"participant": f"p{i:02d}", "location": a + 1, "method": methods[b], dv: Y[i, a, b]}
        for i in range(n) for a in range(na) for b in range(nb)
    ]
    return pd.DataFrame(rows)


@pytest.mark.parametrize("shape", [(20, 9, 3), (6, 4, 2), (12, 5, 3)])
def test_rm_anova_equals_pingouin(shape):
    rng = np.random.default_rng(sum(shape))
    n, na, nb = shape
    # Non-spherical data: a subject effect, location-dependent spread and an interaction.
    Y = (10 + rng.normal(0, 2, (n, 1, 1)) + rng.normal(0, 1, (1, na, nb)) * 3
         + rng.normal(0, 1, shape) * np.linspace(0.5, 3, na)[None, :, None])
    got = fast.rm_anova2_batch(Y[None])
    ref = study1_anova(_long(Y, "error_mm")).set_index("effect")
    for j, eff in enumerate(["location", "method", "location * method"]):
        for key, col in (("F", "F"), ("p_unc", "p_unc"), ("eps", "eps"), ("p_gg", "p_gg"),
                         ("W_mauchly", "W_mauchly"), ("p_mauchly", "p_mauchly")):
            r = ref.loc[eff, col]
            if pd.isna(r):
                continue
            np.testing.assert_allclose(got[key][0, j], r, rtol=1e-8, atol=1e-12, err_msg=f"{eff} {key}")
        assert got["ddof1"][j] == ref.loc[eff, "ddof1"] and got["ddof2"][j] == ref.loc[eff, "ddof2"]


def test_rm_anova_batches_independently():
    rng = np.random.default_rng(3)
    Y = rng.normal(size=(4, 8, 3, 3))
    together = fast.rm_anova2_batch(Y)
    for s in range(4):
        alone = fast.rm_anova2_batch(Y[s])
        np.testing.assert_allclose(together["F"][s], alone["F"][0], rtol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_friedman_equals_report_on_tied_counts(seed):
    rng = np.random.default_rng(seed)
    n, na, nb = 15, 9, 3
    # Mean counts of 3 trials: multiples of 1/3, many ties (as in study 2).
    Y = rng.integers(3, 9, size=(n, na, nb)) / 3.0
    ref = friedman_tests(_long(Y, "n_selected"))
    for j, (factor, axis) in enumerate((("location", 2), ("method", 1))):
        X = Y.mean(axis=axis)
        got = fast.friedman_batch(X[None])
        np.testing.assert_allclose(got["chi2"][0], ref.loc[factor, "chi2"], rtol=1e-8)
        np.testing.assert_allclose(got["p"][0], ref.loc[factor, "p"], rtol=1e-8)
        np.testing.assert_allclose(got["kendall_w"][0], ref.loc[factor, "kendall_w"], rtol=1e-8)


def test_friedman_all_tied_is_no_effect():
    got = fast.friedman_batch(np.ones((1, 5, 3)))
    assert got["chi2"][0] == 0.0 and got["p"][0] == 1.0


def test_bad_shapes_are_refused():
    with pytest.raises(ValidationError):
        fast.rm_anova2_batch(np.ones((1, 2, 3, 3)))
    with pytest.raises(ValidationError):
        fast.rm_anova2_batch(np.full((1, 5, 3, 3), np.nan))
    with pytest.raises(ValidationError):
        fast.friedman_batch(np.ones((1, 1, 3)))


def test_survival_functions_are_scipys_bit_for_bit():
    # Values inside, at and outside the support, NaN and infinities; degrees of freedom
    # integer, fractional (the Greenhouse-Geisser ones), zero, negative and NaN.
    from scipy import stats

    rng = np.random.default_rng(5)
    x = np.concatenate([rng.exponential(3.0, 400), -rng.exponential(1.0, 20), [0.0, -0.0, np.nan, np.inf, -np.inf,
                                                                                   1e-300, 1e300, 4.5]])
    df = np.concatenate([rng.integers(1, 40, 200).astype(float), rng.uniform(0.2, 30.0, 220), [0.0, -1.0, np.nan,
                                                                                                np.inf, 2.0, 3.0, 5.0,
                                                                                                1.0]])
    dfd = rng.permutation(df)
    for ours, theirs in ((fast.chi2_sf(x, df), stats.chi2.sf(x, df)), (fast.t_sf(x, df), stats.t.sf(x, df)),
                         (fast.t_sf(-x, df), stats.t.sf(-x, df)), (fast.f_sf(x, df, dfd), stats.f.sf(x, df, dfd))):
        np.testing.assert_array_equal(ours, theirs)
        assert ours.dtype == theirs.dtype
    # Scalars and broadcasting, as the callers pass them.
    assert fast.chi2_sf(3.0, 2) == stats.chi2.sf(3.0, 2) and np.ndim(fast.chi2_sf(3.0, 2)) == 0
    np.testing.assert_array_equal(fast.f_sf(x[:12, None], np.array([1.0, 2.0, 4.5]), 17.0),
                                  stats.f.sf(x[:12, None], np.array([1.0, 2.0, 4.5]), 17.0))


def test_average_ranks_are_scipys_bit_for_bit():
    from scipy import stats

    rng = np.random.default_rng(8)
    X = rng.integers(0, 4, (50, 12, 9)).astype(float)  # many ties
    X[3, 2, 4] = np.nan
    X[7, :, :] = 1.0  # all tied
    X[9] = rng.normal(size=(12, 9))  # none tied
    eq = (X[:, :, :, None] == X[:, :, None, :]).sum(axis=3)
    np.testing.assert_array_equal(fast._average_ranks(X, eq), stats.rankdata(X, axis=2))
