"""scripts/baseline_findings.py and the baseline it wrote (issue 42's c313a27 participants)."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ENV = {"PYTHONPATH": f"{ROOT / 'src'}:{ROOT / 'scripts'}", "PATH": "/usr/bin:/bin"}


def test_refuses_a_checkout_of_another_commit(tmp_path):
    out = tmp_path / "baseline.json"
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "baseline_findings.py"), "--checkout", str(ROOT),
                          "--out", str(out)], capture_output=True, text=True, timeout=120, env=ENV)
    assert res.returncode == 2
    assert "not a checkout of c313a27" in res.stderr
    assert not out.exists()


def test_the_stored_baseline_covers_every_finding_on_whole_seed_ranges():
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from check_findings import BASELINE, HEADLINE_KEYS, ROWS
    finally:
        sys.path.pop(0)
    data = json.loads(BASELINE.read_text(encoding="utf-8"))
    assert data["commit"].startswith("c313a27")
    assert {"700-739", "800-999"} <= set(data["seeds"])
    for span, block in data["seeds"].items():
        first, last = map(int, span.split("-"))
        assert block["studies"] == last - first + 1
        assert {key for _, key in ROWS} | set(HEADLINE_KEYS) <= set(block["holds"])
        assert all(0 <= k <= block["studies"] for k in block["holds"].values())
        # The headline row (a 10-30 % reduction as well) can only hold where the method row holds.
        assert block["holds"]["s2_headline"] <= block["holds"]["s2_method"]
        red = block["s2_reduction"]
        assert red["p5"] <= red["median"] <= red["p95"]
