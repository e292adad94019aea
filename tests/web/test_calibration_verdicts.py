"""A web calibration's quality verdicts: shown, and required to be accepted before use (issue 38, item 4)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
from fastapi.testclient import TestClient

from vibrofocus.web.app import create_app

TOKEN = "t" * 32


def _dead_a2(kind, seed=None, **kwargs):
    """The simulated forearm with actuator A2 weak enough to read as dead."""
    from vibrofocus.rigs import SimulatedForearm
    from vibrofocus.skin import ForearmParameters

    lay = SimulatedForearm(seed=4).layout
    params = ForearmParameters.draw(4, lay)
    # 26 dB down: under the dead-actuator verdict (a tenth of the strongest) while the designs still
    # fit a window, so that using it with the override can be tested.
    weak = replace(params, gains=params.gains * np.array([1.0, 0.05, 1.0, 1.0]))
    return SimulatedForearm(seed=4, participant=weak)


@pytest.fixture
def client(tmp_path):
    app = create_app(tmp_path / "s.sqlite", token=TOKEN, rig_factory=_dead_a2, allowed_hosts=("testserver",),
                     resume=False, pace="fast")
    with TestClient(app, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}) as c:
        yield c, tmp_path


def _calibrated(c) -> dict:
    assert c.post("/api/participants", json={"participant_id": "P01"}).status_code == 201
    job = c.post("/api/calibrations", json={"participant_id": "P01"}).json()
    deadline = time.monotonic() + 300
    while (j := c.get(f"/api/calibrations/jobs/{job['job_id']}").json())["status"] == "running":
        assert time.monotonic() < deadline, j
        time.sleep(0.2)
    assert j["status"] == "done", j
    return j


def test_a_calibration_with_a_dead_actuator_is_shown_and_used_only_with_the_override(client):
    c, tmp_path = client
    job = _calibrated(c)
    cid = job["calibration_id"]
    assert job["n_errors"] >= 1 and any("A2 looks dead" in v["message"] for v in job["verdicts"]), job["verdicts"]
    assert job["verdicts"][0]["severity"] == "error", "errors come first"
    q = c.get(f"/api/calibrations/{cid}/quality").json()
    assert q["n_errors"] == job["n_errors"] and any(v["check"] == "dead_actuator" for v in q["verdicts"])

    plan = {"participant_id": "P01", "study": 1, "calibration_id": cid, "n_training": 0, "repetitions": 1}
    r = c.post("/api/sessions", json=plan)
    assert r.status_code == 409 and "A2 looks dead" in r.json()["detail"], r.text
    assert c.get("/api/sessions").json() == [], "a refused plan writes nothing"

    r = c.post("/api/sessions", json={**plan, "allow_calibration_errors": True})
    assert r.status_code == 201, r.text
    s = r.json()
    assert any("A2 looks dead" in m for m in s["config"]["calibration_errors_accepted"])
    assert c.post(f"/api/sessions/{s['session_id']}/start").status_code == 200

    # A file saved by the web is netCDF, named like the CLI's (.nc).
    files = list((tmp_path / "s-files" / "calibrations").iterdir())
    assert [f.suffix for f in files] == [".nc"]
