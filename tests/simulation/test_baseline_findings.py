"""scripts/baseline_findings.py and the baseline it wrote (issue 42's c313a27 participants)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibrofocus_tools import baseline, findings

ROOT = Path(__file__).resolve().parents[2]


def test_refuses_a_checkout_of_another_commit(tmp_path):
    out = tmp_path / "baseline.json"
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "baseline_findings.py"), "--checkout", str(ROOT),
                          "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert "not a checkout of c313a27" in res.stderr
    assert not out.exists()


def test_the_stored_baseline_covers_every_finding_on_whole_seed_ranges():
    data = json.loads(baseline.BASELINE.read_text(encoding="utf-8"))
    assert data["commit"].startswith("c313a27")
    assert {"700-739", "800-999"} <= set(data["seeds"])
    for span, block in data["seeds"].items():
        first, last = map(int, span.split("-"))
        assert block["studies"] == last - first + 1
        assert {key for _, key in findings.ROWS} | set(baseline.HEADLINE_KEYS) <= set(block["holds"])
        assert all(0 <= k <= block["studies"] for k in block["holds"].values())
        # The headline row (a 10-30 % reduction as well) can only hold where the method row holds.
        assert block["holds"]["s2_headline"] <= block["holds"]["s2_method"]
        red = block["s2_reduction"]
        assert red["p5"] <= red["median"] <= red["p95"]


def test_paired_difference_p_is_the_exact_mcnemar_test():
    gained = np.ones(10, bool)
    assert baseline.paired_difference_p(gained, ~gained) == pytest.approx(2 * 0.5**10, rel=1e-12)
    assert baseline.paired_difference_p(gained, gained) == 1.0
    # Concordant pairs do not count: 3 gained, 1 lost -> two-sided binomial p of 1 in 4 = 0.625.
    model = np.array([1, 1, 1, 0, 1, 0, 1, 1], bool)
    base = np.array([0, 0, 0, 1, 1, 0, 1, 1], bool)
    assert baseline.paired_difference_p(model, base) == pytest.approx(0.625, rel=1e-12)


def test_baseline_outcomes_follow_the_seeds_and_refuse_unmeasured_ones():
    out = baseline.baseline_outcomes(range(700, 740))
    counts = baseline.baseline()["700-739"]["holds"]
    assert all(int(out[key].sum()) == counts[key] for key in counts)
    np.testing.assert_array_equal(baseline.baseline_outcomes(range(738, 740))["s1_interaction"], out["s1_interaction"][-2:])
    with pytest.raises(ValueError, match="not on seed 740"):
        baseline.baseline_outcomes(range(735, 745))


def test_check_findings_prints_the_baseline_beside_the_model():
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_findings.py"), "--seeds", "700", "703",
                          "--against-baseline"], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    rows = [line.split("|")[1:-1] for line in res.stdout.splitlines() if line.startswith("| ")]
    assert rows[0] == [" finding ", " holds in ", " baseline (c313a27) ", " paired McNemar p "]
    assert all(len(r) == 4 for r in rows)
    ps = [float(r[3]) for r in rows[1:] if r[3].strip()]
    assert len(ps) == 16 and all(0.0 <= p <= 1.0 for p in ps)  # every row of check_findings.ROWS
    bad = subprocess.run([sys.executable, str(ROOT / "scripts" / "check_findings.py"), "--seeds", "600", "603",
                          "--against-baseline"], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "not on seed 600" in bad.stderr
