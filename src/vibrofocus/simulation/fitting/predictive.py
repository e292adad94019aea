"""Posterior-predictive check of a fitted hypothesis: observed vs predicted answer frequencies.

For the lab's own stimuli (method x target, as many trials as it ran), the population's
predicted share of answers at each location beside the observed share, per method:
Study 1 exactly (the answer probabilities of each trial at its level among its allowed
locations, :func:`~.likelihood_fit.study1_probabilities_of`, averaged over the
population's draws; a point answer counts at its stored location), Study 2 by the sampler
(one set of selections per draw; a location's share is how often it is selected). The predictions are MODEL
output; the observations are the lab's data. docs/fitting-hypotheses.md, "Predictive check".
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...errors import ValidationError
from ..bank import FeatureBank, default_bank
from ..perception import draw_answers
from .lab_trials import LabTrials
from .likelihood_fit import FitSettings, level_draws, model_at, study1_probabilities_of

__all__ = ["predictive_check"]


def _by_method(values: np.ndarray, stim: np.ndarray, n_loc: int, methods: tuple[str, ...]) -> dict[str, list[float]]:
    """Mean of ``values`` (n, n_loc) over each method's trials; methods without trials are left out."""
    method = stim // n_loc
    out = {}
    for i, name in enumerate(methods):
        rows = method == i
        if rows.any():
            out[name] = values[rows].mean(axis=0).tolist()
    return out


def predictive_check(hypothesis: Any, data: LabTrials, params: Mapping[str, float] | None = None, *,
                     bank: FeatureBank | None = None, settings: FitSettings | None = None) -> dict[str, Any]:
    """Observed vs predicted answer frequency per location and method.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    data : LabTrials
    params : mapping of str to float, optional
        The free parameters (a fit's); default the hypothesis' own.
    bank : FeatureBank, optional
    settings : FitSettings, optional
        Its draws (``n_draws``, ``seed``) are the population predicted from.

    Returns
    -------
    dict
        ``study1``: per method, ``observed`` and ``predicted`` share of answers at each
        location 1..n (lists), and ``by_target``: per target number, the same;
        ``study2``: per method, ``observed`` and ``predicted`` share of trials selecting
        each location, and ``observed_count`` / ``predicted_count`` (mean locations
        selected). A study without trials is None.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    s = settings or FitSettings()
    m = model_at(h, params)
    n_loc = data.n_locations
    p1 = np.zeros((data.stim1.size, n_loc))
    sel2 = np.zeros((data.stim2.size, n_loc))
    rng = np.random.default_rng([int(s.seed), 0x99C])
    level1, allowed1, _ = data.study1_conditions()
    level2, allowed2 = data.study2_conditions()
    if data.stim2.size and (np.any(level2 != 0.0) or not allowed2.all()):
        raise ValidationError("the predictive check draws Study 2 answers at 0 dB among every location; these "
                              "trials have other levels or allowed locations")
    for traits, at in level_draws(h, m, b, s, sorted(set(level1.tolist()) | {0.0})):
        if data.stim1.size:
            p1 += study1_probabilities_of(data, at, m, traits, s.quadrature)
        if data.stim2.size:
            st, per = at[0.0]
            sel2 += draw_answers(per, data.stim2, st.locations_xy, st.centre_xy, m, traits, rng)[1]
    out: dict[str, Any] = {"study1": None, "study2": None}
    if data.stim1.size:
        p1 = (1.0 - s.lapse) * p1 / s.n_draws + s.lapse * allowed1 / allowed1.sum(axis=1, keepdims=True)
        obs1 = np.eye(n_loc)[data.answer1]
        study1 = {name: {"observed": o, "predicted": p}
                  for (name, o), p in zip(_by_method(obs1, data.stim1, n_loc, data.methods).items(),
                                          _by_method(p1, data.stim1, n_loc, data.methods).values())}
        target = data.stim1 % n_loc
        for name in study1:
            rows = data.stim1 // n_loc == data.methods.index(name)
            study1[name]["by_target"] = {
                str(t + 1): {"observed": obs1[rows & (target == t)].mean(axis=0).tolist(),
                             "predicted": p1[rows & (target == t)].mean(axis=0).tolist()}
                for t in np.unique(target[rows])}
        out["study1"] = study1
    if data.stim2.size:
        sel2 /= s.n_draws
        obs2 = data.selected2.astype(float)
        observed = _by_method(obs2, data.stim2, n_loc, data.methods)
        predicted = _by_method(sel2, data.stim2, n_loc, data.methods)
        out["study2"] = {name: {"observed": observed[name], "predicted": predicted[name],
                                "observed_count": float(np.sum(observed[name])),
                                "predicted_count": float(np.sum(predicted[name]))} for name in observed}
    return out
