"""One job per physical device, across threads and processes.

A hardware rig takes an exclusive, non-blocking ``flock`` on a lock file named after its
device when it opens and releases it when it closes (or when its process ends, whatever
the cause: the kernel drops the lock with the file descriptor). A second rig on the same
device, in this process or in another one (``vibrofocus calibrate`` while ``vibrofocus
serve`` runs), is refused with :class:`~vibrofocus.rigs.DeviceBusyError` naming the
process that holds it.

The lock files live in ``$VIBROFOCUS_LOCK_DIR`` when set, else in a folder of the
user's own under the system's temporary folder.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

from .devices import DeviceBusyError

__all__ = ["DeviceLock", "lock_dir"]


def lock_dir() -> Path:
    """The folder of the device lock files (created 0700 if missing)."""
    env = os.environ.get("VIBROFOCUS_LOCK_DIR")
    folder = Path(env) if env else Path(tempfile.gettempdir()) / f"vibrofocus-locks-{os.getuid()}"
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    return folder


class DeviceLock:
    """An exclusive lock on one physical device.

    Parameters
    ----------
    device_id : str
        The device's identity, e.g. ``"nidaq:Dev1"`` or ``"audio:focusrite usb"``.
    owner : str
        What takes it, shown to whoever is refused.
    """

    def __init__(self, device_id: str, owner: str):
        self.device_id = device_id
        self.owner = owner
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", device_id)[:100]
        self.path = lock_dir() / f"{safe}.lock"
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> "DeviceLock":
        """Take the lock now or raise :class:`DeviceBusyError` (never waits)."""
        if self._fd is not None:
            return self
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = self._read_holder(fd)
            os.close(fd)
            raise DeviceBusyError(
                f"{self.device_id} is in use by {holder}; one job uses a device at a time. Wait until it "
                "ends, or stop it first"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        info = {"pid": os.getpid(), "owner": self.owner, "since": time.strftime("%Y-%m-%d %H:%M:%S"),
                "command": " ".join(os.path.basename(a) for a in sys.argv[:3])}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(info).encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        """Give the lock back (no-op when not held)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                os.ftruncate(fd, 0)
            finally:
                os.close(fd)  # closing the descriptor drops the flock

    @staticmethod
    def _read_holder(fd: int) -> str:
        try:
            info = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
        except (OSError, ValueError):
            info = {}
        if not info:
            return "another job"
        return f"{info.get('owner', 'a job')} (process {info.get('pid', '?')}, {info.get('command', '')}, since {info.get('since', '?')})"

    def __enter__(self) -> "DeviceLock":
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # a rig that was never closed still frees its device
        try:
            self.release()
        except Exception:  # noqa: BLE001
            pass
