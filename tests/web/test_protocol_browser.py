"""Sessions from protocols end to end in a real chromium, on the simulated rig: a protocol
uploaded and picked on the experimenter page, its threshold block answered felt / not felt
(keys and buttons), the threshold on the experimenter page, the point block planned (in dB
SL from the threshold) and answered on the picture of the arm, a too-loud block refused;
then, for the same participant, a protocol that ``design-experiment`` wrote (a threshold
block, then designed point answers); and the exports of both."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys

import pytest

from tests.studies.test_bids_validator import validate

from .conftest import calibrate, login
from .test_participant_browser import wait_answers, wait_respond
from .tiny_protocol import FELT, THRESHOLD_DB, TINY_PROTOCOL

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: The designed protocol's point block: the inverse filter at -10 dB re the paper's levels.
DESIGNED_LEVEL_DB = -10.0


def _designed_protocol() -> str:
    """A protocol as ``design-experiment --threshold-trials 10`` writes it: a tiny design (one
    point block of the corners) after a 10-trial threshold block."""
    from vibrofocus.simulation.design import DesignSettings, design_experiment, design_protocol_text

    d = design_experiment(DesignSettings(n_forearms=1, n_traits=2, n_parameter_draws=1, n_replicates=1, budget=4,
                                         levels_db=(DESIGNED_LEVEL_DB,), methods=("inverse",), responses=("point",),
                                         locations=(1, 3, 7, 9)))
    return design_protocol_text(d, "designed-tiny", threshold_trials=len(FELT))


def test_protocol_sessions_end_to_end(server, chromium, tmp_path):
    assert server.api("POST", "/api/participants", json={"participant_id": "P01"}).status_code == 201
    cid = calibrate(server, "P01")
    context = chromium.new_context(viewport={"width": 1280, "height": 800})
    context.set_default_timeout(20_000)
    runs = {}
    try:
        exp = context.new_page()
        login(exp, server)
        exp.select_option("#participant", "P01")
        exp.wait_for_function(f"document.getElementById('calibration').value === '{cid}'")
        part = context.new_page()

        def plan_next() -> tuple[int, str]:
            n = exp.locator("#sessions tbody tr").count()
            exp.click("#new-session button")
            exp.wait_for_function(f"document.querySelectorAll('#sessions tbody tr').length === {n + 1}")
            row = exp.locator("#sessions tbody tr").first
            sid = int(row.get_attribute("data-session"))
            href = row.locator("a").get_attribute("href")
            exp.click(f"#sessions tr[data-session='{sid}'] button[data-action=start]")
            exp.locator(f"#sessions tr[data-session='{sid}'] td.status.running").wait_for()
            return sid, href

        for name, text, level, blocks in (("tiny-threshold", TINY_PROTOCOL, THRESHOLD_DB + 6.0, "3. too-loud"),
                                          ("designed-tiny", _designed_protocol(), DESIGNED_LEVEL_DB, "2. b1-")):
            file = tmp_path / f"{name}.toml"
            file.write_text(text, encoding="utf-8")
            exp.set_input_files("#protocol-file", str(file))
            exp.wait_for_function(f"document.getElementById('protocol').value === '{name}'")
            assert exp.is_disabled("#study") and blocks in exp.inner_text("#block")

            # Block 1: the threshold, half by keys, half by the buttons.
            sid, href = plan_next()
            part.goto(server.base_url + href)
            part.click("#begin")
            for i, felt in enumerate(FELT):
                wait_respond(part, i)
                if i % 2:
                    part.click(f".felt[data-felt='{felt}']")
                else:
                    part.keyboard.press("y" if felt else "n")
                wait_answers(server, sid, i + 1)
            exp.locator(f"#sessions tr[data-session='{sid}']").click()
            exp.wait_for_function("document.getElementById('live-staircase').textContent.startsWith('Threshold')")
            assert f"Threshold {THRESHOLD_DB:.1f} dB" in exp.inner_text("#live-staircase")
            assert server.rows("SELECT threshold_db FROM thresholds WHERE session_id = ?", sid) == [
                (pytest.approx(THRESHOLD_DB),)]

            # Block 2: point answers (tiny: at -9 + 6 dB SL), a click on each target's dot.
            sid2, href2 = plan_next()
            (cfg,) = server.rows("SELECT config FROM sessions WHERE session_id = ?", sid2)
            assert json.loads(cfg[0])["level_db"] == pytest.approx(level)
            part.goto(server.base_url + href2)
            part.click("#begin")
            targets = [t for (t,) in server.rows("SELECT target FROM planned_trials WHERE session_id = ? "
                                                 "ORDER BY trial_index", sid2)]
            for i, target in enumerate(targets):
                wait_respond(part, i)
                part.click(f"#arm g.location[data-loc='{target}'] circle", force=True)
                wait_answers(server, sid2, i + 1)
            assert [r for (r,) in server.rows("SELECT response FROM answers WHERE session_id = ? ORDER BY "
                                              "trial_index", sid2)] == [str(t) for t in targets]
            runs[name] = (sid, sid2, len(targets), level)

            # Block 3 (tiny): +15 dB re the paper's levels, over the drive limit: refused, nothing written.
            if name == "tiny-threshold":
                n_sessions = server.rows("SELECT COUNT(*) FROM sessions")
                exp.click("#new-session button")
                exp.wait_for_function("document.getElementById('flash').className === 'error'")
                assert "blocks[2].levels" in exp.inner_text("#flash") and "drive limit" in exp.inner_text("#flash")
                assert server.rows("SELECT COUNT(*) FROM sessions") == n_sessions
    finally:
        context.close()

    # The exports: the trials file (location trials: the point blocks), the BIDS dataset.
    trials = list(csv.DictReader(io.StringIO(server.api("GET", "/api/export/trials.csv").text)))
    assert sorted((t["protocol"], t["response_x_mm"] != "") for t in trials) == sorted(
        (name, True) for name, run in runs.items() for _ in range(run[2]))
    out = tmp_path / "bids"
    done = subprocess.run([sys.executable, "-m", "vibrofocus", "export", str(server.db), "--bids", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    for name, (sid, sid2, n, level) in runs.items():
        beh = out / "sub-P01" / f"ses-{sid}" / "beh"
        with open(beh / f"sub-P01_ses-{sid}_task-threshold_events.tsv", encoding="utf-8") as fh:
            detection = list(csv.DictReader(fh, delimiter="\t"))
        assert [int(r["response"]) for r in detection] == list(FELT)
        assert {(r["protocol"], r["block"], r["threshold_db"]) for r in detection} == {(name, "0", "-9.0")}
        beh2 = out / "sub-P01" / f"ses-{sid2}" / "beh"
        with open(beh2 / f"sub-P01_ses-{sid2}_task-localization1_events.tsv", encoding="utf-8") as fh:
            points = list(csv.DictReader(fh, delimiter="\t"))
        assert [(r["protocol"], r["block"], float(r["level_db"])) for r in points] == [(name, "1", level)] * n
    sidecar = json.loads((out / "sub-P01" / f"ses-{runs['tiny-threshold'][1]}" / "beh" /
                          f"sub-P01_ses-{runs['tiny-threshold'][1]}_task-localization1_events.json").read_text(
                              encoding="utf-8"))
    assert sidecar["Sessions"][0]["ThresholdDb"] == THRESHOLD_DB and sidecar["Sessions"][0]["LevelSlDb"] == 6.0
    status, issues = validate(out)
    assert status == 0 and not [i for i in issues if i[0] == "error"], issues
