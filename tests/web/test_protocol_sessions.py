"""Sessions planned from a study protocol over HTTP, against the real server: uploads and their
refusals, a threshold block answered felt / not felt through the answer route, its
threshold on the experimenter's session, and the dB SL block planned from it."""

from __future__ import annotations

import httpx
import pytest

from .test_api import snapshot, wait_state
from .tiny_protocol import FELT, THRESHOLD_DB, TINY_PROTOCOL


def upload(server, text: str, filename: str = "tiny.toml") -> httpx.Response:
    return server.api("POST", "/api/protocols", json={"text": text, "filename": filename})


def protocols_dir(server):
    return server.db.parent / f"{server.db.stem}-files" / "protocols"


def answer(server, sid: int, key: str, index: int, **fields) -> httpx.Response:
    body = {"session_id": sid, "trial_index": index, "rt_s": 0.5, "answer_id": f"felt-{sid}-{index:04d}", **fields}
    return httpx.post(f"{server.base_url}/api/participant/{sid}/answer", json=body,
                      headers={"X-Participant-Key": key}, timeout=10)


#: Bad protocol files and the one line each gets.
BAD = [
    (TINY_PROTOCOL.replace('methods = ["funneling"]\nlocations = [5]', 'methods = ["telepathy"]\nlocations = [5]'),
     "protocol tiny.toml, line 8, blocks[0].methods: unknown method 'telepathy'"),
    (TINY_PROTOCOL.replace("repetitions = 10\n", ""), "protocol tiny.toml, line 5, blocks[0].repetitions: missing"),
    (TINY_PROTOCOL.replace("repetitions = 10", 'repetitions = "ten"'), "line 11, blocks[0].repetitions"),
    (TINY_PROTOCOL.replace('name = "threshold"\nresponse = "detection"', 'name = "threshold"\nresponse = "location"'),
     "line 19, blocks[1].level_unit: levels in dB SL need"),
    ("format = 1\nname = [", "protocol tiny.toml: not valid TOML"),
]


def test_bad_protocols_and_felt_answers_are_refused_and_nothing_is_stored(server):
    for text, words in BAD:
        r = upload(server, text)
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert words in detail and "\n" not in detail, (words, detail)
    r = upload(server, TINY_PROTOCOL + "#" * 70_000)  # over the server's request size
    assert r.status_code == 413, r.text
    assert not list(protocols_dir(server).glob("*"))
    names = [p["name"] for p in server.api("GET", "/api/protocols").json()]
    assert names == ["paper-study1", "paper-study2"]
    # A felt answer in a location session (the same server: each start costs seconds).
    s = server.plan("P02", 1, n_training=0)
    sid, key = s["session_id"], s["participant_url"].split("key=")[1]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    wait_state(server, sid, key, "respond")
    before = snapshot(server.db)
    r = answer(server, sid, key, 0, felt=True)
    assert r.status_code == 422 and "not whether" in r.json()["detail"]
    r = answer(server, sid, key, 0, felt=True, response=[1])
    assert r.status_code == 422 and "not both" in str(r.json()["detail"])
    assert snapshot(server.db) == before


def test_a_threshold_block_over_http_then_its_db_sl_block(server):
    r = upload(server, TINY_PROTOCOL)
    assert r.status_code == 201, r.text
    assert [b["n_trials"] for b in r.json()["blocks"]] == [10, 2, 1]
    assert upload(server, TINY_PROTOCOL).status_code == 201  # the same text again: no change
    other = upload(server, TINY_PROTOCOL.replace("repetitions = 1\n", "repetitions = 2\n"))
    assert other.status_code == 409 and "another protocol named 'tiny-threshold'" in other.json()["detail"]
    assert server.api("POST", "/api/participants", json={"participant_id": "P01"}).status_code == 201
    # The dB SL block needs the threshold first: refused, nothing written.
    before = snapshot(server.db)
    r = server.api("POST", "/api/sessions", json={"participant_id": "P01", "protocol": "tiny-threshold", "block": 1})
    assert r.status_code == 409 and "P01 has no threshold from the threshold block 'threshold'" in r.json()["detail"]
    r = server.api("POST", "/api/sessions", json={"participant_id": "P01", "protocol": "tiny-threshold", "study": 1})
    assert r.status_code == 422 and "leave out study" in r.json()["detail"]
    assert snapshot(server.db) == before
    # No block given: the first unfinished one, the threshold block.
    r = server.api("POST", "/api/sessions", json={"participant_id": "P01", "protocol": "tiny-threshold", "seed": 3})
    assert r.status_code == 201, r.text
    s = r.json()
    sid, key = s["session_id"], s["participant_url"].split("key=")[1]
    assert s["config"]["protocol"] == "tiny-threshold" and s["config"]["block"] == 0 and s["n_trials"] == 10
    assert s["staircase"] == {"level_db": -6.0, "reversals": 0, "levels_db": [-6.0], "threshold_db": None,
                              "finished": False}
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    for i, felt in enumerate(FELT):
        st = wait_state(server, sid, key, "respond")
        assert st["detection"] and st["trial_index"] == i, st
        if i == 0:  # a location, or a point, is not a detection answer; felt is not a location answer
            assert answer(server, sid, key, 0, point_mm=[0.0, 0.0]).status_code == 422
        r = answer(server, sid, key, i, felt=bool(felt))
        assert r.status_code == 200, r.text
        assert r.json()["response"] == [felt]
    out = server.api("GET", f"/api/sessions/{sid}").json()
    assert out["staircase"]["threshold_db"] == pytest.approx(THRESHOLD_DB, abs=1e-9)
    assert out["staircase"]["reversals"] == 6 and out["status"] == "completed"
    assert server.rows("SELECT session_id, threshold_db FROM thresholds") == [(sid, pytest.approx(THRESHOLD_DB))]
    levels = [e for (e,) in server.rows("SELECT json_extract(payload, '$.level_db') FROM events "
                                        "WHERE session_id = ? AND kind = 'stimulus_onset' ORDER BY event_id", sid)]
    assert levels == [-6.0, -10.0, -8.0, -8.0, -10.0, -8.0, -8.0, -10.0, -8.0, -8.0]
    # The next block, in dB SL, on that threshold.
    r = server.api("POST", "/api/sessions", json={"participant_id": "P01", "protocol": "tiny-threshold"})
    assert r.status_code == 201, r.text
    cfg = r.json()["config"]
    assert (cfg["block"], cfg["threshold_db"], cfg["level_sl_db"], cfg["level_db"]) == (1, THRESHOLD_DB, 6.0, -3.0)
    assert cfg["point"] and r.json()["staircase"] is None
