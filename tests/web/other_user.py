"""A real second local user (made with ``useradd``) for the tests of what another user can do.

The ``other_user`` fixture makes the user once per test session and removes it at the
end; it skips when the tests do not run as root or ``useradd`` is missing. ``shared_dir``
is a sticky folder every user may write in, which that user can reach. Files
"planted" by that user are made here and given to it (``chown``); a program of that user
is a child process forked here that gives up root for the user's ids, so it needs no
interpreter the user could run.
"""

from __future__ import annotations

import json
import os
import secrets
import select
import shutil
import socket
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass
class OtherUser:
    """The second user: its name and ids."""

    name: str
    uid: int
    gid: int

    def chown(self, *paths: Path) -> None:
        """Give ``paths`` (links themselves, not their targets) to this user."""
        for path in paths:
            os.chown(path, self.uid, self.gid, follow_symlinks=False)

    def answer_stop_socket(self, path: Path, *, folder_mode: int = 0o755, socket_mode: int = 0o777) -> PlantedSocket:
        """Run, as this user, a program that answers ``vibrofocus stop`` at ``path`` as a server would.

        The user makes its folder (``folder_mode``), which must not exist yet and whose
        parent the user must be able to write in; the socket gets ``socket_mode``.
        """
        return PlantedSocket(self, Path(path), folder_mode, socket_mode)


class PlantedSocket:
    """A forked child, running as another user, answering every connection ``{"stopped": [...]}``.

    It reports each connection (``c``) and each request it read (``r``) on a pipe, so the
    test can tell whether the client talked to it.
    """

    def __init__(self, user: OtherUser, path: Path, folder_mode: int, socket_mode: int) -> None:
        self.path = path
        ready_r, ready_w = os.pipe()
        self._events, events_w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns into pytest
            code = 1
            try:
                os.close(ready_r)
                os.close(self._events)
                os.setgroups([])
                os.setgid(user.gid)
                os.setuid(user.uid)
                path.parent.mkdir()
                os.chmod(path.parent, folder_mode)
                sock = socket.socket(socket.AF_UNIX)
                sock.bind(str(path))
                os.chmod(path, socket_mode)
                sock.listen(16)
                os.write(ready_w, b"ok")
                while True:
                    conn, _ = sock.accept()
                    os.write(events_w, b"c")
                    conn.settimeout(2.0)
                    try:
                        if conn.recv(64):
                            os.write(events_w, b"r")
                        conn.sendall(json.dumps({"stopped": ["every rig output to 0 V", "session 1 paused"]}).encode()
                                     + b"\n")
                    except OSError:
                        pass
                    conn.close()
            except BaseException as exc:  # noqa: BLE001 - say why, then leave
                try:
                    os.write(ready_w, f"child failed: {exc!r}".encode()[:500])
                except OSError:
                    pass
            finally:
                os._exit(code)
        self.pid = pid
        os.close(ready_w)
        os.close(events_w)
        ready, _, _ = select.select([ready_r], [], [], 10.0)
        said = os.read(ready_r, 600) if ready else b"(nothing in 10 s)"
        os.close(ready_r)
        if said != b"ok":
            self.close()
            raise RuntimeError(f"the other user's socket did not start: {said.decode(errors='replace')}")

    def events(self) -> str:
        """What the child saw so far: one ``c`` per connection, one ``r`` per request read."""
        seen = b""
        while select.select([self._events], [], [], 0.2)[0]:
            chunk = os.read(self._events, 100)
            if not chunk:
                break
            seen += chunk
        return seen.decode()

    def close(self) -> None:
        try:
            os.kill(self.pid, 9)
        except ProcessLookupError:
            pass
        os.waitpid(self.pid, 0)
        os.close(self._events)

    def __enter__(self) -> PlantedSocket:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@pytest.fixture(scope="session")
def other_user():
    """A second local user, made for this test session and removed after it."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("needs root, to make a second local user")
    useradd, userdel = shutil.which("useradd"), shutil.which("userdel")
    if not (useradd and userdel):
        pytest.skip("needs useradd and userdel, to make a second local user")
    import pwd

    name = f"vft{os.getpid()}{secrets.token_hex(3)}"[:32]
    made = subprocess.run([useradd, "--no-create-home", "--user-group", "--shell", "/usr/sbin/nologin", name],
                          capture_output=True, text=True)
    if made.returncode != 0:
        pytest.skip(f"useradd could not make a user: {made.stderr.strip()}")
    try:
        entry = pwd.getpwnam(name)
        yield OtherUser(name, entry.pw_uid, entry.pw_gid)
    finally:
        subprocess.run([userdel, name], capture_output=True)


@pytest.fixture
def shared_dir(other_user):
    """A folder every user may write in, sticky (as a shared ``/tmp``-like folder), that the other user
    can reach (pytest's own temporary folders are root's alone); removed after the test."""
    path = Path(tempfile.mkdtemp(prefix="vibrofocus-shared-"))
    try:
        os.chmod(path, 0o1777)
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)
