"""Fitting the simulated participants to the paper: the objective, the search, adopting fits.

The perceptual model's *fitted* parameters (:class:`~vibrofocus.simulation.PerceptualModel`)
are fitted to the statistics of de Vlam et al. (IEEE ToH 16(4), 2023) kept in
``simulation/data/psychophysics.json``; :func:`adopt` writes the shipped fits
(``simulation/data/hypotheses_fit.json``). The method is in docs/simulated-participants.md
("The fit"); ``scripts/fit_participants.py`` is its command line.

:mod:`.objective`
    :func:`loss` and :func:`residuals` of simulated studies against the paper.
:mod:`.candidates`
    :func:`sample`: the search's candidates.
:mod:`.searching`
    :func:`search`: one hypothesis' fit, written as a fit file.
:mod:`.fitfile`
    :func:`read_fit` / :func:`check_fit`: fit files, checked before use.
:mod:`.adoption`
    :func:`adopt`: the best path of each hypothesis, its held-out loss, the default.
:mod:`.seeds`
    :data:`FIT_SEEDS` and :data:`HELD_OUT_SEEDS`.

Fitting to a lab's trials (docs/fitting-hypotheses.md):

:mod:`.lab_trials`
    :class:`LabTrials`, :func:`lab_trials`, :func:`trials_source`: the trials on a bank's stimuli.
:mod:`.likelihood_fit`
    :class:`FitSettings`, :func:`participant_loglik`, :func:`fit_hypothesis`: maximum marginal likelihood.
:mod:`.elpd`
    :func:`compare_hypotheses`: leave-one-participant-out ELPD, on Dask.
:mod:`.predictive`
    :func:`predictive_check`: observed vs predicted answer frequencies.
:mod:`.lab_fit`
    :func:`fit_trials`: all of it, the content of ``hypotheses.json``.
:mod:`.recovery`
    :func:`simulate_trials`, :func:`simulate_plan_trials`, :func:`recovery_study`,
    :func:`model_recovery`, :func:`confusion`, :func:`recovery_rates`, :func:`parameter_recovery`.
"""

from .adoption import FITS_FILE, adopt, check_fit_set
from .candidates import CENTRAL_WEIGHT_RANGE, sample
from .fitfile import check_fit, fit_model, read_fit
from .objective import PATTERNS, loss, residuals, targets, weight_keys
from .searching import search
from .seeds import FIT_SEEDS, HELD_OUT_SEEDS
from .elpd import compare_hypotheses
from .lab_fit import fit_trials
from .lab_trials import LabTrials, lab_trials, trials_source
from .likelihood_fit import Fit, FitSettings, fit_hypothesis, participant_loglik
from .predictive import predictive_check
from .recovery import (confusion, model_recovery, parameter_recovery, profile_recovery_study, profile_summary,
                       recovery_rates, recovery_study, simulate_plan_trials, simulate_trials)

__all__ = [
    "FIT_SEEDS",
    "HELD_OUT_SEEDS",
    "FITS_FILE",
    "CENTRAL_WEIGHT_RANGE",
    "PATTERNS",
    "targets",
    "weight_keys",
    "loss",
    "residuals",
    "sample",
    "search",
    "read_fit",
    "check_fit",
    "fit_model",
    "check_fit_set",
    "adopt",
    "LabTrials",
    "lab_trials",
    "trials_source",
    "FitSettings",
    "Fit",
    "participant_loglik",
    "fit_hypothesis",
    "compare_hypotheses",
    "predictive_check",
    "fit_trials",
    "simulate_trials",
    "simulate_plan_trials",
    "model_recovery",
    "recovery_study",
    "profile_recovery_study",
    "profile_summary",
    "confusion",
    "recovery_rates",
    "parameter_recovery",
]
