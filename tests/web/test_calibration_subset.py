"""The web calibration flow offers the subset plans (measure some points, predict the
rest) and says which points of a calibration were predicted."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from vibrofocus.web.app import create_app

TOKEN = "t" * 32


@pytest.fixture
def client(tmp_path):
    app = create_app(tmp_path / "s.sqlite", token=TOKEN, allowed_hosts=("testserver",), resume=False, pace="fast")
    with TestClient(app, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}) as c:
        assert c.post("/api/participants", json={"participant_id": "P01"}).status_code == 201
        yield c


def test_the_plans_offered_are_every_point_then_9_7_5(client):
    r = client.get("/api/calibrations/plans", params={"rig": "simulated", "seed": 4})
    assert r.status_code == 200, r.text
    plans = r.json()["plans"]
    assert [p["points"] for p in plans] == [None, 9, 7, 5]
    assert plans[0]["label"] == "all 13 points" and plans[0]["predicted"] == []
    five = plans[-1]
    assert five["measured"] == ["5", "G1", "G2", "G3", "G4"]
    assert five["predicted"] == ["1", "2", "3", "4", "6", "7", "8", "9"]
    assert "measures 5 of 13 points and predicts the other 8" in five["description"]
    # The simulated rig records every point at once: no aim to save.
    assert five["aims_saved"] == 0 and five["seconds_saved"] == 0


@pytest.mark.parametrize("points, status", [(14, 422), (1, 422), ("five", 422)])
def test_a_subset_the_layout_cannot_give_is_refused_before_the_job(client, points, status):
    r = client.post("/api/calibrations", json={"participant_id": "P01", "points": points})
    assert r.status_code == status, r.text
    assert "points" in r.text
    assert client.app.state.web.jobs == {}, "a refused plan starts no job"


@pytest.mark.slow
def test_a_subset_calibration_says_which_points_were_predicted(client):
    job = client.post("/api/calibrations", json={"participant_id": "P01", "points": 5, "seed": 4}).json()
    deadline = time.monotonic() + 300
    while (j := client.get(f"/api/calibrations/jobs/{job['job_id']}").json())["status"] == "running":
        assert time.monotonic() < deadline, j
        time.sleep(0.2)
    assert j["status"] == "done" and j["n_errors"] == 0, j
    assert sum(v["check"] == "predicted" for v in j["verdicts"]) == 8
    q = client.get(f"/api/calibrations/{j['calibration_id']}/quality").json()
    assert q["measured"] == ["5", "G1", "G2", "G3", "G4"]
    assert q["predicted"] == ["1", "2", "3", "4", "6", "7", "8", "9"]
