"""Model and parameter recovery: simulate studies under a hypothesis, fit, and see what comes back.

:func:`simulate_trials` draws a whole study of the paper's design (Study 1 and Study 2,
every method x location ``repetitions`` times) from the same model and forearms as
:func:`~vibrofocus.simulation.bank.simulate_cell_means`, trial by trial;
:func:`model_recovery` fits every hypothesis to studies simulated under each and counts
which one the leave-one-participant-out score chooses (the confusion matrix);
:func:`parameter_recovery` refits a hypothesis' free parameters to studies simulated at
known values. ``scripts/model_recovery.py`` is their command line; the tables are in
docs/fitting-hypotheses.md. Simulated participants: a model, not data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import optimize

from ...errors import ValidationError
from ..bank import FeatureBank, default_bank
from ..perception import Traits, draw_answers
from .elpd import compare_hypotheses
from .lab_trials import LabTrials
from .likelihood_fit import STUDY2_ONLY, FitSettings, fit_hypothesis, model_at, participant_loglik

__all__ = ["simulate_trials", "simulate_plan_trials", "recovery_study", "confusion", "recovery_rates",
           "model_recovery", "parameter_recovery", "profile_recovery_study", "profile_summary"]


def simulate_trials(hypothesis: Any, n_participants: int, rng: np.random.Generator, *,
                    bank: FeatureBank | None = None, values: Mapping[str, float] | None = None,
                    repetitions: int = 3) -> LabTrials:
    """One simulated study of the paper's design, as trials (a MODEL, not data).

    Parameters
    ----------
    hypothesis : str or Hypothesis
    n_participants : int
    rng : numpy.random.Generator
        All randomness (forearms, traits, answers).
    bank : FeatureBank, optional
        Default :func:`~vibrofocus.simulation.bank.default_bank`.
    values : mapping of str to float, optional
        The hypothesis' free parameters (by key); default its own.
    repetitions : int
        Trials per method x location and study.

    Returns
    -------
    LabTrials
        Participants ``sim-001`` ...
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    m = model_at(h, values)
    for name, v in (("n_participants", n_participants), ("repetitions", repetitions)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValidationError(f"{name} must be an integer >= 1, got {v!r}")
    n_loc = len(b.locations_xy)
    stim = np.repeat(np.arange(len(b.methods) * n_loc), repetitions)
    forearms = rng.choice(b.n_forearms, size=n_participants, replace=n_participants > b.n_forearms)
    a1, s2 = [], []
    for i in range(n_participants):
        traits = Traits.draw(m, rng)
        per = h.percepts(b.energy[forearms[i]].reshape(stim.max() + 1, -1), b.points_xy, m, traits,
                         b.actuator_energy[forearms[i]].reshape(stim.max() + 1, -1), b.actuators_xy, b.locations_xy)
        a1.append(draw_answers(per, stim, b.locations_xy, b.centre_xy, m, traits, rng)[0])
        s2.append(draw_answers(per, stim, b.locations_xy, b.centre_xy, m, traits, rng)[1])
    part = np.repeat(np.arange(n_participants), stim.size)
    stims = np.tile(stim, n_participants)
    return LabTrials(tuple(f"sim-{i + 1:03d}" for i in range(n_participants)), tuple(b.methods), n_loc,
                     part, stims, np.concatenate(a1), part, stims, np.concatenate(s2), source="<simulated>",
                     levels=b.levels)


def simulate_plan_trials(hypothesis: Any, plan: Sequence[Any], n_participants: int, rng: np.random.Generator, *,
                         bank: FeatureBank | None = None) -> LabTrials:
    """One simulated study of a plan's Study 1 blocks, as trials (a MODEL, not data).

    Each participant is a forearm of the bank and traits from the hypothesis' population
    (at its shipped parameters); every block's trials are answered by
    :func:`~vibrofocus.simulation.perception.draw_answers`, the sampler of
    ``simulate-study``, among the block's locations and at its level. The study engine
    (the simulated forearm playing every trial) is not run.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    plan : sequence of PlanBlock
        Blocks with ``methods``, ``level_db`` (dB re the bank's level rule),
        ``locations`` (numbers from 1) and ``repetitions``; location answers
        (:func:`~vibrofocus.simulation.design.paper_plan`, a designed protocol's blocks).
    n_participants : int
    rng : numpy.random.Generator
        The stream of the study: forearms, traits and answers, in that order.
    bank : FeatureBank, optional
        Default :func:`~vibrofocus.simulation.bank.default_bank`.

    Returns
    -------
    LabTrials
        Study 1 trials with their levels and allowed answers; no Study 2.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    if any(getattr(blk, "response", "location") != "location" for blk in plan):
        raise ValidationError("simulate_plan_trials answers location blocks only")
    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    m = h.model()
    n_loc = len(b.locations_xy)
    levels = sorted({blk.level_db for blk in plan})
    part, stim, ans, lev, allowed = [], [], [], [], []
    forearms = rng.choice(b.n_forearms, size=n_participants, replace=n_participants > b.n_forearms)
    for i in range(n_participants):
        traits = Traits.draw(m, rng)
        per = {}
        for v in levels:
            g = 10.0 ** (v / 10.0)
            e = b.energy[forearms[i]].reshape(len(b.methods) * n_loc, -1) * g
            a = b.actuator_energy[forearms[i]].reshape(len(b.methods) * n_loc, -1) * g
            per[v] = h.percepts(e, b.points_xy, m, traits, a, b.actuators_xy, b.locations_xy)
        for blk in plan:
            ok = np.asarray(blk.locations) - 1
            mask = np.zeros(n_loc, dtype=bool)
            mask[ok] = True
            for meth in blk.methods:
                idx = np.tile(b.methods.index(meth) * n_loc + ok, blk.repetitions)
                answers, _, _ = draw_answers(per[blk.level_db], idx, b.locations_xy, b.centre_xy, m, traits, rng,
                                             allowed=ok)
                part.append(np.full(idx.size, i))
                stim.append(idx)
                ans.append(answers)
                lev.append(np.full(idx.size, blk.level_db))
                allowed.append(np.tile(mask, (idx.size, 1)))
    empty = np.zeros(0, dtype=int)
    return LabTrials(tuple(f"sim-{i + 1:03d}" for i in range(n_participants)), tuple(b.methods), n_loc,
                     np.concatenate(part), np.concatenate(stim), np.concatenate(ans), empty, empty,
                     np.zeros((0, n_loc), dtype=bool), source="<simulated plan>", levels=b.levels,
                     level1=np.concatenate(lev), level2=np.zeros(0), allowed1=np.concatenate(allowed),
                     allowed2=np.zeros((0, n_loc), dtype=bool))


def recovery_study(hypotheses: Sequence[Any], truth: int, study: int, *, n_participants: int = 12, seed: int = 0,
                   bank: FeatureBank | None = None, settings: FitSettings | None = None, study1_only: bool = False,
                   refit: bool = True, **cluster: Any) -> dict[str, Any]:
    """One study of a model recovery: simulate it under ``hypotheses[truth]``, score every hypothesis.

    The study draws from ``numpy.random.default_rng([seed, truth, study])``.

    Parameters
    ----------
    hypotheses : sequence of str or Hypothesis
    truth : int
        Index of the hypothesis that answers.
    study : int
        The study's number under that hypothesis.
    n_participants, seed, bank, settings, study1_only
        As :func:`model_recovery`.
    refit : bool
        True: every hypothesis' free parameters are fitted to the study and scored by
        leave-one-participant-out ELPD (:func:`compare_hypotheses`). False: every
        hypothesis is scored at its shipped parameters (its fit to the paper), nothing
        fitted to the study, so the score is each participant's marginal log-likelihood
        there; the true hypothesis then answers with exactly the parameters it is scored
        at, so this bounds recovery from above (a refit lets every hypothesis move
        toward the data, the true one's advantage can only shrink).
    **cluster
        As :func:`compare_hypotheses`.

    Returns
    -------
    dict
        ``true``, ``study``, ``chosen``, ``elpd`` (per name), ``difference`` (chosen minus
        runner-up) and ``difference_se``.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    hs = [find_hypothesis(h) for h in hypotheses]
    b = bank if bank is not None else default_bank()
    data = simulate_trials(hs[truth], n_participants, np.random.default_rng([seed, truth, study]), bank=b)
    if study1_only:
        data = data.subset(np.arange(n_participants), studies=(1,))
    scored = hs if refit else [dataclasses.replace(h, free_parameters=()) for h in hs]
    if not refit:
        cluster = {"local": True}  # one likelihood per hypothesis: no folds to spread
        # nothing is tuned to the draws: scored on them (settings.n_draws)
        settings = dataclasses.replace(settings or FitSettings(), score_draws=0)
    res = compare_hypotheses(data, scored, bank=b, settings=settings, **cluster)
    return {"true": hs[truth].name, "study": study, "chosen": res["chosen"],
            "elpd": {n: r["elpd"] for n, r in res["hypotheses"].items()},
            "difference": res["difference"], "difference_se": res["difference_se"]}


def confusion(names: Sequence[str], studies: Sequence[Mapping[str, Any]]) -> list[list[int]]:
    """Counts of (true, chosen) over ``studies`` (rows: true, in the order of ``names``)."""
    out = np.zeros((len(names), len(names)), dtype=int)
    for st in studies:
        out[list(names).index(st["true"]), list(names).index(st["chosen"])] += 1
    return out.tolist()


def recovery_rates(names: Sequence[str], studies: Sequence[Mapping[str, Any]], *,
                   confidence: float = 0.95) -> dict[str, dict[str, Any]]:
    """How often each true hypothesis was chosen, with an exact interval, and by what margin.

    Parameters
    ----------
    names : sequence of str
        The hypotheses, in the order of :func:`confusion`.
    studies : sequence of mapping
        Scored studies: ``true`` and ``chosen`` (names); optionally ``elpd`` (per name, the
        ELPD or summed log-likelihood, natural log), ``difference`` and ``difference_se``
        (the chosen minus the runner-up, :func:`~.elpd.compare_hypotheses`).
    confidence : float
        Of the Clopper-Pearson interval of each rate (exact binomial,
        :meth:`scipy.stats.binomtest`'s ``proportion_ci``).

    Returns
    -------
    dict
        Per true hypothesis that has studies: ``studies``, ``correct`` (count), ``rate``,
        ``low`` and ``high`` (the interval), ``decisive`` (studies whose choice leads the
        runner-up by more than two standard errors: right, wrong), ``rival`` (the other
        hypothesis chosen most often, or None) and ``lead`` (the mean, over the studies, of
        the true hypothesis' score minus the best other's; NaN without ``elpd``).
    """
    from scipy import stats

    out: dict[str, dict[str, Any]] = {}
    for name in names:
        rows = [st for st in studies if st["true"] == name]
        if not rows:
            continue
        correct = sum(st["chosen"] == name for st in rows)
        ci = stats.binomtest(correct, len(rows)).proportion_ci(confidence_level=confidence, method="exact")
        decisive = [st["chosen"] == name for st in rows
                    if "difference" in st and st["difference"] > 2.0 * st.get("difference_se", np.inf)]
        others = [st["chosen"] for st in rows if st["chosen"] != name]
        leads = [st["elpd"][name] - max(v for k, v in st["elpd"].items() if k != name)
                 for st in rows if "elpd" in st]
        out[name] = {"studies": len(rows), "correct": int(correct), "rate": correct / len(rows),
                     "low": float(ci.low), "high": float(ci.high),
                     "decisive": (int(sum(decisive)), int(len(decisive) - sum(decisive))),
                     "rival": max(set(others), key=others.count) if others else None,
                     "lead": float(np.mean(leads)) if leads else float("nan")}
    return out


def model_recovery(hypotheses: Sequence[Any], *, n_studies: int, n_participants: int = 12, seed: int = 0,
                   bank: FeatureBank | None = None, settings: FitSettings | None = None, study1_only: bool = False,
                   refit: bool = True, **cluster: Any) -> dict[str, Any]:
    """Simulate studies under each hypothesis, score every hypothesis on each, count the choices.

    Study ``j`` under hypothesis ``t`` (index in ``hypotheses``) draws from
    ``numpy.random.default_rng([seed, t, j])`` (:func:`recovery_study`).

    Parameters
    ----------
    hypotheses : sequence of str or Hypothesis
        At least two.
    n_studies : int
        Studies per true hypothesis.
    n_participants : int
        Participants per study (the paper's design otherwise).
    seed : int
    bank : FeatureBank, optional
    settings : FitSettings, optional
    study1_only : bool
        Fit Study 1's answers only (fast; the selections are simulated and dropped).
    refit : bool
        Fit every hypothesis to each study and score by leave-one-participant-out ELPD
        (True), or score each at its shipped parameters (False; see :func:`recovery_study`).
    **cluster
        ``scheduler``, ``n_workers``, ``local``: as :func:`compare_hypotheses`.

    Returns
    -------
    dict
        ``names``, ``confusion`` (true x chosen counts, list of lists), ``studies`` (per
        study: true, chosen, elpd per hypothesis, the difference to the next and its SE).
    """
    from ..hypotheses import hypothesis as find_hypothesis

    hs = [find_hypothesis(h) for h in hypotheses]
    if len(hs) < 2:
        raise ValidationError("model recovery needs at least two hypotheses")
    names = [h.name for h in hs]
    b = bank if bank is not None else default_bank()
    studies = [recovery_study(hs, t, j, n_participants=n_participants, seed=seed, bank=b, settings=settings,
                              study1_only=study1_only, refit=refit, **cluster)
               for t in range(len(hs)) for j in range(n_studies)]
    return {"names": names, "confusion": confusion(names, studies), "studies": studies,
            "n_participants": n_participants}


def parameter_recovery(hypothesis: Any, *, n_studies: int, n_participants: int = 12, seed: int = 0,
                       bank: FeatureBank | None = None, settings: FitSettings | None = None) -> dict[str, Any]:
    """Simulate studies at known values of a hypothesis' free parameters, refit, compare.

    Study ``j``'s true values are drawn uniformly within the middle 60 % of each range
    (``default_rng([seed, 0x9A2, j])``), its trials from ``default_rng([seed, 0x9A3, j])``.
    A parameter is reported recovered when the refits track the truth (correlation of at
    least 0.7 over the studies) and its mean bias is below 10 % of its range.

    Parameters
    ----------
    hypothesis : str or Hypothesis
        With at least one free parameter.
    n_studies : int
    n_participants : int
    seed : int
    bank : FeatureBank, optional
    settings : FitSettings, optional

    Returns
    -------
    dict
        Per parameter key: ``true`` and ``fitted`` (per study), ``bias`` (mean fitted -
        true), ``rmse``, ``correlation``, ``range`` and ``recovered`` (bool).
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    if not h.free_parameters:
        raise ValidationError(f"hypothesis {h.name!r} has no free parameters to recover")
    b = bank if bank is not None else default_bank()
    ranges = h.free_parameters
    truth, fitted = [], []
    for j in range(n_studies):
        u = np.random.default_rng([seed, 0x9A2, j]).uniform(0.2, 0.8, len(ranges))
        values = {r.key: r.lo + (r.hi - r.lo) * x for r, x in zip(ranges, u)}
        data = simulate_trials(h, n_participants, np.random.default_rng([seed, 0x9A3, j]), bank=b, values=values)
        fit = fit_hypothesis(h, data, bank=b, settings=settings)
        truth.append([values[r.key] for r in ranges])
        fitted.append([fit.params[r.key] for r in ranges])
    t, f = np.array(truth), np.array(fitted)
    out = {}
    for i, r in enumerate(ranges):
        bias = float(np.mean(f[:, i] - t[:, i]))
        corr = float(np.corrcoef(t[:, i], f[:, i])[0, 1]) if n_studies > 2 else float("nan")
        out[r.key] = {"true": t[:, i].tolist(), "fitted": f[:, i].tolist(), "bias": bias,
                      "rmse": float(np.sqrt(np.mean((f[:, i] - t[:, i]) ** 2))), "correlation": corr,
                      "range": [r.lo, r.hi],
                      "recovered": bool(corr >= 0.7 and abs(bias) <= 0.1 * (r.hi - r.lo))}
    return out


def profile_recovery_study(hypothesis: Any, key: str, study: int, n_studies: int, *, n_participants: int = 12,
                           seed: int = 0, bank: FeatureBank | None = None,
                           settings: FitSettings | None = None) -> dict[str, Any]:
    """One study of a one-at-a-time parameter recovery: one free parameter moved, simulated, refitted alone.

    Every other parameter stays at the hypothesis' shipped value, in the simulation and in
    the fit, so this is a necessary condition of recovery, not a sufficient one: a
    parameter that fails it cannot be recovered from the design even when everything else
    is known; one that passes may still trade off with others in a joint fit. The fit:
    the summed marginal log-likelihood on a grid of 9 values across the range, then
    Brent's bounded search (``settings.maxiter`` steps) between the best one's neighbours.
    Study
    ``study`` of ``n_studies`` puts the parameter at the fraction ``0.15 + 0.7 j / (n - 1)``
    of its range (for one end of a population range: of the part that keeps the pair in
    order, up to the other end's shipped value) and simulates ``n_participants`` on the
    paper's design (``default_rng([seed, 0x9A5, study])``), Study 2 only for the selection's
    parameters (:data:`STUDY2_ONLY`), Study 1 only for the others.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    key : str
        The free parameter (:attr:`ParameterRange.key`).
    study, n_studies : int
    n_participants, seed, bank, settings
        As :func:`parameter_recovery`.

    Returns
    -------
    dict
        ``hypothesis``, ``key``, ``study``, ``lo``, ``hi`` (the range moved within),
        ``true``, ``fitted``, ``data`` ("study 1" or "study 2").
    """
    from ..hypotheses import hypothesis as find_hypothesis
    from ..parameters import read_parameters

    h = find_hypothesis(hypothesis)
    ranges = {r.key: r for r in h.free_parameters}
    if key not in ranges:
        raise ValidationError(f"{key!r} is not a free parameter of {h.name!r} ({', '.join(ranges)})")
    r = ranges[key]
    shipped = dict(zip(ranges, read_parameters(h.model(), h.free_parameters)))
    lo, hi = r.lo, r.hi
    if r.index is not None:
        other = shipped.get(f"{r.name}[{1 - r.index}]")
        if other is not None:
            lo, hi = (lo, other) if r.index == 0 else (other, hi)
    if not hi > lo:
        raise ValidationError(f"{h.name} {key}: no room to move it ({lo} to {hi})")
    one = dataclasses.replace(h, free_parameters=(dataclasses.replace(r, lo=lo, hi=hi),))
    value = lo + (hi - lo) * (0.15 + 0.7 * study / max(n_studies - 1, 1))
    b = bank if bank is not None else default_bank()
    data = simulate_trials(one, n_participants, np.random.default_rng([seed, 0x9A5, study]), bank=b,
                           values={key: value})
    which = 2 if r.name in STUDY2_ONLY else 1
    data = data.subset(np.arange(n_participants), studies=(which,))
    s = settings or FitSettings()

    def neg(x: float) -> float:
        v = float(participant_loglik(one, data, [x], bank=b, settings=s).sum())
        return -v if np.isfinite(v) else 1e300

    # A grid, then Brent's bounded search around its best point: no gradient, as a
    # parameter that acts through a threshold (detection) is piecewise flat at a
    # finite-difference step.
    grid = np.linspace(lo, hi, 9)
    k = int(np.argmin([neg(x) for x in grid]))
    a, c = grid[max(k - 1, 0)], grid[min(k + 1, 8)]
    res = optimize.minimize_scalar(neg, bounds=(a, c), method="bounded",
                                   options={"xatol": 0.01 * (hi - lo), "maxiter": s.maxiter})
    fitted = float(res.x) if res.fun <= neg(grid[k]) else float(grid[k])
    return {"hypothesis": h.name, "key": key, "study": study, "lo": lo, "hi": hi, "true": value,
            "fitted": fitted, "data": f"study {which}"}


def profile_summary(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    """Per hypothesis and parameter: bias, RMSE, correlation, recovered (from :func:`profile_recovery_study` rows).

    Recovered: the refits track the truth (correlation at least 0.7) and their RMSE is at
    most 15 % of the range moved within.
    """
    out: dict[str, dict[str, dict[str, Any]]] = {}
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["hypothesis"], row["key"]), []).append(row)
    for (name, key), rs in groups.items():
        t = np.array([x["true"] for x in rs])
        f = np.array([x["fitted"] for x in rs])
        span = rs[0]["hi"] - rs[0]["lo"]
        corr = float(np.corrcoef(t, f)[0, 1]) if len(rs) > 2 and np.std(f) > 0 else float("nan")
        rmse = float(np.sqrt(np.mean((f - t) ** 2)))
        out.setdefault(name, {})[key] = {
            "n": len(rs), "range": [rs[0]["lo"], rs[0]["hi"]], "bias": float(np.mean(f - t)), "rmse": rmse,
            "correlation": corr, "data": rs[0]["data"],
            "recovered": bool(np.isfinite(corr) and corr >= 0.7 and rmse <= 0.15 * span)}
    return out
