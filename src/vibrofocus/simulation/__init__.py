"""Simulated participants: a perceptual MODEL that answers in place of a person (not data).

The model's two stages and their sources are in :mod:`.perception`
(docs/simulated-participants.md); :mod:`.participants` plugs it into the study engine of
:mod:`vibrofocus.studies` as a responder. The simulated forearm it feels with is
:mod:`vibrofocus.skin`.

Public API
----------
Participants (:mod:`.participants`, :mod:`.perception`)
    :class:`SimulatedParticipant`, :class:`PerceptualModel`, :class:`Percepts`,
    :data:`MODEL_VERSION`, :data:`MODEL_LABEL` (what every record of simulated data
    carries), :data:`MODEL_NOTICE`, :data:`STUDY_SKIN` (the arm the model is fitted on).
Whole studies (:mod:`.simulate`)
    :func:`simulate_studies`, :func:`participant_seeds`, :func:`summarize_simulation`.
Fast studies and power (:mod:`.bank`, :mod:`.power`, :mod:`.paper`)
    :class:`FeatureBank`, :func:`build_feature_bank`, :func:`default_bank`,
    :func:`simulate_cell_means`; :class:`PowerDesign`, :func:`run_power`,
    :func:`power_table`, :func:`study_statistics`; :func:`seed_statistics`,
    :func:`compare` (the model beside the paper).
Figures of simulated data
    :func:`model_footer` (the footer that says what in a figure is a model).
Fitting (:mod:`.fitting`)
    the objective, the search and the adoption of the shipped fits.
Likelihood (:mod:`.likelihood`)
    :func:`loglik` (each answer's log-probability given a participant's traits),
    :func:`marginal_loglik` (integrated over a hypothesis' population), :class:`Stimuli`.
Designing a study (:mod:`.design`)
    :func:`design_experiment`, :class:`DesignSettings` (the Study 1 blocks that tell the
    hypotheses apart), :func:`identification` (P(correct) against N, on Dask),
    :func:`choose_hypothesis` (model choice on a study database).
Free parameters (:mod:`.parameters`)
    :class:`ParameterRange` (a hypothesis' free parameter, its range and source).
"""

from .bank import FeatureBank, build_feature_bank, default_bank, simulate_cell_means
from .design import DesignSettings, ExperimentDesign, choose_hypothesis, design_experiment, identification
from .hypotheses import (DEFAULT_HYPOTHESIS, Hypothesis, available_hypotheses, hypotheses_with_fixed, hypothesis,
                         register_hypothesis)
from .paper import compare, seed_statistics
from .likelihood import Stimuli, loglik, marginal_loglik
from .parameters import ParameterRange
from .participants import MODEL_NOTICE, SimulatedParticipant
from .perception import MODEL_LABEL, MODEL_VERSION, STUDY_SKIN, Percepts, PerceptualModel
from .power import PowerDesign, power_table, robust_conclusions, run_power, study_statistics
from .simulate import participant_seeds, simulate_studies, summarize_simulation
from .._style import model_footer

__all__ = [
    "SimulatedParticipant",
    "Hypothesis",
    "hypothesis",
    "available_hypotheses",
    "hypotheses_with_fixed",
    "register_hypothesis",
    "DEFAULT_HYPOTHESIS",
    "robust_conclusions",
    "loglik",
    "marginal_loglik",
    "Stimuli",
    "ParameterRange",
    "DesignSettings",
    "ExperimentDesign",
    "design_experiment",
    "identification",
    "choose_hypothesis",
    "PerceptualModel",
    "Percepts",
    "MODEL_VERSION",
    "MODEL_LABEL",
    "MODEL_NOTICE",
    "STUDY_SKIN",
    "simulate_studies",
    "participant_seeds",
    "summarize_simulation",
    "FeatureBank",
    "build_feature_bank",
    "default_bank",
    "simulate_cell_means",
    "PowerDesign",
    "run_power",
    "power_table",
    "study_statistics",
    "seed_statistics",
    "compare",
    "model_footer",
]

# The former name of vibrofocus.participant_models (DEVELOPING.md, "Names"): an import from outside warns.
from .._deprecated import warn_if_imported_from_outside  # noqa: E402

warn_if_imported_from_outside(__name__, "vibrofocus.participant_models")
