"""``vibrofocus stop``: the emergency stop through the server's owner-only socket (issue 38, item 9)."""

from __future__ import annotations

import os
import socket
import stat
import subprocess
import sys

import httpx

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
