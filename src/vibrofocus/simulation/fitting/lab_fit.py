"""``vibrofocus analyze --hypotheses``: every hypothesis fitted to a lab's trials, scored and checked.

:func:`fit_trials` maps the loaded trials onto the feature bank's stimuli
(:func:`~.lab_trials.lab_trials`), fits and scores every hypothesis by
leave-one-participant-out ELPD (:func:`~.elpd.compare_hypotheses`, on Dask) and adds each
one's predictive check (:func:`~.predictive.predictive_check`): the content of
``hypotheses.json``. docs/fitting-hypotheses.md.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from ..bank import FeatureBank, default_bank
from .elpd import compare_hypotheses
from .lab_trials import lab_trials
from .likelihood_fit import FitSettings
from .predictive import predictive_check

__all__ = ["fit_trials"]

#: What hypotheses.json says of itself.
ABOUT = ("MODEL OUTPUT: the simulated participants' hypotheses fitted to these trials by maximum marginal "
         "likelihood (per participant, integrated over the hypothesis' population of traits and simulated forearms) "
         "and scored by leave-one-participant-out predictive log-likelihood (elpd, natural log; se its standard error). "
         "check: observed (the lab's data) vs predicted (the model) share of answers per location and method. "
         "docs/fitting-hypotheses.md")


def fit_trials(trials: Any, *, hypotheses: Sequence[Any] | None = None, bank: FeatureBank | None = None,
               settings: FitSettings | None = None, **cluster: Any) -> dict[str, Any]:
    """Fit and score every hypothesis on a lab's trials: the content of ``hypotheses.json``.

    Parameters
    ----------
    trials : DataFrame
        As :func:`vibrofocus.analysis.load_trials` returns (main-phase rows are fitted).
    hypotheses : sequence of str or Hypothesis, optional
        Default every registered hypothesis.
    bank : FeatureBank, optional
        The simulated forearms the stimuli are felt on (default the shipped one).
    settings : FitSettings, optional
    **cluster
        ``scheduler``, ``n_workers``, ``client``, ``local``: see
        :func:`~.elpd.compare_hypotheses`.

    Returns
    -------
    dict
        ``about``, ``chosen``, ``runner_up``, ``difference``, ``difference_se``,
        ``hypotheses`` (per name: ``elpd``, ``se``, ``params``, ``check``, ...),
        ``participants``, ``source``, ``levels`` (the bank's), ``settings``, ``elapsed_s``.
    """
    t0 = time.perf_counter()
    b = bank if bank is not None else default_bank()
    s = settings or FitSettings()
    data = lab_trials(trials, b)
    out = compare_hypotheses(data, hypotheses, bank=b, settings=s, **cluster)
    for name, h in out["hypotheses"].items():
        h["check"] = predictive_check(name if hypotheses is None else _named(hypotheses, name), data, h["params"],
                                      bank=b, settings=s)
    return {"about": ABOUT, **out, "source": data.source, "levels": b.levels, "elapsed_s": time.perf_counter() - t0}


def _named(hypotheses: Sequence[Any], name: str) -> Any:
    from ..hypotheses import hypothesis as find_hypothesis

    return next(h for h in (find_hypothesis(x) for x in hypotheses) if h.name == name)
