"""Study 1: localization error, ellipses, two-way RM-ANOVA (GG) and post hoc tests.

References used here, all from outside vibrofocus:
- JAMOVI values for pingouin's ``rm_anova2`` dataset and R ``afex::aov_ez`` values for a
  seeded 3 × 3 design, as documented in pingouin's own test suite
  (``tests/test_parametric.py::TestParametric::test_rm_anova2``, pingouin >= 0.7);
- a textbook implementation in numpy written for this test (sums of squares; Greenhouse–
  Geisser epsilon and Mauchly's W from the covariance of orthonormal contrasts, the
  Kronecker product of each factor's contrasts for the interaction);
- scipy.stats.ttest_rel for the post hoc t-tests.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from numpy.testing import assert_allclose
from scipy import linalg, stats

from vibrofocus.analysis import (
    check_design,
    load_trials,
    localization_summary,
    shapiro_tests,
    study1_anova,
    study1_errors,
    study1_posthoc,
)
from vibrofocus.errors import ValidationError

# --------------------------------------------------------------------------- references


def textbook_rm_anova2(y: np.ndarray) -> dict[str, dict[str, float]]:
    """Two-way RM-ANOVA of ``y`` with shape (n_subjects, a, b), from the textbook formulas."""
    n, a, b = y.shape
    g = y.mean()
    m_s, m_a, m_b = y.mean(axis=(1, 2)), y.mean(axis=(0, 2)), y.mean(axis=(0, 1))
    m_sa, m_sb, m_ab = y.mean(axis=2), y.mean(axis=1), y.mean(axis=0)
    ss = {
        "A": n * b * np.sum((m_a - g) ** 2),
        "B": n * a * np.sum((m_b - g) ** 2),
        "AB": n * np.sum((m_ab - m_a[:, None] - m_b[None, :] + g) ** 2),
    }
    ss_err = {
        "A": b * np.sum((m_sa - m_s[:, None] - m_a[None, :] + g) ** 2),
        "B": a * np.sum((m_sb - m_s[:, None] - m_b[None, :] + g) ** 2),
        "AB": np.sum(
            (
                y
                - m_sa[:, :, None]
                - m_sb[:, None, :]
                - m_ab[None]
                + m_s[:, None, None]
                + m_a[None, :, None]
                + m_b[None, None, :]
                - g
            )
            ** 2
        ),
    }
    c_a = linalg.null_space(np.ones((1, a)))  # orthonormal contrasts, shape (a, a-1)
    c_b = linalg.null_space(np.ones((1, b)))
    scores = {"A": m_sa @ c_a, "B": m_sb @ c_b, "AB": y.reshape(n, a * b) @ np.kron(c_a, c_b)}
    out = {}
    for key, z in scores.items():
        d = z.shape[1]
        df1, df2 = d, d * (n - 1)
        f = (ss[key] / df1) / (ss_err[key] / df2)
        s = np.atleast_2d(np.cov(z, rowvar=False))
        eps = np.trace(s) ** 2 / (d * np.trace(s @ s))
        w = np.linalg.det(s) / (np.trace(s) / d) ** d
        out[key] = {
            "F": f,
            "ddof1": df1,
            "ddof2": df2,
            "p_unc": stats.f.sf(f, df1, df2),
            "eps": eps,
            "p_gg": stats.f.sf(f, eps * df1, eps * df2),
            "W": w,
        }
    return out


def _long(y: np.ndarray, a_levels, b_levels) -> pd.DataFrame:
    n = y.shape[0]
    rows = [
        (f"S{s:02d}", a_levels[i], b_levels[j], y[s, i, j])
        for s in range(n)
        for i in range(len(a_levels))
        for j in range(len(b_levels))
    ]
    return pd.DataFrame(rows, columns=["participant", "location", "method", "error_mm"])


# --------------------------------------------------------------------------- ANOVA


def test_anova_reproduces_jamovi_on_pingouin_rm_anova2():
    # pingouin's rm_anova2 dataset (10 subjects, Time 2 × Metric 3); JAMOVI values as listed
    # in pingouin's tests/test_parametric.py (test_rm_anova2), rounded there to 5 decimals.
    data = pg.read_dataset("rm_anova2")
    aov = study1_anova(data, dv="Performance", within=("Time", "Metric"), subject="Subject")
    assert aov["effect"].tolist() == ["Time", "Metric", "Time * Metric"]
    assert_allclose(aov["F"], [33.85228, 26.95919, 12.63227], atol=1e-4)
    assert_allclose(aov["MS"], [828.81667, 682.61667, 112.21667], atol=1e-4)
    assert_allclose(aov["eps"], [1.0, 0.96910, 0.72717], atol=1e-4)
    assert_allclose(aov["W_mauchly"].iloc[1:], [0.96812, 0.6248], atol=1e-4)
    assert_allclose(aov["p_mauchly"], [1.0, 0.87844, 0.15239], atol=1e-4)
    assert aov["ddof1"].tolist() == [1, 2, 2] and aov["ddof2"].tolist() == [9, 18, 18]
    # GG-corrected p from its definition (F distribution with eps-scaled dofs).
    assert_allclose(aov["p_gg"], stats.f.sf(aov["F"], aov["eps"] * aov["ddof1"], aov["eps"] * aov["ddof2"]), rtol=1e-10)


def test_anova_reproduces_afex_on_nonspherical_3x3_design():
    # Seeded non-spherical 3 × 3 design and R afex::aov_ez results, both as documented in
    # pingouin's tests/test_parametric.py (test_rm_anova2, the interaction epsilon fix).
    rng = np.random.default_rng(1)
    rows = []
    for s in range(15):
        base = rng.normal()
        for i, fa in enumerate("abc"):
            for j, fb in enumerate("xyz"):
                rows.append((s, fa, fb, base + 0.5 * i + 0.3 * j * i + rng.normal(0, 0.3 + 0.5 * i * j)))
    df = pd.DataFrame(rows, columns=["S", "A", "B", "y"])
    aov = study1_anova(df, dv="y", within=("A", "B"), subject="S")
    assert_allclose(aov["F"], [53.9024, 3.53315, 3.05294], atol=1e-4)
    assert_allclose(aov["eps"], [0.76334, 0.86145, 0.67162], atol=1e-4)
    assert_allclose(aov["p_gg"], [0.0, 0.05118, 0.04513], atol=1e-4)
    assert_allclose(aov["W_mauchly"], [0.68997, 0.83917, 0.32683], atol=1e-4)
    assert_allclose(aov["p_mauchly"], [0.08962, 0.31991, 0.12972], atol=1e-4)


def test_anova_matches_textbook_formulas_on_the_study_design():
    # 20 participants × 9 locations × 3 methods, heteroscedastic so that eps < 1.
    rng = np.random.default_rng(20261122)
    n, a, b = 20, 9, 3
    sd = rng.uniform(0.5, 3.0, size=(a, b))
    y = rng.normal(0, 1, (n, 1, 1)) + np.arange(b) * 0.4 + rng.normal(0, 1, (n, a, b)) * sd
    methods = ["funneling", "inverse", "combination"]
    aov = study1_anova(_long(y, list(range(1, a + 1)), methods)).set_index("effect")
    ref = textbook_rm_anova2(y)
    for effect, key in (("location", "A"), ("method", "B"), ("location * method", "AB")):
        row = aov.loc[effect]
        for col in ("F", "ddof1", "ddof2", "p_unc", "eps", "p_gg"):
            assert_allclose(row[col], ref[key][col], rtol=1e-8, err_msg=f"{effect} {col}")
        assert_allclose(row["ddof1_gg"], ref[key]["eps"] * ref[key]["ddof1"], rtol=1e-8)
        assert_allclose(row["W_mauchly"], ref[key]["W"], rtol=1e-6, err_msg=f"{effect} Mauchly W")
        assert row["mauchly_defined"]
    assert aov.loc["location", "eps"] < 0.9  # the design really is non-spherical


def test_anova_marks_mauchly_undefined_with_few_participants():
    rng = np.random.default_rng(3)
    y = rng.normal(size=(6, 9, 3))
    aov = study1_anova(_long(y, list(range(1, 10)), ["funneling", "inverse", "combination"])).set_index("effect")
    # 6 participants: 8 location contrasts and 16 interaction contrasts cannot be tested.
    assert not aov.loc["location", "mauchly_defined"] and not aov.loc["location * method", "mauchly_defined"]
    assert np.isnan(aov.loc["location", "p_mauchly"]) and aov.loc["location", "sphericity_violated"] is None
    assert aov.loc["method", "mauchly_defined"]
    assert_allclose(aov.loc["location", "eps"], textbook_rm_anova2(y)["A"]["eps"], rtol=1e-8)


def test_anova_refuses_incomplete_subject():
    rng = np.random.default_rng(4)
    df = _long(rng.normal(size=(5, 3, 2)), [1, 2, 3], ["funneling", "inverse"])
    with pytest.raises(ValidationError, match="S02"):
        study1_anova(df.drop(index=13))  # rows 12..17 are S02: it loses one cell
    with pytest.raises(ValidationError, match="at least 3 participants, got 1"):
        study1_anova(df[df["participant"] == "S00"])
    # Two subjects: pingouin's Mauchly divides by zero; refused with a reason instead.
    with pytest.raises(ValidationError, match="at least 3 participants, got 2.*Mauchly"):
        study1_anova(df[df["participant"].isin(["S00", "S01"])])


# --------------------------------------------------------------------------- errors, ellipses


def _trials(rows) -> pd.DataFrame:
    cols = ["participant", "study", "phase", "trial", "method", "target", "response", "rt_s"]
    return load_trials(pd.DataFrame(rows, columns=cols))


def test_errors_are_euclidean_distances_in_mm():
    # Reference layout: 1 = (-10, +10) mm, 2 = (0, +10), 5 = (0, 0), 9 = (+10, -10).
    trials = _trials(
        [
            ("P1", 1, "main", 1, "inverse", 1, "2", 1.0),  # 10 mm
            ("P1", 1, "main", 2, "inverse", 1, "1", 1.0),  # 0 mm
            ("P1", 1, "main", 3, "funneling", 5, "9", 1.0),  # sqrt(200) mm
        ]
    )
    errors = study1_errors(trials).set_index(["location", "method"])
    assert_allclose(errors.loc[(1, "inverse"), "error_mm"], 5.0, rtol=1e-12)
    assert errors.loc[(1, "inverse"), "n_trials"] == 2
    assert_allclose(errors.loc[(5, "funneling"), "error_mm"], np.sqrt(200.0), rtol=1e-12)


def test_localization_ellipse_by_hand():
    # Target 5 answered 4, 6, 2, 8: x = -10, 10, 0, 0 and y = 0, 0, 10, -10 mm.
    rows = [("P1", 1, "main", i + 1, "inverse", 5, r, 1.0) for i, r in enumerate(["4", "6", "2", "8"])]
    # Target 1 answered 1, 1, 3: x = -10, -10, 10 (var 133.3), y = 10 always.
    rows += [("P1", 1, "main", 10 + i, "funneling", 1, r, 1.0) for i, r in enumerate(["1", "1", "3"])]
    summary = localization_summary(_trials(rows)).set_index(["location", "method"])
    s5 = summary.loc[(5, "inverse")]
    assert_allclose([s5.mean_x_mm, s5.mean_y_mm, s5.bias_mm], [0, 0, 0], atol=1e-12)
    assert_allclose([s5.cov_xx_mm2, s5.cov_yy_mm2, s5.cov_xy_mm2], [200 / 3, 200 / 3, 0], atol=1e-9)
    assert_allclose([s5.ellipse_width_mm, s5.ellipse_height_mm], 2 * np.sqrt(200 / 3), rtol=1e-9)
    s1 = summary.loc[(1, "funneling")]
    assert_allclose([s1.mean_x_mm, s1.mean_y_mm], [-10 / 3, 10], rtol=1e-12)
    assert_allclose(s1.ellipse_width_mm, 2 * np.sqrt(400 / 3), rtol=1e-9)  # var of (-10,-10,10), ddof 1
    assert_allclose(s1.ellipse_height_mm, 0.0, atol=1e-9)
    assert_allclose(s1.ellipse_angle_deg % 180, 0.0, atol=1e-6)  # major axis along x
    assert_allclose(s1.mean_error_mm, 20 / 3, rtol=1e-12)


# --------------------------------------------------------------------------- post hoc, normality


def test_posthoc_matches_paired_t_tests_with_bonferroni():
    rng = np.random.default_rng(7)
    y = rng.normal(size=(10, 3, 3)) + np.array([0.0, 0.8, 0.2])
    methods = ["funneling", "inverse", "combination"]
    errors = _long(y, [1, 2, 3], methods)
    main, inter = study1_posthoc(errors)
    per_method = y.mean(axis=1)  # (subjects, methods): mean over locations
    for row in main.itertuples():
        i, j = methods.index(row.A), methods.index(row.B)
        ref = stats.ttest_rel(per_method[:, i], per_method[:, j])
        assert_allclose([row.T, row.p_unc], [ref.statistic, ref.pvalue], rtol=1e-8)
        assert_allclose(row.p_bonf, min(1.0, 3 * ref.pvalue), rtol=1e-8)
    assert len(main) == 3 and len(inter) == 9 and set(inter["location"]) == {1, 2, 3}
    for row in inter.itertuples():
        i, j = methods.index(row.A), methods.index(row.B)
        ref = stats.ttest_rel(y[:, row.location - 1, i], y[:, row.location - 1, j])
        assert_allclose(row.p_bonf, min(1.0, 3 * ref.pvalue), rtol=1e-8)  # 3 comparisons per location


def test_shapiro_per_condition_and_too_few_values():
    rng = np.random.default_rng(8)
    y = rng.normal(size=(8, 2, 2))
    y[:, 1, 1] = rng.exponential(size=8) ** 3  # strongly skewed cell
    res = shapiro_tests(_long(y, [1, 2], ["funneling", "inverse"])).set_index(["location", "method"])
    ref = stats.shapiro(y[:, 1, 1])
    assert_allclose([res.loc[(2, "inverse"), "W"], res.loc[(2, "inverse"), "p"]], [ref.statistic, ref.pvalue])
    assert len(res) == 4
    two = shapiro_tests(_long(y[:2], [1, 2], ["funneling", "inverse"]))
    assert two["W"].isna().all() and (two["n"] == 2).all()


# --------------------------------------------------------------------------- planted / null effects


def _anova_method_p(df: pd.DataFrame) -> float:
    trials = load_trials(df)
    complete, _, _ = check_design(trials, 1)
    aov = study1_anova(study1_errors(complete)).set_index("effect")
    return float(aov.loc["method", "p_gg"])


def test_planted_method_effect_is_detected(synthetic):
    df = synthetic(
        10, seed=101, sd_mm={"funneling": 9.0, "inverse": 5.0, "combination": 5.0}, studies=(1,), n_training=0
    )
    trials = load_trials(df)
    complete, _, _ = check_design(trials, 1)
    errors = study1_errors(complete)
    aov = study1_anova(errors).set_index("effect")
    assert aov.loc["method", "p_gg"] < 0.05
    main, _ = study1_posthoc(errors)
    pair = main[(main["A"] == "funneling") | (main["B"] == "funneling")]
    assert (pair["p_bonf"] < 0.05).all()
    means = errors.groupby("method")["error_mm"].mean()
    assert means["funneling"] > max(means["inverse"], means["combination"])


def test_no_method_effect_without_one_fixed_seed(synthetic):
    # Seed 0 fixed before the first run; all methods share the same perceptual noise.
    assert _anova_method_p(synthetic(10, seed=0, studies=(1,), n_training=0)) > 0.05


def test_false_positive_rate_of_the_method_effect_is_near_alpha(synthetic):
    # 30 null data sets (seeds 1000..1029, chosen in advance). Under H0 the number of
    # p < 0.05 is Binomial(30, 0.05): mean 1.5, P(X >= 6) = 0.016. A test that ignored the
    # repeated measures or the sphericity correction would reject far more often.
    pvals = np.array([_anova_method_p(synthetic(8, seed=s, studies=(1,), n_training=0)) for s in range(1000, 1030)])
    assert np.sum(pvals < 0.05) <= 5
    # and the p-values are not degenerate (a broken test could return p = 1 always)
    assert 0.2 < np.median(pvals) < 0.8


def test_posthoc_identical_differences_are_no_test_and_in_method_order():
    # Differences combination - inverse equal in every subject up to float rounding
    # (10.786893 - 7.45356 != 3.333333 exactly): a t statistic of ~1e15 would be an
    # artefact; the pair must be reported as "no test". Pairs follow method_order.
    rng = np.random.default_rng(12)
    y = rng.normal(5.0, 2.0, size=(4, 2, 3))  # subjects, locations, methods (funneling, inverse, combination)
    y[:, 0, 2] = y[:, 0, 1] + 10.0 / 3.0
    errors = _long(y, [1, 2], ["funneling", "inverse", "combination"])
    main, inter = study1_posthoc(errors)
    assert list(zip(main["A"], main["B"])) == [("funneling", "inverse"), ("funneling", "combination"),
                                               ("inverse", "combination")]  # fmt: skip
    flat = inter[(inter["location"] == 1) & (inter["A"] == "inverse") & (inter["B"] == "combination")]
    assert len(flat) == 1 and np.isnan(flat["T"].iloc[0]) and np.isnan(flat["p_bonf"].iloc[0])
    assert "no variance" in flat["note"].iloc[0]
    # The swapped pairs keep the sign of A - B.
    row = main[(main["A"] == "funneling") & (main["B"] == "combination")].iloc[0]
    ref = stats.ttest_rel(y[:, :, 0].mean(axis=1), y[:, :, 2].mean(axis=1))
    assert_allclose([row["T"], row["p_unc"]], [ref.statistic, ref.pvalue], rtol=1e-8)


def test_posthoc_refuses_one_subject():
    rng = np.random.default_rng(13)
    errors = _long(rng.normal(size=(1, 2, 2)), [1, 2], ["funneling", "inverse"])
    with pytest.raises(ValidationError, match="at least 2 participants"):
        study1_posthoc(errors)
