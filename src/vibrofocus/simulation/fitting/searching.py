"""The search: a seeded random search, then a local refinement, judged on the fit seeds.

Every candidate is judged on the same simulated 20-participant studies (:data:`~.seeds.FIT_SEEDS`,
fast path: feature bank + vectorized statistics; common random numbers make candidates
comparable). Every hypothesis is fitted with the same budget, weights and seeds, along
the same random paths (the ``rng_seed`` of each stage).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..._atomic import write_text
from ..bank import FeatureBank, default_bank
from ..hypotheses import hypothesis
from ..paper import N_PARTICIPANTS, seed_statistics
from ..perception import PerceptualModel
from .candidates import CENTRAL_WEIGHT_RANGE, sample, sample_within
from .fitfile import fit_model, read_fit
from .objective import loss
from .seeds import FIT_SEEDS

__all__ = ["search"]


def search(n_eval: int, n_refine: int, out: str | os.PathLike, start: str | os.PathLike | None, rng_seed: int,
           weights: Mapping[str, float], central_range: tuple[float, float] = CENTRAL_WEIGHT_RANGE,
           bank: FeatureBank | None = None, integration_s: float | None = None,
           name: str | None = None, unfused: bool = False, aware: bool = False,
           report: Callable[[str], Any] | None = None, fit_seeds: range = FIT_SEEDS,
           n_participants: int = N_PARTICIPANTS) -> PerceptualModel:
    """Fit one hypothesis: ``n_eval`` random candidates, then ``n_refine`` refinements; write the fit.

    Parameters
    ----------
    n_eval : int
        Random candidates (drawn from broad ranges).
    n_refine : int
        Refinement candidates (jittered around the best, the jitter shrinking to 20 %).
    out : path-like
        Where to write the fit file (JSON, atomically).
    start : path-like or None
        A fit file to start from (checked first); None starts from ``PerceptualModel()``'s
        defaults (every hypothesis starts from the same place).
    rng_seed : int
        Seed of this stage's random path.
    weights : mapping
        The objective's weights (:func:`~.objective.loss`).
    central_range : (float, float)
        Range searched for ``central_weight``.
    bank : FeatureBank, optional
        The feature bank (default the shipped one).
    integration_s : float, optional
        The integration window the bank was built with, s (never searched).
    name : str, optional
        The hypothesis (default the default one).
    unfused, aware : bool
        Search the unfused percepts / the conflict awareness too
        (:func:`~.candidates.sample`).
    report : callable, optional
        Called with a line of text at the start, at each improvement and at the end.
    fit_seeds : range
        The studies every candidate is judged on (default :data:`~.seeds.FIT_SEEDS`).
    n_participants : int
        Participants per study (default the paper's 20).

    Returns
    -------
    PerceptualModel
        The best candidate.
    """
    say = report or (lambda line: None)
    h = hypothesis(name)
    b = bank if bank is not None else default_bank()
    rng = np.random.default_rng(rng_seed)
    start_fit = read_fit(start) if start is not None else None
    # Every hypothesis starts from the same place (model v3's own fit, PerceptualModel()'s
    # defaults), not from its shipped fit: a refit repeats the shipped one.
    ranges = h.free_parameters
    # A hypothesis that declares its free parameters is searched inside their ranges only
    # (every other parameter stays at its start); the others along the broad ranges of
    # candidates.sample.
    fresh = h.start_model() if ranges else PerceptualModel()
    best = (fit_model(start_fit) if start_fit is not None else fresh).replace(integration_s=integration_s)
    fixed = best
    best_loss = loss(seed_statistics(best, fit_seeds, n_participants=n_participants, bank=b, hypothesis=h), weights)
    say(f"start: loss {best_loss:.4f}")
    t0 = time.perf_counter()
    for i in range(n_eval + n_refine):
        scale = 1.0 - 0.8 * (i - n_eval) / max(n_refine, 1)
        if ranges:
            cand = sample_within(rng, fixed if i < n_eval else best, ranges, None if i < n_eval else scale)
        else:
            cand = (sample(rng, central_range=central_range, unfused=unfused, aware=aware) if i < n_eval else
                    sample(rng, best, scale=scale, central_range=central_range, unfused=unfused, aware=aware))
        cand = cand.replace(integration_s=integration_s)  # the bank's window, never searched
        val = loss(seed_statistics(cand, fit_seeds, n_participants=n_participants, bank=b, hypothesis=h), weights)
        if val < best_loss:
            best, best_loss = cand, val
            say(f"{i}: loss {val:.4f} ({time.perf_counter() - t0:.0f} s) {json.dumps(cand.to_dict())}")
    write_text(out, json.dumps({"hypothesis": h.name, "levels": b.levels, "bank_forearms": b.n_forearms,
                                "budget": {"n_eval": n_eval, "n_refine": n_refine, "rng_seed": rng_seed,
                                           **({"unfused": True} if unfused else {}),
                                           **({"aware": True} if aware else {}),
                                           **({"within_ranges": True} if ranges else {}),
                                           "start": start_fit["budget"] if start_fit is not None else None},
                                "loss": best_loss, "weights": dict(weights),
                                "fit_seeds": [fit_seeds.start, fit_seeds.stop],
                                "model": best.to_dict()}, indent=1), what="fit")
    say(f"best loss {best_loss:.4f} after {n_eval + n_refine} candidates ({time.perf_counter() - t0:.0f} s) -> {out}")
    return best
