"""The candidates of the search: drawn from broad ranges, or jittered around the best so far."""

from __future__ import annotations

import numpy as np

from ..parameters import ParameterRange, apply_parameters, ordered_pairs, read_parameters
from ..perception import PerceptualModel

__all__ = ["CENTRAL_WEIGHT_RANGE", "sample", "sample_within"]

#: Range searched for the drive cue's weight (``--central-weight LO HI`` narrows it, e.g.
#: to hold the paper's reading that funneling is coded centrally).
CENTRAL_WEIGHT_RANGE = (0.0, 1.0)


def sample(rng: np.random.Generator, base: PerceptualModel | None = None, scale: float = 1.0,
           central_range: tuple[float, float] = CENTRAL_WEIGHT_RANGE, unfused: bool = False,
           aware: bool = False) -> PerceptualModel:
    """A candidate: drawn from broad ranges (``base`` None) or jittered around ``base``.

    Parameters
    ----------
    rng : numpy.random.Generator
        The search's random generator (its path).
    base : PerceptualModel, optional
        The model to jitter around (the refinement); None draws from the broad ranges.
    scale : float
        Size of the jitter relative to its full size (the refinement shrinks it).
    central_range : (float, float)
        Range of the drive cue's weight ``central_weight``.
    unfused : bool
        Search the unfused percepts too (``PerceptualModel.unfused_*``).
    aware : bool
        Search ``PerceptualModel.conflict_awareness`` too, with the conflict gain's
        random range widened to 0-4 (a selection that reads the trial's discrepancy pairs
        with more conflict noise).

    Returns
    -------
    PerceptualModel
        The candidate. Without ``unfused`` and ``aware`` nothing more is drawn, so a
        search repeats the fits made before them.
    """
    drawn = _sample(rng, base, scale, central_range, unfused)
    if not aware:
        return drawn
    if base is None:
        return drawn.replace(conflict_gain=rng.uniform(0.0, 4.0), conflict_awareness=rng.uniform(0.0, 2.0))
    # Additive, so a search that starts without it (0) can find it.
    return drawn.replace(conflict_awareness=float(np.clip(base.conflict_awareness + rng.normal(0, 0.1 * scale), 0.0, 3.0)))


def _sample(rng: np.random.Generator, base: PerceptualModel | None, scale: float,
            central_range: tuple[float, float], unfused: bool) -> PerceptualModel:
    """:func:`sample` without the conflict awareness."""
    if base is None:
        lo_a, lo_p, lo_k = rng.uniform(3e-3, 12e-3), rng.uniform(5e-3, 25e-3), rng.uniform(0.05, 0.6)
        drawn = PerceptualModel().replace(
            sl_ref_db=rng.uniform(10, 45), funneling_exponent=rng.uniform(0.2, 2.0),
            central_weight=rng.uniform(*central_range), conflict_gain=rng.uniform(0.0, 2.0),
            acuity_sd_m=(lo_a, lo_a * rng.uniform(1.2, 2.0)), spread_gain=tuple(sorted(rng.uniform(0, 2, 2))),
            prior_sd_m=(lo_p, lo_p * rng.uniform(1.2, 2.0)),
            bias_mean_m=(rng.uniform(-8e-3, 8e-3), rng.uniform(-8e-3, 0.0)), bias_sd_m=rng.uniform(0, 4e-3),
            select_kappa=(lo_k, min(lo_k + rng.uniform(0.1, 0.4), 0.99)), select_log_sd=rng.uniform(0.1, 1.0),
        )
        if not unfused:
            return drawn
        return drawn.replace(unfused_per_m=rng.uniform(0.0, 400.0), unfused_jump_m=rng.uniform(10e-3, 35e-3),
                             unfused_width=rng.uniform(1.0, 3.5))

    def jit(v: float) -> float:
        return float(v * np.exp(rng.normal(0, 0.15 * scale)))

    b = base
    jittered = b.replace(
        sl_ref_db=float(np.clip(b.sl_ref_db + rng.normal(0, 2 * scale), 5, 50)),
        central_weight=float(np.clip(b.central_weight + rng.normal(0, 0.1 * scale), *central_range)),
        conflict_gain=float(abs(b.conflict_gain + rng.normal(0, 0.15 * scale))),
        funneling_exponent=float(np.clip(jit(b.funneling_exponent), 0.05, 1.5)),
        acuity_sd_m=tuple(sorted(jit(v) for v in b.acuity_sd_m)),
        spread_gain=tuple(sorted(abs(jit(v + 1e-3)) for v in b.spread_gain)),
        prior_sd_m=tuple(sorted(jit(v) for v in b.prior_sd_m)),
        bias_mean_m=(float(b.bias_mean_m[0] + rng.normal(0, 1.5e-3 * scale)),
                     float(min(0.0, b.bias_mean_m[1] + rng.normal(0, 1.5e-3 * scale)))),
        bias_sd_m=float(abs(b.bias_sd_m + rng.normal(0, 5e-4 * scale))),
        select_kappa=tuple(sorted(float(np.clip(jit(v), 0.01, 0.99)) for v in b.select_kappa)),
        select_log_sd=jit(b.select_log_sd),
    )
    if not unfused:
        return jittered
    return jittered.replace(
        # Additive, so a search that starts without unfused percepts (0) can find them.
        unfused_per_m=float(abs(b.unfused_per_m + rng.normal(0, 40.0 * scale))),
        unfused_jump_m=float(np.clip(jit(b.unfused_jump_m), 5e-3, 50e-3)),
        unfused_width=float(np.clip(b.unfused_width + rng.normal(0, 0.2 * scale), 1.0, 5.0)),
    )


def sample_within(rng: np.random.Generator, base: PerceptualModel, ranges: tuple[ParameterRange, ...],
                  scale: float | None = None) -> PerceptualModel:
    """A candidate that moves only ``ranges``' parameters, always inside their ranges.

    Parameters
    ----------
    rng : numpy.random.Generator
        The search's random generator (its path).
    base : PerceptualModel
        The fixed parameters, and the point to jitter around.
    ranges : tuple of ParameterRange
        The free parameters (:attr:`~vibrofocus.simulation.hypotheses.Hypothesis.free_parameters`).
    scale : float, optional
        None: every free parameter drawn uniformly from its range; else a Gaussian step of
        ``0.1 * scale`` of the range's width around ``base``'s value, clipped into the range.
        The two ends of a population range, both free, are kept in order.

    Returns
    -------
    PerceptualModel
    """
    lo = np.array([r.lo for r in ranges])
    hi = np.array([r.hi for r in ranges])
    if scale is None:
        values = rng.uniform(lo, hi)
    else:
        values = np.clip(np.array(read_parameters(base, ranges)) + rng.normal(0.0, 0.1 * scale, lo.size) * (hi - lo),
                         lo, hi)
    return apply_parameters(base, ranges, ordered_pairs(ranges, values))
