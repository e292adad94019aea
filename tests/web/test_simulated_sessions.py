"""The page's "simulated" participant: the perceptual model answers, and nothing else is labelled model output (issue 38, item 3)."""

from __future__ import annotations

import csv
import io
import time

import pytest

from vibrofocus.defaults import participant_seed

from .test_api import answer, wait_state


def _wait_status(server, sid: int, status: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.rows("SELECT status FROM sessions WHERE session_id = ?", sid) == [(status,)]:
            return
        time.sleep(0.2)
    raise AssertionError(f"session {sid} never became {status}: {server.rows('SELECT status FROM sessions')}")


def _export(server) -> list[dict]:
    r = server.api("GET", "/api/export/trials.csv")
    assert r.status_code == 200, r.text
    return list(csv.DictReader(io.StringIO(r.text)))


def test_a_simulated_participant_is_answered_by_the_model_and_a_person_never_is(server):
    assert server.api("POST", "/api/participants", json={"participant_id": "sim-A", "simulated": True}).status_code == 201
    job = server.api("POST", "/api/calibrations", json={"participant_id": "sim-A"}).json()  # no seed: from the id
    deadline = time.monotonic() + 180
    while (j := server.api("GET", f"/api/calibrations/jobs/{job['job_id']}").json())["status"] == "running":
        assert time.monotonic() < deadline
        time.sleep(0.3)
    assert j["status"] == "done", j
    cal = j["calibration_id"]

    # A simulated participant's session without a calibration (a dry run) has nobody to answer it.
    r = server.api("POST", "/api/sessions", json={"participant_id": "sim-A", "study": 1})
    assert r.status_code == 409 and "simulated participant" in r.json()["detail"]
    r = server.api("POST", "/api/sessions", json={"participant_id": "sim-A", "study": 1, "calibration_id": cal,
                                                  "n_training": 1, "repetitions": 1})
    assert r.status_code == 201, r.text
    s = r.json()
    sid, key = s["session_id"], s["participant_url"].split("key=")[1]
    assert s["config"]["rig_seed"] == participant_seed("sim-A"), "the seed derives from the participant id"
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    st = wait_state(server, sid, key, "respond", timeout=60)
    assert st["simulated"] is True
    # A person on the participant page cannot answer for the model.
    r = answer(server, sid, key, trial_index=st["trial_index"])
    assert r.status_code == 409 and "simulated participant" in r.json()["detail"], r.text
    _wait_status(server, sid, "completed")
    n_trials = server.rows("SELECT COUNT(*) FROM planned_trials WHERE session_id = ?", sid)[0][0]

    # A person's session on the same server.
    human = server.plan("P01", 1, n_training=1, repetitions=1)
    hsid, hkey = human["session_id"], human["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{hsid}/start").status_code == 200
    st = wait_state(server, hsid, hkey, "respond", timeout=60)
    assert st["simulated"] is False
    assert answer(server, hsid, hkey, trial_index=st["trial_index"]).status_code == 200

    rows = _export(server)
    model = [r for r in rows if r["participant"] == "sim-A"]
    person = [r for r in rows if r["participant"] == "P01"]
    assert len(model) == n_trials and {r["simulated"] for r in model} == {"1"}
    assert len(person) == 1 and person[0]["simulated"] == "0"


def test_simulated_forearm_seeds_derive_from_the_participant_id(server):
    for pid in ("P21", "P22"):
        assert server.api("POST", "/api/participants", json={"participant_id": pid}).status_code == 201
        r = server.api("POST", "/api/sessions", json={"participant_id": pid, "study": 1, "n_training": 0, "repetitions": 1})
        assert r.status_code == 201
        assert r.json()["config"]["rig_seed"] == participant_seed(pid)
    assert participant_seed("P21") != participant_seed("P22")
    r = server.api("POST", "/api/sessions", json={"participant_id": "P21", "study": 1, "rig_seed": 5, "repetitions": 1})
    assert r.json()["config"]["rig_seed"] == 5, "a seed given is kept"


@pytest.mark.slow
def test_a_session_plays_on_the_forearm_of_its_calibration(tmp_path):
    """Issue 53, item 12: S01 calibrated on arm 5 got a session on arm 745814248 (no seed given)
    or on arm 6 (another seed given); the drives were designed for one arm and played, and
    judged by the model, on another."""
    from fastapi.testclient import TestClient

    from vibrofocus.rigs import make_rig
    from vibrofocus.web.app import create_app

    token = "t" * 32
    db = tmp_path / "s.sqlite"
    headers = {"X-Vibrofocus-Token": token, "Origin": "http://testserver"}
    app = create_app(db, token=token, allowed_hosts=("testserver",), resume=False, pace="fast")
    with TestClient(app, headers=headers) as c:
        assert c.post("/api/participants", json={"participant_id": "S01", "simulated": True}).status_code == 201
        job = c.post("/api/calibrations", json={"participant_id": "S01", "seed": 5}).json()["job_id"]
        deadline = time.monotonic() + 300
        while (j := c.get(f"/api/calibrations/jobs/{job}").json())["status"] == "running":
            assert time.monotonic() < deadline
            time.sleep(0.2)
        assert j["status"] == "done", j
        cal = j["calibration_id"]
        assert c.app.state.web.calibration(cal).rig["seed"] == 5
        plan = {"participant_id": "S01", "study": 1, "calibration_id": cal, "n_training": 0, "repetitions": 1}

        r = c.post("/api/sessions", json=plan)  # no seed: the calibration's arm, not the id's
        assert r.status_code == 201, r.text
        sid = r.json()["session_id"]
        assert r.json()["config"]["rig_seed"] == 5 != participant_seed("S01")
        runner = c.app.state.web.runner(sid, create=True)
        assert runner.rig.seed == 5 and runner.model.seed == 5, "the model feels the calibration's arm"
        assert c.post("/api/sessions", json={**plan, "rig_seed": 5}).json()["config"]["rig_seed"] == 5

        n_sessions = len(c.get("/api/sessions").json())
        r = c.post("/api/sessions", json={**plan, "rig_seed": 6})
        assert r.status_code == 422, r.text
        assert r.json()["detail"] == (
            f"Calibration {cal} was made on the simulated forearm of seed 5, and a session on it plays on that "
            "forearm; the rig seed 6 would be another arm. Leave the seed empty or give 5.")
        assert len(c.get("/api/sessions").json()) == n_sessions, "nothing stored"

    # The same database served with another skin (serve --skin high) cannot build that arm.
    def high(kind, seed=None, **kwargs):
        return make_rig(kind, seed=seed, skin="high" if kind == "simulated" else None, **kwargs)

    app = create_app(db, token=token, allowed_hosts=("testserver",), resume=False, pace="fast", rig_factory=high)
    with TestClient(app, headers=headers) as c:
        r = c.post("/api/sessions", json=plan)
        assert r.status_code == 409, r.text
        assert "skin 'nominal' (this server's: 'high')" in r.json()["detail"]
        assert "Restart 'vibrofocus serve' with that --skin, or calibrate again" in r.json()["detail"]
