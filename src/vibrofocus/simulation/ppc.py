"""Posterior-predictive check of the hypotheses against the paper's own numbers (a MODEL, not data).

Each registered hypothesis, with its fitted parameters, simulates many studies of the
paper's design (20 participants, 9 locations x 3 methods x 3 repetitions, stimuli at the
paper's levels). For each of the paper's 7 test statistics (de Vlam et al., IEEE ToH
16(4), 2023, Sec. III.B-C: Study 1 location F, its Greenhouse-Geisser epsilon, method F,
interaction F; Study 2 location chi2(8), method chi2(2), and the reduction of selected
points with the inverse filter) the check gives the model's median and 90 % interval
over the studies, and whether the paper's value lies inside. Beside them: the share of
studies in which the Study 1 and Study 2 directions (inverse filter vs funneling,
Bonferroni tests) are significant as in the paper, significant in reverse, or neither;
and the Study 1 answers per target location beside the paper's Fig. 6.

The rule that picks the default hypothesis (written down before any result of this
check was looked at):

1. The default is the hypothesis with the most of the paper's 7 statistics inside its
   90 % posterior-predictive interval (:data:`LEVEL`, over :data:`PPC_SEEDS`).
2. Ties are broken by the paper's Study 1 direction: the larger share of studies in which
   the inverse filter's error is significantly lower than funneling's (Bonferroni paired
   t-test); then the smaller share of studies with the reverse significant; then the
   name, so the choice is deterministic.
3. A hypothesis *reproduces the paper* when at least :data:`MIN_INSIDE` of the 7
   statistics lie inside its interval and the paper's Study 1 direction is significant
   in most (more than half) of its studies. Where the default does not, every output
   says: :data:`NONE_REPRODUCES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["LEVEL", "MIN_INSIDE", "NONE_REPRODUCES", "reproduces", "choose_default"]

#: Central interval of the check.
LEVEL = 0.9
#: Statistics (of 7) inside the interval for a hypothesis to reproduce the paper's sizes.
MIN_INSIDE = 5
#: What every output says when no hypothesis reproduces the paper (rule 3).
NONE_REPRODUCES = "no registered hypothesis reproduces both the paper's effect sizes and its Study 1 direction"


def reproduces(check: Mapping[str, Any]) -> bool:
    """Whether one hypothesis' check reproduces the paper (rule 3 of the module).

    Parameters
    ----------
    check : mapping
        ``{"inside": int, "study1": {"paper": share, "reverse": share, "neither": share}, ...}``.
    """
    return int(check["inside"]) >= MIN_INSIDE and float(check["study1"]["paper"]) > 0.5


def choose_default(checks: Mapping[str, Mapping[str, Any]]) -> str:
    """The default hypothesis by the rule of the module (rules 1 and 2).

    Parameters
    ----------
    checks : mapping
        ``{name: check}`` with ``check`` as in :func:`reproduces`.

    Returns
    -------
    str
        The name chosen.
    """
    return min(checks, key=lambda n: (-int(checks[n]["inside"]), -float(checks[n]["study1"]["paper"]),
                                      float(checks[n]["study1"]["reverse"]), n))
