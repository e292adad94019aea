"""Study 2: counts of selected locations, Friedman tests and pairwise Wilcoxon tests.

References from outside vibrofocus:
- R's ``friedman.test`` documentation example (RoundingTimes, Hollander & Wolfe 1973,
  p. 140): Friedman chi-squared = 11.143, df = 2, p-value = 0.003805;
- scipy.stats.friedmanchisquare, an implementation independent of pingouin's;
- R's ``wilcox.test`` documentation example (depression scores, Hollander & Wolfe 1973,
  p. 29): paired, alternative "greater": V = 40, p-value = 0.01953, hence two-sided
  exact p = 0.0390625;
- the normal approximation of the signed-rank statistic with tie and continuity
  corrections written out from the textbook formula (what R's wilcox.test does with ties).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from vibrofocus.analysis import check_design, friedman_tests, load_trials, study2_counts, wilcoxon_posthoc
from vibrofocus.errors import ValidationError

ROUNDING_TIMES = np.array(
    [
        [5.40, 5.50, 5.55], [5.85, 5.70, 5.75], [5.20, 5.60, 5.50], [5.55, 5.50, 5.40], [5.90, 5.85, 5.70],
        [5.45, 5.55, 5.60], [5.40, 5.40, 5.35], [5.45, 5.50, 5.35], [5.25, 5.15, 5.00], [5.85, 5.80, 5.70],
        [5.25, 5.20, 5.10], [5.65, 5.55, 5.45], [5.60, 5.35, 5.45], [5.05, 5.00, 4.95], [5.50, 5.50, 5.40],
        [5.45, 5.55, 5.50], [5.55, 5.55, 5.35], [5.45, 5.50, 5.55], [5.50, 5.45, 5.25], [5.65, 5.60, 5.40],
        [5.70, 5.65, 5.55], [6.30, 6.30, 6.25],
    ]
)  # fmt: skip


def _long(y: np.ndarray, methods, locations=(1,)) -> pd.DataFrame:
    """(subjects, methods) or (subjects, locations, methods) to the counts table."""
    y = y.reshape(y.shape[0], len(locations), len(methods))
    rows = [
        (f"S{s:02d}", loc, m, y[s, i, j])
        for s in range(y.shape[0])
        for i, loc in enumerate(locations)
        for j, m in enumerate(methods)
    ]
    return pd.DataFrame(rows, columns=["participant", "location", "method", "n_selected"])


def test_friedman_reproduces_r_rounding_times():
    counts = _long(ROUNDING_TIMES, ["round_out", "narrow_angle", "wide_angle"])
    res = friedman_tests(counts, factors=("method",)).loc["method"]
    assert_allclose(res["chi2"], 11.143, atol=5e-4)  # R prints 3 decimals
    assert_allclose(res["p"], 0.003805, atol=1e-6)  # R prints 4 significant digits
    assert res["dof"] == 2 and res["n"] == 22


def test_friedman_matches_scipy_on_tied_counts():
    rng = np.random.default_rng(5)
    methods, locations = ["funneling", "inverse", "combination"], list(range(1, 10))
    y = rng.integers(1, 4, size=(12, 9, 3)).astype(float) + (np.arange(3) == 0)  # many ties
    res = friedman_tests(_long(y, methods, locations))
    by_method = y.mean(axis=1)  # per-participant mean over locations
    by_location = y.mean(axis=2)
    ref_m = stats.friedmanchisquare(*by_method.T)
    ref_l = stats.friedmanchisquare(*by_location.T)
    assert_allclose(res.loc["method", ["chi2", "p"]].astype(float), [ref_m.statistic, ref_m.pvalue], rtol=1e-10)
    assert_allclose(res.loc["location", ["chi2", "p"]].astype(float), [ref_l.statistic, ref_l.pvalue], rtol=1e-10)
    assert res.loc["location", "dof"] == 8 and res.loc["method", "dof"] == 2
    # Kendall's W = chi2 / (n (k - 1))
    assert_allclose(res.loc["method", "kendall_w"], ref_m.statistic / (12 * 2), rtol=1e-10)


def test_friedman_all_tied_is_no_evidence():
    res = friedman_tests(_long(np.ones((6, 3)), ["a", "b", "c"]), factors=("method",))
    assert res.loc["method", "p"] == 1.0 and res.loc["method", "chi2"] == 0.0


def test_friedman_refuses_missing_level():
    counts = _long(ROUNDING_TIMES[:5], ["a", "b", "c"]).drop(index=4)  # S01 misses level b
    with pytest.raises(ValidationError, match="S01"):
        friedman_tests(counts, factors=("method",))


def test_wilcoxon_exact_reproduces_r_example():
    x = [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30]
    y = [0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29]
    res = wilcoxon_posthoc(_long(np.column_stack([x, y]), ["first", "second"]), "method")
    assert len(res) == 1
    assert_allclose(res["p_unc"].iloc[0], 2 * 0.01953125, rtol=1e-12)  # R: V = 40, one-sided p = 0.01953
    assert res["W"].iloc[0] == 5.0  # min(V, n(n+1)/2 - V) = min(40, 5)


def test_wilcoxon_with_ties_uses_corrected_normal_approximation():
    rng = np.random.default_rng(6)
    a = rng.integers(1, 5, size=15).astype(float)
    b = a + rng.choice([-1.0, 0.0, 1.0, 1.0, 2.0], size=15)
    res = wilcoxon_posthoc(_long(np.column_stack([a, b]), ["a", "b"]), "method")
    # Textbook: drop zero differences, rank |d| with mid-ranks, V = sum of positive ranks.
    d = (a - b)[(a - b) != 0]
    n = d.size
    ranks = stats.rankdata(np.abs(d))
    v = ranks[d > 0].sum()
    _, t = np.unique(np.abs(d), return_counts=True)
    sigma = np.sqrt(n * (n + 1) * (2 * n + 1) / 24 - np.sum(t**3 - t) / 48)
    diff = v - n * (n + 1) / 4
    z = (diff - 0.5 * np.sign(diff)) / sigma
    assert_allclose(res["p_unc"].iloc[0], 2 * stats.norm.sf(abs(z)), rtol=1e-10)


def test_wilcoxon_bonferroni_over_pairs():
    rng = np.random.default_rng(9)
    y = rng.normal(size=(10, 3)) + [0.0, 1.0, 0.3]
    res = wilcoxon_posthoc(_long(y, ["funneling", "inverse", "combination"]), "method")
    assert len(res) == 3
    assert_allclose(res["p_bonf"], np.minimum(1.0, 3 * res["p_unc"]), rtol=1e-12)
    for row in res.itertuples():
        i = ["funneling", "inverse", "combination"].index(row.A)
        j = ["funneling", "inverse", "combination"].index(row.B)
        assert_allclose(row.p_unc, stats.wilcoxon(y[:, i], y[:, j], method="exact").pvalue, rtol=1e-12)


def _trials(rows) -> pd.DataFrame:
    cols = ["participant", "study", "phase", "trial", "method", "target", "response", "rt_s"]
    return load_trials(pd.DataFrame(rows, columns=cols))


def test_counts_and_target_restriction_by_hand():
    rows = [
        ("P1", 2, "main", 1, "inverse", 5, "4 5", 1.0),  # 2 selected, contains target
        ("P1", 2, "main", 2, "inverse", 5, "1 2 3", 1.0),  # 3 selected, misses target
        ("P1", 2, "main", 3, "funneling", 5, "6", 1.0),  # misses target
        ("P2", 2, "main", 1, "inverse", 5, "5", 1.0),
        ("P2", 2, "main", 2, "funneling", 5, "5 6 8 9", 1.0),
    ]
    complete, _, _ = check_design(_trials(rows), 2)
    counts, excluded = study2_counts(complete)
    c = counts.set_index(["participant", "method"])
    assert_allclose(c.loc[("P1", "inverse"), ["n_selected", "hit_rate"]].astype(float), [2.5, 0.5])
    assert c.loc[("P1", "inverse"), "n_trials"] == 2 and excluded == []
    hit, excluded = study2_counts(complete, contains_target=True)
    # P1 never selected the target with funneling: that cell is empty, but P1 keeps its
    # inverse cell (the tests use marginal means, so one empty cell drops nobody).
    assert excluded == []
    h = hit.set_index(["participant", "method"])
    assert sorted(h.index) == [("P1", "inverse"), ("P2", "funneling"), ("P2", "inverse")]
    assert_allclose(h.loc[("P1", "inverse"), "n_selected"], 2.0)
    assert_allclose(h.loc[("P2", "funneling"), "n_selected"], 4.0)


def test_target_containing_friedman_on_marginal_means_by_hand():
    # Three participants, 3 locations x 2 methods; P3 has no target-containing trial at
    # location 2 with the inverse filter (an empty cell), and none at all at location 3.
    cells = {
        ("P1", 1, "funneling"): 3.0, ("P1", 1, "inverse"): 1.0, ("P1", 2, "funneling"): 2.0,
        ("P1", 2, "inverse"): 2.0, ("P1", 3, "funneling"): 4.0, ("P1", 3, "inverse"): 2.0,
        ("P2", 1, "funneling"): 2.0, ("P2", 1, "inverse"): 1.0, ("P2", 2, "funneling"): 3.0,
        ("P2", 2, "inverse"): 1.0, ("P2", 3, "funneling"): 1.0, ("P2", 3, "inverse"): 3.0,
        ("P3", 1, "funneling"): 4.0, ("P3", 1, "inverse"): 2.0, ("P3", 2, "funneling"): 1.0,
    }
    counts = pd.DataFrame([(p, loc, m, v, 2) for (p, loc, m), v in cells.items()],
                          columns=["participant", "location", "method", "n_selected", "n_trials"])
    with pytest.raises(ValidationError, match="miss a level"):
        friedman_tests(counts)
    res = friedman_tests(counts, incomplete="drop")
    # Method: every participant has both methods; P3's means are over the cells it has
    # (funneling (4 + 1) / 2, inverse 2 / 1).
    method = np.array([[3.0, 5 / 3], [2.0, 5 / 3], [2.5, 2.0]])
    assert res.loc["method", "n"] == 3 and res.loc["method", "n_trials"] == 2 * len(cells)
    assert_allclose(res.loc["method", "chi2"], _friedman_chi2(method), rtol=1e-10)
    # Location: P3 lacks location 3 and is left out of this test only.
    location = np.array([[2.0, 2.0, 3.0], [1.5, 2.0, 2.0]])
    assert res.loc["location", "n"] == 2 and res.loc["location", "n_trials"] == 2 * 12
    assert_allclose(res.loc["location", "chi2"], _friedman_chi2(location), rtol=1e-10)


def _friedman_chi2(x: np.ndarray) -> float:
    """Friedman's chi-square with the tie correction (Hollander & Wolfe), subjects x levels."""
    n, k = x.shape
    ranks = np.apply_along_axis(stats.rankdata, 1, x)
    ties = sum(np.sum(c**3 - c) for c in (np.unique(row, return_counts=True)[1] for row in x))
    return float((12 / (n * k * (k + 1)) * np.sum(ranks.sum(axis=0) ** 2) - 3 * n * (k + 1))
                 / (1 - ties / (n * k * (k**2 - 1))))


# --------------------------------------------------------------------------- planted / null effects


def _friedman_method_p(df: pd.DataFrame) -> float:
    complete, _, _ = check_design(load_trials(df), 2)
    counts, _ = study2_counts(complete)
    return float(friedman_tests(counts).loc["method", "p"])


def test_planted_count_effect_is_detected(synthetic):
    df = synthetic(
        10, seed=202, extra_mean={"funneling": 2.0, "inverse": 0.8, "combination": 0.8}, studies=(2,), n_training=0
    )
    complete, _, _ = check_design(load_trials(df), 2)
    counts, _ = study2_counts(complete)
    assert friedman_tests(counts).loc["method", "p"] < 0.05
    pairs = wilcoxon_posthoc(counts, "method")
    with_funneling = pairs[(pairs["A"] == "funneling") | (pairs["B"] == "funneling")]
    assert (with_funneling["p_bonf"] < 0.05).all()
    means = counts.groupby("method")["n_selected"].mean()
    assert means["funneling"] > max(means["inverse"], means["combination"])


def test_no_count_effect_without_one(synthetic):
    # Seed 0 fixed in advance, then a false-positive check over 30 null data sets
    # (seeds 2000..2029): Binomial(30, 0.05) gives P(X >= 6) = 0.016.
    assert _friedman_method_p(synthetic(10, seed=0, studies=(2,), n_training=0)) > 0.05
    pvals = np.array([_friedman_method_p(synthetic(8, seed=s, studies=(2,), n_training=0)) for s in range(2000, 2030)])
    assert np.sum(pvals < 0.05) <= 5
    assert 0.2 < np.median(pvals) < 0.8


def test_friedman_recognises_ties_of_means_despite_float_noise():
    # Cell means are counts of 3 repetitions / 3; averaging them over the methods gives
    # values like 17/9 computed along different float paths (1.888...89 vs 1.888...87).
    # Rationally equal means are ties; the reference ranks the integer totals.
    rng = np.random.default_rng(11)
    methods, locations = ["funneling", "inverse", "combination"], list(range(1, 10))
    totals = rng.integers(3, 10, size=(4, 9, 3))  # selected locations summed over 3 repetitions
    y = totals / 3.0
    res = friedman_tests(_long(y, methods, locations), factors=("location",))
    by_location = totals.sum(axis=2)  # integers: ties are exact
    ref = stats.friedmanchisquare(*by_location.T)
    assert_allclose(res.loc["location", ["chi2", "p"]].astype(float), [ref.statistic, ref.pvalue], rtol=1e-10)


def test_missing_target_containing_wilcoxon_says_which_cells_lack_participants():
    # Issue 54, item 7: four participants, one repetition; only P01 selects the target at
    # location 9, so no two participants have a target-containing trial at every location.
    from vibrofocus.analysis import analyze, load_trials

    from .synthetic import make_trials

    df = make_trials(4, seed=5, repetitions=1, n_training=0, studies=(2,))
    at9 = df["target"] == 9
    df.loc[at9, "response"] = np.where(df.loc[at9, "participant"] == "P01", "9", "1")
    part = analyze(load_trials(df)).study2.contains_target
    assert part.wilcoxon == {}
    why = part.wilcoxon_unavailable
    assert "of the 4 participants with a target-containing trial, 1 have one at every location" in why
    assert "4 with every method" in why and "more participants" in why
