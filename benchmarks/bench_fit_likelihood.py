"""Speed of the free fit of a hypothesis (``vibrofocus analyze --hypotheses``): old vs new likelihood.

Prints, from one run, for a simulated study of N participants on the paper's design (Study 1
and Study 2 both, ``simulate_trials``):

- one likelihood evaluation (``participant_loglik``, every participant, the fit's
  ``FitSettings``): CPU seconds with the Study 2 selection probability taken trial by trial
  (``likelihood._per_trial_selection_probability``, the previous code path) and once per
  law (``selection_probability``), their ratio, and the largest difference of a
  participant's log-likelihood (asserted below 1e-6 nats);
- one hypothesis' free fit to every participant (``fit_hypothesis``, ``--starts`` starts of
  ``--maxiter`` Nelder-Mead iterations): CPU seconds both ways, the ratio, the number of
  likelihood evaluations, and whether both reach the same parameters (asserted);
- the CPU cost of that hypothesis' whole leave-one-participant-out score at the shipped
  settings, extrapolated from the cost per evaluation at about a thousand evaluations,
  plus the scoring of the left-out participants on their own draws;
- the designed protocol's Study 1 trials (every hypothesis, ``--designed-draws`` draws): the
  population's draws scored in batches (``draw_batches``: one answer law per trial group for
  64 draws at once, each draw's levels in one call of the hypothesis) against draw by draw
  (``level_draws`` and ``study1_probabilities_of``, the previous code path), milliseconds per
  draw, their ratio, and the largest difference (asserted below 1e-9 nats);
- ``--folds``: the leave-one-participant-out folds of that hypothesis on the study's Study 1
  trials, each fitted alone on its participants' trials (as before) and all of them sharing
  their evaluations (``fold_logliks``): likelihood evaluations, CPU seconds and their ratio,
  and whether both give the same folds (asserted).

Run: ``python benchmarks/bench_fit_likelihood.py [--hypothesis grid-peak] [--participants 12]
[--starts 1] [--maxiter 4] [--folds]``. One BLAS thread. CPU time (``time.process_time``), so a busy
machine inflates wall time, not these numbers.
"""

from __future__ import annotations

import argparse
import time
from unittest import mock

import numpy as np
from threadpoolctl import threadpool_limits


#: Likelihood evaluations of one hypothesis' refit and folds on a study of N = 12 (docs/fitting-hypotheses.md).
EVALUATIONS_PER_REFIT = 1000


def _cpu(fn):
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


def main() -> None:
    from vibrofocus.participant_models import likelihood
    from vibrofocus.participant_models.bank import default_bank
    from vibrofocus.participant_models.fitting import likelihood_fit
    from vibrofocus.participant_models.fitting.likelihood_fit import FitSettings, fit_hypothesis, participant_loglik
    from vibrofocus.participant_models.fitting.recovery import simulate_trials

    ap = argparse.ArgumentParser()
    ap.add_argument("--hypothesis", default="grid-peak")
    ap.add_argument("--participants", type=int, default=12)
    ap.add_argument("--seed", type=int, default=7300)
    ap.add_argument("--starts", type=int, default=1)
    ap.add_argument("--maxiter", type=int, default=4)
    ap.add_argument("--folds", action="store_true", help="also time the folds alone against sharing evaluations")
    ap.add_argument("--designed-draws", type=int, default=256, help="draws of the designed-protocol timing")
    args = ap.parse_args()
    bank = default_bank()
    data = simulate_trials(args.hypothesis, args.participants, np.random.default_rng([args.seed, 51]), bank=bank)
    settings = FitSettings()
    old = mock.patch.object(likelihood_fit, "selection_probability", likelihood._per_trial_selection_probability)
    print(f"{args.hypothesis}, N = {args.participants}, Study 1 + Study 2 ({data.stim1.size} + {data.stim2.size} "
          f"trials), {settings.n_draws} draws")
    with threadpool_limits(1):
        participant_loglik(args.hypothesis, data, bank=bank, settings=settings)  # warm caches
        t_new, ll_new = _cpu(lambda: participant_loglik(args.hypothesis, data, bank=bank, settings=settings))
        with old:
            t_old, ll_old = _cpu(lambda: participant_loglik(args.hypothesis, data, bank=bank, settings=settings))
        diff = float(np.max(np.abs(ll_new - ll_old)))
        assert diff < 1e-6, diff
        print(f"one likelihood evaluation: old {t_old:.2f} s, new {t_new:.2f} s CPU, ratio {t_old / t_new:.1f}; "
              f"largest |difference| of a participant's log-likelihood {diff:.1e} nats")
        fit_settings = FitSettings(n_starts=args.starts, maxiter=args.maxiter)
        t_fit_new, fit_new = _cpu(lambda: fit_hypothesis(args.hypothesis, data, bank=bank, settings=fit_settings))
        with old:
            t_fit_old, fit_old = _cpu(lambda: fit_hypothesis(args.hypothesis, data, bank=bank, settings=fit_settings))
        same = all(abs(fit_new.params[k] - fit_old.params[k]) <= 1e-9 * max(1.0, abs(fit_old.params[k]))
                   for k in fit_new.params)
        assert same, (fit_new.params, fit_old.params)
        print(f"free fit ({args.starts} start(s) x {args.maxiter} iterations, {fit_new.n_evaluations} evaluations): "
              f"old {t_fit_old:.1f} s, new {t_fit_new:.1f} s CPU, ratio {t_fit_old / t_fit_new:.1f}; same parameters")
        per_eval, per_eval_old = t_fit_new / fit_new.n_evaluations, t_fit_old / fit_new.n_evaluations
        t_score, _ = _cpu(lambda: participant_loglik(args.hypothesis, data.subset(np.array([0])), bank=bank,
                                                     settings=settings.scoring()))
        print(f"a refit of this hypothesis at about {EVALUATIONS_PER_REFIT} evaluations (the full fit and "
              f"{args.participants} folds): about {EVALUATIONS_PER_REFIT * per_eval / 60:.0f} CPU-min new, "
              f"{EVALUATIONS_PER_REFIT * per_eval_old / 60:.0f} old, plus "
              f"{args.participants * t_score / 60:.1f} CPU-min new to score the left-out participants")
        _designed(args, bank)
        if args.folds:
            _folds(args, data.subset(np.arange(args.participants), studies=(1,)), bank)


def _per_draw_study1(name, data, bank, settings):
    """Study 1 location answers' marginal log-likelihood, draw by draw (the previous code path, lapse included)."""
    from scipy import special

    from vibrofocus.participant_models.fitting.likelihood_fit import level_draws, study1_probabilities_of
    from vibrofocus.participant_models.hypotheses import hypothesis

    h = hypothesis(name)
    m = h.model()
    level1, allowed1, _ = data.study1_conditions()
    floor = settings.lapse / allowed1.sum(axis=1)
    total = np.zeros((settings.n_draws, data.n_participants))
    for k, (traits, at) in enumerate(level_draws(h, m, bank, settings, sorted(set(level1.tolist())))):
        p = study1_probabilities_of(data, at, m, traits, settings.quadrature)[np.arange(data.stim1.size), data.answer1]
        total[k] = np.bincount(data.part1, np.log((1.0 - settings.lapse) * p + floor), data.n_participants)
    return special.logsumexp(total, axis=0) - np.log(settings.n_draws)


def _designed(args, bank) -> None:
    """The designed protocol's Study 1 (the docs' default design): batched draws against draw by draw."""
    from vibrofocus.participant_models import available_hypotheses
    from vibrofocus.participant_models.design import PlanBlock
    from vibrofocus.participant_models.fitting import simulate_plan_trials
    from vibrofocus.participant_models.fitting.likelihood_fit import FitSettings, participant_loglik

    def block(methods, level, locations, repetitions):
        return PlanBlock(methods, level, locations, repetitions, "", "location")

    corners, outer = (1, 3, 7, 9), (1, 2, 3, 7, 8, 9)
    plan = (block(("funneling", "combination"), 0.0, corners, 1), block(("inverse",), 0.0, corners, 6),
            block(("inverse",), 0.0, outer, 2), block(("combination",), 0.0, outer, 1),
            block(("funneling",), -5.0, corners, 2), block(("inverse", "combination"), -20.0, corners, 1),
            block(("funneling",), -20.0, outer, 2))
    settings = FitSettings(n_draws=args.designed_draws)
    print(f"designed protocol, Study 1 only, N = 6, {settings.n_draws} draws:")
    for name in available_hypotheses():
        data = simulate_plan_trials(name, plan, 6, np.random.default_rng([args.seed, 55]))
        t_new, new = _cpu(lambda: participant_loglik(name, data, bank=bank, settings=settings))
        t_old, old = _cpu(lambda: _per_draw_study1(name, data, bank, settings))
        diff = float(np.max(np.abs(new - old)))
        assert diff < 1e-9, diff
        print(f"  {name}: draw by draw {1e3 * t_old / settings.n_draws:.2f} ms per draw, batched "
              f"{1e3 * t_new / settings.n_draws:.2f}, ratio {t_old / t_new:.1f}; largest |difference| {diff:.1e} nats")


def _folds(args, data, bank) -> None:
    """The folds of one hypothesis on Study 1 trials: each alone, then sharing their evaluations."""
    from vibrofocus.participant_models.fitting.likelihood_fit import Evaluations, FitSettings, fit_hypothesis
    from vibrofocus.participant_models.hypotheses import hypothesis

    h = hypothesis(args.hypothesis)
    settings = FitSettings(n_draws=16, n_starts=1, maxiter=20 * args.maxiter)
    start = fit_hypothesis(h, data, bank=bank, settings=settings).params
    keeps = [np.delete(np.arange(args.participants), i) for i in range(args.participants)]
    t_alone, alone = _cpu(lambda: [fit_hypothesis(h, data.subset(k), bank=bank, settings=settings, start=start)
                                   for k in keeps])
    shared = Evaluations(h, data, bank, settings)
    t_shared, together = _cpu(lambda: [fit_hypothesis(h, data, bank=bank, settings=settings, start=start,
                                                      participants=k, evaluations=shared) for k in keeps])
    assert all(a.params == b.params for a, b in zip(alone, together))
    print(f"{args.participants} folds on Study 1 ({settings.maxiter} iterations, {settings.n_draws} draws): each "
          f"alone {sum(f.n_evaluations for f in alone)} evaluations, {t_alone:.1f} s CPU; sharing {len(shared)}, "
          f"{t_shared:.1f} s CPU; ratio {t_alone / t_shared:.1f}; same folds")


if __name__ == "__main__":
    main()
