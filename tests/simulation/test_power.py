"""Power by simulation: a planted effect of known analytic power, Dask equals one process."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from vibrofocus.analysis.fast import rm_anova2_batch
from vibrofocus.errors import ValidationError
from vibrofocus.simulation.bank import default_bank, simulate_cell_means
from vibrofocus.simulation.bank import StudyArrays
from vibrofocus.simulation.power import (TESTS, PowerDesign, direction_sentences, directional_shares,
                                         effect_directions, paper_implied_power,
                                         paper_implied_wilcoxon_power, power_table, robust_conclusions,
                                         run_power, study_statistics)


@pytest.mark.parametrize(("n", "effect"), [(10, 0.6), (20, 0.5)])
def test_planted_paired_effect_matches_analytic_power(n, effect):
    # A 2 x 2 repeated-measures design whose only effect is a method difference d_s ~ N(effect, 1)
    # per subject: the RM-ANOVA F test of method is the paired t-test of d_s, whose power is
    # known analytically (noncentral t).
    n_studies = 3000
    rng = np.random.default_rng(n)
    u = rng.normal(0, 2, (n_studies, n, 1, 1))
    d = rng.normal(effect, 1.0, (n_studies, n, 1, 1))
    noise = rng.normal(0, 0.3, (n_studies, n, 2, 2))
    Y = u + np.concatenate([np.zeros_like(d), d], axis=3) * np.ones((1, 1, 2, 1)) + noise
    p = rm_anova2_batch(Y)["p_gg"][:, 1]
    results = {n: [{"planted_p": float(x)} for x in p]}
    row = power_table(results, 0.05, tests=[("planted", "paired t")])[0]
    # Per-subject method difference of the means over a: d_s + mean_a(e_a1 - e_a0), whose
    # variance is 1 + 2 * 0.3**2 / 2.
    sd = np.sqrt(1.0 + 0.3**2)
    ncp = effect / sd * np.sqrt(n)
    tcrit = stats.t.ppf(0.975, n - 1)
    analytic = stats.nct.sf(tcrit, n - 1, ncp) + stats.nct.cdf(-tcrit, n - 1, ncp)
    se = np.sqrt(analytic * (1 - analytic) / n_studies)
    assert abs(row["power"] - analytic) < 3 * se, (row, analytic, se)
    assert row["se"] == pytest.approx(np.sqrt(row["power"] * (1 - row["power"]) / n_studies))


def test_no_effect_gives_alpha():
    # Spherical data, no effect: the uncorrected F tests reject at alpha; the GG-corrected
    # ones (epsilon <= 1 by construction) at most that often.
    rng = np.random.default_rng(5)
    Y = rng.normal(size=(4000, 12, 3, 3))
    res = rm_anova2_batch(Y)
    se = np.sqrt(0.05 * 0.95 / 4000)
    for j in range(3):
        assert abs(np.mean(res["p_unc"][:, j] < 0.05) - 0.05) < 3 * se
        assert np.mean(res["p_gg"][:, j] < 0.05) < 0.05 + 3 * se


def test_study_statistics_has_every_test():
    arrays = simulate_cell_means(8, np.random.default_rng(0))
    s = study_statistics(arrays)
    for key, _ in TESTS:
        assert 0 <= s[f"{key}_p"] <= 1
    assert arrays.error_mm.shape == (8, 9, 3) and np.all(arrays.count >= 1)


@pytest.mark.slow
def test_dask_equals_one_process():
    design = PowerDesign(n_participants=(4, 6), n_studies=6, seed=3)
    local = run_power(design, local=True, chunk=4)
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        seen = []
        dask = run_power(design, client=client, chunk=2, progress=lambda done, total: seen.append((done, total)))
    np.testing.assert_equal(local["table"], dask["table"])  # exact; NaN (a test that never ran) equals NaN
    for n in design.n_participants:
        for a, b in zip(local["results"][n], dask["results"][n]):
            assert a.keys() == b.keys()
            for k in a:
                np.testing.assert_array_equal(a[k], b[k])
    assert seen[-1] == (12, 12)
    assert "not data" in dask["label"]


def test_bad_designs_are_refused():
    with pytest.raises(ValidationError):
        PowerDesign(n_participants=(2,))
    with pytest.raises(ValidationError):
        PowerDesign(n_studies=0)
    with pytest.raises(ValidationError):
        PowerDesign(alpha=1.5)
    with pytest.raises(ValidationError):
        run_power(PowerDesign(n_participants=(5,), n_studies=1), local=True, chunk=0)


def test_bank_is_the_simulated_participants():
    bank = default_bank()
    assert bank.energy.shape[1:3] == (3, 9) and bank.n_forearms >= 20
    assert bank.methods == ("funneling", "inverse", "combination")


def test_a_method_outside_the_bank_is_refused_with_the_way_to_a_bank_that_has_it():
    design = PowerDesign(n_participants=(5,), n_studies=1, methods=("inverse", "minimax"))  # registered: accepted
    with pytest.raises(ValidationError, match=r"no stimuli of minimax.*--methods funneling,inverse,combination,minimax"):
        run_power(design, local=True)
    with pytest.raises(ValidationError, match="unknown method"):
        PowerDesign(methods=("inverse", "minimx"))


@pytest.mark.slow
def test_power_for_the_minimax_design_from_a_bank_that_renders_it(tmp_path):
    from vibrofocus.simulation.bank import FeatureBank, build_feature_bank

    # Two forearms (sim-001, sim-002 of seed 0) rendered with the inverse filter and minimax.
    bank = build_feature_bank(2, seed=0, methods=("inverse", "minimax"), levels="paper")
    bank.save(tmp_path / "bank.npz")
    loaded = FeatureBank.load(tmp_path / "bank.npz")
    assert loaded.methods == ("inverse", "minimax") and loaded.energy.shape[:3] == (2, 2, 9)
    # The same forearms, calibrations, levels and renderer as the shipped bank: the inverse
    # filter's felt energies are the shipped bank's first two forearms'.
    shipped = default_bank()
    assert shipped.levels == loaded.levels == "paper"
    np.testing.assert_allclose(loaded.energy[:, 0], shipped.energy[:2, shipped.methods.index("inverse")], rtol=1e-6)
    # A minimax drive is a different drive: its felt field differs.
    assert not np.allclose(loaded.energy[:, 1], loaded.energy[:, 0], rtol=0.05)
    design = PowerDesign(n_participants=(6,), n_studies=4, methods=("inverse", "minimax"))
    result = run_power(design, local=True, bank=loaded)
    assert result["design"]["methods"] == ["inverse", "minimax"]
    rows = {r["test"]: r for r in result["table"]}
    assert rows["s1_method"]["n_studies"] == 4 and 0.0 <= rows["s1_method"]["power"] <= 1.0


def test_paper_implied_power_matches_monte_carlo_t_tests():
    # The paper: Bonferroni p = 0.007 over 3 method pairs, 20 participants -> t(19) ~ 3.5,
    # d_z ~ 0.79; a Bonferroni-corrected paired t replication of N has power 0.38 / 0.80 /
    # 0.95 at N = 10 / 20 / 30, and 0.09 / 0.22 / 0.36 at half the effect.
    imp = paper_implied_power((10, 20, 30))
    assert imp["t"] == pytest.approx(3.51, abs=0.01) and imp["d_z"] == pytest.approx(0.785, abs=0.001)
    for n, full, half in ((10, 0.38, 0.09), (20, 0.80, 0.22), (30, 0.95, 0.36)):
        assert imp["power"][str(n)] == pytest.approx(full, abs=0.006)
        assert imp["power_half"][str(n)] == pytest.approx(half, abs=0.006)
    # Independently: simulated replications, each a paired t-test of N differences of mean
    # d_z (SD 1), Bonferroni over 3 pairs.
    rng = np.random.default_rng(2023)
    n_studies = 20000
    for n in (10, 20, 30):
        for key, eff in (("power", imp["d_z"]), ("power_half", imp["d_z"] / 2)):
            d = rng.normal(eff, 1.0, (n_studies, n))
            p = stats.ttest_1samp(d, 0.0, axis=1).pvalue
            share = np.mean(np.minimum(p * 3, 1.0) < 0.05)
            se = np.sqrt(share * (1 - share) / n_studies)
            assert abs(share - imp[key][str(n)]) < 4 * se + 1e-3, (n, key, share, imp[key][str(n)])


def _rows(powers):
    return [{"n_participants": 20, "test": t, "label": t, "power": p, "n_studies": 200, "se": 0.0}
            for t, p in powers.items()]


def test_robust_only_where_the_hypotheses_agree_on_the_direction():
    # Both hypotheses power the Study 1 method test, in opposite directions: no conclusion.
    a = _rows({"s1_location": 1.0, "s1_method": 1.0, "s1_inverse_below": 0.9, "s1_inverse_above": 0.0})
    b = _rows({"s1_location": 1.0, "s1_method": 1.0, "s1_inverse_below": 0.0, "s1_inverse_above": 0.9})
    rows = {r["test"]: r for r in robust_conclusions({"a": a, "b": b})}
    assert rows["s1_location"]["robust"] and rows["s1_location"]["direction"] is None
    for t in ("s1_method", "s1_inverse_below", "s1_inverse_above"):
        assert not rows[t]["robust"] and rows[t]["conclusion"] == "depends on the hypothesis"
        assert rows[t]["direction"] == {"a": "paper", "b": "reverse"}
    # Both not powered in the paper's direction (0.0 and 0.0) but one powered in the reverse.
    assert rows["s1_inverse_below"]["power"] == {"a": 0.9, "b": 0.0}
    # The same direction under both: robust.
    same = {r["test"]: r for r in robust_conclusions({"a": a, "b": a})}
    assert same["s1_method"]["robust"] and same["s1_method"]["conclusion"] == "powered"
    sentence = direction_sentences(effect_directions({"a": a, "b": b}))["s1_inverse_vs_funneling"]
    assert "depends on the hypothesis" in sentence and "a predicts inverse < funneling" in sentence
    assert "b predicts the reverse" in sentence
    agree = direction_sentences(effect_directions({"a": a, "b": a}))["s1_inverse_vs_funneling"]
    assert agree.startswith("at N = 20, every hypothesis predicts inverse < funneling")
    # Neither direction shows when the two shares are within two standard errors.
    tie = _rows({"s1_inverse_below": 0.02, "s1_inverse_above": 0.01})
    assert effect_directions({"a": tie})["s1_inverse_vs_funneling"]["a"][20] == "none"


def test_directional_shares_count_paper_reverse_and_neither():
    results = {10: [{"s1_inverse_below_p": 0.01, "s1_inverse_above_p": 1.0},
                    {"s1_inverse_below_p": 1.0, "s1_inverse_above_p": 0.001},
                    {"s1_inverse_below_p": 1.0, "s1_inverse_above_p": 0.3},
                    {"s1_inverse_below_p": 1.0, "s1_inverse_above_p": 0.02}]}
    shares = directional_shares(results)
    assert shares == {"s1_inverse_vs_funneling": {"10": {"paper": 0.25, "reverse": 0.5, "neither": 0.25}}}


def test_study_statistics_reports_the_reverse():
    # Funneling's error clearly below the inverse filter's: significant in the reverse only.
    rng = np.random.default_rng(4)
    err = 8.0 + rng.normal(0, 0.5, (12, 9, 3))
    err[:, :, 1] += 2.0  # methods: funneling, inverse, combination
    count = 2.0 + rng.normal(0, 0.1, (12, 9, 3))
    count[:, :, 1] += 0.5
    s = study_statistics(StudyArrays(err, count, count.copy()), methods=("funneling", "inverse", "combination"))
    assert s["s1_inverse_above_p"] < 0.05 and s["s1_inverse_below_p"] == 1.0
    assert s["s2_inverse_more_p"] < 0.05 and s["s2_inverse_fewer_p"] == 1.0


def test_wilcoxon_p_is_scipys_bit_for_bit():
    # The power tables' Wilcoxon p (fast where scipy runs its exact permutation test one
    # sign flip at a time) is scipy's own p, exactly: ties, zeros, both signs, n below and
    # past the permutation test's limit of 13 (at 13 scipy's own takes seconds).
    from vibrofocus.simulation.power import _wilcoxon_p

    rng = np.random.default_rng(5)
    cases = [
        (np.array([1.0, 2, 2, 3, 0, 4, 1]), np.array([0.0, 1, 3, 1, 0, 2, 2])),  # zero and ties
        (np.array([2.0, 1, 3, 1, 2, 3, 1, 2, 1]), np.array([1.0, 2, 1, 3, 1, 1, 3, 1, 2])),  # |d| ties across signs
        (rng.normal(size=8), rng.normal(size=8)),  # no ties: scipy's exact distribution
        (rng.integers(0, 3, 11).astype(float), rng.integers(0, 3, 11).astype(float)),
        (rng.integers(0, 3, 14).astype(float), rng.integers(0, 3, 14).astype(float)),  # asymptotic
    ]
    for x, y in cases:
        assert np.count_nonzero(x - y) >= 2
        assert _wilcoxon_p(x, y) == float(stats.wilcoxon(x, y).pvalue), (x, y)
    assert _wilcoxon_p(np.ones(5), np.ones(5)) == 1.0


def test_paper_implied_wilcoxon_power_is_that_of_the_papers_study2_effect():
    # The paper: Bonferroni Wilcoxon p = 0.013 over 3 method pairs, 20 participants (Sec.
    # III.C) -> z = 2.85, a shift of 0.80 SD of normal paired differences; a Bonferroni
    # Wilcoxon replication has power about 0.35 / 0.80 / 0.96 at N = 10 / 20 / 30.
    imp = paper_implied_wilcoxon_power((10, 20, 30), n_studies=2000)
    assert imp["z"] == pytest.approx(2.853, abs=0.001) and imp["theta"] == pytest.approx(0.802, abs=0.002)
    for n, full in ((10, 0.35), (20, 0.80), (30, 0.96)):
        assert imp["power"][str(n)] == pytest.approx(full, abs=0.04)
        assert imp["power_half"][str(n)] < imp["power"][str(n)] / 2
    assert paper_implied_wilcoxon_power((30,), n_studies=2000)["power"]["30"] == imp["power"]["30"]  # per-N seeds
    # Independently: at that shift, 20 participants' signed-rank z (W+ standardized under
    # the null) is the paper's on average.
    rng = np.random.default_rng(7)
    d = rng.normal(imp["theta"], 1.0, (4000, 20))
    ranks = stats.rankdata(np.abs(d), axis=1)
    w = np.sum(ranks * (d > 0), axis=1)
    z = (w - 20 * 21 / 4) / np.sqrt(20 * 21 * 41 / 24)
    assert abs(z.mean() - imp["z"]) < 4 * z.std() / np.sqrt(z.size), z.mean()
