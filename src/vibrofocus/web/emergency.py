"""The emergency stop of a running ``vibrofocus serve``: the one action, and a way to it without TCP.

:func:`stop_all` is what the page's emergency stop does: every rig's outputs to 0 V,
every calibration cancelled, every running session paused (and stored as paused).

``vibrofocus stop`` reaches the same action through a Unix socket that the server opens
(:class:`StopListener`), so the stop works when the TCP port is flooded, the browser has
hung or the page is closed:

- the socket is ``stop.sock`` in the database's files folder (``<db stem>-files/``,
  which the server keeps 0700); when that path is too long for a Unix socket, it is
  ``vibrofocus-stop-<hash of the database path>.sock`` in ``$XDG_RUNTIME_DIR`` (a folder
  only this user can enter);
- the socket itself is 0600 and every connection's peer is checked (``SO_PEERCRED``):
  only the user running the server (or root) is answered. Another local user can neither
  reach the folder nor pass the check, so cannot trigger a stop; the socket has its own
  thread and nobody else can connect to it, so cannot block it either.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import socket
import struct
import threading
from pathlib import Path
from typing import Any

from ..errors import StudyError, ValidationError

__all__ = ["stop_all", "stop_socket_path", "StopListener", "request_stop"]

log = logging.getLogger(__name__)

#: Longest path a Unix socket can be bound at (``sun_path`` less its final NUL), bytes.
_MAX_SOCKET_PATH = 107
#: What the client sends, and the largest request read.
_REQUEST = b"stop\n"


def stop_all(web: Any) -> list[str]:
    """Everything to a stop now: the page's emergency stop and ``vibrofocus stop``.

    Parameters
    ----------
    web : WebState
        The app's state.

    Returns
    -------
    list of str
        What was stopped, as people read it.
    """
    done = web.emergency_stop()
    with web.lock:
        session_ids = list(web.runners)
    for sid in session_ids:
        with web.db:
            try:
                if web.store.session(sid).status == "running":
                    web.store.set_status(sid, "paused")
            except StudyError:
                continue
    log.warning("emergency stop: %s", "; ".join(done) or "nothing was running")
    return done


def stop_socket_path(db_path: str | os.PathLike) -> Path | None:
    """Where the server of ``db_path`` listens for ``vibrofocus stop``; None if nowhere fits.

    Parameters
    ----------
    db_path : path-like
        The study database.

    Returns
    -------
    Path or None
        ``<db stem>-files/stop.sock``, or a path in ``$XDG_RUNTIME_DIR`` when that one is
        too long for a Unix socket.
    """
    db = Path(db_path).resolve()
    primary = db.parent / f"{db.stem}-files" / "stop.sock"
    if len(os.fsencode(primary)) <= _MAX_SOCKET_PATH:
        return primary
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime:
        digest = hashlib.sha256(os.fsencode(db)).hexdigest()[:20]
        other = Path(runtime) / f"vibrofocus-stop-{digest}.sock"
        if len(os.fsencode(other)) <= _MAX_SOCKET_PATH:
            return other
    return None


def _peer_uid(conn: socket.socket) -> int | None:
    """The user id of a Unix socket's peer (Linux ``SO_PEERCRED``); None where unknown."""
    opt = getattr(socket, "SO_PEERCRED", None)
    if opt is None:
        return None
    creds = conn.getsockopt(socket.SOL_SOCKET, opt, struct.calcsize("3i"))
    return struct.unpack("3i", creds)[1]


class StopListener:
    """A thread answering ``vibrofocus stop`` on the server's stop socket.

    Parameters
    ----------
    web : WebState
        The app's state (:func:`stop_all` runs on it).
    path : Path
        The socket's path (:func:`stop_socket_path`).
    """

    def __init__(self, web: Any, path: Path) -> None:
        self.web, self.path = web, Path(path)
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False

    def start(self) -> bool:
        """Bind the socket and start answering; False (with a warning logged) if it cannot be made."""
        if not hasattr(socket, "AF_UNIX"):
            return False
        try:
            self.path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
            st = self.path.parent.stat()
            if st.st_uid != os.getuid() or st.st_mode & 0o077:
                raise OSError(f"{self.path.parent} is not a folder only this user can enter")
            self._clear_stale()
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            old = os.umask(0o177)  # 0600 from the start: no window where others could connect
            try:
                sock.bind(str(self.path))
            finally:
                os.umask(old)
            sock.listen(8)
        except OSError as exc:
            log.warning("'vibrofocus stop' is not available for this server (%s); the page's emergency stop still is", exc)
            return False
        self._sock = sock
        self._thread = threading.Thread(target=self._serve, name="vibrofocus-stop-socket", daemon=True)
        self._thread.start()
        return True

    def close(self) -> None:
        """Stop answering and remove the socket."""
        self._closing = True
        sock, self._sock = self._sock, None
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
            try:
                self.path.unlink()
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(2.0)

    def _clear_stale(self) -> None:
        """Remove a socket left by a server that died; refuse if one still answers there."""
        if not (self.path.exists() or self.path.is_symlink()):
            return
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        probe.settimeout(1.0)
        try:
            probe.connect(str(self.path))
        except OSError:
            self.path.unlink()  # nobody listens: a dead server's socket
            return
        finally:
            probe.close()
        raise OSError(f"another server already answers at {self.path}")

    def _serve(self) -> None:
        while not self._closing:
            try:
                conn, _ = self._sock.accept()
            except OSError:
                return  # closed
            with conn:
                try:
                    self._answer(conn)
                except Exception:  # noqa: BLE001 - the listener must keep answering
                    log.exception("the stop socket could not answer a request")

    def _answer(self, conn: socket.socket) -> None:
        uid = _peer_uid(conn)
        if uid is not None and uid not in (os.getuid(), 0):
            conn.sendall(json.dumps({"error": "not the user running this server"}).encode() + b"\n")
            return
        conn.settimeout(2.0)
        data = b""
        while not data.endswith(b"\n") and len(data) < 64:
            chunk = conn.recv(64)
            if not chunk:
                break
            data += chunk
        if data != _REQUEST:
            conn.sendall(json.dumps({"error": "unknown request"}).encode() + b"\n")
            return
        done = stop_all(self.web)
        conn.sendall(json.dumps({"stopped": done}).encode() + b"\n")


def request_stop(db_path: str | os.PathLike, timeout_s: float = 5.0) -> list[str]:
    """Ask the ``vibrofocus serve`` of ``db_path`` to stop everything now.

    Parameters
    ----------
    db_path : path-like
        The study database the server was started with.
    timeout_s : float
        Longest wait for the server's answer, s.

    Returns
    -------
    list of str
        What the server stopped.

    Raises
    ------
    ValidationError
        No server of this database answers (none running, or it has no stop socket).
    """
    path = stop_socket_path(db_path)
    where = f"--db {db_path}"
    if path is None or not (path.exists() or path.is_symlink()):
        raise ValidationError(f"{where}: no 'vibrofocus serve' of this database is running (no stop socket); "
                              "if a server is running, use its page's emergency stop or switch the amplifier off")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.settimeout(timeout_s)
    try:
        sock.connect(str(path))
        sock.sendall(_REQUEST)
        answer = b""
        while not answer.endswith(b"\n"):
            chunk = sock.recv(65536)
            if not chunk:
                break
            answer += chunk
    except OSError as exc:
        raise ValidationError(f"{where}: the server's stop socket did not answer ({exc.strerror or exc}); "
                              "switch the amplifier off") from None
    finally:
        sock.close()
    try:
        reply = json.loads(answer)
    except ValueError:
        raise ValidationError(f"{where}: the server gave no answer to the stop; switch the amplifier off") from None
    if "error" in reply:
        raise ValidationError(f"{where}: the server refused the stop ({reply['error']})")
    return [str(x) for x in reply.get("stopped", [])]
