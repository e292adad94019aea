"""The likelihood of a participant's answers under a hypothesis (a MODEL, not data).

The simulated participants' answers are draws from a probability distribution; this
module computes that distribution, so that answers — simulated or a lab's — can be
scored: the log-probability of each observed Study 1 location and Study 2 selection
given the stimulus, a participant's traits and a hypothesis (:func:`loglik`), and, over
the hypothesis' population of participants, per participant (:func:`marginal_loglik`).

One model, sampled and integrated
---------------------------------
:func:`~vibrofocus.simulation.perception.draw_answers` (the sampler) draws standard-normal
noise ``z``, the criterion's jitter ``J`` and, where the model has them, whether a trial
is unfused and the direction of its jump, and pushes them through
:func:`~vibrofocus.simulation.perception.trial_posteriors`,
:func:`~vibrofocus.simulation.perception.unfuse` and the answer rule
(:func:`~vibrofocus.simulation.perception.select_locations`). The likelihood integrates
the same map over the same draws, calling the same functions:

* the perceived place is affine in ``z`` with an isotropic scale, so
  :func:`answer_law` reads its mean and SD from ``trial_posteriors`` at ``z = 0`` and at
  the unit vectors (no copy of its formulas); an unfused trial is a mixture over the
  jump's direction (``n_angle`` equally spaced directions, the trapezoid rule on the
  circle), weighted by :func:`~vibrofocus.simulation.perception.unfused_probability`; with
  ``conflict_awareness`` the selection's width depends on the conflict's part of the
  noise, integrated by Gauss-Hermite quadrature (``n_conflict`` nodes per axis; it
  converges slowly where the conflict's noise dominates the place's: about 1 % off at 16
  nodes on the worst Study 2 cell tested; Study 1 does not need it and is exact);
* the answer is the nearest allowed location: along each line of the place's first axis
  (``n_place`` Gauss-Legendre nodes on the probability scale) the squared distances are
  linear in the second coordinate, so the stretches where each location is nearest are
  exact, and a Study 1 answer's probability on that line is a difference of normal CDFs;
* a Study 2 selection holds every location whose posterior density reaches ``kappa * J``
  of the answer's, so it is the ``m`` nearest locations for a ``log J`` in an interval:
  its probability given the place is a difference of normal CDFs of ``log J``, integrated
  along each stretch of constant distance order by Gauss-Legendre (``n_segment`` nodes).
  On a stretch the ``m`` nearest are one set for each ``m``, so one pass over a law's
  stretches gives the probability of every selection at once: it is taken once per
  distinct law (every trial of a stimulus), not per trial.

The test ``tests/simulation/test_likelihood.py`` checks, for every registered hypothesis
and with unfused and conflict-aware percepts, that the sampler's answer frequencies
match these probabilities within Monte Carlo error in every stimulus x answer cell.

A probability the quadrature puts at 0 (an answer far beyond the model's tails) gives
``-inf``: the model, as it stands, has no lapse rate. The likelihood is that of the
model's own answer rule (:func:`~vibrofocus.simulation.perception.posterior_ratio_rule`);
other rules given to ``draw_answers(rule=...)`` are not covered.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from ..errors import ValidationError
from .perception import Percepts, PerceptualModel, Traits, trial_posteriors, unfuse, unfused_probability

__all__ = ["Quadrature", "AnswerLaw", "Stimuli", "answer_law", "answer_probabilities", "selection_probability",
           "point_loglik", "trial_loglik", "loglik", "marginal_loglik"]

#: Queries (trial x mixture component) integrated at once: bounds the memory of Study 2.
_CHUNK = 48


@dataclass(frozen=True)
class Quadrature:
    """Nodes of the numerical integrals (defaults: errors well below 1e-3 in probability).

    Attributes
    ----------
    n_place : int
        Gauss-Legendre nodes over the perceived place's first axis, on the probability
        scale, per stretch between the places where the nearest location jumps.
    n_segment : int
        Gauss-Legendre nodes per stretch of constant distance order along the second axis
        (Study 2 only; Study 1 is exact along it).
    n_angle : int
        Directions of an unfused percept's jump (only where ``unfused_per_m > 0``).
    n_conflict : int
        Gauss-Hermite nodes per axis of the conflict's noise (only where
        ``conflict_awareness > 0``).
    """

    n_place: int = 12
    n_segment: int = 6
    n_angle: int = 16
    n_conflict: int = 12

    def __post_init__(self) -> None:
        for name in ("n_place", "n_segment", "n_angle", "n_conflict"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v <= 4096:
                raise ValidationError(f"quadrature {name} must be an integer from 1 to 4096, got {v!r}")


@dataclass(frozen=True)
class AnswerLaw:
    """Per-trial law of the perceived place and of the selection's width.

    A mixture, per trial, of ``K`` isotropic Gaussians of the perceived place (the
    posterior mean), each with the posterior SD the Study 2 selection reads.

    Attributes
    ----------
    weight : ndarray, shape (n_trials, K)
        Mixture weights (each row sums to 1).
    mean_m : ndarray, shape (n_trials, K, 2)
        Mean of the perceived place, m.
    sd_m : ndarray, shape (n_trials, K)
        SD of the perceived place per axis, m.
    width_m : ndarray, shape (n_trials, K)
        Posterior SD with which the selection is made, m.
    kappa : float
        The participant's Study 2 criterion.
    log_sd : float
        SD of the criterion's per-trial log-normal jitter.
    """

    weight: np.ndarray
    mean_m: np.ndarray
    sd_m: np.ndarray
    width_m: np.ndarray
    kappa: float
    log_sd: float


def answer_law(
    percepts: Percepts,
    index: np.ndarray,
    centre_xy: np.ndarray,
    model: PerceptualModel,
    traits: Traits,
    quadrature: Quadrature | None = None,
    *,
    study: int = 2,
) -> AnswerLaw:
    """The law of each trial's perceived place, read from the sampler's own functions.

    Parameters
    ----------
    percepts : Percepts
        Of the distinct stimuli.
    index : ndarray of int, shape (n_trials,)
        Which stimulus each trial presents.
    centre_xy : ndarray, shape (2,)
        Array centre, m.
    model : PerceptualModel
    traits : Traits
    quadrature : Quadrature, optional
    study : {1, 2}
        2 (default): the law of the place and of the selection's width. 1: of the place
        only (``width_m`` NaN), which is exact with ``conflict_awareness`` too (the
        conflict's part of the noise is then merged into the place's SD instead of
        integrated over: only the width reads it separately).

    Returns
    -------
    AnswerLaw

    Raises
    ------
    ValidationError
        If the place's noise is not isotropic and affine (a change to
        :func:`~vibrofocus.simulation.perception.trial_posteriors` this law does not cover).
    """
    q = quadrature or Quadrature()
    idx = np.asarray(index, dtype=int)
    n = idx.size
    zero = np.zeros((n, 2))
    unit_x = np.tile([1.0, 0.0], (n, 1))
    unit_y = np.tile([0.0, 1.0], (n, 1))
    if study not in (1, 2):
        raise ValidationError(f"study must be 1 or 2, got {study!r}")
    place_only = study == 1 and model.conflict_awareness > 0
    if place_only:
        nodes = [(np.zeros(2), 1.0)]
    elif model.conflict_awareness > 0:
        z, w = np.polynomial.hermite_e.hermegauss(q.n_conflict)
        w = w / w.sum()
        nodes = [(np.array([a, b]), wa * wb) for a, wa in zip(z, w) for b, wb in zip(z, w)]
    else:
        nodes = [(None, 1.0)]
    unfusing = model.unfused_per_m > 0 and percepts.conflict_m is not None
    conflict = percepts.conflict_m[idx] if unfusing else None
    weights, means, sds, widths = [], [], [], []
    for node, w_node in nodes:
        cn = None if node is None else np.tile(node, (n, 1))
        post = trial_posteriors(percepts, idx, centre_xy, model, traits, zero, cn)
        dx = trial_posteriors(percepts, idx, centre_xy, model, traits, unit_x, cn).perceived_m - post.perceived_m
        dy = trial_posteriors(percepts, idx, centre_xy, model, traits, unit_y, cn).perceived_m - post.perceived_m
        sd = _isotropic_sd(dx, dy)
        if place_only:
            # The conflict's part of the noise, read the same way, merged into the place's SD.
            cx = trial_posteriors(percepts, idx, centre_xy, model, traits, zero, unit_x).perceived_m - post.perceived_m
            cy = trial_posteriors(percepts, idx, centre_xy, model, traits, zero, unit_y).perceived_m - post.perceived_m
            sd = np.hypot(sd, _isotropic_sd(cx, cy))
            post = type(post)(post.perceived_m, np.full(n, np.nan), post.felt)
        p_unf = np.zeros(n)
        if unfusing:
            p_unf = unfused_probability(conflict, model) * post.felt
        weights.append(w_node * (1.0 - p_unf))
        means.append(post.perceived_m)
        sds.append(sd)
        widths.append(post.sd_m)
        if unfusing:
            for angle in 2.0 * np.pi * np.arange(q.n_angle) / q.n_angle:
                # uniform = -1: every felt trial unfused here; the weight carries the probability.
                moved, _ = unfuse(post, conflict, model, np.full(n, -1.0), np.full(n, angle))
                weights.append(w_node * p_unf / q.n_angle)
                means.append(moved.perceived_m)
                sds.append(sd)
                widths.append(moved.sd_m)
    return AnswerLaw(np.stack(weights, axis=1), np.stack(means, axis=1), np.stack(sds, axis=1),
                     np.stack(widths, axis=1), float(traits.kappa), float(model.select_log_sd))


def _isotropic_sd(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """SD of a place whose displacements by unit noise along x and y are ``dx``, ``dy`` (n, 2), m."""
    sd = dx[:, 0]
    scale = np.maximum(np.abs(sd), 1e-300)
    if (np.any(np.abs(dx[:, 1]) > 1e-9 * scale) or np.any(np.abs(dy[:, 0]) > 1e-9 * scale)
            or np.any(np.abs(dy[:, 1] - sd) > 1e-9 * scale) or np.any(sd < 0)):
        raise ValidationError("the perceived place's noise is not isotropic: the likelihood does not cover this model")
    return sd


def _allowed(locations_xy: np.ndarray, allowed: np.ndarray | None) -> np.ndarray:
    n_loc = len(locations_xy)
    if allowed is None:
        return np.arange(n_loc)
    a = np.asarray(allowed, dtype=int)
    if a.ndim != 1 or a.size < 1 or np.any((a < 0) | (a >= n_loc)) or len(set(a.tolist())) != a.size:
        raise ValidationError(f"allowed must be distinct 0-based location indices below {n_loc}")
    return np.sort(a)


def _lines(mean: np.ndarray, sd: np.ndarray, locs: np.ndarray, q: Quadrature):
    """Along lines of the place's first axis: node weights, and distances linear in the second axis.

    The lines' nodes are Gauss-Legendre on the probability scale of the first coordinate,
    ``q.n_place`` per stretch between the vertical bisectors of locations on one row
    (where the nearest location jumps, so that the integrand is continuous on each).
    Squared distance to location j on line i, at second coordinate ``v`` (in SDs):
    ``A_ij + B_j v + (sd v)**2``; the last term is the same for every location.
    Returns the lines' weights (M, I), A (M, I, J), B (M, J), and the edges of the
    stretches of constant distance order along each line, on the probability scale of
    ``v``, sorted, (M, I, S + 1).
    """
    sd = np.maximum(sd, 1e-12)  # a place known to a picometre: as good as exact
    j, k = np.triu_indices(locs.shape[0], 1)
    row = np.abs(locs[j, 1] - locs[k, 1]) <= 1e-9
    x_jump = np.unique(np.round((locs[j[row], 0] + locs[k[row], 0]) / 2.0, 12))
    tb = special.ndtr((x_jump[None, :] - mean[:, None, 0]) / sd[:, None])  # (M, n_jump), sorted
    lo_hi = np.concatenate([np.zeros((mean.shape[0], 1)), tb, np.ones((mean.shape[0], 1))], axis=1)
    x, w = np.polynomial.legendre.leggauss(q.n_place)
    span = np.diff(lo_hi, axis=1)  # (M, n_jump + 1)
    tu = (lo_hi[:, :-1, None] + span[..., None] * (x + 1.0) / 2.0).reshape(mean.shape[0], -1)
    wu = (span[..., None] * w / 2.0).reshape(mean.shape[0], -1)
    u = special.ndtri(np.clip(tu, 1e-300, 1.0 - 1e-16))
    X = mean[:, None, 0] + sd[:, None] * u  # (M, I)
    A = (X[:, :, None] - locs[None, None, :, 0]) ** 2 + ((mean[:, 1, None] - locs[None, :, 1]) ** 2)[:, None, :]
    B = 2.0 * sd[:, None] * (mean[:, 1, None] - locs[None, :, 1])  # (M, J)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = -(A[:, :, j] - A[:, :, k]) / (B[:, None, j] - B[:, None, k])
    t = special.ndtr(np.where(np.isfinite(v), v, np.inf))
    edges = np.concatenate([np.zeros(t.shape[:2] + (1,)), np.sort(t, axis=2), np.ones(t.shape[:2] + (1,))], axis=2)
    return wu, A, B, edges


def _as_queries(law: AnswerLaw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, k = law.weight.shape
    return law.mean_m.reshape(n * k, 2), law.sd_m.reshape(n * k), law.width_m.reshape(n * k)


def answer_probabilities(law: AnswerLaw, locations_xy: np.ndarray, allowed: np.ndarray | None = None,
                         quadrature: Quadrature | None = None) -> np.ndarray:
    """Probability of each Study 1 answer (the nearest allowed location to the perceived place).

    Parameters
    ----------
    law : AnswerLaw
        Of the trials (:func:`answer_law`).
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    allowed : ndarray of int, optional
        0-based locations that may be answered (default all).
    quadrature : Quadrature, optional

    Returns
    -------
    ndarray, shape (n_trials, n_locations)
        Rows sum to 1 (to rounding); 0 for locations not allowed.
    """
    q = quadrature or Quadrature()
    locs_all = np.asarray(locations_xy, dtype=float)
    ok = _allowed(locs_all, allowed)
    locs = locs_all[ok]
    mean, sd, _ = _as_queries(law)
    out = np.zeros((mean.shape[0], locs.shape[0]))
    for s in range(0, mean.shape[0], _CHUNK * 8):
        sl = slice(s, s + _CHUNK * 8)
        wu, A, B, edges = _lines(mean[sl], sd[sl], locs, q)
        dt = np.diff(edges, axis=2)  # (M, I, S)
        mid = special.ndtri(np.clip((edges[:, :, 1:] + edges[:, :, :-1]) / 2.0, 1e-300, 1.0 - 1e-16))
        f = A[:, :, None, :] + B[:, None, None, :] * mid[..., None]  # (M, I, S, J)
        nearest = np.argmin(f, axis=3)
        mass = (dt * wu[:, :, None])[..., None] * (nearest[..., None] == np.arange(locs.shape[0]))
        out[sl] = mass.sum(axis=(1, 2))
    n, k = law.weight.shape
    probs = np.einsum("nk,nkj->nj", law.weight, out.reshape(n, k, -1))
    full = np.zeros((n, locs_all.shape[0]))
    full[:, ok] = probs
    return full


def selection_probability(law: AnswerLaw, locations_xy: np.ndarray, selected: np.ndarray,
                          allowed: np.ndarray | None = None, quadrature: Quadrature | None = None) -> np.ndarray:
    """Probability of each trial's observed Study 2 selection.

    The selection holds every allowed location whose posterior density is at least
    ``kappa * J`` of the nearest's (``J`` log-normal, SD ``log_sd``), and always the
    nearest: for a given place, the ``m`` nearest locations, with ``log J`` between
    ``-log kappa - delta_(m+1)`` and ``-log kappa - delta_(m)``, ``delta`` the log density
    ratios.

    Parameters
    ----------
    law : AnswerLaw
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    selected : ndarray of bool, shape (n_trials, n_locations)
        The observed selections.
    allowed : ndarray of int, optional
        0-based locations that may be selected (default all); a selection outside them has
        probability 0.
    quadrature : Quadrature, optional

    Returns
    -------
    ndarray, shape (n_trials,)
    """
    q = quadrature or Quadrature()
    locs_all = np.asarray(locations_xy, dtype=float)
    ok = _allowed(locs_all, allowed)
    sel = np.asarray(selected)
    n, k = law.weight.shape
    if sel.shape != (n, locs_all.shape[0]) or sel.dtype != bool:
        raise ValidationError(f"selected must be a boolean array of shape ({n}, {locs_all.shape[0]}), "
                              f"got {sel.dtype} {sel.shape}")
    outside = np.any(np.delete(sel, ok, axis=1), axis=1) | ~np.any(sel, axis=1)
    sel = sel[:, ok]
    locs = locs_all[ok]
    n_j = locs.shape[0]
    if n_j > _MAX_SELECTABLE:
        raise ValidationError(f"a Study 2 selection among more than {_MAX_SELECTABLE} locations is not covered, "
                              f"got {n_j}")
    mean, sd, width = _as_queries(law)
    # Every trial of one stimulus has the same law: the integral is taken once per distinct
    # law (place and width), for every selection at once, and each trial reads its own.
    laws, law_of = np.unique(np.column_stack([mean, sd, width]), axis=0, return_inverse=True)
    law_of = law_of.reshape(-1)
    bits = np.int64(1) << np.arange(n_j, dtype=np.int64)
    sel_mask = np.repeat(sel.astype(np.int64) @ bits, k)
    size = np.repeat(sel.sum(axis=1), k)
    out = np.zeros(mean.shape[0])
    for s in range(0, laws.shape[0], _CHUNK):
        rows = np.flatnonzero((law_of >= s) & (law_of < s + _CHUNK))
        row_key = (law_of[rows] - s).astype(np.int64) * (np.int64(1) << n_j) + sel_mask[rows]
        m_max = int(size[rows].max())
        if m_max == 0:  # only selections outside the allowed locations
            continue
        key, p = _selection_masses(laws[s:s + _CHUNK], locs, law.kappa, law.log_sd, q, m_max)
        # Summed per selection the trials made (not per every set that is the m nearest somewhere).
        asked, row_of = np.unique(row_key, return_inverse=True)
        pos = np.minimum(np.searchsorted(asked, key), asked.size - 1)
        hit = asked[pos] == key
        out[rows] = np.bincount(pos[hit], p[hit], minlength=asked.size)[row_of.reshape(-1)]
    probs = np.sum(law.weight * out.reshape(n, k), axis=1)
    return np.where(outside, 0.0, probs)


#: Most locations a Study 2 selection is made among (a selection and its law's number in a chunk:
#: one int64).
_MAX_SELECTABLE = 56


def _selection_masses(laws: np.ndarray, locs: np.ndarray, kappa: float, log_sd: float, q: Quadrature,
                      m_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Probability mass of every selection of at most ``m_max`` locations, per stretch of constant distance order.

    ``laws``: rows (mean x, mean y, SD, width), m. Along every line of the place's first
    axis (:func:`_lines`) the distance order is constant on each stretch, so on a stretch
    the ``m`` nearest locations are one set for each ``m``, and the selection is that set
    when ``log J`` lies between ``-log kappa - delta_(m+1)`` and ``-log kappa - delta_(m)``
    (``delta`` the log density ratios to the nearest, from the posterior of SD ``width``);
    that probability is integrated over the stretch by Gauss-Legendre (``q.n_segment``
    nodes). Returns, per (law, line, stretch, m), the selection as a bit mask plus the
    law's row number times ``2**n_locations``, and its mass, both flat.
    """
    n_j = locs.shape[0]
    xg, wg = np.polynomial.legendre.leggauss(q.n_segment)
    tg, wg = (xg + 1.0) / 2.0, wg / 2.0
    wu, A, B, edges = _lines(laws[:, :2], laws[:, 2], locs, q)
    dt = np.diff(edges, axis=2)  # (M, I, S)
    # Stretches of no mass are left out (e.g. past the crossings of locations on one row, which
    # never cross along a line: edges at 1): P of them stay.
    li, ii, si = np.nonzero(dt * wu[:, :, None] > 0)
    dt, w = dt[li, ii, si], dt[li, ii, si] * wu[li, ii]
    lo = edges[li, ii, si]
    mid = special.ndtri(np.clip(lo + dt / 2.0, 1e-300, 1.0 - 1e-16))
    A, B = A[li, ii], B[li]  # (P, J)
    order = np.argsort(A + B * mid[:, None], axis=1, kind="stable")  # (P, J)
    # Squared distances, nearest first (the order is constant on the stretch), re the nearest's,
    # as log density ratios: delta = a + b v at the stretch's nodes v.
    a = np.take_along_axis(A, order, axis=1)
    b = np.take_along_axis(B, order, axis=1)
    two_w2 = 2.0 * laws[li, 3, None] ** 2
    a = (a - a[:, :1]) / two_w2
    b = (b - b[:, :1]) / two_w2
    v = special.ndtri(np.clip(lo[:, None] + dt[:, None] * tg, 1e-300, 1.0 - 1e-16))  # (P, G)
    # The m nearest are selected when log J is at most x_m = -log kappa - delta_m, and the
    # (m + 1)-th is not: above x_(m+1) (none beyond the last location). below[..., m - 1]:
    # the probability that log J is at most x_m (1 for the nearest, always selected).
    top = min(m_max + 1, n_j)  # the (m_max + 1)-th nearest bounds the largest selection asked for
    # x[p, g, m - 1] = (x_m - b v) / log_sd for m = 1 .. top - 1, laid out contiguously.
    x = np.multiply(b[:, None, 1:top], v[..., None])
    np.subtract(-np.log(kappa) - a[:, None, 1:top], x, out=x)
    if log_sd > 0:
        x /= log_sd
        special.ndtr(x, out=x)
    else:
        x = (x >= 0).astype(float)
    # The mass is linear in "below": average over the stretch's nodes first, then take the
    # differences between successive m (the m nearest, at [:, m - 1]).
    below = np.zeros((x.shape[0], m_max + 1))
    below[:, 0] = wg.sum()
    below[:, 1:top] = np.einsum("pgt,g->pt", x, wg)
    mass = np.maximum(below[:, :-1] - below[:, 1:], 0.0) * w[:, None]
    prefix = np.cumsum(np.int64(1) << order[:, :m_max].astype(np.int64), axis=1)  # the m nearest as a bit mask
    key = prefix + (li.astype(np.int64) * (np.int64(1) << n_j))[:, None]
    return key.reshape(-1), mass.reshape(-1)


def _per_trial_selection_probability(law: AnswerLaw, locations_xy: np.ndarray, selected: np.ndarray,
                                     allowed: np.ndarray | None = None,
                                     quadrature: Quadrature | None = None) -> np.ndarray:
    """:func:`selection_probability` trial by trial, as it was computed before (a reference, slower).

    For each trial, every stretch of constant distance order where its selection is the
    ``m`` nearest, integrated by Gauss-Legendre: the per-law integral must give the same
    numbers (tests/simulation/test_likelihood.py; benchmarks/bench_fit_likelihood.py times
    both). Not chunked: memory grows with trials x lines x stretches x locations.
    """
    q = quadrature or Quadrature()
    locs_all = np.asarray(locations_xy, dtype=float)
    ok = _allowed(locs_all, allowed)
    sel = np.asarray(selected)
    n, k = law.weight.shape
    outside = np.any(np.delete(sel, ok, axis=1), axis=1) | ~np.any(sel, axis=1)
    sel, locs = sel[:, ok], locs_all[ok]
    mean, sd, width = _as_queries(law)
    sel_q = np.repeat(sel, k, axis=0)
    m = sel_q.sum(axis=1)
    xg, wg = np.polynomial.legendre.leggauss(q.n_segment)
    tg, wg = (xg + 1.0) / 2.0, wg / 2.0
    wu, A, B, edges = _lines(mean, sd, locs, q)
    dt = np.diff(edges, axis=2)
    mid = special.ndtri(np.clip((edges[:, :, 1:] + edges[:, :, :-1]) / 2.0, 1e-300, 1.0 - 1e-16))
    inside = sel_q[:, None, None, :]
    f_mid = A[:, :, None, :] + B[:, None, None, :] * mid[..., None]
    match = np.max(np.where(inside, f_mid, -np.inf), axis=3) < np.min(np.where(inside, np.inf, f_mid), axis=3)
    qi, ii, si = np.nonzero(match & (dt > 0))
    v = special.ndtri(np.clip(edges[qi, ii, si][:, None] + dt[qi, ii, si][:, None] * tg, 1e-300, 1.0 - 1e-16))
    f = A[qi, ii][:, None, :] + B[qi][:, None, :] * v[..., None]
    ins = sel_q[qi][:, None, :]
    near = np.min(np.where(ins, f, np.inf), axis=2)
    two_w2 = 2.0 * width[qi][:, None] ** 2
    hi_x = -np.log(law.kappa) - (np.max(np.where(ins, f, -np.inf), axis=2) - near) / two_w2
    lo_x = -np.log(law.kappa) - (np.min(np.where(ins, np.inf, f), axis=2) - near) / two_w2
    hi = np.where((m[qi] == 1)[:, None], 1.0, special.ndtr(hi_x / law.log_sd))
    p_place = np.clip(hi - special.ndtr(lo_x / law.log_sd), 0.0, 1.0)
    out = np.bincount(qi, np.sum(p_place * wg, axis=1) * dt[qi, ii, si] * wu[qi, ii], minlength=mean.shape[0])
    return np.where(outside, 0.0, np.sum(law.weight * out.reshape(n, k), axis=1))


def point_loglik(law: AnswerLaw, perceived_m: np.ndarray) -> np.ndarray:
    """Log-density of a perceived place reported as a point (per trial), log(1/m^2).

    Parameters
    ----------
    law : AnswerLaw
    perceived_m : ndarray, shape (n_trials, 2)
        The reported places, m (in the array's frame).

    Returns
    -------
    ndarray, shape (n_trials,)
    """
    x = np.asarray(perceived_m, dtype=float)
    if x.shape != (law.weight.shape[0], 2) or not np.all(np.isfinite(x)):
        raise ValidationError(f"perceived_m must be finite with shape ({law.weight.shape[0]}, 2), got {x.shape}")
    d2 = np.sum((x[:, None, :] - law.mean_m) ** 2, axis=2)
    log_n = -d2 / (2.0 * law.sd_m**2) - np.log(2.0 * np.pi * law.sd_m**2)
    with np.errstate(divide="ignore"):
        return special.logsumexp(log_n + np.log(law.weight), axis=1)


def trial_loglik(
    percepts: Percepts,
    index: np.ndarray,
    locations_xy: np.ndarray,
    centre_xy: np.ndarray,
    model: PerceptualModel,
    traits: Traits,
    *,
    study: int,
    answers: np.ndarray,
    allowed: np.ndarray | None = None,
    quadrature: Quadrature | None = None,
) -> np.ndarray:
    """Log-probability of each observed answer given the percepts and the participant's traits.

    Parameters
    ----------
    percepts : Percepts
        Noise-free percepts of the distinct stimuli (a hypothesis' :meth:`percepts`).
    index : ndarray of int, shape (n_trials,)
        Which stimulus each trial presents.
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    centre_xy : ndarray, shape (2,)
        Array centre, m.
    model : PerceptualModel
    traits : Traits
    study : {1, 2}
        1: ``answers`` are 0-based locations, shape (n_trials,); 2: selections, boolean
        (n_trials, n_locations).
    answers : ndarray
    allowed : ndarray of int, optional
        0-based locations that may be answered (default all).
    quadrature : Quadrature, optional

    Returns
    -------
    ndarray, shape (n_trials,)
        Natural log; ``-inf`` for an answer the model cannot give.
    """
    idx = np.asarray(index, dtype=int)
    n_stim = percepts.position_m.shape[0]
    if idx.ndim != 1 or np.any((idx < 0) | (idx >= n_stim)):
        raise ValidationError(f"index must be 0-based stimulus numbers below {n_stim}")
    if study not in (1, 2):
        raise ValidationError(f"study must be 1 or 2, got {study!r}")
    law = answer_law(percepts, idx, centre_xy, model, traits, quadrature, study=study)
    n_loc = len(locations_xy)
    with np.errstate(divide="ignore"):
        if study == 1:
            a = np.asarray(answers)
            if a.shape != idx.shape or not np.issubdtype(a.dtype, np.integer) or np.any((a < 0) | (a >= n_loc)):
                raise ValidationError(f"Study 1 answers must be 0-based locations below {n_loc}, one per trial")
            p = answer_probabilities(law, locations_xy, allowed, quadrature)
            return np.log(p[np.arange(idx.size), a])
        if study == 2:
            return np.log(selection_probability(law, locations_xy, np.asarray(answers), allowed, quadrature))
    raise ValidationError(f"study must be 1 or 2, got {study!r}")


@dataclass(frozen=True)
class Stimuli:
    """The felt field of a participant's stimuli: what a hypothesis reads.

    Attributes
    ----------
    energy : ndarray, shape (n_stimuli, n_points)
        Felt energy at the skin points, re the reference tap.
    points_xy : ndarray, shape (n_points, 2)
        m.
    locations_xy : ndarray, shape (n_locations, 2)
        m.
    centre_xy : ndarray, shape (2,)
        Array centre, m.
    actuator_energy : ndarray, shape (n_stimuli, n_actuators), optional
        Felt energy each actuator delivers at its own contact.
    actuators_xy : ndarray, shape (n_actuators, 2), optional
        m.
    """

    energy: np.ndarray
    points_xy: np.ndarray
    locations_xy: np.ndarray
    centre_xy: np.ndarray
    actuator_energy: np.ndarray | None = None
    actuators_xy: np.ndarray | None = None

    @classmethod
    def from_bank(cls, bank: Any, forearm: int, level_db: float = 0.0) -> "Stimuli":
        """Forearm ``forearm`` of a feature bank; stimulus ``method * n_locations + location`` (0-based).

        ``level_db``: the stimuli played that many dB re the bank's level rule
        (:meth:`~vibrofocus.simulation.bank.FeatureBank.at_level`).
        """
        if level_db != 0.0:
            bank = bank.at_level(level_db)
        if not 0 <= int(forearm) < bank.n_forearms:
            raise ValidationError(f"forearm must be a bank row from 0 to {bank.n_forearms - 1}, got {forearm!r}")
        return cls(bank.energy[forearm].reshape(-1, bank.points_xy.shape[0]), bank.points_xy, bank.locations_xy,
                   bank.centre_xy, bank.actuator_energy[forearm].reshape(-1, bank.actuators_xy.shape[0]),
                   bank.actuators_xy)

    def percepts(self, hypothesis: Any, model: PerceptualModel, traits: Traits) -> Percepts:
        """Noise-free percepts under ``hypothesis`` for a participant of ``traits``."""
        return hypothesis.percepts(self.energy, self.points_xy, model, traits, self.actuator_energy,
                                   self.actuators_xy, self.locations_xy)


def loglik(
    hypothesis: Any,
    stimuli: Stimuli,
    traits: Traits,
    *,
    study: int,
    index: np.ndarray,
    answers: np.ndarray,
    model: PerceptualModel | None = None,
    allowed: np.ndarray | None = None,
    quadrature: Quadrature | None = None,
) -> np.ndarray:
    """Log-probability of each observed answer under a hypothesis, for a participant of known traits.

    Parameters
    ----------
    hypothesis : str or Hypothesis
        Registered name or hypothesis (:func:`~vibrofocus.simulation.hypotheses.hypothesis`).
    stimuli : Stimuli
        The participant's felt field (a simulated forearm's, e.g. :meth:`Stimuli.from_bank`).
    traits : Traits
    study : {1, 2}
    index : ndarray of int, shape (n_trials,)
        Stimulus of each trial (row of ``stimuli.energy``).
    answers : ndarray
        Study 1: 0-based locations (n_trials,); Study 2: selections, bool (n_trials, n_locations).
    model : PerceptualModel, optional
        Default the hypothesis' fitted model.
    allowed, quadrature
        As :func:`trial_loglik`.

    Returns
    -------
    ndarray, shape (n_trials,)
    """
    from .hypotheses import hypothesis as find_hypothesis

    h = find_hypothesis(hypothesis)
    m = model or h.model()
    per = stimuli.percepts(h, m, traits)
    return trial_loglik(per, index, stimuli.locations_xy, stimuli.centre_xy, m, traits, study=study,
                        answers=answers, allowed=allowed, quadrature=quadrature)


def marginal_loglik(
    hypothesis: Any,
    stimuli: Stimuli,
    *,
    study1: tuple[np.ndarray, np.ndarray] | None = None,
    study2: tuple[np.ndarray, np.ndarray] | None = None,
    model: PerceptualModel | None = None,
    n_draws: int = 64,
    seed: int = 0,
    allowed: np.ndarray | None = None,
    quadrature: Quadrature | None = None,
) -> float:
    """Log-likelihood of one participant's answers, integrated over the hypothesis' population.

    ``log mean_k p(answers | traits_k)`` over ``n_draws`` traits drawn from the model's
    population (:meth:`Traits.draw`) with a fixed seed: Monte Carlo over the traits, the
    same draws for every hypothesis and parameter set (common random numbers, so the
    estimate is smooth in the population's parameters).

    Parameters
    ----------
    hypothesis : str or Hypothesis
    stimuli : Stimuli
    study1 : (index, answers), optional
        Study 1 trials: stimulus index (n,) and 0-based answered locations (n,).
    study2 : (index, selected), optional
        Study 2 trials: stimulus index (n,) and selections, bool (n, n_locations).
    model : PerceptualModel, optional
        Default the hypothesis' fitted model.
    n_draws : int
        Traits drawn.
    seed : int
        Seed of the traits' draws.
    allowed, quadrature
        As :func:`trial_loglik`.

    Returns
    -------
    float
        Natural log.
    """
    from .hypotheses import hypothesis as find_hypothesis

    if isinstance(n_draws, bool) or not isinstance(n_draws, (int, np.integer)) or not 1 <= n_draws <= 100_000:
        raise ValidationError(f"n_draws must be an integer from 1 to 100000, got {n_draws!r}")
    if study1 is None and study2 is None:
        raise ValidationError("marginal_loglik needs the trials of study 1, study 2 or both")
    h = find_hypothesis(hypothesis)
    m = model or h.model()
    rng = np.random.default_rng([int(seed), 0x11C])
    total = np.zeros(n_draws)
    for k in range(n_draws):
        traits = Traits.draw(m, rng)
        per = stimuli.percepts(h, m, traits)
        for study, trials in ((1, study1), (2, study2)):
            if trials is not None:
                total[k] += trial_loglik(per, trials[0], stimuli.locations_xy, stimuli.centre_xy, m, traits,
                                         study=study, answers=trials[1], allowed=allowed, quadrature=quadrature).sum()
    with np.errstate(divide="ignore"):
        return float(special.logsumexp(total) - np.log(n_draws))
