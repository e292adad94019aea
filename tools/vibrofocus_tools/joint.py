"""Findings made of other findings (a MODEL's, not data).

Kept free of vibrofocus imports: ``scripts/baseline_findings.py`` applies them to the
findings of an older commit, and ``scripts/check_findings.py`` to today's.
"""

from __future__ import annotations

#: The paper's reduction of selected points with the inverse filter (abstract: about 20 %);
#: a reduction within this range counts as reproduced.
HEADLINE_REDUCTION = (0.10, 0.30)

#: Each study of the paper as a whole: all of its effects at once, as the paper reported
#: them (the post hoc patterns aside, which no model reproduces).
JOINT = {
    "s1_all": ("s1_location", "s1_method_significant", "s1_inverse_lower", "s1_interaction"),
    "s2_all": ("s2_location", "s2_method", "s2_hit_location_ns", "s2_hit_method_ns"),
}


def headline(method_holds: bool, reduction: float) -> bool:
    """The Study 2 headline: fewer points with the inverse filter, by a reduction in :data:`HEADLINE_REDUCTION`."""
    return bool(method_holds and HEADLINE_REDUCTION[0] <= reduction <= HEADLINE_REDUCTION[1])


def add_joint(findings: dict) -> dict:
    """``findings`` with every :data:`JOINT` finding added (each True only where all its parts hold)."""
    findings.update({key: all(bool(findings[p]) for p in parts) for key, parts in JOINT.items()})
    return findings
