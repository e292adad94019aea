"""Issue 42's baseline: the paper's findings under the participants of commit c313a27 (a MODEL, not data).

Measured by ``scripts/baseline_findings.py`` on the same seeds as the checks, and kept in
``scripts/fits/baseline-c313a27.json``; here read, seed by seed, and compared with a paired
test.
"""

from __future__ import annotations

import functools
import json

import numpy as np
from scipy import stats

from .markers import ROOT

#: The baseline: the findings under commit c313a27's participants (model v3, every method at
#: equal peak drive) on the same seeds, measured by scripts/baseline_findings.py.
BASELINE = ROOT / "scripts" / "fits" / "baseline-c313a27.json"
#: The issue's headline findings (the Study 1 direction, the Study 2 headline) must hold in
#: at least two thirds of the studies; every other finding at least as often as under the baseline.
HEADLINE_KEYS, HEADLINE_BAR = ("s1_inverse_lower", "s2_headline"), 2 / 3


@functools.cache
def baseline() -> dict[str, dict]:
    """The baseline's counts by seed range (``"700-739"``: ``studies``, ``holds``, ``s2_reduction``).

    Read once per process; callers must not modify it.
    """
    return json.loads(BASELINE.read_text(encoding="utf-8"))["seeds"]


def baseline_outcomes(seeds: range) -> dict[str, np.ndarray]:
    """The baseline's outcome of each finding in each study of ``seeds``, shape (len(seeds),) per key.

    Raises ValueError if a seed lies outside the ranges the baseline was measured on.
    """
    parts: dict[int, dict[str, bool]] = {}
    for span, block in baseline().items():
        first = int(span.split("-")[0])
        for key, bits in block["per_seed"].items():
            for i, bit in enumerate(bits):
                parts.setdefault(first + i, {})[key] = bit == "1"
    missing = [s for s in seeds if s not in parts]
    if missing:
        raise ValueError(f"the baseline was measured on seeds {', '.join(baseline())}, not on seed {missing[0]} "
                         "(scripts/baseline_findings.py)")
    return {key: np.array([parts[s][key] for s in seeds]) for key in parts[seeds[0]]}


def paired_difference_p(model: np.ndarray, base: np.ndarray) -> float:
    """Exact two-sided McNemar p of two paired 0/1 outcomes (the same seeds): 1.0 if none differ."""
    gained, lost = int(np.sum(model & ~base)), int(np.sum(~model & base))
    return 1.0 if gained + lost == 0 else float(stats.binomtest(gained, gained + lost, 0.5).pvalue)
