"""The posterior-predictive check of the hypotheses against the paper (simulation.ppc)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.simulation.bank import default_bank
from vibrofocus.simulation.hypotheses import DEFAULT_HYPOTHESIS, available_hypotheses, hypothesis, hypothesis_fits
from vibrofocus.simulation.paper import seed_statistics
from vibrofocus.simulation.ppc import (NONE_REPRODUCES, STATISTICS, choose_default, ppc_markdown, record_default,
                                       reproduces, run_ppc, study_checks, summarize)


def _check(inside: int, paper: float, reverse: float = 0.0) -> dict:
    return {"inside": inside, "study1": {"paper": paper, "reverse": reverse, "neither": 1.0 - paper - reverse}}


def test_the_default_has_the_most_statistics_inside_and_the_papers_direction_breaks_ties():
    checks = {"a": _check(4, 0.9), "b": _check(5, 0.0, 0.8), "c": _check(5, 0.3)}
    assert choose_default(checks) == "c"  # 5 inside; of those, the paper's direction more often
    assert choose_default({"a": _check(3, 0.5, 0.1), "b": _check(3, 0.5, 0.0)}) == "b"  # then less reverse
    assert choose_default({"b": _check(2, 0.0), "a": _check(2, 0.0)}) == "a"  # then the name
    assert reproduces(_check(5, 0.51)) and not reproduces(_check(5, 0.5)) and not reproduces(_check(4, 1.0))


def test_a_checked_study_is_the_study_of_seed_statistics_with_its_answers_counted():
    bank = default_bank()
    (row,) = study_checks("v3-centroid", [5], n_participants=4, bank=bank)
    (ref,) = seed_statistics(None, [5], n_participants=4, bank=bank, hypothesis="v3-centroid")
    for key, _, _ in STATISTICS:
        assert row[key] == ref[key] or (np.isnan(row[key]) and np.isnan(ref[key]))
    counts = np.array(row["answers"])
    # Study 1 only: 4 participants x 9 targets x 3 methods x 3 repetitions, 27 per target.
    assert counts.shape == (9, 9) and counts.sum() == 4 * 81 and set(counts.sum(axis=1)) == {4 * 9}


def test_the_summary_puts_the_paper_inside_its_interval_only_where_it_lies_there():
    locs = default_bank().locations_xy
    answers = np.eye(9, dtype=int).tolist()  # every answer on its target: every mean inside its cell
    base = {k: v for k, _, v in STATISTICS}
    studies = [{**{k: v * f for k, v in base.items()}, "s1_inverse_below_p": 0.01, "s1_inverse_above_p": 1.0,
                "s2_inverse_fewer_p": 1.0, "s2_inverse_more_p": 0.01, "answers": answers} for f in (0.5, 1.5)]
    studies[0]["s1_method_F"] = studies[1]["s1_method_F"] = 100.0  # the paper's 6.09 outside [100, 100]
    s = summarize(studies, locs)
    assert s["inside"] == 6 and not s["statistics"]["s1_method_F"]["inside"]
    assert s["study1"] == {"paper": 1.0, "reverse": 0.0, "neither": 0.0}
    assert s["study2"] == {"paper": 0.0, "reverse": 1.0, "neither": 0.0}
    assert s["answers"]["1"]["inside_share"] == 1.0 and s["answers"]["1"]["share"][0] == 1.0
    assert s["answers"]["4"]["paper_inside"] and not s["answers"]["1"]["paper_inside"]
    assert s["reproduces"]


def test_the_check_runs_every_hypothesis_and_says_whether_the_default_reproduces_the_paper(tmp_path):
    names = ["v3-centroid", "intensity"]
    result = run_ppc(names, range(3000, 3002), n_participants=6, local=True, chunk=1)
    assert set(result["hypotheses"]) == set(names) and result["default"] in names
    assert all(s["n_studies"] == 2 for s in result["hypotheses"].values())
    md = ppc_markdown(result)
    assert "`intensity`" in md and "inside, of 7" in md and "target 9" in md
    if not result["default_reproduces"]:
        assert result["statement"] == NONE_REPRODUCES and NONE_REPRODUCES in md
    # Recording it needs a check of every hypothesis of the file.
    fits = tmp_path / "fits.json"
    fits.write_text(json.dumps({"default": "x", "hypotheses": {n: {} for n in names}}), encoding="utf-8")
    doc = record_default(result, fits)
    assert json.loads(fits.read_text(encoding="utf-8")) == doc and doc["default"] == result["default"]
    fits.write_text(json.dumps({"default": "x", "hypotheses": {"grid-peak": {}}}), encoding="utf-8")
    with pytest.raises(ValidationError, match="grid-peak"):
        record_default(result, fits)


def test_the_shipped_default_is_the_checks_and_every_label_says_what_the_check_found():
    check = hypothesis_fits()["ppc"]
    assert set(check["hypotheses"]) == set(available_hypotheses())
    assert choose_default(check["hypotheses"]) == DEFAULT_HYPOTHESIS == hypothesis_fits()["default"]
    assert check["seeds"][1] - check["seeds"][0] >= 200
    for name in available_hypotheses():
        label = hypothesis(name).label()
        assert (NONE_REPRODUCES in label) == (not check["default_reproduces"]) and label.endswith("not data")


def test_the_documented_check_is_the_recorded_one():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "simulated-participants.md").read_text(encoding="utf-8")
    block = page.split("<!-- ppc-table:start -->\n", 1)[1].split("\n<!-- ppc-table:end -->", 1)[0]
    rows = [line.split(" | ") for line in block.splitlines() if line.startswith("| ")]
    names = [c.strip("` |") for c in rows[0][2:]]
    inside = next(r for r in rows if r[0] == "| **inside, of 7**")
    check = hypothesis_fits()["ppc"]
    assert set(names) == set(check["hypotheses"])
    assert {n: int(c.strip("* |")) for n, c in zip(names, inside[2:])} == {
        n: c["inside"] for n, c in check["hypotheses"].items()}
    assert f"**{DEFAULT_HYPOTHESIS}**; {check['statement']}." in block
