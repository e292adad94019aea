"""The client half of ``vibrofocus stop``: the stop socket's path, its checks, and the request.

Standard library only, so the terminal stop answers in milliseconds: ``python -m
vibrofocus stop`` (and the ``vibrofocus`` command) handle ``stop`` here before importing
the command line (:func:`main`). The server half is :mod:`vibrofocus.web.emergency`; the
rules are in its docstring and docs/security.md.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import stat
import struct
import sys
import time
from pathlib import Path

from ._db_files import files_dir
from ._owners import owner_name
from .errors import ValidationError

__all__ = ["stop_socket_path", "request_stop", "main"]

#: Longest path a Unix socket can be bound at (``sun_path`` less its final NUL), bytes.
_MAX_SOCKET_PATH = 107
#: What the client sends.
_REQUEST = b"stop\n"
#: How every failure of ``vibrofocus stop`` ends.
_SWITCH_OFF = "switch the amplifier off"


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
    primary = files_dir(db) / "stop.sock"
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


def _trusted_uid(uid: int) -> bool:
    """This user, or root."""
    return uid in (os.geteuid(), 0)


def _socket_problem(path: Path, *, socket_too: bool = True) -> str | None:
    """What makes the stop socket at ``path`` (or its folder) one this user cannot trust; None if nothing.

    The folder and the socket must be this user's (or root's), not links, and closed to
    other users: else another user may have made them, and may answer in the server's place.
    """
    if os.name == "nt":  # no owners or modes to check there
        return None
    folder = path.parent
    problem = _not_owned(folder, f"its folder {folder}", stat.S_ISDIR, "folder")
    if problem or not socket_too:
        return problem
    return _not_owned(path, str(path), stat.S_ISSOCK, "socket")


def _not_owned(path: Path, name: str, is_kind, kind: str) -> str | None:
    """What makes ``path`` (called ``name``) not this user's own ``kind``, closed to others; None if nothing."""
    try:
        st = os.lstat(path)
    except OSError as exc:
        return f"{name} cannot be read ({exc.strerror or exc})"
    if stat.S_ISLNK(st.st_mode):
        return f"{name} is a symbolic link"
    if not is_kind(st.st_mode):
        return f"{path} is not a {kind}"
    if not _trusted_uid(st.st_uid):
        return f"{name} belongs to {owner_name(st.st_uid)}, not to you"
    if stat.S_IMODE(st.st_mode) & 0o077:
        return f"{name} is open to other users (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def request_stop(db_path: str | os.PathLike, timeout_s: float = 5.0) -> list[str]:
    """Ask the ``vibrofocus serve`` of ``db_path`` to stop everything now.

    The socket is believed only if it and its folder are the user's own (or root's) and
    closed to others, and the peer that answers runs as the user (or root).

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
        Not stopped: no server of this database answers (none running, or it has no stop
        socket), the socket cannot be trusted, or the server refused or gave no answer.
        The message starts with "not stopped" and ends with "switch the amplifier off".
    """
    path = stop_socket_path(db_path)
    where = f"--db {db_path}"
    if path is None or not os.path.lexists(path):
        raise ValidationError(f"not stopped: {where}: no 'vibrofocus serve' of this database is running (no stop socket); "
                              f"if a server is running, use its page's emergency stop or {_SWITCH_OFF}")
    problem = _socket_problem(path)
    if problem:
        raise ValidationError(f"not stopped: {where}: the stop socket cannot be the server's ({problem}); {_SWITCH_OFF}")
    deadline = time.monotonic() + timeout_s
    sock = None
    try:
        while True:
            sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                sock.connect(str(path))
                break
            except BlockingIOError:  # its queue of connections is full for now (a busy or flooded server)
                sock.close()
                if time.monotonic() >= deadline:
                    raise
                time.sleep(0.02)
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        uid = _peer_uid(sock)
        if uid is not None and not _trusted_uid(uid):
            raise ValidationError(f"not stopped: {where}: the program at the stop socket runs as {owner_name(uid)}, "
                                  f"not as you: it is not the server; {_SWITCH_OFF}")
        sock.sendall(_REQUEST)
        answer = b""
        while not answer.endswith(b"\n") and len(answer) < 1 << 20:
            chunk = sock.recv(65536)
            if not chunk:
                break
            answer += chunk
    except OSError as exc:
        raise ValidationError(f"not stopped: {where}: the server's stop socket did not answer "
                              f"({exc.strerror or exc}); {_SWITCH_OFF}") from None
    finally:
        if sock is not None:
            sock.close()
    try:
        reply = json.loads(answer)
    except ValueError:
        reply = None
    if not isinstance(reply, dict):
        raise ValidationError(f"not stopped: {where}: the server gave no answer to the stop; {_SWITCH_OFF}")
    if "error" in reply:
        raise ValidationError(f"not stopped: {where}: the server refused the stop ({str(reply['error'])[:200]}); "
                              f"{_SWITCH_OFF}")
    stopped = reply.get("stopped")
    if not isinstance(stopped, list):
        raise ValidationError(f"not stopped: {where}: the server's answer says nothing was stopped; {_SWITCH_OFF}")
    return [str(x) for x in stopped]


def main(argv: list[str]) -> int | None:
    """``vibrofocus stop [--db PATH]`` without the command line's imports; None for anything else.

    Parameters
    ----------
    argv : list of str
        The arguments after the program's name.

    Returns
    -------
    int or None
        The exit status (0 stopped, 2 not stopped, 130 interrupted), or None when
        ``argv`` is not a plain stop: the full command line handles it (``--help``, a
        bad option).
    """
    if not argv or argv[0] != "stop":
        return None
    rest = argv[1:]
    if not rest:
        db = "vibrofocus-studies.sqlite"
    elif len(rest) == 2 and rest[0] == "--db" and rest[1] and not rest[1].startswith("-"):
        db = rest[1]
    elif len(rest) == 1 and rest[0].startswith("--db=") and len(rest[0]) > 5:
        db = rest[0][5:]
    else:
        return None
    try:
        done = request_stop(db)
    except ValidationError as exc:
        text = "".join(ch if ch.isprintable() else " " for ch in str(exc))
        print(f"error: {text}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        print(f"error: interrupted: not stopped; {_SWITCH_OFF}", file=sys.stderr, flush=True)
        return 130
    print("stopped: " + ("; ".join(done) if done else "nothing was running"), flush=True)
    return 0
