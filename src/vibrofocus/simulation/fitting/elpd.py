"""Leave-one-participant-out predictive log-likelihood (ELPD) of each hypothesis, on Dask.

For each hypothesis and each participant ``i``, the free parameters are refitted
without ``i`` (from the fit to everyone; folds run together share their likelihood
evaluations, :func:`fold_logliks`) and ``i``'s marginal log-likelihood is taken
there; the ELPD is their sum, its standard error ``sqrt(N var_i)`` (Vehtari, Gelman &
Gabry 2017, Stat. Comput. 27(5), eq. 22-23). A hypothesis without free parameters is
not fitted, so its leave-one-out score is its likelihood. :func:`compare_hypotheses`
names the best and its difference to the next with that difference's SE. The folds run
as Dask tasks with the cluster options of ``vibrofocus power``
(:func:`~vibrofocus.simulation.power.dask_client`). Method: docs/fitting-hypotheses.md.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...errors import ValidationError
from ..bank import FeatureBank, default_bank
from .lab_trials import LabTrials
from .likelihood_fit import Evaluations, Fit, FitSettings, fit_hypothesis, participant_loglik

__all__ = ["fold_loglik", "fold_logliks", "elpd_summary", "compare_hypotheses"]


def fold_loglik(hypothesis: Any, data: LabTrials, left_out: int, start: dict[str, float], bank: FeatureBank,
                settings: FitSettings, evaluations: Evaluations | None = None) -> tuple[float, dict[str, float]]:
    """One fold: refit without participant ``left_out``, score that participant there.

    The score integrates over :meth:`FitSettings.scoring`'s draws, not the fit's: held out
    from the Monte Carlo draws the refit tuned the population to, as from the participant.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    data : LabTrials
    left_out : int
        Participant index.
    start : dict of str to float
        The fit to every participant (the refit's first start).
    bank : FeatureBank
    settings : FitSettings
    evaluations : Evaluations, optional
        Likelihoods of every participant of ``data`` to reuse (:func:`fold_logliks`).

    Returns
    -------
    loglik : float
        The left-out participant's marginal log-likelihood at the refitted parameters.
    params : dict of str to float
        The refitted parameters.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    keep = np.delete(np.arange(data.n_participants), left_out)
    one = dataclasses.replace(settings, n_starts=1)
    fit = fit_hypothesis(h, data, bank=bank, settings=one, start=start, participants=keep, evaluations=evaluations)
    ll = participant_loglik(h, data.subset(np.array([left_out])), fit.params, bank=bank,
                            settings=settings.scoring())
    return float(ll[0]), fit.params


def fold_logliks(hypothesis: Any, data: LabTrials, left_out: Sequence[int], start: dict[str, float],
                 bank: FeatureBank, settings: FitSettings) -> list[tuple[float, dict[str, float]]]:
    """:func:`fold_loglik` for several folds, sharing their likelihood evaluations.

    The folds start at the same place with the same first simplex and their searches
    agree for many steps: each parameter set is scored once for all of them
    (:class:`~.likelihood_fit.Evaluations`); the results are those of separate folds.

    Parameters
    ----------
    hypothesis, data, start, bank, settings
        As :func:`fold_loglik`.
    left_out : sequence of int
        The participants left out, one fold each.

    Returns
    -------
    list of (float, dict)
        Per fold, as :func:`fold_loglik`.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    shared = Evaluations(h, data, bank, dataclasses.replace(settings, n_starts=1))
    return [fold_loglik(h, data, int(i), start, bank, settings, shared) for i in left_out]


def elpd_summary(pointwise: np.ndarray) -> tuple[float, float]:
    """ELPD and its standard error from the per-participant scores.

    Parameters
    ----------
    pointwise : ndarray, shape (N,)
        Each participant's left-out log-likelihood, natural log.

    Returns
    -------
    elpd : float
        The sum.
    se : float
        ``sqrt(N var)`` (NaN for one participant).
    """
    p = np.asarray(pointwise, dtype=float)
    se = float(np.sqrt(p.size * np.var(p, ddof=1))) if p.size > 1 else float("nan")
    return float(p.sum()), se


def compare_hypotheses(data: LabTrials, hypotheses: Sequence[Any] | None = None, *,
                       bank: FeatureBank | None = None, settings: FitSettings | None = None,
                       scheduler: str | None = None, n_workers: int | None = None, client: Any = None,
                       local: bool = False) -> dict[str, Any]:
    """Fit each hypothesis to the trials and score it by leave-one-participant-out ELPD.

    Parameters
    ----------
    data : LabTrials
        At least two participants.
    hypotheses : sequence of str or Hypothesis, optional
        Default every registered hypothesis.
    bank : FeatureBank, optional
        Default :func:`~vibrofocus.simulation.bank.default_bank`.
    settings : FitSettings, optional
    scheduler, n_workers, client
        The Dask cluster (:func:`~vibrofocus.simulation.power.dask_client`): default a
        LocalCluster on this machine.
    local : bool
        Run in this process without Dask (the same numbers).

    Returns
    -------
    dict
        ``chosen`` (the name of the highest ELPD), ``runner_up``, ``difference`` (ELPD of
        the chosen minus the runner-up's) and ``difference_se``; ``hypotheses``: per name,
        ``elpd``, ``se``, ``params`` (the fit to every participant), ``loglik``,
        ``pointwise`` (per participant), ``fold_params`` and ``label``; ``participants``.

    Raises
    ------
    ValidationError
        Fewer than two participants (no participant can be left out).
    """
    from ..hypotheses import available_hypotheses, hypothesis as find_hypothesis

    hs = [find_hypothesis(h) for h in (hypotheses if hypotheses is not None else available_hypotheses())]
    if not hs:
        raise ValidationError("no hypothesis to fit")
    if data.n_participants < 2:
        raise ValidationError(f"leave-one-participant-out needs at least two participants, got {data.n_participants}")
    b = bank if bank is not None else default_bank()
    s = settings or FitSettings()
    fits: dict[str, Fit] = {}
    folds: dict[str, list[tuple[float, dict[str, float]] | None]] = {}
    if local:
        for h in hs:
            fits[h.name] = fit_hypothesis(h, data, bank=b, settings=s)
            if h.free_parameters:
                folds[h.name] = fold_logliks(h, data, range(data.n_participants), fits[h.name].params, b, s)
    else:
        from ..power import dask_client

        with dask_client(scheduler=scheduler, n_workers=n_workers, client=client) as dask:
            bank_f = dask.scatter(b, broadcast=True)
            full = {h.name: dask.submit(fit_hypothesis, h, data, bank=bank_f, settings=s, pure=False) for h in hs}
            # As few tasks per hypothesis as keep every worker thread busy: a task's folds
            # share their evaluations (fold_logliks).
            threads = sum(dask.nthreads().values()) or 1
            chunks = np.array_split(np.arange(data.n_participants), min(data.n_participants, -(-threads // len(hs))))
            pending = {}
            for h in hs:
                fits[h.name] = full[h.name].result()
                if h.free_parameters:
                    pending[h.name] = [dask.submit(fold_logliks, h, data, c.tolist(), fits[h.name].params, bank_f, s,
                                                   pure=False) for c in chunks]
            folds = {name: [r for f in futs for r in f.result()] for name, futs in pending.items()}
    out: dict[str, Any] = {}
    pointwise: dict[str, np.ndarray] = {}
    for h in hs:
        fit = fits[h.name]
        if h.name in folds:
            pointwise[h.name] = np.array([ll for ll, _ in folds[h.name]])
            fold_params = [p for _, p in folds[h.name]]
        else:  # nothing fitted: leaving a participant out changes nothing
            pointwise[h.name] = (fit.participant_loglik if s.score_draws == 0 else
                                 participant_loglik(h, data, None, bank=b, settings=s.scoring()))
            fold_params = []
        elpd, se = elpd_summary(pointwise[h.name])
        out[h.name] = {"elpd": elpd, "se": se, "params": fit.params, "loglik": fit.loglik,
                       "pointwise": pointwise[h.name].tolist(), "fold_params": fold_params, "label": h.label(),
                       "free_parameters": [{"key": r.key, "lo": r.lo, "hi": r.hi, "source": r.source}
                                           for r in h.free_parameters]}
    order = sorted(out, key=lambda n: -out[n]["elpd"] if np.isfinite(out[n]["elpd"]) else np.inf)
    chosen = order[0]
    runner = order[1] if len(order) > 1 else None
    diff = se_diff = None
    if runner is not None:
        d = pointwise[chosen] - pointwise[runner]
        diff, se_diff = elpd_summary(d)
    return {"chosen": chosen, "runner_up": runner, "difference": diff, "difference_se": se_diff,
            "hypotheses": out, "participants": list(data.participants), "settings": _settings_dict(s)}


def _settings_dict(s: FitSettings) -> dict[str, Any]:
    q = s.quadrature
    return {"n_draws": s.n_draws, "seed": s.seed, "n_starts": s.n_starts, "lapse": s.lapse, "maxiter": s.maxiter,
            "score_draws": s.score_draws,
            "quadrature": {"n_place": q.n_place, "n_segment": q.n_segment, "n_angle": q.n_angle,
                           "n_conflict": q.n_conflict}}
