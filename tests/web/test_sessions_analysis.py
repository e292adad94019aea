"""Run analysis on a database where a participant has an aborted session, a new one and
a dry run: the analysis runs, leaves out the aborted session and the dry run, and lists
them as excluded in the report."""

from __future__ import annotations

import csv
import io
import json
import time

import httpx
import pytest

from vibrofocus.studies.export import (ONSET_COLUMNS, POINT_COLUMNS, PROTOCOL_COLUMNS, SESSION_COLUMNS,
                                       STIMULUS_COLUMNS, TRIALS_COLUMNS)

from .conftest import calibrate
from .test_api import wait_state

pytestmark = pytest.mark.slow


def answer_trials(server, session: dict, n: int, rng_seed: int) -> None:
    import numpy as np

    rng = np.random.default_rng(rng_seed)
    sid = session["session_id"]
    key = session["participant_url"].split("key=")[1]
    for _ in range(n):
        st = wait_state(server, sid, key, "respond", timeout=60)
        r = httpx.post(f"{server.base_url}/api/participant/{sid}/answer", headers={"X-Participant-Key": key}, json={
            "session_id": sid, "trial_index": st["trial_index"], "response": [int(rng.integers(1, 10))],
            "rt_s": float(rng.uniform(0.3, 1.5)), "answer_id": f"s{sid}-t{st['trial_index']}-answer"})
        assert r.status_code == 200, r.text


def plan(server, participant: str, **fields) -> dict:
    r = server.api("POST", "/api/sessions", json={"participant_id": participant, "study": 1, "seed": 11, **fields})
    assert r.status_code == 201, r.text
    s = r.json()
    assert server.api("POST", f"/api/sessions/{s['session_id']}/start").status_code == 200
    return s


def test_analysis_with_an_aborted_session_a_new_one_and_a_dry_run(server):
    assert server.api("POST", "/api/participants", json={"participant_id": "P50"}).status_code == 201
    cal = calibrate(server, "P50", seed=5)
    aborted = plan(server, "P50", calibration_id=cal, repetitions=1, n_training=0)
    answer_trials(server, aborted, 2, rng_seed=1)
    assert server.api("POST", f"/api/sessions/{aborted['session_id']}/stop").status_code == 200
    fresh = plan(server, "P50", calibration_id=cal, repetitions=1, n_training=0)
    answer_trials(server, fresh, 27, rng_seed=2)
    dry = plan(server, "P50", repetitions=1, n_training=0)
    answer_trials(server, dry, 1, rng_seed=3)
    assert server.api("GET", "/api/sessions").json()[-1]["dry_run"] is True

    text = server.api("GET", "/api/export/trials.csv").text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert tuple(rows[0]) == (TRIALS_COLUMNS + SESSION_COLUMNS + ONSET_COLUMNS + STIMULUS_COLUMNS + PROTOCOL_COLUMNS
                              + POINT_COLUMNS + ("xrun_represented", "level_db", "allowed"))  # docs/file-formats.md
    assert {r["onset_clock"] for r in rows if r["dry_run"] == "1"} == {""}  # nothing played, no device time
    by_session = {(int(r["session"]), r["session_status"], r["dry_run"]) for r in rows}
    assert by_session == {(aborted["session_id"], "aborted", "0"), (fresh["session_id"], "completed", "0"),
                          (dry["session_id"], "running", "1")}

    # P50's sessions ran on the simulated rig: a rehearsal, analysed only when asked for.
    job = server.api("POST", "/api/analysis", json={"kind": "rehearsals"}).json()
    deadline = time.monotonic() + 300
    while job["status"] == "running" and time.monotonic() < deadline:
        time.sleep(1)
        job = server.api("GET", f"/api/analysis/{job['name']}").json()
    assert job["status"] == "done", job["log"]
    assert job["log"].splitlines()[0].endswith("(rehearsals on the simulated rig)")
    report = json.loads(server.api("GET", f"/reports/{job['name']}/report.json").text)
    reasons = " | ".join(e["reason"] for e in report["exclusions"])
    assert f"session {aborted['session_id']} left out because it was aborted" in reasons
    assert f"session {dry['session_id']} left out because it was a dry run" in reasons
    html = server.api("GET", f"/reports/{job['name']}/report.html").text
    assert f"session {aborted['session_id']} left out" in html
    # Issue 38: the served report names its source by name, never by the account's folders.
    root = str(server.db.parent)
    assert root not in html and "Source: trials.csv" in html
    assert root not in json.dumps(report) and report["source"] == "trials.csv"
