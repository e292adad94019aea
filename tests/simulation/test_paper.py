"""The fitted model v3 beside the paper (de Vlam et al. 2023, Sec. III.B-C).

Each finding is checked in simulated 20-participant studies on seeds that neither the fit
(1000-1063) nor the documented table (0-19) used; the criteria are written out here,
independently of ``vibrofocus.simulation.paper``. The issue's aim is every finding in at
least 2/3 of the seeds; the findings the model does not reach are listed in
docs/simulated-participants.md ("What the model does not reproduce"), and a test checks
that the list is still true.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vibrofocus.simulation.bank import default_bank, simulate_cell_means
from vibrofocus.simulation.paper import compare, comparison_markdown, seed_statistics
from vibrofocus.simulation.perception import MODEL_LABEL, PARAMETER_SOURCES, PerceptualModel
from vibrofocus.simulation.power import study_statistics

ROOT = Path(__file__).resolve().parents[2]
# 80 studies (a few seconds): a share near the two-thirds bar needs them (binomial SE about
# 5 points; on 40 the target-containing method test crossed the bar by one study).
SEEDS = range(300, 380)


@pytest.fixture(scope="module")
def stats():
    bank = default_bank()
    return [study_statistics(simulate_cell_means(20, np.random.default_rng([s, 77]), bank=bank), methods=bank.methods)
            for s in SEEDS]


def _share(stats, predicate) -> float:
    return float(np.mean([bool(predicate(s)) for s in stats]))


def _rank(s, location: int) -> int:
    """0 = the lowest mean error."""
    return int(np.argsort(np.argsort(s["s1_error_by_location"]))[location - 1])


AIM = 2 / 3
# (finding, criterion on one study). Each must hold in at least 2/3 of the 40 seeds.
REPRODUCED = [
    ("Study 1 location significant (GG)", lambda s: s["s1_location_p"] < 0.05),
    ("Study 1 location: sphericity violated", lambda s: s["s1_location_p_mauchly"] < 0.05),
    ("Study 1 method significant", lambda s: s["s1_method_p"] < 0.05),
    ("inverse lower error than funneling (Study 1)",
     lambda s: s["s1_method_pairs"]["funneling vs inverse"] < 0.05
     and s["s1_error_by_method"][1] < s["s1_error_by_method"][0]),
    ("locations 4, 5, 7, 8 below the others",
     lambda s: s["s1_error_by_location"][[3, 4, 6, 7]].mean() < s["s1_error_by_location"][[0, 1, 2, 5, 8]].mean()),
    ("best locations exactly 4, 5, 7, 8",
     lambda s: set(np.argsort(s["s1_error_by_location"])[:4]) == {3, 4, 6, 7}),
    ("location 1 among the five worst", lambda s: _rank(s, 1) >= 4),
    ("Study 2 location significant", lambda s: s["s2_location_p"] < 0.05),
    ("Study 2 method significant, inverse fewer points",
     lambda s: s["s2_method_p"] < 0.05 and s["s2_inverse_fewer"]),
    # Not significant, but on a median of 4-5 participants kept (docs: "What the model
    # does not reproduce" says so).
    ("Study 2 with the target: location not significant", lambda s: s["s2_hit_location_p"] >= 0.05),
]
# Findings the docs say the default hypothesis does not reproduce in two thirds of the
# seeds (docs/simulated-participants.md, "What the model does not reproduce"):
# (finding, criterion, the phrase that names it there).
NOT_REPRODUCED = [
    ("only funneling vs inverse differ (Study 1 post hoc)", lambda s: s["s1_only_funneling_vs_inverse"],
     "only funneling and the inverse filter differ"),
    ("at 1, 3 and 9 the inverse differs from both others",
     lambda s: np.isin([0, 2, 8], s["s1_inverse_differs_locations"]).all(),
     "at locations 1, 3 and 9 the inverse filter differs from both other methods"),
    ("Study 2 with the target: method not significant", lambda s: s["s2_hit_method_p"] >= 0.05,
     "the target-containing study 2 method test"),
]


@pytest.mark.parametrize(("row", "criterion"), REPRODUCED, ids=[r[0] for r in REPRODUCED])
def test_fitted_model_reproduces_each_finding_in_two_thirds_of_the_seeds(stats, row, criterion):
    share = _share(stats, criterion)
    assert share >= AIM, f"{row}: reproduced in {share:.0%} of {len(stats)} seeds (needs {AIM:.0%})"


@pytest.mark.parametrize(("row", "criterion", "phrase"), NOT_REPRODUCED, ids=[r[0] for r in NOT_REPRODUCED])
def test_the_documented_shortfalls_are_still_true(stats, row, criterion, phrase):
    # The docs name each finding the model misses; if the model comes to reproduce one,
    # this fails and the docs (and REPRODUCED) must change.
    share = _share(stats, criterion)
    assert share < AIM, f"{row}: now reproduced in {share:.0%} of the seeds; update the docs"
    assert phrase in _shortfalls(), f"the docs no longer say: {phrase!r}"


def _shortfalls() -> str:
    text = (ROOT / "docs" / "simulated-participants.md").read_text(encoding="utf-8").lower()
    return " ".join(text.split("what the model does not reproduce", 1)[1].split("<!--", 1)[0].split())


def test_selected_points_fall_by_ten_to_thirty_percent(stats):
    # The paper's headline (abstract): about 20 % fewer points with the inverse filter.
    reduction = np.median([s["s2_reduction"] for s in stats])
    assert 0.10 <= reduction <= 0.30, reduction


def test_target_containing_tests_keep_the_participants_with_a_hit_at_every_level():
    # Marginal means: a participant is dropped only where a whole level (a location over
    # its three methods, or a method over its nine locations) never held the target, not
    # for one empty cell as a complete-cell analysis would.
    bank = default_bank()
    for seed in SEEDS[:10]:
        a = simulate_cell_means(20, np.random.default_rng([seed, 77]), bank=bank)
        hit = np.isfinite(a.count_hit)  # (n, 9, 3)
        complete = int(hit.all(axis=(1, 2)).sum())
        by_location, by_method = int(hit.any(axis=2).all(axis=1).sum()), int(hit.any(axis=1).all(axis=1).sum())
        st = study_statistics(a, methods=bank.methods)
        assert st["s2_hit_n"] == min(by_location, by_method) >= complete


def test_fitted_statistics_are_near_the_papers(stats):
    # The fit matches medians. Out of sample (these seeds), under the default hypothesis,
    # the location F, the interaction F and the Study 2 chi2 of location and of method are
    # each within a factor 3 of the paper's value (Sec. III.B-C).
    paper = {"s1_location_F": 10.958, "s1_interaction_F": 3.919, "s2_location_chi2": 30.749, "s2_method_chi2": 15.797}
    for k, v in paper.items():
        med = float(np.median([s[k] for s in stats]))
        assert 1 / 3 < med / v < 3, (k, med, v)


def test_the_documented_size_of_the_method_effect_is_the_models(stats):
    # The method F is farther: the docs list it among the shortfalls with its ratio to the
    # paper's (F = 6.090), "about X-Y times"; the median of these seeds lies in that range.
    import re

    ratio = float(np.median([s["s1_method_F"] for s in stats])) / 6.090
    said = re.search(r"the size of the study 1 method effect\.\* its f is about ([0-9.]+)[–-]([0-9.]+) times",
                     _shortfalls())
    assert said is not None, "the docs no longer give the method F's ratio to the paper's"
    lo, hi = float(said.group(1)), float(said.group(2))
    assert ratio > 1 and lo <= round(ratio, 1) <= hi, (ratio, lo, hi)


def test_comparison_rows_match_the_criteria(stats):
    # The documented table's shares come from vibrofocus.simulation.paper; they agree with the
    # criteria written out above on the same studies.
    rows = {r["label"]: r for r in compare(stats)}
    criteria = {row: criterion for row, criterion, *_ in REPRODUCED + NOT_REPRODUCED}
    assert rows["Study 1 location, F"]["share"] == _share(stats, criteria["Study 1 location significant (GG)"])
    assert rows["Study 1 method, F"]["share"] == _share(stats, criteria["Study 1 method significant"])
    assert rows["best locations"]["share"] == _share(stats, criteria["locations 4, 5, 7, 8 below the others"])
    assert rows["Study 2, trials containing the target: method, chi2(2)"]["share"] == _share(
        stats, criteria["Study 2 with the target: method not significant"])
    assert rows["Study 1 method, inverse vs funneling"]["share"] == _share(
        stats, criteria["inverse lower error than funneling (Study 1)"])
    f = np.array([s["s1_location_F"] for s in stats])
    r = rows["Study 1 location, F"]
    assert r["median"] == pytest.approx(np.median(f)) and r["low"] == pytest.approx(np.percentile(f, 5))
    md = comparison_markdown(list(rows.values()), SEEDS)
    assert MODEL_LABEL in md and md.count("\n|") == len(rows) + 2 and f"seeds {SEEDS.start}-{SEEDS.stop - 1}" in md
    short = comparison_markdown(list(rows.values()), SEEDS, short=True)
    assert MODEL_LABEL in short and short.count("\n|") < md.count("\n|")


def test_seed_statistics_are_seeded():
    a = seed_statistics(seeds=[3])[0]
    b = seed_statistics(seeds=[3])[0]
    c = seed_statistics(seeds=[4])[0]
    assert a["s1_location_F"] == b["s1_location_F"] != c["s1_location_F"]


def test_every_parameter_says_where_it_comes_from():
    fields = set(PerceptualModel().to_dict()) - {"version"}
    assert set(PARAMETER_SOURCES) == fields
    assert {kind for kind, _ in PARAMETER_SOURCES.values()} <= {"assumption", "fitted", "source + fitted"}


def test_documented_tables_are_those_of_the_code(capsys):
    # What `scripts/fit_participants.py table --check` runs, in this process.
    from vibrofocus_tools.participants_docs import table

    code = table(20, check=True)
    out = capsys.readouterr().out
    assert code == 0, out[-2000:]
    assert "up to date" in out
