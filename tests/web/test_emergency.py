"""``vibrofocus stop``: the emergency stop through the server's owner-only socket (issue 38, item 9).

Issue 53: the client believes only a socket that can be the server's (items 1), a second
server of one database is refused (item 5), silent peers delay no stop (item 13).
"""

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

from vibrofocus.errors import StudyError, ValidationError
from vibrofocus.web import emergency
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


class _Web:
    """Just what :func:`vibrofocus.web.emergency.stop_all` uses of the app's state."""

    def __init__(self) -> None:
        self.lock = self.db = threading.RLock()
        self.runners = {}
        self.stopped = []

    def emergency_stop(self):
        self.stopped.append(1)
        return ["simulated rig outputs at 0 V"]


def _listener(tmp_path) -> tuple[_Web, emergency.StopListener]:
    """A started stop listener of ``tmp_path/studies.sqlite`` on a stand-in state."""
    web = _Web()
    folder = tmp_path / "studies-files"
    folder.mkdir(mode=0o700)
    listener = emergency.StopListener(web, folder / "stop.sock")
    assert listener.start()
    return web, listener


def test_the_stop_socket_answers_only_its_own_user(tmp_path, monkeypatch):
    web, listener = _listener(tmp_path)
    stopped = web.stopped
    folder = tmp_path / "studies-files"
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
    import vibrofocus.calibration.files

    # The save step of the calibration workflow (vibrofocus.workflows.calibrate_participant).
    entered, release = _held(monkeypatch, vibrofocus.calibration.files, "save_calibration_keeping")
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
    # The button's plain form (no script yet): a browser asks for a page, and reads what stopped.
    page = client.post("/api/emergency-stop", headers={"accept": "text/html,application/xhtml+xml"})
    assert page.headers["content-type"].startswith("text/html") and "Nothing was running." in page.text
    assert client.get(f"/api/sessions/{first}").json()["status"] == "completed"

    second = client.post("/api/sessions", json=plan).json()["session_id"]
    assert client.post(f"/api/sessions/{second}/start").status_code == 200
    page = client.post("/api/emergency-stop", headers={"accept": "text/html"})
    assert f"Stopped: simulated rig (seed 5): outputs at 0 V; session {second} paused." in page.text
    assert client.get(f"/api/sessions/{second}").json()["status"] == "paused"
    assert client.get(f"/api/sessions/{first}").json()["status"] == "completed"


# ---------------------------------------------------------------------------- issue 53, item 1
def _not_stopped(db) -> str:
    with pytest.raises(ValidationError) as caught:
        emergency.request_stop(db, timeout_s=2.0)
    message = str(caught.value)
    assert message.startswith("not stopped") and message.endswith("switch the amplifier off"), message
    return message


@pytest.mark.parametrize("case", ["their folder and socket", "their socket in our folder",
                                  "our socket file, their program", "our folder open to others"])
def test_stop_believes_no_socket_another_user_planted(shared_dir, other_user, case):
    """Before issue 53 each of these printed "stopped: every rig output to 0 V; session 1 paused", exit 0."""
    db = shared_dir / "study.sqlite"
    sock = stop_socket_path(db)
    with other_user.answer_stop_socket(sock) as planted:
        if case != "their folder and socket":  # later made to look like ours, piece by piece
            os.chown(sock.parent, os.getuid(), os.getgid())
            os.chmod(sock.parent, 0o755 if case == "our folder open to others" else 0o700)
        if case in ("our socket file, their program", "our folder open to others"):
            os.chown(sock, os.getuid(), os.getgid())
            os.chmod(sock, 0o600)
        message = _not_stopped(db)
        expected = {
            "their folder and socket": f"its folder {sock.parent} belongs to user {other_user.name}",
            "their socket in our folder": f"{sock} belongs to user {other_user.name}",
            "our socket file, their program": f"the program at the stop socket runs as user {other_user.name}",
            "our folder open to others": f"its folder {sock.parent} is open to other users (mode 0755)",
        }[case]
        assert expected in message, message
        assert "r" not in planted.events(), "the client sent its stop to another user's program"


def test_the_stop_command_says_not_stopped_with_exit_2(shared_dir, other_user):
    db = shared_dir / "study.sqlite"
    with other_user.answer_stop_socket(stop_socket_path(db)) as planted:
        done = _stop(db)
        assert planted.events() == ""
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "stopped" not in done.stdout
    assert "error: not stopped" in done.stderr and "switch the amplifier off" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def _serve_refused(db, env=None) -> subprocess.CompletedProcess:
    """``vibrofocus serve`` that is expected to refuse to start (killed after 60 s if it starts)."""
    env = dict(os.environ, VIBROFOCUS_TOKEN="test-token-" + "x" * 20, **(env or {}))
    try:
        return subprocess.run([sys.executable, "-m", "vibrofocus", "serve", "--db", str(db), "--port", "0",
                               "--no-browser"], capture_output=True, text=True, timeout=60, env=env)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"the server started: {exc.stdout}") from None


def test_serve_refuses_to_start_without_its_stop_socket(tmp_path, monkeypatch):
    """A database path too long for a Unix socket, without XDG_RUNTIME_DIR: before issue 53 the server
    started, printed the stop hint, then warned that 'vibrofocus stop' was not available."""
    deep = tmp_path / ("d" * 60)
    deep.mkdir(mode=0o700)
    db = deep / "study.sqlite"
    monkeypatch.setenv("XDG_RUNTIME_DIR", "")
    assert stop_socket_path(db) is None
    done = _serve_refused(db)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "vibrofocus stop" not in done.stdout and "experimenter page" not in done.stdout, done.stdout
    assert "too long for the socket of 'vibrofocus stop'" in done.stderr, done.stderr


# ---------------------------------------------------------------------------- issue 53, item 5
def test_a_second_server_of_one_database_is_refused_naming_the_first(tmp_path):
    first = Server(tmp_path / "studies.sqlite", free_port(), tmp_path / "first.log")
    first.start()
    try:
        done = _serve_refused(first.db)
        assert done.returncode == 2, (done.stdout, done.stderr)
        assert f"(PID {first.proc.pid}, port {first.port})" in done.stderr, done.stderr
        assert "another 'vibrofocus serve' already serves" in done.stderr
        assert "vibrofocus stop" not in done.stdout, "the stop hint of a server that does not run"
        assert emergency.request_stop(first.db) == []  # still the first server's socket
    finally:
        first.stop()


def test_the_lock_names_its_holder_and_goes_with_a_killed_server(tmp_path):
    """The lock itself: a second claim fails and names the holder; a SIGKILLed holder leaves it free."""

    class Web(_Web):
        db_path = tmp_path / "studies.sqlite"
        data_dir = tmp_path / "studies-files"

    Web.data_dir.mkdir(mode=0o700)
    with emergency.ServerGuard(Web()) as one:
        one.claim(8123)
        with pytest.raises(StudyError, match=rf"already serves .* \(PID {os.getpid()}, port 8123\)"):
            emergency.ServerGuard(Web()).claim(8124)
    ready_r, ready_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # a server that is killed while it holds the lock
        try:
            emergency.ServerGuard(Web()).claim(8126)
            os.write(ready_w, b"ok")
            time.sleep(60)
        finally:
            os._exit(0)
    try:
        assert os.read(ready_r, 2) == b"ok"
        with pytest.raises(StudyError, match=rf"\(PID {pid}, port 8126\)"):
            emergency.ServerGuard(Web()).claim(8125)
    finally:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
        os.close(ready_r)
        os.close(ready_w)
    with emergency.ServerGuard(Web()) as again:
        again.claim(8125)


# ---------------------------------------------------------------------------- issue 53, item 13
def test_silent_peers_delay_no_stop(tmp_path):
    """Before issue 53: one connection at a time, 2 s for each silent one; 3 silent peers made the
    stop wait past the client's 5 s and fail, and a silent peer was dropped after 2 s."""
    web, listener = _listener(tmp_path)
    path = tmp_path / "studies-files" / "stop.sock"
    silent = []
    try:
        for _ in range(2 * getattr(emergency, "MAX_PENDING", 64)):  # more than are kept waiting
            s = socket.socket(socket.AF_UNIX)
            s.settimeout(1.0)
            try:
                s.connect(str(path))
            except OSError:
                s.close()
                continue
            silent.append(s)
        assert len(silent) >= 6
        t0 = time.monotonic()
        assert emergency.request_stop(tmp_path / "studies.sqlite") == ["simulated rig outputs at 0 V"]
        assert time.monotonic() - t0 < 1.0
        # A silent peer is dropped well under a second after it connected.
        with socket.socket(socket.AF_UNIX) as s:
            s.settimeout(5.0)
            s.connect(str(path))
            t0 = time.monotonic()
            assert s.recv(64) == b""
            waited = time.monotonic() - t0
        assert waited < 0.8, waited
    finally:
        for s in silent:
            s.close()
        listener.close()
    assert web.stopped == [1]


def test_a_page_polling_while_an_abort_waits_does_not_start_the_session_again(client, monkeypatch):
    # An abort stops the session's runner before it stores "aborted". A participant page
    # that polled in that window found a session stored as running with no runner and
    # built one: the aborted session went on presenting trials.
    from vibrofocus.web.session_runner import SessionRunner

    entered, release = _held(monkeypatch, SessionRunner, "stop")
    assert client.post("/api/participants", json={"participant_id": "P03"}).status_code == 201
    session = client.post("/api/sessions", json={"participant_id": "P03", "study": 1, "seed": 3,
                                                 "n_training": 1, "repetitions": 1}).json()
    sid, key = session["session_id"], session["participant_url"].split("key=")[1]
    assert client.post(f"/api/sessions/{sid}/start").status_code == 200
    abort = threading.Thread(target=lambda: client.post(f"/api/sessions/{sid}/stop"))
    abort.start()
    try:
        assert entered.wait(30), "the abort never reached the runner's stop"
        polled = client.get(f"/api/participant/{sid}/state", headers={"X-Participant-Key": key})
        assert polled.status_code == 200, polled.text
    finally:
        release.set()
        abort.join(30)
    web = client.app.state.web
    assert client.get(f"/api/sessions/{sid}").json()["status"] == "aborted"
    assert sid not in web.runners, "a runner was built for the session being aborted"
    page = client.get(f"/api/participant/{sid}/state", headers={"X-Participant-Key": key}).json()
    assert page["state"] == "stopped"
