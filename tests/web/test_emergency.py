"""``vibrofocus stop``: the emergency stop through the server's owner-only socket (issue 38, item 9)."""

from __future__ import annotations

import importlib
import os
import socket
import stat
import subprocess
import sys
import threading
import time

import httpx
import pytest

from vibrofocus.web.emergency import stop_socket_path

from .conftest import Server, free_port
from .test_api import wait_state
from .test_load import _slow_bodies


def _stop(db) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vibrofocus", "stop", "--db", str(db)],
                          capture_output=True, text=True, timeout=60)


def test_vibrofocus_stop_pauses_a_running_session_while_the_port_is_flooded(tmp_path):
    srv = Server(tmp_path / "studies.sqlite", free_port(), tmp_path / "server.log", args=("--max-connections", "20"))
    srv.start()
    held = []
    try:
        s = srv.plan("P01", 1, n_training=1, repetitions=1)
        sid, key = s["session_id"], s["participant_url"].split("key=")[1]
        assert srv.api("POST", f"/api/sessions/{sid}/start").status_code == 200
        wait_state(srv, sid, key, "respond", timeout=60)
        path = stop_socket_path(srv.db)
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, oct(path.stat().st_mode)
        assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
        held = _slow_bodies(srv.port, 60)  # the TCP port is full of stalled requests
        done = _stop(srv.db)
        assert done.returncode == 0, done.stderr
        assert "stopped:" in done.stdout and f"session {sid} paused" in done.stdout, done.stdout
        assert srv.rows("SELECT status FROM sessions WHERE session_id = ?", sid) == [("paused",)]
    finally:
        for sock in held:
            sock.close()
        srv.stop()
    assert not path.exists(), "the stop socket outlives its server"


def test_vibrofocus_stop_without_a_server_says_so(tmp_path):
    done = _stop(tmp_path / "studies.sqlite")
    assert done.returncode == 2
    assert "no 'vibrofocus serve' of this database is running" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_the_stop_socket_answers_only_its_own_user(tmp_path, monkeypatch):
    from vibrofocus.web import emergency

    stopped = []

    class Web:
        def emergency_stop(self):
            stopped.append(1)
            return ["simulated rig outputs at 0 V"]

    web = Web()
    web.lock = web.db = __import__("threading").RLock()
    web.runners = {}
    folder = tmp_path / "studies-files"
    listener = emergency.StopListener(web, folder / "stop.sock")
    assert listener.start()
    try:
        monkeypatch.setattr(emergency, "_peer_uid", lambda conn: os.getuid() + 1)  # as if another user connected
        with socket.socket(socket.AF_UNIX) as c:
            c.connect(str(folder / "stop.sock"))
            try:
                c.sendall(b"stop\n")
            except BrokenPipeError:
                pass  # the server refuses another user as it accepts, before it reads: its answer is there
            assert b"not the user running this server" in c.recv(4096)
        assert stopped == []
        monkeypatch.undo()
        assert emergency.request_stop(tmp_path / "studies.sqlite") == ["simulated rig outputs at 0 V"]
        assert stopped == [1]
    finally:
        listener.close()


def test_a_stale_socket_of_a_dead_server_is_replaced(tmp_path):
    folder = tmp_path / "studies-files"
    folder.mkdir(mode=0o700)
    dead = socket.socket(socket.AF_UNIX)
    dead.bind(str(folder / "stop.sock"))
    dead.close()  # the file stays, nobody listens
    srv = Server(tmp_path / "studies.sqlite", free_port(), tmp_path / "server.log")
    srv.start()
    try:
        assert _stop(srv.db).returncode == 0
        assert httpx.get(f"{srv.base_url}/api/rigs", headers=srv.headers).status_code == 200
    finally:
        srv.stop()


# ---------------------------------------------------------------------- what the stop reports (issue 53, item 6)
TOKEN = "t" * 32


@pytest.fixture
def client(tmp_path):
    from fastapi.testclient import TestClient

    from vibrofocus.web.app import create_app

    app = create_app(tmp_path / "s.sqlite", token=TOKEN, allowed_hosts=("testserver",), resume=False, pace="fast")
    with TestClient(app, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}) as c:
        yield c


def _wait_job(client, job_id: str, timeout: float = 300.0) -> dict:
    deadline = time.monotonic() + timeout
    while (j := client.get(f"/api/calibrations/jobs/{job_id}").json())["status"] in ("running", "waiting"):
        assert time.monotonic() < deadline, j
        time.sleep(0.1)
    return j


def _held(monkeypatch, module, name: str):
    """Hold ``module.name`` (a step of the calibration job) until released: (entered, release)."""
    entered, release = threading.Event(), threading.Event()
    real = getattr(module, name)

    def held(*args, **kwargs):
        entered.set()
        assert release.wait(120), "the test never released the step"
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, held)
    return entered, release


def _saved_calibrations(client, participant: str) -> list:
    people = {p["participant_id"]: p for p in client.get("/api/participants").json()}
    return people[participant]["calibrations"]


@pytest.mark.slow
def test_a_stop_during_the_estimation_cancels_the_calibration_and_saves_nothing(client, tmp_path, monkeypatch):
    # The sweeps are over and H is being estimated (the quality verdicts come last): a stop
    # then said "cancelled", and the job went on to save a usable calibration.
    estimating = importlib.import_module("vibrofocus.calibration.calibrate")
    entered, release = _held(monkeypatch, estimating, "assess_quality")
    assert client.post("/api/participants", json={"participant_id": "P02"}).status_code == 201
    job = client.post("/api/calibrations", json={"participant_id": "P02", "seed": 7}).json()["job_id"]
    assert entered.wait(300), "the calibration never reached its estimation"
    stopped = client.post("/api/emergency-stop").json()["stopped"]
    release.set()
    j = _wait_job(client, job)
    assert (j["status"], j["message"], j["calibration_id"], j["error"]) == ("cancelled", "cancelled: nothing was saved", None, None)
    assert _saved_calibrations(client, "P02") == []
    assert not list(tmp_path.glob("s-files/calibrations/*.nc"))
    assert stopped == ["simulated rig (seed 7): outputs at 0 V", "calibration of P02 cancelled: nothing is saved"]
    # Cancelling it again says it has ended, in the same word.
    r = client.post(f"/api/calibrations/jobs/{job}/cancel")
    assert r.status_code == 409 and "already ended (cancelled)" in r.json()["detail"]


@pytest.mark.slow
def test_a_stop_once_the_calibration_is_being_saved_says_it_is_saved(client, monkeypatch):
    import vibrofocus.calibration

    entered, release = _held(monkeypatch, vibrofocus.calibration, "save_calibration")
    assert client.post("/api/participants", json={"participant_id": "P02"}).status_code == 201
    job = client.post("/api/calibrations", json={"participant_id": "P02", "seed": 7}).json()["job_id"]
    assert entered.wait(300), "the calibration never reached its saving"
    try:
        stopped = client.post("/api/emergency-stop").json()["stopped"]
        assert stopped == ["simulated rig (seed 7): outputs at 0 V",
                           "calibration of P02 not cancelled: its recordings had finished; it is being saved"]
        r = client.post(f"/api/calibrations/jobs/{job}/cancel")
        assert r.status_code == 409 and "it can no longer be cancelled" in r.json()["detail"], r.text
    finally:
        release.set()
    j = _wait_job(client, job)
    assert j["status"] == "done" and j["calibration_id"] is not None, j
    assert [c["calibration_id"] for c in _saved_calibrations(client, "P02")] == [j["calibration_id"]]


def test_a_stop_during_a_recording_is_a_cancel_not_a_failure(tmp_path):
    """On a rig whose takes last (hardware), the stop ends the take with the rig's "stopped"
    error: the job said "failed: the recording was stopped ... discarded" while the stop
    said "cancelled"."""
    from fastapi.testclient import TestClient

    from vibrofocus.rigs.simulated import SimulatedForearm
    from vibrofocus.web.app import create_app

    recording = threading.Event()

    class LastingTakes(SimulatedForearm):
        def _play_and_record(self, *args):
            out = super()._play_and_record(*args)
            recording.set()
            deadline = time.monotonic() + 60
            while not self._stop_requested() and time.monotonic() < deadline:
                time.sleep(0.01)
            self._raise_if_stopped("recording")
            return out

    def factory(kind, seed=None, **_):
        return LastingTakes(seed=0 if seed is None else seed)

    app = create_app(tmp_path / "s.sqlite", token=TOKEN, allowed_hosts=("testserver",), resume=False, pace="fast",
                     rig_factory=factory)
    with TestClient(app, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}) as client:
        assert client.post("/api/participants", json={"participant_id": "P03"}).status_code == 201
        job = client.post("/api/calibrations", json={"participant_id": "P03", "seed": 8}).json()["job_id"]
        assert recording.wait(120)
        stopped = client.post("/api/emergency-stop").json()["stopped"]
        j = _wait_job(client, job)
        assert (j["status"], j["message"], j["error"]) == ("cancelled", "cancelled: nothing was saved", None), j
        assert _saved_calibrations(client, "P03") == []
        assert stopped == ["simulated rig (seed 8): outputs at 0 V", "calibration of P03 cancelled: nothing is saved"]


@pytest.mark.slow
def test_the_stop_names_what_was_running_each_rig_once(client):
    # A finished session and an idle simulated arm are not "stopped"; a running session
    # and the arm it plays on are named once each, with the arm's seed.
    assert client.post("/api/participants", json={"participant_id": "S01", "simulated": True}).status_code == 201
    j = _wait_job(client, client.post("/api/calibrations", json={"participant_id": "S01", "seed": 5}).json()["job_id"])
    assert j["status"] == "done", j
    assert client.get("/api/rigs/straps", params={"rig": "simulated", "seed": 9}).status_code == 200  # another arm, idle
    plan = {"participant_id": "S01", "study": 1, "calibration_id": j["calibration_id"], "n_training": 0, "repetitions": 1}
    first = client.post("/api/sessions", json=plan).json()["session_id"]
    assert client.post(f"/api/sessions/{first}/start").status_code == 200
    deadline = time.monotonic() + 300
    while client.get(f"/api/sessions/{first}").json()["status"] != "completed":
        assert time.monotonic() < deadline
        time.sleep(0.2)
    assert client.post("/api/emergency-stop").json() == {"stopped": []}, "nothing was running"
    assert client.get(f"/api/sessions/{first}").json()["status"] == "completed"

    second = client.post("/api/sessions", json=plan).json()["session_id"]
    assert client.post(f"/api/sessions/{second}/start").status_code == 200
    stopped = client.post("/api/emergency-stop").json()["stopped"]
    assert stopped == ["simulated rig (seed 5): outputs at 0 V", f"session {second} paused"]
    assert client.get(f"/api/sessions/{second}").json()["status"] == "paused"
    assert client.get(f"/api/sessions/{first}").json()["status"] == "completed"
