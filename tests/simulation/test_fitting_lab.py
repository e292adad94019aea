"""Fitting hypotheses to a lab's trials: the marginal likelihood, the fit, ELPD, recovery, the report."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from vibrofocus.analysis import load_trials
from vibrofocus.errors import ValidationError
from vibrofocus.simulation import Hypothesis, ParameterRange, default_bank, hypothesis, marginal_loglik
from vibrofocus.simulation.fitting import (FitSettings, compare_hypotheses, fit_hypothesis, lab_trials,
                                           model_recovery, participant_loglik, recovery_rates, simulate_plan_trials,
                                           simulate_trials)
from vibrofocus.simulation.fitting.elpd import fold_logliks
from vibrofocus.simulation.likelihood import Quadrature, Stimuli
from vibrofocus.simulation.parameters import read_parameters

#: A hypothesis with one free parameter: v3's readout, the prior's centre free along x.
SHIFT = Hypothesis(name="test-shift", version="1", title="v3 with the prior's x shift free", sources="test",
                   parameters=dict(hypothesis("v3-centroid").parameters),
                   free_parameters=(ParameterRange("bias_mean_m", -0.01, 0.01, "assumption: a test range", 0),))
FAST = FitSettings(n_draws=8, n_starts=1, maxiter=15)


def _study1_only(data):
    return data.subset(np.arange(data.n_participants), studies=(1,))


def test_participant_loglik_is_marginal_loglik_per_participant():
    # One forearm, no lapse, the likelihood's own quadrature: the shared-draw pass over all
    # participants gives each one exactly what marginal_loglik gives it alone.
    b = default_bank()
    one = dataclasses.replace(b, energy=b.energy[:1], actuator_energy=b.actuator_energy[:1],
                              forearm_seeds=b.forearm_seeds[:1])
    data = simulate_trials("v3-centroid", 2, np.random.default_rng(3), bank=one, repetitions=1)
    got = participant_loglik("v3-centroid", data, bank=one,
                             settings=FitSettings(n_draws=3, lapse=0.0, quadrature=Quadrature()))
    st = Stimuli.from_bank(one, 0)
    for i in range(2):
        m1, m2 = data.part1 == i, data.part2 == i
        want = marginal_loglik("v3-centroid", st, study1=(data.stim1[m1], data.answer1[m1]),
                               study2=(data.stim2[m2], data.selected2[m2]), n_draws=3, seed=0)
        np.testing.assert_allclose(got[i], want, rtol=1e-12)


def test_draw_batches_are_the_population_draws_level_by_level():
    # Batches of 2 of 5 draws at three levels (the levels' stimuli stacked in one call of the
    # hypothesis): each draw's traits and percepts are those of level_draws, one at a time.
    from vibrofocus.simulation.fitting.likelihood_fit import draw_batches, level_draws

    b = default_bank()
    levels = (-20.0, -5.0, 0.0)
    for name in ("grid-peak", "level-reliability", "intensity"):
        h = hypothesis(name)
        m = h.model()
        s = FitSettings(n_draws=5, seed=4)
        batches = list(draw_batches(h, m, b, s, levels, size=2))
        assert [len(x.traits) for x in batches] == [2, 2, 1]
        for k, (traits, at) in enumerate(level_draws(h, m, b, s, levels)):
            batch = batches[k // 2]
            assert batch.traits[k % 2].to_dict() == traits.to_dict()
            for v in levels:
                want, got = at[v][1], batch.draw_percepts(v, k % 2)
                for f in dataclasses.fields(want):
                    a, c = getattr(want, f.name), getattr(got, f.name)
                    assert (a is None) == (c is None), f.name
                    if a is not None:  # the same to rounding (a stacked call's sums may round apart)
                        np.testing.assert_allclose(np.asarray(c, float), np.asarray(a, float), rtol=1e-12, atol=1e-15,
                                                   err_msg=f"{name} {v} dB {f.name}")


def test_traits_per_row_give_each_row_its_own_posterior():
    from vibrofocus.simulation.perception import Traits, trial_posteriors

    b = default_bank()
    h = hypothesis("level-reliability")
    m = h.model()
    rng = np.random.default_rng(8)
    drawn = [Traits.draw(m, rng) for _ in range(3)]
    per = Stimuli.from_bank(b.at_level(-20.0), 2).percepts(h, m, drawn[0])
    idx = np.array([0, 5, 26, 13, 0])
    who = np.array([0, 1, 2, 1, 2])
    noise = rng.standard_normal((idx.size, 2))
    rows = Traits(0.0, np.array([t.acuity_sd_m for t in drawn])[who], np.array([t.prior_sd_m for t in drawn])[who],
                  np.array([t.bias_m for t in drawn])[who], 0.5, 1.0, np.array([t.spread_gain for t in drawn])[who])
    got = trial_posteriors(per, idx, b.centre_xy, m, rows, noise)
    assert not got.felt.all()  # both branches: felt and not felt
    for i in range(idx.size):
        want = trial_posteriors(per, idx[i:i + 1], b.centre_xy, m, drawn[who[i]], noise[i:i + 1])
        np.testing.assert_allclose(got.perceived_m[i], want.perceived_m[0], rtol=1e-12, atol=0)
        np.testing.assert_allclose(got.sd_m[i], want.sd_m[0], rtol=1e-12, atol=0)


@pytest.mark.slow
def test_fit_recovers_a_free_parameter():
    truth = 0.006
    data = _study1_only(simulate_trials(SHIFT, 10, np.random.default_rng(11), values={"bias_mean_m[0]": truth}))
    fit = fit_hypothesis(SHIFT, data, settings=FAST)
    assert abs(fit.params["bias_mean_m[0]"] - truth) < 0.002, fit.params
    # the fit is a maximum: the hypothesis' own value (-3.6 mm) scores lower
    assert fit.loglik > participant_loglik(SHIFT, data, None, settings=FAST).sum()
    again = fit_hypothesis(SHIFT, data, settings=FAST)
    assert again.params == fit.params  # deterministic


def test_the_fit_moves_a_parameter_that_acts_through_the_threshold():
    # intensity's sensation level of the reference tap, alone free: it moves the felt
    # field's points across the detection threshold, so the likelihood is jagged at a
    # finite-difference step (the old L-BFGS-B, eps 1e-4 of the range, stayed at the
    # start, 16.3 dB, 70 below the truth's log-likelihood). The fit must climb at least
    # as high as the true value and leave the start.
    h = hypothesis("intensity")
    one = dataclasses.replace(h, name="intensity-sl",
                              free_parameters=tuple(r for r in h.free_parameters if r.key == "sl_ref_db"))
    s = FitSettings(n_draws=8, n_starts=1, maxiter=30)
    data = _study1_only(simulate_trials(one, 8, np.random.default_rng([5, 5]), values={"sl_ref_db": 12.0}))
    fit = fit_hypothesis(one, data, settings=s)
    at_truth = participant_loglik(one, data, [12.0], settings=s).sum()
    assert fit.loglik >= at_truth - 1e-9, (fit.params, fit.loglik, at_truth)
    assert abs(fit.params["sl_ref_db"] - 16.3) > 2.0, fit.params


def test_a_parameter_fixed_out_of_the_fit_stays_at_the_hypothesis_value():
    # Hypothesis.with_fixed: the fit neither returns nor moves it; the likelihood reads
    # the hypothesis' own value (the same as passing that value to the full hypothesis).
    h = hypothesis("intensity")
    f = h.with_fixed(("sl_ref_db",), "a test")
    data = _study1_only(simulate_trials("intensity", 2, np.random.default_rng(9), repetitions=1))
    s = FitSettings(n_draws=4, n_starts=1, maxiter=4)
    fit = fit_hypothesis(f, data, settings=s)
    assert "sl_ref_db" not in fit.params and set(fit.params) == {r.key for r in f.free_parameters}
    full = {**fit.params, "sl_ref_db": h.model().sl_ref_db}
    np.testing.assert_allclose(fit.participant_loglik, participant_loglik(h, data, full, settings=s), rtol=1e-12)


def test_the_first_simplex_steps_a_tenth_of_every_range_inward():
    from vibrofocus.simulation.fitting.likelihood_fit import initial_simplex

    got = initial_simplex(np.array([0.0, 0.7, 1.0]))
    np.testing.assert_allclose(got, [[0.0, 0.7, 1.0], [0.1, 0.7, 1.0], [0.0, 0.6, 1.0], [0.0, 0.7, 0.9]],
                               atol=1e-15)


def test_without_study2_the_selection_parameters_stay_where_they_start():
    data = _study1_only(simulate_trials("grid-peak", 2, np.random.default_rng(8), repetitions=1))
    h = hypothesis("grid-peak")
    fit = fit_hypothesis(h, data, settings=FitSettings(n_draws=2, n_starts=2, maxiter=6))
    shipped = dict(zip([r.key for r in h.free_parameters], read_parameters(h.model(), h.free_parameters)))
    selection = [k for k in shipped if k.startswith("select_")]
    assert selection  # grid-peak's recovered selection parameter(s): docs/fitting-hypotheses.md
    for k in selection:
        assert fit.params[k] == pytest.approx(shipped[k], abs=1e-12), (k, fit.params)


def test_model_recovery_chooses_the_true_hypothesis():
    # Two hypotheses that differ clearly, Study 1 only, few small studies: the true one wins.
    # Scored at their shipped parameters (refit=False): a refit of their 14-15 free
    # parameters costs thousands of likelihoods per study (scripts/model_recovery.py).
    rec = model_recovery(["v3-centroid", "grid-peak"], n_studies=2, n_participants=5, seed=51,
                         settings=FitSettings(n_draws=6), local=True, study1_only=True, refit=False)
    assert np.array_equal(np.diag(rec["confusion"]), [2, 2]), rec["confusion"]


def test_recovery_rates_give_the_exact_interval_the_decisive_choices_and_the_lead():
    names = ["a", "b"]
    # a: chosen in 30 of 30; b: in 0 of 30, always lost to a, by 1 +- 0.4 (decisive) or 1 +- 1.
    studies = ([{"true": "a", "chosen": "a", "elpd": {"a": -10.0, "b": -13.0}, "difference": 3.0,
                 "difference_se": 1.0}] * 30
               + [{"true": "b", "chosen": "a", "elpd": {"a": -10.0, "b": -11.0}, "difference": 1.0,
                   "difference_se": 0.4 if j % 3 == 0 else 1.0} for j in range(30)])
    rates = recovery_rates(names, studies)
    # Clopper-Pearson at 0 or n of n successes: the open end is (alpha/2) ** (1/n) from the other.
    tail = 0.025 ** (1.0 / 30.0)
    assert (rates["a"]["correct"], rates["a"]["studies"], rates["a"]["rate"]) == (30, 30, 1.0)
    np.testing.assert_allclose([rates["a"]["low"], rates["a"]["high"]], [tail, 1.0], rtol=1e-9)
    np.testing.assert_allclose([rates["b"]["low"], rates["b"]["high"]], [0.0, 1.0 - tail], rtol=1e-9, atol=1e-12)
    assert rates["a"]["decisive"] == (30, 0) and rates["b"]["decisive"] == (0, 10)
    assert rates["a"]["rival"] is None and rates["b"]["rival"] == "a"
    np.testing.assert_allclose([rates["a"]["lead"], rates["b"]["lead"]], [3.0, -1.0], rtol=1e-12)
    assert recovery_rates(names, [{"true": "a", "chosen": "b"}])["a"]["decisive"] == (0, 0)


def test_a_plan_s_simulated_answers_stay_within_each_block():
    from vibrofocus.participant_models.design import PlanBlock

    plan = (PlanBlock(("inverse",), 0.0, (1, 3, 7, 9), 2, "corners", "location"),
            PlanBlock(("funneling", "combination"), -10.0, tuple(range(1, 10)), 1, "all", "location"))
    data = simulate_plan_trials("v3-centroid", plan, 3, np.random.default_rng(8))
    per_participant = 4 * 2 + 2 * 9
    assert data.stim1.size == 3 * per_participant and data.stim2.size == 0
    assert np.array_equal(np.bincount(data.part1), [per_participant] * 3)
    corners = data.level1 == 0.0
    assert corners.sum() == 3 * 8 and np.isin(data.answer1[corners] + 1, (1, 3, 7, 9)).all()
    assert data.allowed1[np.arange(data.answer1.size), data.answer1].all()
    assert np.array_equal(data.allowed1[corners].sum(axis=1), np.full(24, 4))
    again = simulate_plan_trials("v3-centroid", plan, 3, np.random.default_rng(8))
    assert np.array_equal(again.answer1, data.answer1)
    with pytest.raises(ValidationError, match="location blocks only"):
        simulate_plan_trials("v3-centroid", (PlanBlock(("inverse",), 0.0, (1, 9), 1, "", "point"),), 1,
                             np.random.default_rng(8))


def test_elpd_names_the_best_with_its_difference():
    # The hypotheses as shipped, nothing fitted (their 14-15 free parameters would cost
    # thousands of likelihoods): the score and its difference are bookkeeping either way.
    data = _study1_only(simulate_trials("grid-peak", 5, np.random.default_rng(5), repetitions=2))
    fixed = [dataclasses.replace(hypothesis(n), free_parameters=()) for n in ("v3-centroid", "grid-peak")]
    res = compare_hypotheses(data, fixed, settings=FitSettings(n_draws=6), local=True)
    assert res["chosen"] == "grid-peak" and res["runner_up"] == "v3-centroid"
    h = res["hypotheses"]
    np.testing.assert_allclose(res["difference"], h["grid-peak"]["elpd"] - h["v3-centroid"]["elpd"], rtol=1e-12)
    d = np.subtract(h["grid-peak"]["pointwise"], h["v3-centroid"]["pointwise"])
    np.testing.assert_allclose(res["difference_se"], np.sqrt(d.size * d.var(ddof=1)), rtol=1e-12)
    np.testing.assert_allclose(h["grid-peak"]["elpd"], np.sum(h["grid-peak"]["pointwise"]), rtol=1e-12)


def test_a_left_out_participant_is_scored_on_draws_the_fit_did_not_tune():
    # The ELPD's score integrates over score_draws draws of another stream: a fit tunes
    # the population to its own few draws, and a score on them favours the hypothesis with
    # the most free parameters (docs/fitting-hypotheses.md, "Model recovery").
    data = _study1_only(simulate_trials(SHIFT, 3, np.random.default_rng(2), repetitions=1))
    s = FitSettings(n_draws=3, n_starts=1, maxiter=4, score_draws=20)
    assert s.scoring().n_draws == 20 and s.scoring().seed != s.seed
    res = compare_hypotheses(data, [SHIFT], settings=s, local=True)["hypotheses"]["test-shift"]
    for i, params in enumerate(res["fold_params"]):
        one = data.subset(np.array([i]))
        np.testing.assert_allclose(res["pointwise"][i], participant_loglik(SHIFT, one, params, settings=s.scoring()),
                                   rtol=1e-12)
        assert res["pointwise"][i] != participant_loglik(SHIFT, one, params, settings=s)[0]


def test_folds_sharing_evaluations_give_the_numbers_of_folds_fitted_alone():
    # A fold refits on the other participants' own trials (data.subset), from the fit to
    # everyone; folds run together read each parameter set's likelihoods from one pass
    # over every participant. The numbers must not depend on which way.
    data = simulate_trials(SHIFT, 3, np.random.default_rng(4), repetitions=1)
    s = FitSettings(n_draws=2, n_starts=1, maxiter=4, score_draws=4)
    start = {"bias_mean_m[0]": 0.002}
    shared = fold_logliks(SHIFT, data, [0, 1, 2], start, default_bank(), s)
    evaluations = 0
    for i, (ll, params) in enumerate(shared):
        keep = np.delete(np.arange(3), i)
        alone = fit_hypothesis(SHIFT, data.subset(keep), settings=s, start=start)
        evaluations += alone.n_evaluations
        assert params == pytest.approx(alone.params, rel=1e-12, abs=0.0)
        want = participant_loglik(SHIFT, data.subset(np.array([i])), alone.params, settings=s.scoring())[0]
        np.testing.assert_allclose(ll, want, rtol=1e-12)
    assert evaluations >= 3 * 3  # each fold's first simplex and a step: the folds did search


def test_trial_groups_cover_every_trial_once_with_its_own_stimulus():
    data = simulate_trials("v3-centroid", 3, np.random.default_rng(8), repetitions=1)
    rng = np.random.default_rng(9)
    allowed1 = np.ones((data.stim1.size, data.n_locations), dtype=bool)
    allowed1[::3, :4] = False
    level2 = np.where(rng.random(data.stim2.size) < 0.5, 0.0, -10.0)
    data = dataclasses.replace(data, level1=np.where(np.arange(data.stim1.size) % 2, -5.0, 0.0), allowed1=allowed1,
                               level2=level2)
    level1, allowed, _ = data.study1_conditions()
    seen = np.zeros(data.stim1.size, dtype=int)
    for g in data.study1_groups:
        seen[g.rows] += 1
        np.testing.assert_array_equal(g.stimuli[g.which], data.stim1[g.rows])
        assert np.all(level1[g.rows] == g.level_db)
        want = np.arange(data.n_locations) if g.allowed is None else g.allowed
        assert np.all(allowed[g.rows] == np.isin(np.arange(data.n_locations), want))
    assert np.all(seen == 1) and len(data.study1_groups) == 4
    seen = np.zeros(data.stim2.size, dtype=int)
    for g in data.study2_groups:
        seen[g.rows] += 1
        np.testing.assert_array_equal(g.stimuli[g.which], data.stim2[g.rows])
        np.testing.assert_array_equal(g.selections[g.which], data.selected2[g.rows])
        assert np.all(level2[g.rows] == g.level_db) and g.allowed is None
    assert np.all(seen == 1) and {g.level_db for g in data.study2_groups} == {0.0, -10.0}


@pytest.mark.slow
def test_folds_on_dask_give_the_numbers_of_one_process():
    data = _study1_only(simulate_trials(SHIFT, 3, np.random.default_rng(2), repetitions=1))
    s = FitSettings(n_draws=3, n_starts=1, maxiter=5)
    here = compare_hypotheses(data, [SHIFT], settings=s, local=True)
    there = compare_hypotheses(data, [SHIFT], settings=s, n_workers=1)
    assert len(here["hypotheses"]["test-shift"]["fold_params"]) == 3
    np.testing.assert_allclose(there["hypotheses"]["test-shift"]["pointwise"],
                               here["hypotheses"]["test-shift"]["pointwise"], rtol=1e-12)


def _table(rows):
    return load_trials(pd.DataFrame(rows, columns=["participant", "study", "phase", "trial", "method", "target",
                                                   "response", "rt_s"]))


@pytest.mark.parametrize("rows, match", [
    ([("p1", 1, "training", 1, "funneling", 5, "5", "")], "no main-phase trials"),
    ([("p1", 1, "main", 1, "minimax", 5, "5", "")], "minimax"),
])
def test_trials_the_bank_cannot_present_are_refused(rows, match):
    with pytest.raises(ValidationError, match=match):
        lab_trials(_table(rows), default_bank())


def test_trials_at_another_level_rule_are_refused():
    trials = _table([("p1", 1, "main", 1, "funneling", 5, "5", "")])
    trials["levels"] = "equal-peak"
    with pytest.raises(ValidationError, match="level rule 'equal-peak'"):
        lab_trials(trials, default_bank())


@pytest.mark.parametrize("spec, named", [("intensity", "NAME:KEY"), ("telepathy:sl_ref_db", "NAME:KEY"),
                                          ("intensity:central_weight", "'central_weight' is not a free parameter")])
def test_analyze_refuses_a_bad_fix_before_any_work(tmp_path, spec, named):
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    data = _study1_only(simulate_trials("grid-peak", 2, np.random.default_rng(9), repetitions=1))
    csv = tmp_path / "trials.csv"
    data.table().to_csv(csv, index=False)
    res = CliRunner().invoke(app, ["analyze", str(csv), "--out", str(tmp_path / "report"), "--hypotheses",
                                   "--no-dask", "--fix", spec])
    assert res.exit_code == 2 and named in res.output, res.output
    assert not (tmp_path / "report").exists()


@pytest.mark.slow
def test_analyze_hypotheses_writes_the_fit_and_its_section(tmp_path):
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    data = _study1_only(simulate_trials("grid-peak", 3, np.random.default_rng(9), repetitions=1))
    csv = tmp_path / "trials.csv"
    data.table().to_csv(csv, index=False)
    out = tmp_path / "report"
    res = CliRunner().invoke(app, ["analyze", str(csv), "--out", str(out), "--hypotheses", "--no-dask",
                                   "--draws", "3", "--score-draws", "5", "--fix", "intensity:sl_ref_db,bias_sd_m", "-q"])
    assert res.exit_code == 0, res.output
    fit = json.loads((out / "hypotheses.json").read_text())
    assert (fit["settings"]["n_draws"], fit["settings"]["score_draws"]) == (3, 5)
    # --fix: intensity fitted without those two; the others as they are.
    free = {name: [r["key"] for r in h["free_parameters"]] for name, h in fit["hypotheses"].items()}
    assert free["intensity"] == [r.key for r in hypothesis("intensity").free_parameters
                                 if r.key not in ("sl_ref_db", "bias_sd_m")]
    assert not {"sl_ref_db", "bias_sd_m"} & set(fit["hypotheses"]["intensity"]["params"])
    assert free["grid-peak"] == [r.key for r in hypothesis("grid-peak").free_parameters]
    assert fit["chosen"] in fit["hypotheses"] and fit["about"].startswith("MODEL OUTPUT")
    for name, h in fit["hypotheses"].items():
        assert {"elpd", "se", "params", "check"} <= set(h)
        check = h["check"]["study1"]
        assert set(check) == {"funneling", "inverse", "combination"}
        observed = np.bincount(data.answer1[data.stim1 < 9], minlength=9) / np.count_nonzero(data.stim1 < 9)
        np.testing.assert_allclose(check["funneling"]["observed"], observed, rtol=1e-12)
        np.testing.assert_allclose(np.sum(check["funneling"]["predicted"]), 1.0, rtol=1e-9)
    html = (out / "report.html").read_text()
    assert "Hypotheses fitted to these trials (model output)" in html and "MODEL OUTPUT" in html
    assert (out / "hypotheses_check.png").stat().st_size > 0


def test_profile_summary_calls_a_parameter_recovered_only_when_the_refits_track_it():
    from vibrofocus.simulation.fitting import profile_recovery_study, profile_summary

    rows = [{"hypothesis": "h", "key": k, "study": j, "lo": 0.0, "hi": 1.0, "true": t, "fitted": f, "data": "study 1"}
            for k, fits in (("tracked", (0.2, 0.5, 0.8)), ("stuck", (0.0, 0.0, 0.01)), ("flat", (0.5, 0.5, 0.5)))
            for j, (t, f) in enumerate(zip((0.15, 0.5, 0.85), fits))]
    got = profile_summary(rows)["h"]
    assert got["tracked"]["recovered"] and got["tracked"]["n"] == 3
    assert not got["stuck"]["recovered"] and not got["flat"]["recovered"]  # at a bound; no correlation
    with pytest.raises(ValidationError, match="not a free parameter of 'grid-peak'"):
        profile_recovery_study("grid-peak", "central_weight", 0, 3)


def test_parameters_not_recovered_are_assumed_and_not_free():
    # The committed one-at-a-time parameter recovery (scripts/model_recovery.py
    # --one-at-a-time): a parameter it did not recover is no free parameter of its
    # hypothesis but an assumption, and one it recovered stays free.
    from pathlib import Path

    from vibrofocus.simulation.fitting import profile_summary

    path = Path(__file__).resolve().parents[2] / "scripts" / "fits" / "recovery" / "one-at-a-time-n20-d8-seed0.jsonl"
    rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()[1:] if line.strip()]
    checked = 0
    for name, params in profile_summary(rows).items():
        h = hypothesis(name)
        free = {r.key for r in h.free_parameters}
        for key, r in params.items():
            if r["n"] == 3:
                assert (key in h.assumed, key in free) == (not r["recovered"], r["recovered"]), (name, key, r)
                checked += 1
    assert checked >= 40
