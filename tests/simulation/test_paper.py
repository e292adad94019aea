"""The default hypothesis beside the paper (de Vlam et al. 2023, Sec. III.B-C).

Each finding is checked in simulated 20-participant studies on seeds that neither the fit
(1000-1015) nor the posterior-predictive check (3000-3199) used; the criteria are written
out here, independently of ``vibrofocus.simulation.paper``. The findings the default
reproduces in fewer than two thirds of the seeds are listed in
docs/simulated-participants.md ("What no hypothesis reproduces"), and a test checks that
the list is exactly those.
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
# (finding, criterion on one study, the phrase that names it in the docs' "What no
# hypothesis reproduces"). The docs name exactly those the default reproduces in fewer than
# two thirds of these seeds.
FINDINGS = [
    ("Study 1 location significant (GG)", lambda s: s["s1_location_p"] < 0.05, "study 1 location effect"),
    ("Study 1 location: sphericity violated", lambda s: s["s1_location_p_mauchly"] < 0.05, "sphericity"),
    ("Study 1 method significant", lambda s: s["s1_method_p"] < 0.05, "study 1 method effect significant"),
    ("inverse lower error than funneling (Study 1)",
     lambda s: s["s1_method_pairs"]["funneling vs inverse"] < 0.05
     and s["s1_error_by_method"][1] < s["s1_error_by_method"][0], "inverse filter's error below funneling's"),
    ("locations 4, 5, 7, 8 below the others",
     lambda s: s["s1_error_by_location"][[3, 4, 6, 7]].mean() < s["s1_error_by_location"][[0, 1, 2, 5, 8]].mean(),
     "locations 4, 5, 7 and 8 below the others"),
    ("best locations exactly 4, 5, 7, 8",
     lambda s: set(np.argsort(s["s1_error_by_location"])[:4]) == {3, 4, 6, 7}, "exactly 4, 5, 7 and 8 best"),
    ("location 1 among the five worst", lambda s: _rank(s, 1) >= 4, "location 1 among the five worst"),
    ("Study 2 location significant", lambda s: s["s2_location_p"] < 0.05, "study 2 location effect"),
    ("Study 2 method significant, inverse fewer points",
     lambda s: s["s2_method_p"] < 0.05 and s["s2_inverse_fewer"], "fewer points with the inverse filter"),
    ("Study 2 with the target: location not significant", lambda s: s["s2_hit_location_p"] >= 0.05,
     "target-containing study 2 location test"),
    ("only funneling vs inverse differ (Study 1 post hoc)", lambda s: s["s1_only_funneling_vs_inverse"],
     "only funneling and the inverse filter differ"),
    ("at 1, 3 and 9 the inverse differs from both others",
     lambda s: np.isin([0, 2, 8], s["s1_inverse_differs_locations"]).all(),
     "at locations 1, 3 and 9 the inverse filter differs from both other methods"),
    ("Study 2 with the target: method not significant", lambda s: s["s2_hit_method_p"] >= 0.05,
     "target-containing study 2 method test"),
]


@pytest.mark.parametrize(("row", "criterion", "phrase"), FINDINGS, ids=[r[0] for r in FINDINGS])
def test_the_docs_name_exactly_the_findings_the_default_misses(stats, row, criterion, phrase):
    # If the default comes to reproduce a finding the docs list as missed, or stops
    # reproducing one they do not list, this fails and the docs must change.
    share = _share(stats, criterion)
    listed = phrase in _shortfalls()
    assert listed == (share < AIM), (f"{row}: reproduced in {share:.0%} of {len(stats)} seeds, "
                                     f"{'listed' if listed else 'not listed'} as missed in the docs")


def _shortfalls() -> str:
    text = (ROOT / "docs" / "simulated-participants.md").read_text(encoding="utf-8").lower()
    return " ".join(text.split("## what no hypothesis reproduces", 1)[1].split("\n## ", 1)[0].split())


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


def test_comparison_rows_match_the_criteria(stats):
    # The documented table's shares come from vibrofocus.simulation.paper; they agree with the
    # criteria written out above on the same studies.
    rows = {r["label"]: r for r in compare(stats)}
    criteria = {row: criterion for row, criterion, *_ in FINDINGS}
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
