"""Bad requests against the real server: each gets a 4xx with a clear message and changes nothing."""

from __future__ import annotations

import sqlite3
import time

import httpx
import pytest

TABLES = ("participants", "calibrations", "sessions", "planned_trials", "answers", "events")


def snapshot(db) -> dict[str, list[tuple]]:
    con = sqlite3.connect(db)
    try:
        return {t: con.execute(f"SELECT * FROM {t} ORDER BY rowid").fetchall() for t in TABLES}
    finally:
        con.close()


def wait_state(server, sid: int, key: str, state: str, timeout: float = 15.0) -> dict:
    # As a page does: each request says which state it has seen (after=seq).
    deadline = time.monotonic() + timeout
    seq = -1
    while time.monotonic() < deadline:
        st = httpx.get(f"{server.base_url}/api/participant/{sid}/state?after={seq}&wait=1&ready=1",
                       headers={"X-Participant-Key": key}).json()
        seq = st["seq"]
        if st["state"] == state:
            return st
    raise AssertionError(f"session {sid} never reached {state!r}; last state {st}")


@pytest.fixture
def running(server):
    """A started Study 1 session waiting for the answer to its first trial."""
    s = server.plan("P01", 1)
    sid = s["session_id"]
    key = s["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    st = wait_state(server, sid, key, "respond")
    return server, sid, key, st


def answer(server, sid, key, **fields):
    body = {"session_id": sid, "trial_index": 0, "response": [5], "rt_s": 0.8, "answer_id": "answer-0001"}
    body.update(fields)
    return httpx.post(f"{server.base_url}/api/participant/{sid}/answer", json=body,
                      headers={"X-Participant-Key": key}, timeout=10)


def test_bad_answers_are_refused_and_change_nothing(running):
    server, sid, key, st = running
    assert st["trial_index"] == 0
    before = snapshot(server.db)
    url = f"{server.base_url}/api/participant/{sid}/answer"
    good = {"session_id": sid, "trial_index": 0, "response": [5], "rt_s": 0.8, "answer_id": "answer-0001"}
    cases = [
        # (request kwargs, expected status, words the message must contain)
        (dict(json=good), 403, "participant link"),  # no key
        (dict(json=good, headers={"X-Participant-Key": "not-the-key"}), 403, "participant link"),
        (dict(json=good, headers=server.headers), 403, "participant link"),  # the token cannot answer
        (dict(content=b"{not json", headers={"X-Participant-Key": key, "Content-Type": "application/json"}), 422, "json"),
        (dict(json={**good, "response": [0]}, headers={"X-Participant-Key": key}), 422, "must be at least 1"),
        (dict(json={**good, "response": [10]}, headers={"X-Participant-Key": key}), 422, "must be at most 9"),
        (dict(json={**good, "response": []}, headers={"X-Participant-Key": key}), 422, "at least 1"),
        (dict(json={**good, "response": ["5"]}, headers={"X-Participant-Key": key}), 422, "answer (item 1) is not a valid value"),
        (dict(json={**good, "response": [4, 5]}, headers={"X-Participant-Key": key}), 422, "exactly one location"),
        (dict(json={**good, "response": [5, 5]}, headers={"X-Participant-Key": key}), 422, "twice"),
        (dict(json={**good, "rt_s": -1}, headers={"X-Participant-Key": key}), 422, "reaction time must be at least 0"),
        (dict(json={**good, "trial_index": 3}, headers={"X-Participant-Key": key}), 409, "not for the current trial"),
        (dict(json={**good, "trial_index": 999}, headers={"X-Participant-Key": key}), 422, "out of range"),
        (dict(json={**good, "session_id": sid + 1}, headers={"X-Participant-Key": key}), 422, "does not match"),
        (dict(json={k: v for k, v in good.items() if k != "answer_id"}, headers={"X-Participant-Key": key}), 422, "answer id is missing"),
        (dict(json={**good, "extra": 1}, headers={"X-Participant-Key": key}), 422, "extra"),
    ]
    for kwargs, status, words in cases:
        r = httpx.post(url, timeout=10, **kwargs)
        assert r.status_code == status, (kwargs, r.text)
        assert words.lower() in r.json()["detail"].lower(), (words, r.json())
    # Another session's URL with this session's key.
    r = httpx.post(f"{server.base_url}/api/participant/{sid + 5}/answer", json={**good, "session_id": sid + 5},
                   headers={"X-Participant-Key": key})
    assert r.status_code == 403
    assert snapshot(server.db) == before, "a refused request changed the database"

    # The right answer is taken once; a re-send is the same receipt, a different one is refused.
    r = answer(server, sid, key)
    assert r.status_code == 200 and r.json()["committed"] and not r.json()["duplicate"]
    r = answer(server, sid, key)
    assert r.status_code == 200 and r.json()["duplicate"]
    after_one = server.rows("SELECT trial_index, response, answer_id FROM answers")
    assert after_one == [(0, "5", "answer-0001")]
    r = answer(server, sid, key, response=[6])
    assert r.status_code == 409 and "already answered" in r.json()["detail"]
    r = answer(server, sid, key, answer_id="answer-0002")
    assert r.status_code == 409 and "already answered" in r.json()["detail"]
    assert server.rows("SELECT trial_index, response, answer_id FROM answers") == after_one


def test_experimenter_routes_need_the_token_and_validate(server):
    base = server.base_url
    for headers in ({}, {"X-Vibrofocus-Token": "wrong-token-wrong-token"}):
        for method, path in (("GET", "/api/participants"), ("GET", "/api/sessions"), ("GET", "/api/export/trials.csv")):
            r = httpx.request(method, base + path, headers=headers)
            assert r.status_code == 401 and "experimenter token" in r.json()["detail"]
        r = httpx.post(base + "/api/participants", json={"participant_id": "P09"}, headers=headers)
        assert r.status_code == 401
    before = snapshot(server.db)
    checks = [
        ("POST", "/api/participants", {"participant_id": "bad id!"}, 422, "participant id may hold only letters"),
        ("POST", "/api/participants", {"participant_id": ""}, 422, "participant id is empty"),
        ("POST", "/api/sessions", {"participant_id": "nobody", "study": 1}, 404, "unknown participant"),
        ("POST", "/api/sessions", {"participant_id": "P01", "study": 3}, 422, "study must be 1 or 2"),
        ("GET", "/api/sessions/999", None, 404, "unknown session 999"),
        ("POST", "/api/sessions/999/start", None, 404, "unknown session 999"),
        ("POST", "/api/calibrations", {"participant_id": "nobody"}, 404, "unknown participant"),
        ("GET", "/api/calibrations/42/figure.png", None, 404, "unknown calibration 42"),
        ("GET", "/api/preview.png?calibration_id=1&method=magic&location=5", None, 422, "unknown method"),
        ("GET", "/api/preview.png?calibration_id=1&method=inverse&location=0", None, 422, "location"),
    ]
    for method, path, body, status, words in checks:
        r = server.api(method, path, json=body)
        assert r.status_code == status, (path, r.text)
        assert words in r.json()["detail"], (path, r.json())
    assert snapshot(server.db) == before
    # The participant page itself needs its key.
    s = server.plan("P02", 2)
    r = httpx.get(f"{base}/participant/{s['session_id']}")
    assert r.status_code == 403
    assert httpx.get(base + s["participant_url"]).status_code == 200
    # Control actions in the wrong order are refused with the reason.
    r = server.api("POST", f"/api/sessions/{s['session_id']}/pause")
    assert r.status_code == 409 and "only a running session" in r.json()["detail"]
    r = server.api("POST", f"/api/sessions/{s['session_id']}/jump")
    assert r.status_code == 404 and "unknown session action" in r.json()["detail"]


def test_an_answer_to_a_trial_not_yet_presented_is_refused(server):
    """Started, but no participant page is open: the runner holds the first cue, no
    stimulus is played, so an answer to trial 0 is not data and must not be stored."""
    s = server.plan("P09", 1)
    sid = s["session_id"]
    key = s["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    time.sleep(0.5)  # the runner is at "get ready", waiting for a page that can beep
    before = snapshot(server.db)
    assert not [e for e in before["events"] if e[2] == "stimulus_onset"]
    r = answer(server, sid, key)
    assert r.status_code == 409, r.text
    assert "not been presented" in r.json()["detail"]
    assert snapshot(server.db)["answers"] == before["answers"] == []


def test_a_session_with_an_unknown_rig_is_refused_and_nothing_is_stored(server):
    assert server.api("POST", "/api/participants", json={"participant_id": "P10"}).status_code == 201
    before = snapshot(server.db)
    r = server.api("POST", "/api/sessions", json={"participant_id": "P10", "study": 1, "rig": "no-such-rig"})
    assert r.status_code == 422, r.text
    assert "no-such-rig" in r.json()["detail"] and "simulated" in r.json()["detail"]
    assert snapshot(server.db) == before


def test_a_session_keeps_its_level_rule_and_a_bad_one_is_refused(server):
    assert server.api("POST", "/api/participants", json={"participant_id": "P11"}).status_code == 201
    r = server.api("POST", "/api/sessions", json={"participant_id": "P11", "study": 1, "levels": "equal-peak"})
    assert r.status_code == 201, r.text
    assert r.json()["config"]["levels"] == "equal-peak"
    r = server.api("POST", "/api/sessions", json={"participant_id": "P11", "study": 2})
    assert r.status_code == 201 and r.json()["config"]["levels"] == "paper"  # the paper's, by default
    before = snapshot(server.db)
    r = server.api("POST", "/api/sessions", json={"participant_id": "P11", "study": 1, "levels": "loud"})
    assert r.status_code == 422 and snapshot(server.db) == before


def test_values_of_the_wrong_type_are_refused_not_converted(tmp_path):
    """Issue 53 (LOW): "true", 1 or "yes" for a boolean, true or 1.0 for a number would change
    what a participant or session is; strict types refuse them with the field named, and
    nothing is stored."""
    from fastapi.testclient import TestClient

    from vibrofocus.web.app import create_app

    token = "t" * 32
    app = create_app(tmp_path / "s.sqlite", token=token, allowed_hosts=("testserver",), resume=False, pace="fast")
    with TestClient(app, headers={"X-Vibrofocus-Token": token, "Origin": "http://testserver"}) as c:
        assert c.post("/api/participants", json={"participant_id": "P01"}).status_code == 201
        before = snapshot(tmp_path / "s.sqlite")
        plan = {"participant_id": "P01", "study": 1}
        checks = [
            ("/api/participants", {"participant_id": "S01", "simulated": "true"}, "'simulated' is not a valid value here: it must be true or false, not \"true\""),
            ("/api/participants", {"participant_id": "S02", "simulated": 1}, "must be true or false, not 1"),
            ("/api/calibrations", {"participant_id": "P01", "seed": True}, "The seed is not a valid value here: it must be a whole number, not true"),
            ("/api/calibrations", {"participant_id": "P01", "seed": "5"}, "must be a whole number, not \"5\""),
            ("/api/calibrations", {"participant_id": "P01", "points": 5.0}, "must be a whole number, not 5.0"),
            ("/api/sessions", {**plan, "allow_calibration_errors": "yes"}, "'allow_calibration_errors' is not a valid value here"),
            ("/api/sessions", {**plan, "rig_seed": True}, "The rig seed is not a valid value here"),
            ("/api/sessions", {**plan, "seed": False}, "The seed is not a valid value here"),
            ("/api/sessions", {**plan, "repetitions": "2"}, "Repetitions is not a valid value here"),
            ("/api/sessions", {**plan, "study": True}, "The study must be 1 or 2"),
            ("/api/sessions", {**plan, "study": 1.0}, "The study must be 1 or 2"),
            ("/api/sessions", {**plan, "study": "1"}, "The study must be 1 or 2"),
            ("/api/analysis", {"study": True}, "The study must be 1 or 2"),
        ]
        for path, body, words in checks:
            r = c.post(path, json=body)
            assert r.status_code == 422, (body, r.text)
            assert words in r.json()["detail"], (body, r.json())
        assert snapshot(tmp_path / "s.sqlite") == before
        assert c.app.state.web.jobs == {}, "a refused calibration starts no job"
        # The right types pass.
        assert c.post("/api/participants", json={"participant_id": "S01", "simulated": True}).json()["simulated"] is True
        r = c.post("/api/sessions", json={**plan, "seed": 3, "rig_seed": 4, "repetitions": 1, "n_training": 0,
                                          "allow_calibration_errors": False})
        assert r.status_code == 201, r.text
