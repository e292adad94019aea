"""The emergency stop of a running ``vibrofocus serve``: the one action, and a way to it without TCP.

:func:`stop_all` is what the page's emergency stop does: every rig's outputs to 0 V,
every calibration cancelled, every running session paused (and stored as paused).

``vibrofocus stop`` reaches the same action through a Unix socket that the server opens
(:class:`StopListener`), so the stop works when the TCP port is flooded, the browser has
hung or the page is closed:

- the socket is ``stop.sock`` in the database's files folder (``<db stem>-files/``,
  which must be the server's user's alone: see :mod:`.private`); when that path is too
  long for a Unix socket, it is ``vibrofocus-stop-<hash of the database path>.sock`` in
  ``$XDG_RUNTIME_DIR`` (a folder only this user can enter);
- the socket itself is 0600 and every connection's peer is checked (``SO_PEERCRED``):
  only the user running the server (or root) is answered. Another local user can neither
  reach the folder nor pass the check, so cannot trigger a stop;
- the listener reads every connection's request at once (one thread, non-blocking) and
  drops a peer silent for :data:`READ_TIMEOUT_S`: no connection, even of the same user,
  delays another's stop;
- a server is the one server of its database (:class:`ServerGuard`): it holds a lock in
  the files folder that names its PID and port, and refuses to start when it cannot
  take that lock or make its stop socket. ``vibrofocus serve`` prints how to stop it
  only once both are done.

The client (:func:`request_stop`) believes only a socket that can be the server's: the
socket and its folder must be the user's own (or root's) and closed to others, and the
peer that answers must run as the user (or root). On any doubt it says "not stopped"
and to switch the amplifier off.
"""

from __future__ import annotations

import json
import logging
import os
import selectors
import socket
import stat
import threading
import time
from pathlib import Path
from typing import Any

from ..errors import StudyError, ValidationError
from .._stop_client import (  # noqa: F401  (the client half, light enough for a fast `vibrofocus stop`)
    _MAX_SOCKET_PATH,
    _REQUEST,
    _peer_uid,
    _socket_problem,
    _trusted_uid,
    request_stop,
    stop_socket_path,
)

__all__ = ["stop_all", "stop_socket_path", "StopListener", "ServerGuard", "request_stop", "READ_TIMEOUT_S"]

log = logging.getLogger(__name__)

#: Largest request read, bytes.
_MAX_REQUEST = 64
#: Longest wait for a connection's request once it is accepted, s; a silent peer is then dropped.
READ_TIMEOUT_S = 0.3
#: Most connections waiting for their request at once; beyond it the oldest is dropped.
MAX_PENDING = 64
#: The lock file in the files folder held by the one server of a database.
LOCK_NAME = "server.lock"


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


class StopListener:
    """A thread answering ``vibrofocus stop`` on the server's stop socket.

    One thread reads every connection's request at once, so that no connection delays
    another's; a peer that sends nothing for :data:`READ_TIMEOUT_S` is dropped, and
    beyond :data:`MAX_PENDING` waiting connections the oldest is.

    Parameters
    ----------
    web : WebState
        The app's state (:func:`stop_all` runs on it).
    path : Path
        The socket's path (:func:`stop_socket_path`); its folder must exist and be this
        user's alone.
    """

    def __init__(self, web: Any, path: Path) -> None:
        self.web, self.path = web, Path(path)
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._closing = False
        self._wake: tuple[int, int] | None = None
        self._inode: int | None = None

    def start(self) -> bool:
        """Bind the socket and start answering.

        Returns
        -------
        bool
            True.

        Raises
        ------
        StudyError
            The socket cannot be made: no Unix sockets, a folder that is not this user's
            alone, another server answering there, or a system error.
        """
        if not hasattr(socket, "AF_UNIX"):
            raise StudyError("'vibrofocus stop' needs Unix sockets, which this system does not have")
        problem = _socket_problem(self.path, socket_too=False)
        if problem:
            raise StudyError(f"the stop socket {self.path} cannot be made: {problem}")
        try:
            self._clear_stale()
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            old = os.umask(0o177)  # 0600 from the start: no window where others could connect
            try:
                sock.bind(str(self.path))
            except OSError:
                sock.close()
                raise
            finally:
                os.umask(old)
            sock.listen(socket.SOMAXCONN)
            sock.setblocking(False)
            self._inode = os.lstat(self.path).st_ino
            self._wake = os.pipe()
        except OSError as exc:
            raise StudyError(f"the stop socket {self.path} cannot be made ({exc.strerror or exc})") from None
        self._sock = sock
        self._thread = threading.Thread(target=self._serve, name="vibrofocus-stop-socket", daemon=True)
        self._thread.start()
        return True

    def close(self) -> None:
        """Stop answering and remove the socket."""
        self._closing = True
        if self._wake is not None:
            try:
                os.write(self._wake[1], b"x")
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(5.0)
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
            try:
                if os.lstat(self.path).st_ino == self._inode:  # ours, not a later server's
                    self.path.unlink()
            except OSError:
                pass
        if self._wake is not None:
            for fd in self._wake:
                os.close(fd)
            self._wake = None

    def _clear_stale(self) -> None:
        """Remove a socket left by a server that died; refuse if one still answers there."""
        if not os.path.lexists(self.path):
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

    # ------------------------------------------------------------------ the thread
    def _serve(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._sock, selectors.EVENT_READ, "accept")
        sel.register(self._wake[0], selectors.EVENT_READ, "wake")
        pending: dict[socket.socket, tuple[float, bytearray]] = {}  # oldest first
        try:
            while not self._closing:
                timeout = max(0.0, min(d for d, _ in pending.values()) - time.monotonic()) if pending else None
                for key, _ in sel.select(timeout):
                    if key.data == "wake":
                        return
                    if key.data == "accept":
                        self._accept(sel, pending)
                    else:
                        self._read(sel, pending, key.fileobj)
                now = time.monotonic()
                for conn in [c for c, (deadline, _) in pending.items() if deadline <= now]:
                    self._drop(sel, pending, conn)  # silent too long
        except Exception:  # noqa: BLE001 - say so: the stop socket is gone
            log.exception("the stop socket stopped answering; the page's emergency stop still works")
        finally:
            for conn in list(pending):
                self._drop(sel, pending, conn)
            sel.close()

    def _accept(self, sel: selectors.BaseSelector, pending: dict) -> None:
        while True:
            try:
                conn, _ = self._sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return  # closed
            uid = _peer_uid(conn)
            if uid is not None and not _trusted_uid(uid):
                self._reply(conn, {"error": "not the user running this server"})
                continue
            if len(pending) >= MAX_PENDING:
                self._drop(sel, pending, next(iter(pending)))
            conn.setblocking(False)
            pending[conn] = (time.monotonic() + READ_TIMEOUT_S, bytearray())
            sel.register(conn, selectors.EVENT_READ, "read")

    def _read(self, sel: selectors.BaseSelector, pending: dict, conn: socket.socket) -> None:
        try:
            chunk = conn.recv(_MAX_REQUEST)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._drop(sel, pending, conn)
            return
        data = pending[conn][1]
        data += chunk
        if not (data.endswith(b"\n") or len(data) >= _MAX_REQUEST):
            return
        sel.unregister(conn)
        del pending[conn]
        if bytes(data) != _REQUEST:
            self._reply(conn, {"error": "unknown request"})
            return
        try:
            done = stop_all(self.web)
        except Exception:  # noqa: BLE001 - the listener must keep answering
            log.exception("the stop socket could not answer a request")
            self._reply(conn, {"error": "the stop failed on the server; its terminal says why"})
            return
        self._reply(conn, {"stopped": done})

    @staticmethod
    def _drop(sel: selectors.BaseSelector, pending: dict, conn: socket.socket) -> None:
        pending.pop(conn, None)
        try:
            sel.unregister(conn)
        except (KeyError, ValueError):
            pass
        conn.close()

    @staticmethod
    def _reply(conn: socket.socket, answer: dict) -> None:
        try:
            conn.settimeout(1.0)
            conn.sendall(json.dumps(answer).encode() + b"\n")
        except OSError:
            pass
        finally:
            conn.close()


class ServerGuard:
    """What makes a server the one server of its database, reachable by ``vibrofocus stop``.

    - :meth:`claim`: a lock (``flock``) on ``server.lock`` in the database's files folder,
      held while the server runs, which records its PID and port. A second server of the
      same database is refused, naming the first. The lock goes with the process, so a
      server that died leaves nothing to clean up.
    - :meth:`open_stop_socket`: the stop socket (:class:`StopListener`).

    Parameters
    ----------
    web : WebState
        The app's state (its ``db_path`` and ``data_dir``).
    """

    def __init__(self, web: Any) -> None:
        self.web = web
        self.listener: StopListener | None = None
        self._fd: int | None = None

    def claim(self, port: int | None = None) -> None:
        """Take the database's lock, recording this process's PID and ``port``.

        Raises
        ------
        StudyError
            Another server holds it (its PID and port are named), or the lock file is
            not this user's plain file.
        """
        try:
            import fcntl
        except ImportError:  # no flock (Windows): nothing to guard with
            return
        path = self.web.data_dir / LOCK_NAME  # the files folder is checked: ours alone, no link
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0) | os.O_NONBLOCK
        try:
            fd = os.open(path, flags, 0o600)
        except OSError as exc:
            raise StudyError(f"the server lock {path} cannot be opened ({exc.strerror or exc})") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid() or st.st_nlink != 1:
                raise StudyError(f"the server lock {path} is not a plain file of yours; remove it")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise StudyError(
                    f"another 'vibrofocus serve' already serves the study database {self.web.db_path} "
                    f"({_holder(fd)}): stop it first, or give this one another --db") from None
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        self.record_port(port)

    def record_port(self, port: int | None) -> None:
        """Write this process's PID and its TCP ``port`` in the lock file (for a second server to name)."""
        if self._fd is None:
            return
        data = json.dumps({"pid": os.getpid(), "port": port}).encode()
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, data, 0)

    def open_stop_socket(self) -> None:
        """Make the stop socket and answer on it.

        Raises
        ------
        StudyError
            No path fits a Unix socket, or the socket cannot be made (:meth:`StopListener.start`).
        """
        path = stop_socket_path(self.web.db_path)
        if path is None:
            raise StudyError(
                f"the study database's path {self.web.db_path} is too long for the socket of 'vibrofocus stop' "
                f"(at most {_MAX_SOCKET_PATH} bytes) and XDG_RUNTIME_DIR is not set: use a shorter path, or set "
                "XDG_RUNTIME_DIR to a folder only you can enter")
        listener = StopListener(self.web, path)
        listener.start()
        self.listener = listener

    def close(self) -> None:
        """Close the stop socket and give the lock back."""
        if self.listener is not None:
            self.listener.close()
            self.listener = None
        if self._fd is not None:
            os.close(self._fd)  # the lock goes with it
            self._fd = None

    def __enter__(self) -> ServerGuard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _holder(fd: int) -> str:
    """The PID and port a lock file names, as people read them."""
    try:
        info = json.loads(os.pread(fd, 256, 0))
        pid, port = int(info["pid"]), info.get("port")
    except (OSError, ValueError, TypeError, KeyError):
        return "its PID and port are not known yet"
    if isinstance(port, int) and not isinstance(port, bool):
        return f"PID {pid}, port {port}"
    return f"PID {pid}"
