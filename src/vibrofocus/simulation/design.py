"""Designing a study that decides between the hypotheses (``vibrofocus design-experiment``).

A MODEL, not data: the design is optimal for the registered hypotheses of simulated
participants (:mod:`vibrofocus.simulation.hypotheses`), as they are implemented. The
method, its assumptions and its tables are in docs/designing-a-study.md.

:func:`design_experiment` chooses Study 1 blocks (one method at one level re the level
rule, over a grid of locations, the participant answering one of them or a point on the
picture of the arm area) that maximize the
expected information gain about which hypothesis is right, greedily per trial of the
budget; the answer laws are those of :mod:`vibrofocus.simulation.likelihood`
(:func:`~vibrofocus.simulation.likelihood.answer_law`), integrated over a population of
simulated participants per hypothesis (parameter draws x forearms x traits).
:func:`identification` estimates, by simulation on Dask, the probability that model
choice by marginal likelihood (:func:`~vibrofocus.simulation.likelihood.marginal_loglik`,
here vectorized over the same trait draws) picks the true hypothesis, against the number
of participants. :func:`design_protocol_text` writes the design as a protocol file
(docs/protocols.md).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import special

from ..errors import ValidationError
from .bank import FeatureBank, check_level_db, default_bank
from .likelihood import AnswerLaw, Quadrature, answer_law, answer_probabilities
from .perception import PerceptualModel, Traits, draw_answers

__all__ = ["DesignSettings", "CandidateBlock", "PlanBlock", "ExperimentDesign", "location_sets",
           "study1_probabilities", "shipped_model", "parameter_draws", "rival_fits_from", "read_rival_fits",
           "condition_gains", "design_experiment", "paper_plan",
           "design_protocol_text", "score_tables", "ScoreTable", "design_report", "write_design",
           "participant_loglik", "choose_hypothesis", "identification", "point_area_m", "DEFAULT_LEVELS_DB",
           "RESPONSES", "SCORE_SEED", "THRESHOLD_BLOCK"]

#: Candidate levels, dB re the level rule (the paper's): 0 down to -30 dB.
DEFAULT_LEVELS_DB = (0.0, -5.0, -10.0, -15.0, -20.0, -30.0)
#: Answers a designed block may take: one location of the block's (a key), or a point on
#: the picture of the arm area (docs/protocols.md, "Point responses").
RESPONSES = ("location", "point")
#: The trait draws' seed of :func:`~vibrofocus.simulation.likelihood.marginal_loglik` used
#: to score simulated studies (its default).
SCORE_SEED = 0
#: Smallest probability of an answer in the design's tables (a log of 0 would make one
#: unlikely simulated answer decide a whole sample; the scores of :func:`identification`
#: use the exact law, as ``marginal_loglik`` does).
_FLOOR = 1e-12


@dataclass(frozen=True)
class DesignSettings:
    """Inputs of :func:`design_experiment` (defaults: those of ``vibrofocus design-experiment``).

    Attributes
    ----------
    hypotheses : tuple of str or None
        Registered hypotheses to tell apart (None: every registered one; at least 2).
    methods : tuple of str or None
        Candidate methods (None: the feature bank's).
    locations : tuple of int or None
        Candidate location numbers (None: all).
    levels_db : tuple of float
        Candidate levels, dB re the bank's level rule (each at most 0 dB over it).
    budget : int
        Study 1 trials per participant.
    n_parameter_draws : int
        Parameter sets per hypothesis: the shipped one and ``n - 1`` drawn around it
        (:func:`parameter_draws`).
    parameter_spread : float
        Half-width of the draws around the shipped value, as a fraction of each free
        parameter's range. 1 (the default): uniform over the whole range, the ranges the
        free fit of ``analyze --hypotheses`` searches, so that the design does not rely
        on a difference of parameters that the fit can remove (docs/designing-a-study.md,
        "Parameter uncertainty"); 0.1 was the default before.
    n_forearms : int
        Forearms of the bank the design integrates over.
    n_traits : int
        Participants' trait draws per hypothesis, parameter set and forearm.
    n_replicates : int
        Simulated answer sets per sample (the Monte Carlo of the expected gain).
    seed : int
        Seed of every draw of the design.
    population : str or None
        None: each hypothesis with its own shipped parameters (as ``simulate-study
        --hypothesis`` simulates it). A hypothesis' name: every hypothesis with that one's
        parameters, so that they differ in their readout only (one population).
    responses : tuple of str
        The answers candidate blocks may take (:data:`RESPONSES`): ``location`` (one of the
        block's locations; the default) and ``point`` (a point on the picture of the arm
        area). Points carry much more information given the person, but model choice by
        the Monte Carlo marginal likelihood over trait draws uses them poorly
        (docs/designing-a-study.md).
    information : str
        What the greedy choice maximizes: ``population`` (default), the information about
        the hypothesis given the forearm only (traits and parameters integrated over, by a
        nested Monte Carlo that is biased low, and noisy when the hypotheses are close);
        ``person``, given the person too (the same traits and parameter draw under every
        hypothesis), which saturates at log(number of hypotheses) once a participant's
        answers decide.
    rival_fits : mapping of str to sequence of mapping, optional
        More parameter sets per hypothesis, by key of its free parameters, added to its
        draws: its free fits to studies simulated under the other hypotheses (the places
        the free fit of ``analyze --hypotheses`` moves a rival to, where it mimics the true
        one; :func:`rival_fits_from`). Draws over the ranges seldom come near them; with
        them, the design looks for trials that a rival cannot fit its way around.
    """

    hypotheses: tuple[str, ...] | None = None
    methods: tuple[str, ...] | None = None
    locations: tuple[int, ...] | None = None
    levels_db: tuple[float, ...] = DEFAULT_LEVELS_DB
    budget: int = 81
    n_parameter_draws: int = 6
    parameter_spread: float = 1.0
    n_forearms: int = 6
    n_traits: int = 8
    n_replicates: int = 2
    seed: int = 0
    population: str | None = None
    responses: tuple[str, ...] = ("location",)
    information: str = "population"
    rival_fits: Mapping[str, Sequence[Mapping[str, float]]] | None = None

    def __post_init__(self) -> None:
        from .._validation import check_in_range
        from .hypotheses import available_hypotheses, hypothesis as find_hypothesis
        from .parameters import model_at

        names = available_hypotheses() if self.hypotheses is None else tuple(
            dict.fromkeys(find_hypothesis(h).name for h in self.hypotheses))
        if len(names) < 2:
            raise ValidationError(f"a design tells hypotheses apart: name at least 2, got {', '.join(names) or 'none'}")
        object.__setattr__(self, "hypotheses", names)
        if self.population is not None:
            object.__setattr__(self, "population", find_hypothesis(self.population).name)
        levels = tuple(check_level_db(x, "levels_db") for x in self.levels_db)
        if not levels or len(set(levels)) != len(levels):
            raise ValidationError(f"levels_db: at least one level, each once, got {list(self.levels_db)}")
        object.__setattr__(self, "levels_db", levels)
        responses = tuple(dict.fromkeys(str(r) for r in self.responses))
        if not responses or any(r not in RESPONSES for r in responses):
            raise ValidationError(f"responses: one or more of {', '.join(RESPONSES)}, got {list(self.responses)}")
        object.__setattr__(self, "responses", responses)
        if self.information not in ("person", "population"):
            raise ValidationError(f"information must be person or population, got {self.information!r}")
        for name, lo, hi in (("budget", 1, 20_000), ("n_parameter_draws", 1, 64), ("n_forearms", 1, 1000),
                             ("n_traits", 1, 1000), ("n_replicates", 1, 100), ("seed", 0, 2**63 - 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise ValidationError(f"{name} must be an integer from {lo} to {hi}, got {v!r}")
        check_in_range(self.parameter_spread, "parameter_spread", 0.0, 1.0)
        if self.rival_fits:
            fits = {}
            for name, sets in self.rival_fits.items():
                h = find_hypothesis(name)
                if h.name not in names:
                    raise ValidationError(f"rival_fits: {h.name} is not among the hypotheses to tell apart")
                sets = tuple(dict(v) for v in sets)
                keys = {r.key for r in h.free_parameters}
                for v in sets:
                    unknown = sorted(set(v) - keys)
                    try:
                        if unknown:
                            raise ValidationError(f"{', '.join(map(repr, unknown))} not among its free parameters")
                        model_at(h, v)  # a missing key, a value out of range
                    except ValidationError as exc:
                        raise ValidationError(f"rival_fits: a parameter set of {h.name}: {exc}") from None
                fits[h.name] = sets
            if self.information == "person" and len({len(fits.get(n, ())) for n in names}) > 1:
                raise ValidationError("rival_fits: the information given the person needs as many sets for every "
                                      "hypothesis")
            object.__setattr__(self, "rival_fits", fits)


@dataclass(frozen=True)
class CandidateBlock:
    """A candidate block: one method at one level over a grid of locations (answered among them).

    Attributes
    ----------
    method : str
    level_db : float
        dB re the level rule.
    locations : tuple of int
        Location numbers (1-based): the targets, and the answers allowed.
    grid : str
        Which grid of the candidate locations (:func:`location_sets`).
    response : str
        ``location`` (answered among the locations) or ``point`` (anywhere on the picture).
    """

    method: str
    level_db: float
    locations: tuple[int, ...]
    grid: str
    response: str = "location"

    @property
    def label(self) -> str:
        return f"{self.method} {self.level_db:+g} dB, {self.grid}" + (", points" if self.response == "point" else "")


@dataclass(frozen=True)
class PlanBlock:
    """A block of a study plan: methods x locations at one level, ``repetitions`` times.

    Attributes
    ----------
    methods : tuple of str
    level_db : float
        dB re the level rule.
    locations : tuple of int
        Location numbers (1-based): the targets, and the answers allowed.
    repetitions : int
    grid : str
        Which grid of :func:`location_sets` the locations are ("" if none).
    response : str
        ``location`` (answered among the locations) or ``point`` (a point on the picture
        of the arm area; its nearest location is the answer's location).
    """

    methods: tuple[str, ...]
    level_db: float
    locations: tuple[int, ...]
    repetitions: int
    grid: str = ""
    response: str = "location"

    @property
    def n_trials(self) -> int:
        return len(self.methods) * len(self.locations) * self.repetitions


@dataclass(frozen=True)
class ExperimentDesign:
    """What :func:`design_experiment` chose, and why.

    Attributes
    ----------
    settings : DesignSettings
    blocks : tuple of PlanBlock
        The designed Study 1 blocks (grouped: same level, grid and repetitions).
    steps : list of dict
        The greedy steps: ``block`` (label), ``trials``, ``gain_nats`` (the expected
        information gain the step added), ``information_nats`` (after it).
    conditions : list of dict
        Per candidate condition (method, location, level): ``gain_nats``, the expected
        information one trial of it gives on its own (answers among all candidate
        locations), sorted best first.
    information_nats : float
        Expected information gain of one participant's designed trials about which
        hypothesis is right, nats (at most log of the number of hypotheses).
    trials : int
        Trials per participant of the design (at most the budget).
    parameter_draws : dict
        Per hypothesis, the parameter sets drawn (what was drawn, and from which ranges).
    elapsed_s : float
    levels : str
        The level rule 0 dB refers to (the bank's).
    timings : dict
        Seconds spent on the answer laws, the tables and the greedy choice.
    """

    settings: DesignSettings
    blocks: tuple[PlanBlock, ...]
    steps: list[dict[str, Any]]
    conditions: list[dict[str, Any]]
    information_nats: float
    trials: int
    parameter_draws: dict[str, Any]
    elapsed_s: float
    levels: str
    timings: dict[str, float] = field(default_factory=dict)


# --------------------------------------------------------------------- answer laws
def location_sets(locations_xy: np.ndarray, locations: Sequence[int]) -> dict[str, tuple[int, ...]]:
    """The grids of candidate locations a block may use: the whole grid, and without its inner rows or columns.

    Parameters
    ----------
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    locations : sequence of int
        Candidate location numbers (1-based).

    Returns
    -------
    dict
        ``{"all": ..., "outer columns": ..., "outer rows": ..., "corners": ...}`` (location
        numbers), the last three only where the candidates form a grid of at least 3 x 3
        (the ones a grid of fewer rows or columns has are the same grid and are left out).
    """
    locs = tuple(sorted(int(x) for x in locations))
    out = {"all": locs}
    xy = np.round(np.asarray(locations_xy, dtype=float)[np.asarray(locs) - 1], 9)
    xs, ys = np.unique(xy[:, 0]), np.unique(xy[:, 1])
    if len(xs) * len(ys) != len(locs):
        return out
    keep_x = np.isin(xy[:, 0], xs[[0, -1]])
    keep_y = np.isin(xy[:, 1], ys[[0, -1]])
    for name, keep, ok in (("outer columns", keep_x, len(xs) > 2), ("outer rows", keep_y, len(ys) > 2),
                           ("corners", keep_x & keep_y, len(xs) > 2 or len(ys) > 2)):
        sub = tuple(int(v) for v in np.asarray(locs)[keep])
        if ok and len(sub) >= 2 and sub not in out.values():
            out[name] = sub
    return out


def _product_grid(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The x and y values of points that form a full product grid (else None)."""
    r = np.round(xy, 9)
    xs, ys = np.unique(r[:, 0]), np.unique(r[:, 1])
    if len(xs) * len(ys) != len(r) or len({(a, b) for a, b in r}) != len(r):
        return None
    return xs, ys


def _cell_mass(mean: np.ndarray, sd: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Normal probability of each cell between the midpoints of sorted ``values``, (..., n_values)."""
    edges = np.concatenate([[-np.inf], (values[1:] + values[:-1]) / 2.0, [np.inf]])
    cdf = special.ndtr((edges - mean[..., None]) / np.maximum(sd, 1e-300)[..., None])
    return np.diff(cdf, axis=-1)


def study1_probabilities(law: AnswerLaw, locations_xy: np.ndarray, allowed: np.ndarray | None = None,
                         quadrature: Quadrature | None = None) -> np.ndarray:
    """Probability of each Study 1 answer; exact and fast where the allowed locations form a grid.

    The answer is the allowed location nearest the perceived place. Where the allowed
    locations are a full product grid (rows x columns), the nearest one is the nearest
    column and the nearest row, so for the law's isotropic Gaussians the probability is a
    product of two differences of normal CDFs: the same numbers as
    :func:`~vibrofocus.simulation.likelihood.answer_probabilities` (to its quadrature
    error), hundreds of times faster. Other sets use that function.

    Parameters
    ----------
    law : AnswerLaw
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    allowed : ndarray of int, optional
        0-based locations that may be answered (default all).
    quadrature : Quadrature, optional
        Of the fallback.

    Returns
    -------
    ndarray, shape (n_trials, n_locations)
    """
    locs = np.asarray(locations_xy, dtype=float)
    ok = np.arange(len(locs)) if allowed is None else np.sort(np.asarray(allowed, dtype=int))
    grid = _product_grid(locs[ok])
    if grid is None:
        return answer_probabilities(law, locs, allowed, quadrature)
    xs, ys = grid
    px = _cell_mass(law.mean_m[..., 0], law.sd_m, xs)  # (n, K, n_x)
    py = _cell_mass(law.mean_m[..., 1], law.sd_m, ys)
    r = np.round(locs[ok], 9)
    ix, iy = np.searchsorted(xs, r[:, 0]), np.searchsorted(ys, r[:, 1])
    p = np.einsum("nk,nkj->nj", law.weight, px[..., ix] * py[..., iy])
    out = np.zeros((p.shape[0], len(locs)))
    out[:, ok] = p
    return out


def point_area_m(bank: FeatureBank) -> tuple[np.ndarray, np.ndarray]:
    """The picture a point answer is given on, as its lower and upper corners, m.

    The bounding box of the bank's actuators and locations widened by
    :data:`~vibrofocus.studies.points.MARGIN_PITCHES` location pitches: the area of
    :func:`~vibrofocus.studies.points.point_area`, within which a simulated participant's
    point answer is kept.

    Parameters
    ----------
    bank : FeatureBank

    Returns
    -------
    lo, hi : ndarray, shape (2,)
    """
    from ..studies.points import MARGIN_PITCHES, _pitch_m

    loc = np.asarray(bank.locations_xy, dtype=float)
    both = np.vstack([loc, np.asarray(bank.actuators_xy, dtype=float)])
    margin = MARGIN_PITCHES * _pitch_m(loc)
    return both.min(axis=0) - margin, both.max(axis=0) + margin


def _point_logpdf(weight: np.ndarray, mean: np.ndarray, sd: np.ndarray, points: np.ndarray) -> np.ndarray:
    """:func:`~vibrofocus.simulation.likelihood.point_loglik` over leading axes, log(1/m^2).

    ``weight`` (..., K), ``mean`` (..., K, 2), ``sd`` (..., K) and ``points`` (..., 2),
    broadcast against each other.
    """
    from .likelihood import point_loglik

    k = weight.shape[-1]
    shape = np.broadcast_shapes(weight.shape[:-1], mean.shape[:-2], sd.shape[:-1], points.shape[:-1])
    w = np.broadcast_to(weight, shape + (k,)).reshape(-1, k)
    sd_ = np.broadcast_to(sd, shape + (k,)).reshape(-1, k)
    law = AnswerLaw(w, np.broadcast_to(mean, shape + (k, 2)).reshape(-1, k, 2), sd_, sd_, 0.0, 0.0)
    return point_loglik(law, np.broadcast_to(points, shape + (2,)).reshape(-1, 2)).reshape(shape)


def _draw_points(weight: np.ndarray, mean: np.ndarray, sd: np.ndarray, u: np.ndarray, z: np.ndarray,
                 area: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Perceived places drawn from answer laws (..., K): a component by ``u`` (...), then its
    Gaussian by ``z`` (..., 2), kept within the picture ``area`` as a point answer is; m."""
    c = np.cumsum(weight, axis=-1)
    k = np.minimum((c < u[..., None] * c[..., -1:]).sum(axis=-1), weight.shape[-1] - 1)
    m = np.take_along_axis(mean, k[..., None, None], axis=-2)[..., 0, :]
    s = np.take_along_axis(sd, k[..., None], axis=-1)
    return np.clip(m + s * z, area[0], area[1])


def shipped_model(name: str, population: str | None = None) -> PerceptualModel:
    """The perceptual model of hypothesis ``name``: its own shipped parameters, or those of ``population``.

    Parameters
    ----------
    name : str
        A registered hypothesis.
    population : str, optional
        A registered hypothesis whose parameters to use instead.

    Returns
    -------
    PerceptualModel
    """
    from .hypotheses import hypothesis as find_hypothesis

    return find_hypothesis(population or name).model()


def parameter_draws(h: Any, n: int, seed: int = 0, spread: float = 1.0,
                    base: PerceptualModel | None = None) -> tuple[list[PerceptualModel], dict[str, Any]]:
    """The shipped parameters of a hypothesis and ``n - 1`` sets drawn around them.

    Each of the hypothesis' free parameters (:attr:`Hypothesis.free_parameters`) is drawn
    uniformly within ``spread`` of its range on either side of the shipped value (clipped
    to the range; the two ends of a population range kept in order). A hypothesis that declares none has one uncertain parameter by
    assumption: the sensation level of the reference tap (``sl_ref_db``), within 3 dB of
    the shipped value (the spread of thresholds across people, ``threshold_sd_db``). The
    fit paths of ``hypotheses_fit.json`` hold each search's budget and loss, not its
    parameters, so they cannot serve as draws. The draws use the same random numbers for
    every hypothesis (the same offsets on the scale of each range).

    Parameters
    ----------
    h : Hypothesis
    n : int
        Parameter sets, the shipped one first.
    seed : int
    spread : float
        Fraction of each range, 0-1 (1: uniform over the whole range, what the free fit
        searches).
    base : PerceptualModel, optional
        The parameters drawn around (default the hypothesis' shipped ones).

    Returns
    -------
    models : list of PerceptualModel
    about : dict
        ``parameters`` (keys), ``ranges`` ({key: [lo, hi]} drawn in), ``values`` (per set).
    """
    from .parameters import ParameterRange, apply_parameters, ordered_pairs, read_parameters

    base = base or h.model()
    ranges = tuple(getattr(h, "free_parameters", ()) or ())
    if ranges:
        lows = np.array([r.lo for r in ranges])
        highs = np.array([r.hi for r in ranges])
        v0 = np.clip(read_parameters(base, ranges), lows, highs)
        half = spread * (highs - lows)
        lo, hi = np.maximum(v0 - half, lows), np.minimum(v0 + half, highs)
    else:
        v0 = np.array([base.sl_ref_db])
        lo, hi = v0 - 3.0, v0 + 3.0
        ranges = (ParameterRange("sl_ref_db", float(lo[0]), float(hi[0]),
                                 "assumption: within the spread of thresholds across people"),)
    rng = np.random.default_rng([int(seed), 0xD5A1])
    # A population range's two ends drawn apart may cross: ordered, low first (Traits.draw needs lo <= hi).
    values = [v0] + [np.array(ordered_pairs(ranges, rng.uniform(lo, hi))) for _ in range(n - 1)]
    models = [base] + [apply_parameters(base, ranges, [float(x) for x in v]) for v in values[1:]]
    about = {"parameters": [r.key for r in ranges], "ranges": {r.key: [float(a), float(b)]
                                                               for r, a, b in zip(ranges, lo, hi)},
             "values": [[float(x) for x in v] for v in values],
             "declared": bool(getattr(h, "free_parameters", ()))}
    return models, about


def rival_fits_from(studies: Sequence[Mapping[str, Any]], hypotheses: Sequence[str],
                    per_pair: int = 2) -> dict[str, list[dict[str, float]]]:
    """Each hypothesis' free fits to studies simulated under another one (for :attr:`DesignSettings.rival_fits`).

    Parameters
    ----------
    studies : sequence of mapping
        Scored studies of a model recovery with the free fit (``true``, and ``params``:
        per hypothesis, its fitted parameters by key), as ``scripts/free_fit_recovery.py``
        writes them.
    hypotheses : sequence of str
        The hypotheses to collect fits of.
    per_pair : int
        Fits kept per (fitted hypothesis, true hypothesis), the first in the order given.

    Returns
    -------
    dict
        Per hypothesis, its parameter sets (up to ``per_pair`` x the other hypotheses).
    """
    out: dict[str, list[dict[str, float]]] = {name: [] for name in hypotheses}
    taken: dict[tuple[str, str], int] = {}
    for st in studies:
        for name in hypotheses:
            if st["true"] == name or name not in st.get("params", {}):
                continue
            key = (name, st["true"])
            if taken.get(key, 0) < per_pair:
                out[name].append({k: float(v) for k, v in st["params"][name].items()})
                taken[key] = taken.get(key, 0) + 1
    return out


def read_rival_fits(path: Any, hypotheses: Sequence[str], per_pair: int = 2) -> dict[str, list[dict[str, float]]]:
    """:func:`rival_fits_from` a free-fit model recovery's results file (JSON lines).

    Parameters
    ----------
    path : path-like
        A file of ``scripts/free_fit_recovery.py`` (a settings line, then one scored study
        per line: ``true`` and ``params``); lines without ``true`` are skipped.
    hypotheses : sequence of str
    per_pair : int

    Returns
    -------
    dict
        As :func:`rival_fits_from`.

    Raises
    ------
    ValidationError
        Unreadable, over 16 MB, a line that is not JSON, or a study without its
        hypotheses' parameters as numbers (the message names the line).
    """
    from ..io._capped import read_capped_json_lines

    rows = []
    for number, row in enumerate(read_capped_json_lines(path, max_bytes=16 * 2**20, what="rival fits file"), 1):
        if not isinstance(row, dict) or "true" not in row:
            continue
        params = row.get("params")
        ok = isinstance(row["true"], str) and isinstance(params, dict) and all(
            isinstance(v, dict) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v.values())
            for v in params.values())
        if not ok:
            raise ValidationError(f"line {number} of the rival fits file {path} has no parameters per hypothesis "
                                  "('params': {name: {key: number}})")
        rows.append(row)
    return rival_fits_from(rows, hypotheses, per_pair)


def _stimulus_index(bank: FeatureBank, levels: Sequence[float], method: str, level: float,
                    locations: Sequence[int]) -> np.ndarray:
    """Rows of the stacked stimuli (level, method, location) of a block's targets."""
    n_m, n_l = len(bank.methods), len(bank.locations_xy)
    li, mi = list(levels).index(level), bank.methods.index(method)
    return li * n_m * n_l + mi * n_l + np.asarray(locations, dtype=int) - 1


def _energies(bank: FeatureBank, forearm: int, levels: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Felt energies of every (level, method, location) of a forearm: (n_stim, n_points), (n_stim, n_act)."""
    e = bank.energy[forearm].reshape(-1, bank.points_xy.shape[0]).astype(float)
    a = bank.actuator_energy[forearm].reshape(-1, bank.actuators_xy.shape[0]).astype(float)
    gains = 10.0 ** (np.asarray(levels, dtype=float) / 10.0)
    return (np.concatenate([e * g for g in gains]), np.concatenate([a * g for g in gains]))


def _laws(h: Any, model: PerceptualModel, traits: Traits, bank: FeatureBank, forearm: int,
          levels: Sequence[float]) -> AnswerLaw:
    e, a = _energies(bank, forearm, levels)
    per = h.percepts(e, bank.points_xy, model, traits, a, bank.actuators_xy, bank.locations_xy)
    return answer_law(per, np.arange(e.shape[0]), bank.centre_xy, model, traits, study=1)


def _stack_laws(laws: list[AnswerLaw]) -> AnswerLaw:
    k = max(x.weight.shape[1] for x in laws)

    def pad(a: np.ndarray, fill: float) -> np.ndarray:
        w = [(0, 0)] * a.ndim
        w[1] = (0, k - a.shape[1])
        return np.pad(a, w, constant_values=fill)

    return AnswerLaw(np.concatenate([pad(x.weight, 0.0) for x in laws]),
                     np.concatenate([pad(x.mean_m, 0.0) for x in laws]),
                     np.concatenate([pad(x.sd_m, 1.0) for x in laws]),
                     np.concatenate([pad(x.width_m, 1.0) for x in laws]), laws[0].kappa, laws[0].log_sd)


def _block_probabilities(laws: AnswerLaw, n_samples: int, bank: FeatureBank, levels: Sequence[float],
                         blocks: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """P[sample, block, target, answer] of blocks (padded to the largest block) and the targets' mask."""
    n_stim = laws.weight.shape[0] // n_samples
    j_max = max(len(b.locations) for b in blocks)
    n_loc = len(bank.locations_xy)
    P = np.zeros((n_samples, len(blocks), j_max, n_loc))
    mask = np.zeros((len(blocks), j_max), dtype=bool)
    by_set: dict[tuple[int, ...], np.ndarray] = {}
    for bi, b in enumerate(blocks):
        if b.locations not in by_set:
            by_set[b.locations] = study1_probabilities(laws, bank.locations_xy, np.asarray(b.locations) - 1).reshape(
                n_samples, n_stim, n_loc)
        idx = _stimulus_index(bank, levels, b.method, b.level_db, b.locations)
        P[:, bi, :len(idx)] = by_set[b.locations][:, idx]
        mask[bi, :len(idx)] = True
    return P, mask


# --------------------------------------------------------------------- the design
def condition_gains(P: np.ndarray, hyp: np.ndarray, n_forearms: int) -> np.ndarray:
    """Expected information one trial gives on its own about the hypothesis, nats.

    Parameters
    ----------
    P : ndarray, shape (n_forearms * n_per, n_conditions, n_answers)
        Answer probabilities per sample (forearm-major) and condition.
    hyp : ndarray of int, shape (n_per,)
        Hypothesis of each sample within a forearm.
    n_forearms : int

    Returns
    -------
    ndarray, shape (n_conditions,)
        ``mean over forearms of sum_h (1/H) KL(p(.|h, forearm) || p(.|forearm))``.
    """
    n_h = int(hyp.max()) + 1
    Pf = P.reshape(n_forearms, -1, *P.shape[1:])
    ph = np.stack([Pf[:, hyp == h].mean(axis=1) for h in range(n_h)], axis=1)  # (F, H, C, A)
    pm = ph.mean(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        kl = np.where(ph > 0, ph * (np.log(ph) - np.log(np.maximum(pm, 1e-300))), 0.0).sum(axis=-1)
    return kl.mean(axis=(0, 1))


def _information(L: np.ndarray, hyp: np.ndarray, n_rep: int, person: bool = False) -> float:
    """Expected information gain (nats) from log-likelihoods L (F, R, S) of simulated answer sets.

    Replicate r was generated by sample ``r // n_rep``, which is left out of its own
    hypothesis' average (a sample always explains its own answers best). With ``person``,
    the information given the person instead: each hypothesis scores the replicate by its
    own sample of the same person (samples hypothesis-major, the same count per hypothesis).
    """
    F, R, S = L.shape
    n_h = int(hyp.max()) + 1
    own = np.arange(R) // n_rep
    if person:
        per = S // n_h
        cols = (own % per)[:, None] + per * np.arange(n_h)[None, :]  # (R, H)
        per_h = L[:, np.arange(R)[:, None], cols]  # (F, R, H)
        true = per_h[:, np.arange(R), hyp[own]]
        return float(np.mean(true - special.logsumexp(per_h, axis=2) + np.log(n_h)))
    Lx = L.copy()
    Lx[:, np.arange(R), own] = -np.inf
    counts = np.bincount(hyp, minlength=n_h).astype(float)
    per_h = np.stack([special.logsumexp(Lx[:, :, hyp == h], axis=2) for h in range(n_h)], axis=2)  # (F, R, H)
    n_eff = counts[None, :] - (hyp[own][:, None] == np.arange(n_h)[None, :])
    per_h = per_h - np.log(np.maximum(n_eff, 1.0))[None]
    true = per_h[:, np.arange(R), hyp[own]]
    return float(np.mean(true - special.logsumexp(per_h, axis=2) + np.log(n_h)))


def design_experiment(settings: DesignSettings | None = None, *, bank: FeatureBank | None = None,
                      progress: Callable[[str, int, int], None] | None = None) -> ExperimentDesign:
    """Choose the Study 1 blocks that tell the hypotheses apart best, within a trial budget.

    The population of each hypothesis is ``n_parameter_draws`` parameter sets
    (:func:`parameter_draws`) x ``n_forearms`` forearms of the bank x ``n_traits``
    participants' traits. For every sample and every candidate block (each method x level
    x grid of :func:`location_sets`) the answer law of every trial is computed once
    (:func:`~vibrofocus.simulation.likelihood.answer_law`, :func:`study1_probabilities`).
    The expected information gain of a plan is estimated by simulating ``n_replicates``
    answer sets per sample (the same random numbers for every candidate) and scoring each
    under every other sample of the same forearm (the forearm is known from the
    calibration; the generating sample left out). Greedily, the block repetition that adds
    the most information per trial is added while it fits the budget.

    Parameters
    ----------
    settings : DesignSettings, optional
        Default :class:`DesignSettings` ().
    bank : FeatureBank, optional
        The felt fields (default the shipped simulated bank).
    progress : callable, optional
        ``progress(stage, done, total)``.

    Returns
    -------
    ExperimentDesign
    """
    from .hypotheses import hypothesis as find_hypothesis

    s = settings or DesignSettings()
    b = bank if bank is not None else default_bank()
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    methods = s.methods or b.methods
    missing = [m for m in methods if m not in b.methods]
    if missing:
        raise ValidationError(f"methods: the feature bank has no stimuli of {', '.join(missing)} (it has "
                              f"{', '.join(b.methods)})")
    locations = tuple(range(1, len(b.locations_xy) + 1)) if s.locations is None else tuple(s.locations)
    if any(not 1 <= x <= len(b.locations_xy) for x in locations) or len(set(locations)) < 2:
        raise ValidationError(f"locations: at least 2 distinct location numbers from 1 to {len(b.locations_xy)}, "
                              f"got {list(locations)}")
    for lvl in s.levels_db:
        b.at_level(lvl)  # refuses a level over the drive limit
    if s.n_forearms > b.n_forearms:
        raise ValidationError(f"n_forearms: the feature bank has {b.n_forearms} forearms, asked {s.n_forearms}")
    rng = np.random.default_rng([s.seed, 0xDE51])
    forearms = np.sort(rng.choice(b.n_forearms, size=s.n_forearms, replace=False))
    names = s.hypotheses
    assert names is not None
    # Samples: per forearm, (hypothesis, parameter set, traits), hypothesis-major.
    laws, hyp_of, draws_about = [], [], {}
    models = {}
    for hi, name in enumerate(names):
        models[name], draws_about[name] = parameter_draws(find_hypothesis(name), s.n_parameter_draws, s.seed,
                                                          s.parameter_spread, shipped_model(name, s.population))
        rivals = (s.rival_fits or {}).get(name, ())
        if rivals:
            from .parameters import model_at

            # As the free fit applies its values: on the hypothesis' own model.
            models[name] = models[name] + [model_at(find_hypothesis(name), v) for v in rivals]
            draws_about[name]["rival_fits"] = [dict(v) for v in rivals]
    total = s.n_forearms * sum(len(models[n]) for n in names) * s.n_traits
    done = 0
    for fi, f in enumerate(forearms):
        for hi, name in enumerate(names):
            h = find_hypothesis(name)
            for ki, m in enumerate(models[name]):
                # For the information given the person, the same random numbers for every
                # hypothesis: sample (h, k, t) of one hypothesis and (h', k, t) of another are
                # the same person (traits drawn at the same quantiles of each population).
                trng = np.random.default_rng([s.seed, 0x7EA7, int(f), ki] if s.information == "person" else
                                             [s.seed, 0x7EA7, int(f), hi, ki])
                for _ in range(s.n_traits):
                    laws.append(_laws(h, m, Traits.draw(m, trng), b, int(f), s.levels_db))
                    if fi == 0:
                        hyp_of.append(hi)
                    done += 1
                    if progress is not None and done % 16 == 0:
                        progress("answer laws", done, total)
    hyp = np.asarray(hyp_of)
    n_samples = len(laws)
    law = _stack_laws(laws)
    timings["answer_laws_s"] = time.perf_counter() - t0
    grids = location_sets(b.locations_xy, locations)
    cands = [CandidateBlock(m, lvl, locs, g, r) for r in s.responses for lvl in s.levels_db for m in methods
             for g, locs in grids.items()]
    by_location = [c for c in cands if c.response == "location"]
    P, mask = (_block_probabilities(law, n_samples, b, s.levels_db, by_location) if by_location else
               (np.zeros((n_samples, 0, 1, len(b.locations_xy))), np.zeros((0, 1), dtype=bool)))
    row = {id(c): i for i, c in enumerate(by_location)}
    # Per-condition gains: one trial of (method, location, level), answered among all the candidates.
    singles = [CandidateBlock(m, lvl, locations, "all") for lvl in s.levels_db for m in methods]
    Ps, _ = _block_probabilities(law, n_samples, b, s.levels_db, singles)
    n_t = len(locations)
    g = condition_gains(Ps.reshape(n_samples, len(singles) * n_t, -1)[:, :len(singles) * n_t],
                        hyp, s.n_forearms).reshape(len(singles), n_t)
    conditions = sorted(({"method": c.method, "location": int(loc), "level_db": c.level_db, "gain_nats": float(g[i, j])}
                         for i, c in enumerate(singles) for j, loc in enumerate(locations)),
                        key=lambda r: -r["gain_nats"])
    timings["tables_s"] = time.perf_counter() - t0 - timings["answer_laws_s"]
    # Greedy: the information of the plan, by simulated answer sets with common random numbers.
    F = s.n_forearms
    S_f = n_samples // F
    R_f = S_f * s.n_replicates
    logP = np.log(np.maximum(P, _FLOOR)).reshape(F, S_f, len(by_location), P.shape[2], P.shape[3])
    cum = np.cumsum(P, axis=-1).reshape(F, S_f, len(by_location), P.shape[2], P.shape[3])
    # The perceived place's law per sample and stimulus, for the point answers.
    n_stim, K = law.weight.shape[0] // n_samples, law.weight.shape[1]
    W = law.weight.reshape(F, S_f, n_stim, K)
    M = law.mean_m.reshape(F, S_f, n_stim, K, 2)
    SD = law.sd_m.reshape(F, S_f, n_stim, K)
    area = point_area_m(b)
    gen = np.repeat(np.arange(S_f), s.n_replicates)
    L = np.zeros((F, R_f, S_f))
    counts = np.zeros(len(cands), dtype=int)
    info = 0.0
    steps: list[dict[str, Any]] = []
    sizes = np.array([len(c.locations) for c in cands])
    jj = np.arange(P.shape[2])

    def increment(ci: int, rep: int) -> np.ndarray:
        rng = np.random.default_rng([s.seed, 0x6A1E, ci, rep])
        out = np.zeros((F, R_f, S_f))
        if cands[ci].response == "point":
            c = cands[ci]
            idx = _stimulus_index(b, s.levels_db, c.method, c.level_db, c.locations)
            u, z = rng.random((F, R_f, idx.size)), rng.standard_normal((F, R_f, idx.size, 2))
            pts = _draw_points(W[:, gen][:, :, idx], M[:, gen][:, :, idx], SD[:, gen][:, :, idx], u, z, area)
            for j, st in enumerate(idx):  # log-density of every replicate's point under every sample
                out += _point_logpdf(W[:, None, :, st], M[:, None, :, st], SD[:, None, :, st], pts[:, :, None, j])
            return out
        li = row[id(cands[ci])]
        u = rng.random((F, R_f, P.shape[2]))
        c = cum[:, gen, li]  # (F, R_f, J, A)
        a = np.minimum((c < u[..., None] * c[..., -1:]).sum(axis=-1), P.shape[3] - 1)  # (F, R_f, J)
        lp = logP[:, :, li]  # (F, S_f, J, A)
        for j in jj[mask[li]]:
            out += np.take_along_axis(lp[:, None, :, j, :], a[:, :, None, j, None], axis=3)[..., 0]
        return out

    budget = s.budget
    used = 0
    cache: dict[tuple[int, int], np.ndarray] = {}
    t1 = time.perf_counter()
    while True:
        fits = np.flatnonzero(sizes <= budget - used)
        if fits.size == 0:
            break
        best, best_rate, best_inc, best_info = -1, -np.inf, None, info
        for ci in fits:
            key = (int(ci), int(counts[ci]))
            if key not in cache:  # the same draws whenever this repetition is weighed
                cache[key] = increment(*key)
            inc = cache[key]
            new = _information(L + inc, hyp, s.n_replicates, s.information == "person")
            rate = (new - info) / sizes[ci]
            if rate > best_rate:
                best, best_rate, best_inc, best_info = int(ci), rate, inc, new
        assert best_inc is not None
        del cache[(best, int(counts[best]))]
        L += best_inc
        counts[best] += 1
        used += int(sizes[best])
        steps.append({"block": cands[best].label, "trials": int(sizes[best]), "gain_nats": best_info - info,
                      "information_nats": best_info})
        info = best_info
        if progress is not None:
            progress("greedy", used, budget)
    timings["greedy_s"] = time.perf_counter() - t1
    chosen: dict[tuple[float, tuple[int, ...], int, str, str], list[str]] = {}
    for ci in np.flatnonzero(counts):
        c = cands[ci]
        chosen.setdefault((c.level_db, c.locations, int(counts[ci]), c.grid, c.response), []).append(c.method)
    blocks = tuple(PlanBlock(tuple(ms), lvl, locs, reps, grid, resp) for (lvl, locs, reps, grid, resp), ms in
                   sorted(chosen.items(), key=lambda kv: (kv[0][4], -kv[0][0], kv[0][3])))
    return ExperimentDesign(s, blocks, steps, conditions, info, used, draws_about, time.perf_counter() - t0,
                            b.levels, timings)


def paper_plan(bank: FeatureBank | None = None) -> tuple[PlanBlock, ...]:
    """The paper's Study 1 as a plan: every method of the shipped protocol at every location, 3 times, 0 dB.

    Parameters
    ----------
    bank : FeatureBank, optional
        Unused (the plan is the shipped protocol's); kept for symmetry with the designs.

    Returns
    -------
    tuple of PlanBlock
    """
    from ..studies.protocol_files import shipped_protocol

    blk = shipped_protocol("paper-study1").blocks[0]
    assert blk.locations is not None
    return (PlanBlock(blk.methods, blk.levels[0], tuple(blk.locations), blk.repetitions, "all"),)


#: The threshold block :func:`design_protocol_text` may put first: the tap with the most
#: felt energy of the shipped bank (the inverse filter at the centre), from -6 dB re the
#: level rule, a 1-up-2-down staircase of 30 trials (docs/protocols.md, "Threshold blocks").
THRESHOLD_BLOCK = {"methods": ("inverse",), "locations": (5,), "start_db": -6.0, "repetitions": 30}


def design_protocol_text(design: ExperimentDesign, name: str = "designed-study1", *,
                         threshold_trials: int = 0) -> str:
    """The design as a protocol file (TOML, docs/protocols.md), checked by the protocol reader.

    One block per designed block: its methods, locations, level and repetitions; the
    participant answers one location per trial among the block's locations
    (``response = "location"``), or a point on the picture of the arm area
    (``response = "point"``). Every block uses each session's own seed for its trial order.
    With ``threshold_trials``, a threshold block (:data:`THRESHOLD_BLOCK`) comes first: each
    participant's detection threshold is measured, stored and exported; the designed
    blocks' levels stay in dB re the level rule (the design does not use it).

    Parameters
    ----------
    design : ExperimentDesign
    name : str
        The protocol's name.
    threshold_trials : int
        Trials of the threshold block first (0: none).

    Returns
    -------
    str
        The file's text (a valid protocol: :func:`~vibrofocus.studies.protocol_files.parse_protocol`).
    """
    from ..studies.protocol_files import parse_protocol

    s = design.settings
    lines = [
        "# Designed by vibrofocus design-experiment (docs/designing-a-study.md): the Study 1 blocks that best tell",
        f"# apart the hypotheses {', '.join(s.hypotheses or ())} of simulated participants (a MODEL, not data),",
        f"# {design.trials} trials per participant, expected information {design.information_nats:.3f} nats per "
        "participant.",
        "format = 1",
        f'name = "{name}"',
        f'description = "designed to tell apart {", ".join(s.hypotheses or ())}; {design.trials} trials"',
    ]
    if threshold_trials:
        t = THRESHOLD_BLOCK
        lines += ["", "[[blocks]]", 'name = "threshold"', 'response = "detection"',
                  "methods = [" + ", ".join(f'"{m}"' for m in t["methods"]) + "]",
                  "locations = [" + ", ".join(str(x) for x in t["locations"]) + "]",
                  f"levels = [{t['start_db']!r}]", f'level_rule = "{design.levels}"', f"repetitions = {int(threshold_trials)}"]
    for k, blk in enumerate(design.blocks):
        lines += [
            "",
            "[[blocks]]",
            f'name = "b{k + 1}-{blk.level_db:+g}dB-{blk.grid.replace(" ", "-")}'
            + ('-points"' if blk.response == "point" else '"'),
            f'response = "{blk.response}"',
            "methods = [" + ", ".join(f'"{m}"' for m in blk.methods) + "]",
            "locations = [" + ", ".join(str(x) for x in blk.locations) + "]",
            f"levels = [{float(blk.level_db)!r}]",
            'level_unit = "dB"',
            f'level_rule = "{design.levels}"',
            f"repetitions = {blk.repetitions}",
            "training_trials = 0",
            "pacing_s = 0.0",
            'seed = "session"',
        ]
    text = "\n".join(lines) + "\n"
    parse_protocol(text, f"<designed {name}>")
    return text


# --------------------------------------------------------------------- P(correct) against N
def score_tables(plans: dict[str, Sequence[PlanBlock]], hypotheses: Sequence[str], bank: FeatureBank,
                 forearms: Sequence[int], *, n_draws: int = 32, seed: int = SCORE_SEED,
                 submit: Callable[..., Any] | None = None, population: str | None = None) -> dict[str, ScoreTable]:
    """Log-probabilities of every answer of each plan's trials, per hypothesis, forearm and trait draw.

    Location answers are tabulated; for point answers, the perceived place's law is kept
    (its density is taken at each simulated point).

    The trait draws are those of :func:`~vibrofocus.simulation.likelihood.marginal_loglik`
    (``n_draws`` from ``default_rng([seed, 0x11C])``, per hypothesis at its shipped
    parameters), so that ``logsumexp`` over them, minus ``log n_draws``, of a participant's
    summed log-probabilities is its marginal log-likelihood.

    Parameters
    ----------
    plans : dict
        ``{name: plan blocks}``.
    hypotheses : sequence of str
    bank : FeatureBank
    forearms : sequence of int
        Bank rows.
    n_draws : int
    seed : int
    submit : callable, optional
        ``submit(fn, *args)`` returning a future (a Dask client's ``submit``): one task per
        hypothesis and forearm; default in this process.
    population : str, optional
        As :attr:`DesignSettings.population` (default each hypothesis' own parameters).

    Returns
    -------
    dict
        Per plan, a :class:`ScoreTable`.
    """
    levels = _plan_levels(*plans.values())
    args = [(plans, name, int(f), bank, levels, n_draws, seed, population) for name in hypotheses for f in forearms]
    if submit is None:
        parts = [_score_part(*a) for a in args]
    else:
        parts = [fut.result() for fut in [submit(_score_part, *a, pure=False) for a in args]]
    shape = (len(hypotheses), len(forearms))
    k = max(x[p][1].shape[-1] for x in parts for p in plans)

    def stacked(p: str, i: int, fill: float) -> np.ndarray:
        arrays = [x[p][i] for x in parts]
        pad = [np.pad(a, [(0, 0), (0, 0), (0, k - a.shape[2])] + [(0, 0)] * (a.ndim - 3), constant_values=fill)
               for a in arrays]
        return np.stack(pad).reshape(shape + pad[0].shape)

    with np.errstate(divide="ignore"):
        return {p: ScoreTable(np.log(np.stack([x[p][0] for x in parts]).reshape(shape + parts[0][p][0].shape)),
                              stacked(p, 1, 0.0), stacked(p, 2, 0.0), stacked(p, 3, 1.0)) for p in plans}


@dataclass(frozen=True)
class ScoreTable:
    """What :func:`score_tables` keeps of a plan, per hypothesis, forearm and trait draw.

    Attributes
    ----------
    location : ndarray, shape (n_hypotheses, n_forearms, n_draws, n_location_stimuli, n_locations)
        Log-probability of each answer to the plan's location-answer stimuli, in order
        (each such block's methods x locations); ``-inf`` for an answer the model cannot give.
    point_weight : ndarray, shape (n_hypotheses, n_forearms, n_draws, n_point_stimuli, K)
        The perceived place's law for the plan's point-answer stimuli, in order: mixture
        weights,
    point_mean : ndarray, shape (..., K, 2)
        means, m,
    point_sd : ndarray, shape (..., K)
        and SDs per axis, m (:class:`~vibrofocus.simulation.likelihood.AnswerLaw`).
    """

    location: np.ndarray
    point_weight: np.ndarray
    point_mean: np.ndarray
    point_sd: np.ndarray


def _score_part(plans: dict[str, Sequence[PlanBlock]], name: str, forearm: int, bank: FeatureBank,
                levels: Sequence[float], n_draws: int, seed: int,
                population: str | None) -> dict[str, tuple[np.ndarray, ...]]:
    """One hypothesis and forearm of :func:`score_tables`: per plan, the probabilities
    (n_draws, n_location_stimuli, n_locations) and the point laws' weights, means and SDs
    (n_draws, n_point_stimuli, K[, 2])."""
    from .hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(name)
    m = shipped_model(name, population)
    rng = np.random.default_rng([int(seed), 0x11C])
    laws = [_laws(h, m, Traits.draw(m, rng), bank, forearm, levels) for _ in range(n_draws)]
    law = _stack_laws(laws)
    n_stim = laws[0].weight.shape[0]
    k = law.weight.shape[1]
    by_set: dict[tuple[int, ...], np.ndarray] = {}
    out = {}
    for p, plan in plans.items():
        rows, points = [], []
        for blk in plan:
            if blk.response == "point":
                points += [_stimulus_index(bank, levels, meth, blk.level_db, blk.locations) for meth in blk.methods]
                continue
            if blk.locations not in by_set:
                by_set[blk.locations] = study1_probabilities(law, bank.locations_xy,
                                                             np.asarray(blk.locations) - 1).reshape(n_draws, n_stim, -1)
            for meth in blk.methods:
                rows.append(by_set[blk.locations][:, _stimulus_index(bank, levels, meth, blk.level_db, blk.locations)])
        pi = np.concatenate(points) if points else np.zeros(0, dtype=int)
        out[p] = (np.concatenate(rows, axis=1) if rows else np.zeros((n_draws, 0, len(bank.locations_xy))),
                  law.weight.reshape(n_draws, n_stim, k)[:, pi], law.mean_m.reshape(n_draws, n_stim, k, 2)[:, pi],
                  law.sd_m.reshape(n_draws, n_stim, k)[:, pi])
    return out


def _plan_levels(*plans: Sequence[PlanBlock]) -> list[float]:
    """The levels of plans, loudest first: the order of :func:`_energies`' stacked stimuli."""
    return sorted({blk.level_db for plan in plans for blk in plan}, reverse=True)


def _simulate_scores(plan: Sequence[PlanBlock], true: str, hypotheses: Sequence[str], indices: Sequence[int],
                     bank: FeatureBank, forearms: np.ndarray, table: ScoreTable, seed: int,
                     levels: Sequence[float], population: str | None = None) -> np.ndarray:
    """Simulated participants of hypothesis ``true`` answer the plan; their marginal log-likelihoods (n, H).

    Each participant (stream ``[seed, 0xE7A1, hypothesis, index]``) has a forearm drawn
    from ``forearms``, traits from the true hypothesis' shipped population and answers
    from :func:`~vibrofocus.simulation.perception.draw_answers` (the sampler of
    ``simulate-study``), among each block's locations; a point answer is the trial's
    perceived place kept within the picture (as :class:`~vibrofocus.simulation.participants.
    SimulatedParticipant` answers it).
    """
    from .hypotheses import hypothesis as find_hypothesis
    from .perception import posterior_ratio_rule

    h = find_hypothesis(true)
    m = shipped_model(true, population)
    hi = list(hypotheses).index(true)
    out = np.empty((len(indices), len(hypotheses)))
    area = point_area_m(bank)
    seen: dict[str, np.ndarray] = {}

    def rule(posteriors: Any, *args: Any) -> tuple[np.ndarray, np.ndarray]:
        seen["perceived_m"] = posteriors.perceived_m
        return posterior_ratio_rule(posteriors, *args)

    for row, i in enumerate(indices):
        rng = np.random.default_rng([int(seed), 0xE7A1, hi, int(i)])
        fi = int(rng.integers(len(forearms)))
        traits = Traits.draw(m, rng)
        e, a = _energies(bank, int(forearms[fi]), levels)
        per = h.percepts(e, bank.points_xy, m, traits, a, bank.actuators_xy, bank.locations_xy)
        total = np.zeros((len(hypotheses), table.location.shape[2]))
        col = pcol = 0
        for blk in plan:
            allowed = np.asarray(blk.locations) - 1
            for meth in blk.methods:
                idx = _stimulus_index(bank, levels, meth, blk.level_db, blk.locations)
                trials = np.tile(np.arange(len(idx)), blk.repetitions)
                ans, _, _ = draw_answers(per, idx[trials], bank.locations_xy, bank.centre_xy, m, traits, rng,
                                         allowed=allowed, rule=rule)
                if blk.response == "point":
                    pts = np.clip(seen["perceived_m"], area[0], area[1])  # (trials, 2)
                    c = pcol + trials
                    total += _point_logpdf(table.point_weight[:, fi][:, :, c], table.point_mean[:, fi][:, :, c],
                                           table.point_sd[:, fi][:, :, c], pts).sum(axis=2)  # (H, draws)
                    pcol += len(idx)
                    continue
                total += table.location[:, fi, :, col + trials, ans].sum(axis=0)  # (trials, H, draws) summed
                col += len(idx)
        out[row] = special.logsumexp(total, axis=1) - np.log(total.shape[1])
    return out


def identification(
    plans: dict[str, Sequence[PlanBlock]],
    hypotheses: Sequence[str],
    *,
    n_participants: Sequence[int] = (2, 4, 6, 8, 10),
    n_studies: int = 200,
    pool: int = 60,
    n_draws: int = 32,
    n_forearms: int | None = 12,
    seed: int = 1,
    bank: FeatureBank | None = None,
    scheduler: str | None = None,
    n_workers: int | None = None,
    client: Any = None,
    local: bool = False,
    chunk: int = 20,
    population: str | None = None,
) -> dict[str, Any]:
    """P(the true hypothesis is chosen) against N, for each plan, by simulation (on Dask).

    For each plan and true hypothesis, ``pool`` simulated participants answer the plan
    (:func:`_simulate_scores`, one Dask task per ``chunk``) and are scored by their
    marginal likelihood under every hypothesis at its shipped parameters; a study of N is
    N of them drawn without replacement, and chooses the hypothesis of the largest summed
    marginal log-likelihood (uniform prior). The forearm is known to the analysis (from
    the calibration), as in :func:`~vibrofocus.simulation.likelihood.marginal_loglik`.

    Parameters
    ----------
    plans : dict
        ``{name: plan blocks}`` (:func:`paper_plan`, :attr:`ExperimentDesign.blocks`).
    hypotheses : sequence of str
    n_participants : sequence of int
        Sample sizes N (each at most ``pool``).
    n_studies : int
        Studies per N and true hypothesis.
    pool : int
        Simulated participants per plan and true hypothesis.
    n_draws : int
        Trait draws of the marginal likelihood.
    n_forearms : int, optional
        Bank forearms the participants are drawn from, the first ones (default 12; None:
        all).
    seed : int
        Seed of the simulated participants and of the studies (not the design's streams).
    bank : FeatureBank, optional
    scheduler, n_workers, client
        As :func:`~vibrofocus.simulation.power.run_power` (:func:`~vibrofocus.simulation.power.dask_client`).
    local : bool
        In this process, without Dask (same numbers).
    chunk : int
        Participants per task.
    population : str, optional
        As :attr:`DesignSettings.population`: the simulated participants and the scores
        use that hypothesis' parameters for every hypothesis (default each its own).

    Returns
    -------
    dict
        ``rates`` ({plan: {hypothesis: {N: P(correct)}}}), ``mean`` ({plan: {N: mean over
        hypotheses}}), ``confusion`` ({plan: {N: {true: {chosen: share}}}}), ``settings``,
        ``elapsed_s``.
    """
    b = bank if bank is not None else default_bank()
    names = list(hypotheses)
    ns = [int(n) for n in n_participants]
    if not ns or min(ns) < 1 or max(ns) > pool:
        raise ValidationError(f"n_participants must be from 1 to the pool of {pool}, got {ns}")
    forearms = np.arange(b.n_forearms if n_forearms is None else int(n_forearms))
    if len(forearms) < 1 or len(forearms) > b.n_forearms:
        raise ValidationError(f"n_forearms must be from 1 to the bank's {b.n_forearms}, got {len(forearms)}")
    t0 = time.perf_counter()
    levels = _plan_levels(*plans.values())
    tasks = [(p, h, list(range(s, min(s + chunk, pool)))) for p in plans for h in names
             for s in range(0, pool, chunk)]
    scores: dict[tuple[str, str], list[tuple[int, np.ndarray]]] = {}
    if local:
        tables = score_tables(plans, names, b, forearms, n_draws=n_draws, population=population)
        t_tables = time.perf_counter() - t0
        for p, h, idx in tasks:
            scores.setdefault((p, h), []).append(
                (idx[0], _simulate_scores(plans[p], h, names, idx, b, forearms, tables[p], seed, levels,
                                          population)))
    else:
        from distributed import as_completed

        from .power import dask_client

        with dask_client(scheduler=scheduler, n_workers=n_workers, client=client) as dc:
            bank_f = dc.scatter(b, broadcast=True)
            tables = score_tables(plans, names, bank_f, forearms, n_draws=n_draws, submit=dc.submit,
                                  population=population)
            t_tables = time.perf_counter() - t0
            table_f = {p: dc.scatter(t, broadcast=True) for p, t in tables.items()}
            futures = {dc.submit(_simulate_scores, plans[p], h, names, idx, bank_f, forearms, table_f[p], seed,
                                 levels, population, pure=False): (p, h, idx[0]) for p, h, idx in tasks}
            for fut in as_completed(futures):
                p, h, start = futures[fut]
                scores.setdefault((p, h), []).append((start, fut.result()))
    rates: dict[str, dict[str, dict[int, float]]] = {}
    confusion: dict[str, dict[int, dict[str, dict[str, float]]]] = {}
    for p in plans:
        for hi, h in enumerate(names):
            sc = np.concatenate([x for _, x in sorted(scores[(p, h)], key=lambda t: t[0])])
            rng = np.random.default_rng([int(seed), 0x57D1, hi])
            for n in ns:
                pick = np.argsort(rng.random((n_studies, pool)), axis=1)[:, :n]
                chosen = np.argmax(sc[pick].sum(axis=1), axis=1)
                rates.setdefault(p, {}).setdefault(h, {})[n] = float(np.mean(chosen == hi))
                confusion.setdefault(p, {}).setdefault(n, {})[h] = {
                    c: float(np.mean(chosen == ci)) for ci, c in enumerate(names)}
    mean = {p: {n: float(np.mean([rates[p][h][n] for h in names])) for n in ns} for p in plans}
    return {"rates": rates, "mean": mean, "confusion": confusion, "elapsed_s": time.perf_counter() - t0,
            "tables_s": t_tables,
            "settings": {"n_participants": ns, "n_studies": n_studies, "pool": pool, "n_draws": n_draws,
                         "population": population,
                         "n_forearms": len(forearms), "seed": seed, "hypotheses": names}}


# --------------------------------------------------------------------- the loop
def participant_loglik(hypothesis: Any, bank: FeatureBank, forearm: int,
                       trials: Sequence[tuple[str, int, Any, float, Sequence[int]]], *, n_draws: int = 32,
                       seed: int = SCORE_SEED, model: PerceptualModel | None = None) -> float:
    """Marginal log-likelihood of one participant's Study 1 answers under a hypothesis.

    The same number as :func:`~vibrofocus.simulation.likelihood.marginal_loglik` (the same
    trait draws: ``n_draws`` from ``default_rng([seed, 0x11C])``), for trials that may come
    from several blocks, each at its own level and with its own allowed answers: per trait
    draw, the log-probabilities of all trials are summed (:class:`~vibrofocus.simulation.
    likelihood.Stimuli` of the bank row at each level, the hypothesis' percepts,
    :func:`~vibrofocus.simulation.likelihood.answer_law` and :func:`study1_probabilities`;
    for a point answer, the density of the perceived place,
    :func:`~vibrofocus.simulation.likelihood.point_loglik`), then averaged over the draws.

    Parameters
    ----------
    hypothesis : str or Hypothesis
    bank : FeatureBank
        Holds the participant's forearm (its felt fields at the bank's level rule).
    forearm : int
        Bank row of the participant's forearm.
    trials : sequence of (method, target, answer, level_db, allowed)
        Method, target and answered location numbers (1-based), the level (dB re the
        bank's rule) and the location numbers that could be answered. A point answer is
        ``(x, y)`` in m in the layout frame instead of a location number.
    n_draws, seed
        As :func:`~vibrofocus.simulation.likelihood.marginal_loglik`.
    model : PerceptualModel, optional
        Default the hypothesis' shipped parameters.

    Returns
    -------
    float
        Natural log; ``-inf`` if an answer is impossible under every draw.
    """
    from .hypotheses import hypothesis as find_hypothesis
    from .likelihood import Stimuli, point_loglik

    h = find_hypothesis(hypothesis)
    m = model or h.model()
    n_loc = len(bank.locations_xy)
    groups: dict[tuple[float, tuple[int, ...]], list[tuple[int, int]]] = {}
    points: dict[float, list[tuple[int, float, float]]] = {}
    for meth, target, answer, level, allowed in trials:
        if meth not in bank.methods:
            raise ValidationError(f"the feature bank has no stimuli of {meth!r} (it has {', '.join(bank.methods)})")
        stim = bank.methods.index(meth) * n_loc + int(target) - 1
        if isinstance(answer, (tuple, list, np.ndarray)):
            points.setdefault(float(level), []).append((stim, float(answer[0]), float(answer[1])))
        else:
            groups.setdefault((float(level), tuple(sorted(int(a) for a in allowed))), []).append((stim, int(answer) - 1))
    stimuli = {lvl: Stimuli.from_bank(bank, forearm, lvl) for lvl in {g[0] for g in groups} | set(points)}
    rng = np.random.default_rng([int(seed), 0x11C])
    total = np.zeros(n_draws)
    for k in range(n_draws):
        traits = Traits.draw(m, rng)
        per = {lvl: st.percepts(h, m, traits) for lvl, st in stimuli.items()}
        for (lvl, allowed), rows in groups.items():
            idx, ans = np.array(rows).T
            st = stimuli[lvl]
            law = answer_law(per[lvl], idx, st.centre_xy, m, traits, study=1)
            p = study1_probabilities(law, st.locations_xy, np.asarray(allowed) - 1)[np.arange(idx.size), ans]
            with np.errstate(divide="ignore"):
                total[k] += np.log(p).sum()
        for lvl, rows in points.items():
            st = stimuli[lvl]
            idx = np.array([r[0] for r in rows])
            law = answer_law(per[lvl], idx, st.centre_xy, m, traits, study=1)
            total[k] += point_loglik(law, np.array([r[1:] for r in rows])).sum()
    return float(special.logsumexp(total) - np.log(n_draws))


def choose_hypothesis(db: Any, bank: FeatureBank, hypotheses: Sequence[str] | None = None, *, n_draws: int = 32,
                      seed: int = SCORE_SEED) -> dict[str, Any]:
    """Model choice on a study database: the hypothesis of the largest marginal likelihood of its Study 1 answers.

    Every participant's main-phase Study 1 answers (all blocks, each at its level and with
    its own locations as the allowed answers; a point block's points as points) are scored by :func:`participant_loglik`
    under each hypothesis at its shipped parameters; the hypotheses' log-likelihoods are
    summed over participants (a uniform prior). Participant ``sim-00k`` of
    ``simulate-study --seed S`` is row ``k - 1`` of a bank built with the same seed
    (``scripts/build_feature_bank.py --seed S``), as :func:`~vibrofocus.simulation.bank.
    build_feature_bank` promises.

    Parameters
    ----------
    db : path-like
        A study database (``simulate-study --db``).
    bank : FeatureBank
        The participants' felt fields.
    hypotheses : sequence of str, optional
        Default every registered one.
    n_draws, seed
        As :func:`participant_loglik`.

    Returns
    -------
    dict
        ``participants`` ({id: {hypothesis: log-likelihood}}), ``total`` ({hypothesis:
        summed log-likelihood}), ``chosen`` (the hypothesis of the largest total).
    """
    from ..studies.storage import StudyStore
    from .hypotheses import available_hypotheses
    from .simulate import SIMULATED_PREFIX

    names = list(hypotheses or available_hypotheses())
    store = StudyStore(db)
    per: dict[str, dict[str, float]] = {}
    for info in store.participants():
        pid = info.participant_id
        if not pid.startswith(SIMULATED_PREFIX) or not pid[len(SIMULATED_PREFIX):].isdigit():
            raise ValidationError(f"participant {pid!r} is not a simulated participant: its forearm is not in a bank")
        row = int(pid[len(SIMULATED_PREFIX):]) - 1
        if row >= bank.n_forearms:
            raise ValidationError(f"participant {pid} needs bank row {row}, the bank has {bank.n_forearms}")
        trials = []
        for sess in store.sessions(pid, study=1):
            d = sess.design
            plan = {t.trial_index: t for t in store.planned_trials(sess.session_id)}
            if d.detection:
                continue  # a threshold block: its answers set levels, they are not scored here
            for a in store.answers(sess.session_id):
                t = plan[a.trial_index]
                if t.phase == "main":
                    answer = (tuple(v * 1e-3 for v in a.point_mm) if d.point and a.point_mm is not None
                              else int(a.response[0]))
                    trials.append((t.method, t.target, answer, float(d.level_db), d.locations))
        if trials:
            per[pid] = {h: participant_loglik(h, bank, row, trials, n_draws=n_draws, seed=seed) for h in names}
    total = {h: float(sum(v[h] for v in per.values())) for h in names}
    return {"participants": per, "total": total, "chosen": max(total, key=total.get) if per else None}


# --------------------------------------------------------------------- the report
def design_report(design: ExperimentDesign, ident: dict[str, Any] | None = None) -> dict[str, Any]:
    """The design and its evaluation as one JSON-ready dict (``design.json``).

    Parameters
    ----------
    design : ExperimentDesign
    ident : dict, optional
        :func:`identification` of the design and the paper's protocol.

    Returns
    -------
    dict
    """
    from .hypotheses import hypothesis as find_hypothesis
    from .perception import MODEL_LABEL

    s = design.settings
    out: dict[str, Any] = {
        "label": MODEL_LABEL,
        "hypotheses": {n: find_hypothesis(n).label() for n in s.hypotheses or ()},
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(s).items()},
        "levels": design.levels,
        "blocks": [{"methods": list(b.methods), "level_db": b.level_db, "locations": list(b.locations),
                    "repetitions": b.repetitions, "grid": b.grid, "response": b.response, "trials": b.n_trials}
                   for b in design.blocks],
        "trials": design.trials,
        "information_nats": design.information_nats,
        "steps": design.steps,
        "conditions": design.conditions,
        "parameter_draws": design.parameter_draws,
        "elapsed_s": design.elapsed_s,
        "timings": design.timings,
    }
    if ident is not None:
        out["identification"] = {
            "rates": {p: {h: {str(n): v for n, v in r.items()} for h, r in by.items()}
                      for p, by in ident["rates"].items()},
            "mean": {p: {str(n): v for n, v in r.items()} for p, r in ident["mean"].items()},
            "confusion": {p: {str(n): c for n, c in by.items()} for p, by in ident["confusion"].items()},
            "settings": ident["settings"], "elapsed_s": ident["elapsed_s"],
        }
    return out


#: What the rates at the shipped parameters do not say (the report and the command's table).
FREE_FIT_CAVEAT = ("These rates assume each hypothesis' parameters known; with the free fit of `analyze "
                   "--hypotheses` (every hypothesis' parameters fitted to the study) they are lower: on the default "
                   "design at N = 6, level-reliability was told from intensity in 6 of 10 simulated studies (some 20 "
                   "to 50 participants for 9 in 10), and in 10 of 10 with intensity fitted alike (`--fix`); "
                   "docs/fitting-hypotheses.md, \"With the free fit\".")


def _markdown(report: dict[str, Any]) -> str:
    lines = [f"# Designed study ({report['label']})", "",
             f"Hypotheses: {', '.join(report['hypotheses'])}. {report['trials']} Study 1 trials per participant; "
             f"expected information about the hypothesis {report['information_nats']:.3f} nats per participant "
             f"(at most {np.log(len(report['hypotheses'])):.3f}). Levels in dB re the {report['levels']} levels.", "",
             "## Designed blocks", "", "| methods | level (dB) | locations | answer | repetitions | trials |",
             "|---|---|---|---|---|---|"]
    for b in report["blocks"]:
        lines.append(f"| {', '.join(b['methods'])} | {b['level_db']:+g} | {' '.join(map(str, b['locations']))} "
                     f"({b['grid']}) | {b['response']} | {b['repetitions']} | {b['trials']} |")
    ident = report.get("identification")
    if ident:
        ns = ident["settings"]["n_participants"]
        lines += ["", "## P(the true hypothesis is chosen) against N", "",
                  "Model choice by marginal likelihood at the hypotheses' shipped parameters; "
                  f"{ident['settings']['n_studies']} simulated studies per N and hypothesis. "
                  f"{FREE_FIT_CAVEAT}", "",
                  "| protocol | true hypothesis | " + " | ".join(f"N={n}" for n in ns) + " |",
                  "|---|---|" + "---|" * len(ns)]
        for p, by in ident["rates"].items():
            for h, r in by.items():
                lines.append(f"| {p} | {h} | " + " | ".join(f"{r[str(n)]:.2f}" for n in ns) + " |")
            lines.append(f"| {p} | mean | " + " | ".join(f"{ident['mean'][p][str(n)]:.2f}" for n in ns) + " |")
    lines += ["", "## Expected information of one trial, per condition (best 20)", "",
              "| method | location | level (dB) | gain (nats) |", "|---|---|---|---|"]
    for c in report["conditions"][:20]:
        lines.append(f"| {c['method']} | {c['location']} | {c['level_db']:+g} | {c['gain_nats']:.4f} |")
    return "\n".join(lines) + "\n"


def _figures(report: dict[str, Any], bank: FeatureBank) -> tuple[Any, Any]:
    import matplotlib.pyplot as plt

    from .._style import METHOD_MARKERS, method_colors, model_footer

    fig1, ax = plt.subplots(figsize=(6.0, 4.0))
    ident = report.get("identification")
    if ident:
        ns = ident["settings"]["n_participants"]
        for p, style in zip(ident["rates"], ("-", "--", ":", "-.")):
            ax.plot(ns, [ident["mean"][p][str(n)] for n in ns], style, color="k", lw=2, label=f"{p}: mean")
            for h, r in ident["rates"][p].items():
                ax.plot(ns, [r[str(n)] for n in ns], style, lw=1, alpha=0.7, label=f"{p}: {h}")
        ax.axhline(0.9, color="0.6", lw=0.8)
        ax.set_xlabel("participants N")
        ax.set_ylabel("P(true hypothesis chosen)")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7)
    ax.set_title("Identifying the hypothesis, designed vs paper's protocol", fontsize=9)
    model_footer(fig1, report["label"])
    levels = sorted({b["level_db"] for b in report["blocks"]}, reverse=True)
    fig2, axes = plt.subplots(1, max(len(levels), 1), figsize=(3.2 * max(len(levels), 1), 3.6), squeeze=False)
    methods = sorted({m for b in report["blocks"] for m in b["methods"]})
    colors = method_colors(methods)
    offsets = {m: (np.array([np.cos(a), np.sin(a)]) * 2.5) for m, a in
               zip(methods, np.linspace(0, 2 * np.pi, len(methods), endpoint=False) + np.pi / 2)}
    locs, acts = bank.locations_xy * 1e3, bank.actuators_xy * 1e3
    for ax, lvl in zip(axes[0], levels):
        ax.scatter(locs[:, 0], locs[:, 1], s=10, color="0.7")
        for k, (x, y) in enumerate(locs):
            ax.annotate(str(k + 1), (x, y), xytext=(-9, -9), textcoords="offset points", fontsize=7, color="0.5")
        ax.scatter(acts[:, 0], acts[:, 1], marker="s", s=120, facecolor="none", edgecolor="0.3")
        reps: dict[tuple[str, int], int] = {}
        for b in report["blocks"]:
            if b["level_db"] == lvl:
                for m in b["methods"]:
                    for loc in b["locations"]:
                        reps[(m, loc)] = reps.get((m, loc), 0) + b["repetitions"]
        for (m, loc), n in reps.items():
            x, y = locs[loc - 1] + offsets[m]
            ax.scatter([x], [y], s=18 * n, color=colors[m], marker=METHOD_MARKERS.get(m, "o"), alpha=0.8)
        ax.set_title(f"{lvl:+g} dB", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-30, 30)
        ax.set_ylim(-30, 30)
        ax.set_xlabel("x (mm)")
    axes[0][0].set_ylabel("y (mm)")
    for m in methods:
        axes[0][-1].scatter([], [], color=colors[m], marker=METHOD_MARKERS.get(m, "o"), label=m)
    axes[0][-1].legend(fontsize=7, loc="lower right")
    fig2.suptitle("Designed trials on the arm (marker area: repetitions; squares: actuators)", fontsize=9)
    model_footer(fig2, report["label"])
    return fig1, fig2


def write_design(design: ExperimentDesign, out: Any, *, ident: dict[str, Any] | None = None,
                 bank: FeatureBank | None = None, name: str = "designed-study1", threshold_trials: int = 0) -> list[Any]:
    """Write ``protocol.toml``, ``design.json``, ``design.md`` and two figures into folder ``out``.

    Parameters
    ----------
    design : ExperimentDesign
    out : path-like
        An existing folder.
    ident : dict, optional
        :func:`identification` of the design and the paper's protocol.
    bank : FeatureBank, optional
        For the map (default the shipped bank).
    name : str
        The protocol's name.
    threshold_trials : int
        As :func:`design_protocol_text`.

    Returns
    -------
    list of Path
        The files written (each whole or not at all).
    """
    import json
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import json_safe, save_figure, write_text

    folder = Path(out)
    report = design_report(design, ident)
    paths = [write_text(folder / "protocol.toml", design_protocol_text(design, name, threshold_trials=threshold_trials),
                        what="protocol"),
             write_text(folder / "design.json", json.dumps(json_safe(report), indent=1) + "\n", what="design"),
             write_text(folder / "design.md", _markdown(report), what="design report")]
    fig1, fig2 = _figures(report, bank if bank is not None else default_bank())
    try:
        paths.append(save_figure(fig1, folder / "identification.png", what="figure", dpi=120))
        paths.append(save_figure(fig2, folder / "design-map.png", what="figure", dpi=120))
    finally:
        plt.close(fig1)
        plt.close(fig2)
    return [Path(p) for p in paths]
