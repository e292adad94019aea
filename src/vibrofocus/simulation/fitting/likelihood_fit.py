"""Maximum marginal likelihood of a hypothesis' free parameters, from a lab's trials.

Each participant's answers (Study 1 locations or points and Study 2 selections, each trial
at its block's level and among its block's allowed locations) are scored by the likelihood
of :mod:`vibrofocus.simulation.likelihood` (Study 1 locations by
:func:`~vibrofocus.simulation.design.study1_probabilities`, the design's own), integrated
over the hypothesis' population of participants as :func:`~vibrofocus.simulation.likelihood.marginal_loglik`
does (the same trait draws, common to every parameter set), and over the simulated
forearms of a feature bank (draw ``k`` feels with forearm ``k mod n_forearms``). The
draws are shared by all participants: one pass over them scores everyone, 64 draws at a
time (:func:`draw_batches`: each Study 1 trial group's answer law is taken once per batch).
:func:`fit_hypothesis` maximizes the sum over participants within the free parameters'
ranges (:attr:`~vibrofocus.simulation.hypotheses.Hypothesis.free_parameters`). The
method and its settings: docs/fitting-hypotheses.md.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize, special

from ...errors import ValidationError
from ..bank import FeatureBank, default_bank
from ..likelihood import Quadrature, Stimuli, answer_law, point_loglik, selection_probability
from ..parameters import model_at, read_parameters
from ..perception import PerceptualModel, Percepts, Traits
from .lab_trials import LabTrials

__all__ = ["FitSettings", "Fit", "model_at", "initial_simplex", "population_draws", "level_draws", "DrawBatch",
           "draw_batches", "study1_probabilities_of",
           "participant_loglik", "Evaluations", "fit_hypothesis"]


#: Draws that score a hypothesis per draw that fits it, by default (FitSettings.score_draws).
SCORE_DRAWS_PER_FIT_DRAW = 8


@dataclass(frozen=True)
class FitSettings:
    """How a hypothesis is fitted and scored.

    Attributes
    ----------
    n_draws : int
        Participants (traits and forearm) drawn from the hypothesis' population to
        integrate each participant's likelihood over (Monte Carlo, common to every
        parameter set and every participant).
    seed : int
        Seed of those draws and of the optimizer's extra starts.
    n_starts : int
        Starts of the bounded optimizer: the hypothesis' own values, then points drawn
        uniformly within the ranges.
    lapse : float
        Share of answers given at random (uniform over the trial's allowed locations in
        Study 1, over the picture of the arm area for a point answer, over the non-empty
        selections of the allowed locations in Study 2), mixed into every answer's probability so that
        an answer the model cannot give costs a finite amount (Wichmann & Hill 2001,
        Percept. Psychophys. 63(8)). An assumption of the fit, the same for every hypothesis.
    quadrature : Quadrature
        Nodes of the likelihood's integrals (coarser than the likelihood's defaults:
        about 1e-3 in log-likelihood per Study 2 trial).
    score_draws : int or None
        Draws that score each hypothesis (the ELPD's left-out participants), from a stream
        independent of the fit's (:meth:`scoring`): a fit tunes the population to its own
        ``n_draws`` draws, and a likelihood on those same few draws favours the hypothesis
        with the most free parameters (docs/fitting-hypotheses.md, "Model recovery").
        None: ``SCORE_DRAWS_PER_FIT_DRAW * n_draws``; 0: scored on the fit's own draws.
    maxiter : int
        Iterations of the Nelder-Mead search per start (each one or two likelihoods; the
        first simplex adds one per free parameter).
    """

    n_draws: int = 32
    seed: int = 0
    n_starts: int = 3
    lapse: float = 0.01
    quadrature: Quadrature = field(default_factory=lambda: Quadrature(n_place=6, n_segment=3))
    maxiter: int = 60
    score_draws: int | None = None

    def __post_init__(self) -> None:
        for name, lo, hi in (("n_draws", 1, 100_000), ("n_starts", 1, 1000), ("maxiter", 1, 10_000),
                             ("seed", 0, 2**63 - 1), ("score_draws", 0, 1_000_000)):
            v = getattr(self, name)
            if name == "score_draws" and v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise ValidationError(f"{name} must be an integer from {lo} to {hi}, got {v!r}")
        if not (isinstance(self.lapse, (int, float)) and 0.0 <= self.lapse < 1.0):
            raise ValidationError(f"lapse must be in [0, 1), got {self.lapse!r}")


    def scoring(self) -> FitSettings:
        """The settings that score: ``score_draws`` draws of another stream (the seed XOR 0x5C0E)."""
        if self.score_draws == 0:
            return self
        n = SCORE_DRAWS_PER_FIT_DRAW * self.n_draws if self.score_draws is None else self.score_draws
        return dataclasses.replace(self, n_draws=n, seed=int(self.seed) ^ 0x5C0E, score_draws=0)


@dataclass(frozen=True)
class Fit:
    """A hypothesis fitted to trials.

    Attributes
    ----------
    hypothesis : str
    params : dict of str to float
        The free parameters at the maximum (by :attr:`ParameterRange.key`, SI units).
    loglik : float
        Summed marginal log-likelihood at the maximum, natural log.
    participant_loglik : ndarray, shape (n_participants,)
        Each participant's marginal log-likelihood there.
    n_evaluations : int
        Likelihood evaluations (each scores every participant).
    """

    hypothesis: str
    params: dict[str, float]
    loglik: float
    participant_loglik: np.ndarray
    n_evaluations: int


def population_draws(h: Any, model: PerceptualModel, bank: FeatureBank,
                     settings: FitSettings) -> Iterator[tuple[Traits, Stimuli, Percepts]]:
    """The population's draws: traits (:meth:`Traits.draw`, the stream of ``marginal_loglik``) and forearm.

    Parameters
    ----------
    h : Hypothesis
    model : PerceptualModel
    bank : FeatureBank
    settings : FitSettings

    Yields
    ------
    traits : Traits
    stimuli : Stimuli
        Draw ``k``'s forearm, ``k mod n_forearms``.
    percepts : Percepts
        Its noise-free percepts of every stimulus of the bank.
    """
    for traits, at in level_draws(h, model, bank, settings, (0.0,)):
        yield traits, *at[0.0]


def level_draws(h: Any, model: PerceptualModel, bank: FeatureBank, settings: FitSettings,
                levels: Sequence[float]) -> Iterator[tuple[Traits, dict[float, tuple[Stimuli, Percepts]]]]:
    """:func:`population_draws` with the bank's stimuli at each of ``levels``.

    Parameters
    ----------
    h, model, bank, settings
        As :func:`population_draws`.
    levels : sequence of float
        dB re the bank's level rule (:meth:`~vibrofocus.simulation.bank.FeatureBank.at_level`).

    Yields
    ------
    traits : Traits
    at : dict
        Per level, the :class:`Stimuli` of draw ``k``'s forearm (``k mod n_forearms``) and
        the percepts of every stimulus there.
    """
    banks = _level_banks(bank, levels)
    for _, traits, forearm in _draw_stream(model, bank, settings):
        at = {}
        for v, b in banks.items():
            st = Stimuli.from_bank(b, forearm)
            at[v] = (st, st.percepts(h, model, traits))
        yield traits, at


def _level_banks(bank: FeatureBank, levels: Sequence[float]) -> dict[float, FeatureBank]:
    """The bank at each level, dB re its level rule (the bank itself at 0 dB)."""
    return {float(v): bank if float(v) == 0.0 else bank.at_level(float(v)) for v in levels}


def _draw_stream(model: PerceptualModel, bank: FeatureBank, settings: FitSettings) -> Iterator[tuple[int, Traits, int]]:
    """The population's draws: number ``k``, traits (the stream of ``marginal_loglik``) and forearm ``k mod n``."""
    rng = np.random.default_rng([int(settings.seed), 0x11C])
    for k in range(settings.n_draws):
        yield k, Traits.draw(model, rng), k % bank.n_forearms


#: Population draws scored together: their Study 1 answer laws are taken in one call per
#: trial group (rows: draws x the group's stimuli x the law's components).
DRAW_BATCH = 64


@dataclass(frozen=True)
class DrawBatch:
    """Consecutive population draws, their percepts stacked draw by draw.

    Attributes
    ----------
    first : int
        Number of the batch's first draw.
    traits : list of Traits
        Each draw's traits.
    percepts : dict of float to Percepts
        Per level, the percepts of every stimulus of the bank for each draw: row
        ``k * n_stimuli + stimulus`` for the batch's ``k``-th draw.
    n_stimuli : int
    centre_xy, locations_xy : ndarray
        Of the bank (the same for every forearm), m.
    """

    first: int
    traits: list[Traits]
    percepts: dict[float, Percepts]
    n_stimuli: int
    centre_xy: np.ndarray
    locations_xy: np.ndarray

    def rows(self, stimuli: np.ndarray) -> np.ndarray:
        """Rows of ``percepts`` of ``stimuli`` (per trial or per distinct stimulus) for every draw, draw by draw."""
        return (np.arange(len(self.traits))[:, None] * self.n_stimuli + np.asarray(stimuli)[None, :]).ravel()

    def row_traits(self, rows: np.ndarray) -> Traits:
        """Traits with one value per row of ``percepts`` in ``rows`` (what ``trial_posteriors`` reads).

        The Study 2 criterion ``kappa`` is the first draw's: a law built from these traits
        serves Study 1 only.
        """
        draw = np.asarray(rows) // self.n_stimuli
        t = self.traits
        pick = lambda name: np.array([getattr(x, name) for x in t], dtype=float)[draw]  # noqa: E731
        return Traits(0.0, pick("acuity_sd_m"), pick("prior_sd_m"), np.array([x.bias_m for x in t], dtype=float)[draw],
                      float(t[0].kappa), float(t[0].rt_median_s), pick("spread_gain"))

    def draw_percepts(self, level_db: float, k: int) -> Percepts:
        """The percepts of the batch's ``k``-th draw at ``level_db`` (every stimulus)."""
        return _take(self.percepts[level_db], slice(k * self.n_stimuli, (k + 1) * self.n_stimuli))


def _take(per: Percepts, rows: slice) -> Percepts:
    return Percepts(*(None if getattr(per, f.name) is None else getattr(per, f.name)[rows]
                      for f in dataclasses.fields(Percepts)))


def _stack(parts: Sequence[Percepts]) -> Percepts:
    first = parts[0]
    return Percepts(*(None if getattr(first, f.name) is None else np.concatenate([getattr(p, f.name) for p in parts])
                      for f in dataclasses.fields(Percepts)))


def draw_batches(h: Any, model: PerceptualModel, bank: FeatureBank, settings: FitSettings, levels: Sequence[float],
                 size: int = DRAW_BATCH) -> Iterator[DrawBatch]:
    """:func:`level_draws` in batches of ``size`` draws (the same draws, in the same order).

    Each draw's percepts at every level come from one call of the hypothesis (the levels'
    stimuli stacked: a stimulus' percept reads its own row only).

    Parameters
    ----------
    h, model, bank, settings, levels
        As :func:`level_draws`.
    size : int
        Draws per batch.

    Yields
    ------
    DrawBatch
    """
    banks = _level_banks(bank, levels)
    n_stim = bank.energy.shape[1] * bank.energy.shape[2]

    def batch(first: int, drawn: list[tuple[Traits, int]]) -> DrawBatch:
        parts: dict[float, list[Percepts]] = {v: [] for v in banks}
        for t, f in drawn:
            both = Stimuli(np.concatenate([b.energy[f].reshape(n_stim, -1) for b in banks.values()]),
                           bank.points_xy, bank.locations_xy, bank.centre_xy,
                           np.concatenate([b.actuator_energy[f].reshape(n_stim, -1) for b in banks.values()]),
                           bank.actuators_xy)
            per = both.percepts(h, model, t)
            for i, v in enumerate(banks):
                parts[v].append(_take(per, slice(i * n_stim, (i + 1) * n_stim)))
        return DrawBatch(first, [t for t, _ in drawn], {v: _stack(p) for v, p in parts.items()}, n_stim,
                         np.asarray(bank.centre_xy, dtype=float), np.asarray(bank.locations_xy, dtype=float))

    drawn: list[tuple[Traits, int]] = []
    for k, traits, forearm in _draw_stream(model, bank, settings):
        drawn.append((traits, forearm))
        if len(drawn) == size or k == settings.n_draws - 1:
            yield batch(k + 1 - len(drawn), drawn)
            drawn = []


def study1_probabilities_of(data: LabTrials, at: Mapping[float, tuple[Stimuli, Percepts]], model: PerceptualModel,
                            traits: Traits, quadrature: Quadrature) -> np.ndarray:
    """Probability of each location answer of each Study 1 trial, at its level and among its allowed locations.

    Parameters
    ----------
    data : LabTrials
    at : mapping
        Per level of the trials, the stimuli and percepts of one draw (:func:`level_draws`).
    model : PerceptualModel
    traits : Traits
    quadrature : Quadrature

    Returns
    -------
    ndarray, shape (n1, n_locations)
        :func:`~vibrofocus.simulation.design.study1_probabilities` of the trial's stimulus
        (0 at locations not allowed).
    """
    from ..design import study1_probabilities

    out = np.zeros((data.stim1.size, data.n_locations))
    for g in data.study1_groups:
        st, per = at[g.level_db]
        law = answer_law(per, g.stimuli, st.centre_xy, model, traits, quadrature, study=1)
        out[g.rows] = study1_probabilities(law, st.locations_xy, g.allowed, quadrature)[g.which]
    return out


def participant_loglik(hypothesis: Any, data: LabTrials, values: Sequence[float] | Mapping[str, float] | None = None,
                       *, bank: FeatureBank | None = None, settings: FitSettings | None = None) -> np.ndarray:
    """Each participant's marginal log-likelihood under a hypothesis with its free parameters at ``values``.

    ``log mean_k prod_trials p(answer | traits_k, forearm_k)``, the product over the
    participant's Study 1 and Study 2 trials together (one person, one set of traits).
    Each trial is scored at its level, among its allowed locations; a point answer by the
    density of the perceived place (:func:`~vibrofocus.simulation.likelihood.point_loglik`,
    per m^2), its lapse uniform over the picture of the arm area
    (:func:`~vibrofocus.simulation.design.point_area_m`).

    Parameters
    ----------
    hypothesis : str or Hypothesis
    data : LabTrials
    values : sequence or mapping of float, optional
        The free parameters (in the order of ``free_parameters``, or by key); None: the
        hypothesis' own.
    bank : FeatureBank, optional
        Default :func:`~vibrofocus.simulation.bank.default_bank`.
    settings : FitSettings, optional

    Returns
    -------
    ndarray, shape (n_participants,)
        Natural log.
    """
    from ..design import point_area_m, study1_probabilities
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    s = settings or FitSettings()
    m = model_at(h, values)
    if tuple(b.methods) != data.methods or len(b.locations_xy) != data.n_locations:
        raise ValidationError("the trials were mapped onto another feature bank's stimuli")
    q = s.quadrature
    level1, allowed1, point1 = data.study1_conditions()
    level2, allowed2 = data.study2_conditions()
    is_point = np.isfinite(point1[:, 0])
    loc = ~is_point
    floor1 = s.lapse / np.maximum(allowed1.sum(axis=1), 1)
    lo, hi = point_area_m(b)
    log_floor_point = np.log(s.lapse / float(np.prod(hi - lo))) if s.lapse else -np.inf
    floor2 = s.lapse / (2.0 ** allowed2.sum(axis=1) - 1.0)
    levels = sorted(set(level1.tolist()) | set(level2.tolist()))
    total = np.zeros((s.n_draws, data.n_participants))
    # Each trial's participant as columns to sum over (a trial's log-probability may be -inf
    # without a lapse, so no matrix product).
    owners1 = [np.flatnonzero(data.part1 == i) for i in range(data.n_participants)]
    for batch in draw_batches(h, m, b, s, levels):
        n_b = len(batch.traits)
        ll1 = np.zeros((n_b, data.stim1.size))
        with np.errstate(divide="ignore"):
            for g in data.study1_groups:
                rows = batch.rows(g.stimuli)
                law = answer_law(batch.percepts[g.level_db], rows, batch.centre_xy, m, batch.row_traits(rows), q,
                                 study=1)
                at_loc = loc[g.rows]
                if at_loc.any():
                    p = study1_probabilities(law, batch.locations_xy, g.allowed, q).reshape(n_b, g.stimuli.size, -1)
                    r = g.rows[at_loc]
                    p1 = p[:, g.which[at_loc], data.answer1[r]]
                    ll1[:, r] = np.log((1.0 - s.lapse) * p1 + floor1[r])
                if not at_loc.all():
                    # A point answer: the density of the perceived place, per trial and draw.
                    r = g.rows[~at_loc]
                    trial_rows = batch.rows(data.stim1[r])
                    law_t = answer_law(batch.percepts[g.level_db], trial_rows, batch.centre_xy, m,
                                       batch.row_traits(trial_rows), q, study=1)
                    dens = point_loglik(law_t, np.tile(point1[r], (n_b, 1))).reshape(n_b, -1)
                    ll1[:, r] = np.logaddexp(np.log1p(-s.lapse) + dens, log_floor_point)
            block = slice(batch.first, batch.first + n_b)
            for i, own in enumerate(owners1):
                total[block, i] += ll1[:, own].sum(axis=1)
            if data.stim2.size:
                for k, traits in enumerate(batch.traits):
                    # Each distinct (stimulus, selection) of a group is scored once per draw for everyone.
                    p2 = np.zeros(data.stim2.size)
                    for g in data.study2_groups:
                        per = batch.draw_percepts(g.level_db, k)
                        law = answer_law(per, g.stimuli, batch.centre_xy, m, traits, q, study=2)
                        p2[g.rows] = selection_probability(law, batch.locations_xy, g.selections, g.allowed,
                                                           q)[g.which]
                    total[batch.first + k] += np.bincount(data.part2, np.log((1.0 - s.lapse) * p2 + floor2),
                                                          data.n_participants)
    with np.errstate(divide="ignore"):
        return special.logsumexp(total, axis=0) - np.log(s.n_draws)


#: Parameters read by the Study 2 selection only: not fitted to trials without Study 2.
STUDY2_ONLY = ("select_kappa", "select_log_sd")

#: Side of the Nelder-Mead start simplex, as a share of each free parameter's range.
SIMPLEX_STEP = 0.1


def initial_simplex(u0: np.ndarray, step: float = SIMPLEX_STEP) -> np.ndarray:
    """Nelder-Mead's first simplex around ``u0`` in the unit cube: ``u0`` and one vertex per axis.

    Vertex ``i`` moves parameter ``i`` by ``step`` of its range (toward the range's
    middle, so that it stays inside): a step on the parameter's own scale, which sees a
    parameter that acts through a threshold (piecewise flat or jagged at a
    finite-difference step) move the likelihood.

    Parameters
    ----------
    u0 : ndarray, shape (n,)
        The start, each parameter scaled to [0, 1] over its range.
    step : float
        Share of the range, in (0, 0.5].

    Returns
    -------
    ndarray, shape (n + 1, n)
    """
    u0 = np.clip(np.asarray(u0, dtype=float), 0.0, 1.0)
    moves = np.where(u0 <= 0.5, step, -step)
    return np.vstack([u0, u0 + np.diag(moves)])


class Evaluations:
    """Every participant's log-likelihood at each parameter set evaluated, kept for reuse.

    For one hypothesis, set of trials, bank and settings. A fit to some of the
    participants (a leave-one-participant-out fold) reads the sum of theirs; the folds
    of one study start at the same place with the same first simplex, and their searches
    agree for many steps, so folds that share one :class:`Evaluations` compute each
    parameter set once. Scoring every participant costs about what scoring all but one
    does: the population's draws, not the participants, dominate the cost.

    Parameters
    ----------
    hypothesis : Hypothesis
    data : LabTrials
    bank : FeatureBank
    settings : FitSettings
    """

    def __init__(self, hypothesis: Any, data: LabTrials, bank: FeatureBank, settings: FitSettings) -> None:
        self.hypothesis, self.data, self.bank, self.settings = hypothesis, data, bank, settings
        self._values: dict[tuple[float, ...], np.ndarray] = {}

    def __len__(self) -> int:
        return len(self._values)

    def __call__(self, values: np.ndarray) -> np.ndarray:
        """Each participant's log-likelihood (shape (n_participants,)) at the free parameters ``values``.

        ``values`` in the order of ``free_parameters``, SI units; a set is reused only
        where it is exactly the same numbers (callers round their search's coordinates).
        """
        key = tuple(np.asarray(values, dtype=float).tolist())
        if key not in self._values:
            self._values[key] = participant_loglik(self.hypothesis, self.data, list(key), bank=self.bank,
                                                   settings=self.settings)
        return self._values[key]


def fit_hypothesis(hypothesis: Any, data: LabTrials, *, bank: FeatureBank | None = None,
                   settings: FitSettings | None = None, start: Mapping[str, float] | None = None,
                   participants: np.ndarray | None = None, evaluations: Evaluations | None = None) -> Fit:
    """Fit a hypothesis' free parameters to trials by maximum marginal likelihood.

    Nelder-Mead within the parameters' ranges (scaled to [0, 1]), from ``settings.n_starts``
    starts: ``start`` (or the hypothesis' own values, clipped into the ranges), then
    points drawn uniformly with ``settings.seed``; each start's first simplex steps every
    parameter by a tenth of its range (:func:`initial_simplex`). No gradient: a parameter
    that acts through a threshold (e.g. ``sl_ref_db``: the felt field's points cross the
    detection threshold) makes the likelihood jagged at a finite-difference step, and a
    gradient there points anywhere (docs/fitting-hypotheses.md, "The fit and the score").
    Stops when the simplex is within 0.1 % of every range and 0.001 in log-likelihood,
    or after ``settings.maxiter`` iterations. Trials without Study 2 leave the selection's
    parameters (:data:`STUDY2_ONLY`) at their start: no answer reads them. Deterministic
    for a seed. A hypothesis without free parameters is scored as it is.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    data : LabTrials
    bank : FeatureBank, optional
    settings : FitSettings, optional
    start : mapping of str to float, optional
        First start (by parameter key), e.g. a fit to all participants when refitting
        without one.
    participants : ndarray of int, optional
        Fit to these participants only (indices into ``data.participants``; default all).
        Whether the Study 2 selection's parameters are fitted depends on ``data`` as a whole.
    evaluations : Evaluations, optional
        Evaluations of the same hypothesis, ``data``, bank and settings to reuse and add
        to (e.g. shared by the folds of :func:`~.elpd.fold_logliks`); the result is the
        same with or without.

    Returns
    -------
    Fit
        ``participant_loglik`` of the participants fitted, in the order of ``participants``.
    """
    from ..hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    b = bank if bank is not None else default_bank()
    s = settings or FitSettings()
    ranges = h.free_parameters
    who = np.arange(data.n_participants) if participants is None else np.asarray(participants, dtype=int)
    if not ranges:
        ll = participant_loglik(h, data, None, bank=b, settings=s)[who]
        return Fit(h.name, {}, float(ll.sum()), ll, 1)
    lo = np.array([r.lo for r in ranges])
    span = np.array([r.hi for r in ranges]) - lo
    first = [start[r.key] for r in ranges] if start is not None else read_parameters(h.model(), ranges)
    full = np.clip((np.asarray(first, dtype=float) - lo) / span, 0.0, 1.0)
    # Without Study 2 trials the selection's parameters touch no answer: kept where they start.
    active = np.array([i for i, r in enumerate(ranges) if data.stim2.size or r.name not in STUDY2_ONLY], dtype=int)
    evaluate = evaluations if evaluations is not None else Evaluations(h, data, b, s)
    seen: set[tuple[float, ...]] = set()

    def at(u: np.ndarray) -> np.ndarray:
        out = full.copy()
        out[active] = u
        return np.clip(out, 0.0, 1.0)

    def per_participant(u: np.ndarray) -> np.ndarray:
        values = lo + span * np.round(at(u), 12)
        seen.add(tuple(values))
        return evaluate(values)[who]

    def objective(u: np.ndarray) -> float:
        value = float(per_participant(u).sum())
        return -value if np.isfinite(value) else 1e300

    if not active.size:
        ll = per_participant(full[active])
        return Fit(h.name, {r.key: float(v) for r, v in zip(ranges, lo + span * full)}, float(ll.sum()), ll, 1)
    starts = [full[active]]
    rng = np.random.default_rng([int(s.seed), 0xF17])
    starts += list(rng.random((s.n_starts - 1, len(ranges)))[:, active])
    best = None
    for u0 in starts:
        res = optimize.minimize(objective, u0, method="Nelder-Mead", bounds=[(0.0, 1.0)] * active.size,
                                options={"maxiter": s.maxiter, "initial_simplex": initial_simplex(u0),
                                         "xatol": 1e-3, "fatol": 1e-3})
        if best is None or res.fun < best.fun:
            best = res
    u = at(best.x)
    ll = per_participant(best.x)
    params = {r.key: float(v) for r, v in zip(ranges, lo + span * u)}
    return Fit(h.name, params, float(ll.sum()), ll, len(seen))
