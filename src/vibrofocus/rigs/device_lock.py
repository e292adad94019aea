"""One job per physical device, across threads, processes and users.

A hardware rig takes an exclusive, non-blocking lock on a file named after its device
when it opens, and releases it when it closes (or when its process ends, whatever the
cause: the system drops the lock with the file descriptor). A second rig on the same
device, in this process, in another one or of another user (``vibrofocus calibrate``
while ``vibrofocus serve`` runs), is refused with :class:`~vibrofocus.rigs.DeviceBusyError`
naming the process that holds it.

One device may be named in several ways (an audio interface by each host API:
``"MOTU Pro Audio"``, ``"Out 1-2 (MOTU Pro Audio)"``, MME's 31-character cut). A lock
may therefore stand on several files (:class:`LockKey`): the audio rig locks one file per
word that identifies its interface, the rule by which the cue check tells two names of
one interface apart (:func:`~vibrofocus.rigs.audio.audio_lock_keys`).

Where the lock files live: ``$VIBROFOCUS_LOCK_DIR`` when set, else one folder for the
whole machine (``/tmp/vibrofocus-locks``; ``%PROGRAMDATA%\\vibrofocus\\locks`` on
Windows), made sticky and writable by every user, so that the users of one machine see
each other's locks. The folder is refused when it is a symbolic link, or when other users
may write in it without the sticky bit; a lock file is opened without following links,
never truncated on opening, and refused unless it is a plain file with one name. A
hostile local user can still hold a device's lock (as they could use the device itself),
but cannot make a job write into another file (docs/security.md).

Locks are ``flock`` where the system has ``fcntl``, byte-range locks (``msvcrt``) on
Windows; ``import vibrofocus.rigs`` needs neither.
"""

from __future__ import annotations

import errno
import json
import os
import re
import stat
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .devices import DeviceBusyError, DeviceError

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None  # type: ignore[assignment]
try:
    import msvcrt
except ImportError:  # everywhere but Windows
    msvcrt = None  # type: ignore[assignment]

__all__ = ["DeviceLock", "LockKey", "lock_dir"]

#: The machine-wide folder on POSIX systems (not ``$TMPDIR``, which may be per user).
POSIX_LOCK_DIR = Path("/tmp/vibrofocus-locks")
#: Holder information read back from a lock file, bytes at most.
_HOLDER_BYTES = 4096
# Windows byte-range locks: far past the holder information, one byte per shared holder.
_RANGE_OFFSET = 1 << 30
_SHARED_SLOTS = 64


def lock_dir() -> Path:
    """The folder of the device lock files (made, sticky and writable by every user, if missing).

    Raises
    ------
    DeviceError
        When the folder is a symbolic link, not a folder, or writable by other users
        without the sticky bit.
    """
    from .._safe_folders import shared_folder_problem

    env = os.environ.get("VIBROFOCUS_LOCK_DIR")
    if env:
        folder = Path(env)
    elif os.name == "nt":
        folder = Path(os.environ.get("PROGRAMDATA") or tempfile.gettempdir()) / "vibrofocus" / "locks"
    else:
        folder = POSIX_LOCK_DIR
    problem = shared_folder_problem(folder)
    if problem:
        raise DeviceError(f"the device lock folder {folder} {problem}; no device was opened. Remove it (or set "
                          "VIBROFOCUS_LOCK_DIR to a folder of your own) and try again")
    return folder


@dataclass(frozen=True)
class LockKey:
    """One lock file of a device lock.

    Attributes
    ----------
    name : str
        What the file is named after (``"nidaq:Dev1"``, ``"audio-word:motu"``).
    shared : bool
        Taken shared: it excludes only the holders that take it exclusively.
    """

    name: str
    shared: bool = False

    def path(self, folder: Path) -> Path:
        """The lock file in ``folder``: the name with every run of other characters than
        letters, digits, ``_``, ``.`` and ``-`` made one ``_``, cut at 100."""
        return folder / (re.sub(r"[^A-Za-z0-9_.-]+", "_", self.name)[:100] + ".lock")


class DeviceLock:
    """An exclusive lock on one physical device.

    Parameters
    ----------
    device_id : str
        The device as people read it, e.g. ``"nidaq:Dev1"`` or ``"audio:focusrite"``.
    owner : str
        What takes it, shown to whoever is refused.
    keys : sequence of LockKey, optional
        The files the lock stands on; default one exclusive file named after ``device_id``.
    """

    def __init__(self, device_id: str, owner: str, keys: "list[LockKey] | tuple[LockKey, ...] | None" = None):
        self.device_id = device_id
        self.owner = owner
        self.keys = tuple(keys) if keys else (LockKey(device_id),)
        self.folder = lock_dir()
        #: The first lock file (the holder information is written in every file held).
        self.path = self.keys[0].path(self.folder)
        # (descriptor, Windows byte range start or None, shared), in the order taken.
        self._held: list[tuple[int, int | None, bool]] = []

    @property
    def held(self) -> bool:
        return bool(self._held)

    def acquire(self) -> "DeviceLock":
        """Take the lock now or raise :class:`DeviceBusyError` (never waits)."""
        if self._held:
            return self
        info = json.dumps({"pid": os.getpid(), "owner": self.owner, "since": time.strftime("%Y-%m-%d %H:%M:%S"),
                           "command": " ".join(os.path.basename(a) for a in sys.argv[:3])}).encode()
        try:
            for key in self.keys:
                path = key.path(self.folder)
                fd = _open_lock_file(path)
                try:
                    start = _try_lock(fd, key.shared)
                except BaseException:
                    os.close(fd)
                    raise
                if start is False:
                    holder = _read_holder(fd)
                    os.close(fd)
                    raise DeviceBusyError(f"{self.device_id} is in use by {holder}; one job uses a device at a time. "
                                          "Wait until it ends, or stop it first")
                self._held.append((fd, start, key.shared))
                if not key.shared:
                    _write_holder(fd, info)
        except BaseException:
            self.release()
            raise
        return self

    def release(self) -> None:
        """Give the lock back (no-op when not held)."""
        held, self._held = self._held, []
        for fd, start, shared in reversed(held):
            try:
                if not shared:
                    _clear_holder(fd)
                _unlock(fd, start)
            except OSError:
                pass
            finally:
                os.close(fd)  # closing the descriptor drops the lock

    def __enter__(self) -> "DeviceLock":
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # a rig that was never closed still frees its device
        try:
            self.release()
        except Exception:  # noqa: BLE001
            pass


# -- the files ----------------------------------------------------------------------------
def _open_lock_file(path: Path) -> int:
    """Open (or make) a lock file: never through a link, never truncated, only a plain file with one name."""
    flags = os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0) \
        | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, os.O_RDWR | flags, 0o666)
    except PermissionError:
        try:  # another user's file that we may not write: a lock needs only reading
            fd = os.open(path, os.O_RDONLY | flags, 0o666)
        except OSError as exc:
            raise _open_error(path, exc) from None
    except OSError as exc:
        raise _open_error(path, exc) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
            raise DeviceError(f"the device lock file {path} is not a plain file with one name (refused: it could "
                              "stand for another file); remove it and try again")
        if os.name != "nt" and st.st_uid == os.geteuid() and stat.S_IMODE(st.st_mode) != 0o666:
            os.fchmod(fd, 0o666)  # the umask narrowed it; other users lock the same device here
    except BaseException:
        os.close(fd)
        raise
    return fd


def _open_error(path: Path, exc: OSError) -> DeviceError:
    if exc.errno == errno.ELOOP or (exc.errno in (errno.EMLINK, errno.ENOTDIR) and os.path.islink(path)):
        return DeviceError(f"the device lock file {path} is a symbolic link (refused: someone may want a job to "
                           "write into the file it points to); remove it and try again")
    return DeviceError(f"cannot open the device lock file {path}: {exc.strerror or exc}")


def _try_lock(fd: int, shared: bool) -> int | None | bool:
    """Lock without waiting: None (flock) or the Windows range start when taken, False when busy."""
    if fcntl is not None:
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        except (BlockingIOError, PermissionError):
            return False
        return None
    if msvcrt is not None:
        # No shared mode: a shared holder takes one byte of the range, an exclusive one the whole range.
        for start, n in ([(_RANGE_OFFSET + i, 1) for i in range(_SHARED_SLOTS)] if shared
                         else [(_RANGE_OFFSET, _SHARED_SLOTS)]):
            os.lseek(fd, start, os.SEEK_SET)
            try:
                msvcrt.locking(fd, msvcrt.LK_NBLCK, n)
            except OSError:
                continue
            return start
        return False
    raise DeviceError("this system offers no file locks (neither fcntl nor msvcrt), so vibrofocus cannot keep two "
                      "jobs off one device; no device was opened")


def _unlock(fd: int, start: int | None) -> None:
    if start is None or msvcrt is None:
        return  # flock: closing the descriptor unlocks
    os.lseek(fd, start, os.SEEK_SET)
    msvcrt.locking(fd, msvcrt.LK_UNLCK, _SHARED_SLOTS if start == _RANGE_OFFSET else 1)


def _write_holder(fd: int, info: bytes) -> None:
    try:
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, info)
    except OSError:
        pass  # a file we may only read: the lock holds, without the holder's name


def _clear_holder(fd: int) -> None:
    try:
        os.ftruncate(fd, 0)
    except OSError:
        pass


def _read_holder(fd: int) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        info = json.loads(os.read(fd, _HOLDER_BYTES).decode() or "{}")
    except (OSError, ValueError):
        info = {}
    if not isinstance(info, dict) or not info:
        return "another job"
    # Any user may write in a lock file: what it says is shown, printable and short.
    text = (f"{info.get('owner', 'a job')} (process {info.get('pid', '?')}, {info.get('command', '')}, since "
            f"{info.get('since', '?')})")
    text = "".join(ch if ch.isprintable() else " " for ch in text)
    return text if len(text) <= 200 else text[:197] + "..."
