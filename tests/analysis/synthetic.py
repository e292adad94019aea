"""Synthetic trial files for the analysis tests (seeded, with or without planted effects).

The generator is a simple model, not data: a participant perceives a tap at the target
plus isotropic Gaussian noise whose SD depends on the method and on a per-participant
skill factor, and answers the nearest location (study 1). In study 2 they also select a
Poisson number of further locations, the nearest ones, with a method-dependent mean.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from vibrofocus import ArrayLayout

METHODS = ("funneling", "inverse", "combination")


def make_trials(
    n_participants: int = 12,
    *,
    seed: int = 0,
    sd_mm: dict[str, float] | None = None,
    extra_mean: dict[str, float] | None = None,
    repetitions: int = 3,
    n_training: int = 5,
    studies: tuple[int, ...] = (1, 2),
) -> pd.DataFrame:
    """Return a trials table with the columns of docs/file-formats.md, "Trials file" (all values as written to CSV)."""
    rng = np.random.default_rng(seed)
    sd_mm = sd_mm or dict.fromkeys(METHODS, 7.0)
    extra_mean = extra_mean or dict.fromkeys(METHODS, 1.0)
    methods = tuple(sd_mm)
    xy = ArrayLayout.reference().locations_xy * 1e3
    rows = []
    for p in range(n_participants):
        pid = f"P{p + 1:02d}"
        skill = rng.lognormal(0.0, 0.2)
        for study in studies:
            conditions = [(m, t) for m in methods for t in range(1, len(xy) + 1) for _ in range(repetitions)]
            order = rng.permutation(len(conditions))
            plan = [("training", conditions[i]) for i in rng.choice(len(conditions), n_training, replace=False)]
            plan += [("main", conditions[i]) for i in order]
            for trial, (phase, (method, target)) in enumerate(plan, start=1):
                felt = xy[target - 1] + rng.normal(0.0, sd_mm[method] * skill, size=2)
                nearest = np.argsort(np.hypot(*(xy - felt).T))
                if study == 1:
                    chosen = [nearest[0] + 1]
                else:
                    k = min(1 + rng.poisson(extra_mean[method] * skill), len(xy))
                    chosen = sorted(int(i) + 1 for i in nearest[:k])
                rows.append(
                    {
                        "participant": pid,
                        "study": study,
                        "phase": phase,
                        "trial": trial,
                        "method": method,
                        "target": target,
                        "response": " ".join(map(str, chosen)),
                        "rt_s": round(float(rng.lognormal(0.3, 0.3)), 3),
                    }
                )
    return pd.DataFrame(rows)
