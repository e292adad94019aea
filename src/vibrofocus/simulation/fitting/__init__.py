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
"""

from .adoption import FITS_FILE, adopt, check_fit_set
from .candidates import CENTRAL_WEIGHT_RANGE, sample
from .fitfile import check_fit, fit_model, read_fit
from .objective import PATTERNS, loss, residuals, targets, weight_keys
from .searching import search
from .seeds import FIT_SEEDS, HELD_OUT_SEEDS

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
]
