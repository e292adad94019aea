"""Owner-only files and folders (0600 / 0700) for the web app's participant data.

Its own module below :mod:`.state` and :mod:`.logins`, which both use it, so neither
imports the other's helpers.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

__all__ = ["private_dir", "private_file", "private_journal", "owner_only"]

log = logging.getLogger(__name__)


def private_dir(path: Path) -> None:
    """Create a folder only its owner can enter (0700); tighten it if it exists."""
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    owner_only(path, 0o700)


def private_file(path: Path) -> None:
    """Create an empty file only its owner can read (0600), or tighten an existing one.

    The study database holds participant data: it is created 0600 before SQLite opens
    it (SQLite gives its journal files the database's mode).
    """
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except FileExistsError:
        owner_only(path, 0o600)
    except OSError:  # a read-only folder: the store says so in its own words
        pass


def owner_only(path: Path, mode: int) -> None:
    """Tighten ``path`` to ``mode`` (e.g. 0o600) when it is ours and others could read it."""
    try:
        st = path.stat()
        if st.st_uid == os.getuid() and st.st_mode & 0o077:
            os.chmod(path, mode)
            log.warning("%s could be read by other users; it is now %s", path.name, oct(mode))
    except OSError:  # not ours, or a file system without modes: leave it as it is
        pass


def private_journal(db_path: Path) -> None:
    """Tighten the database's -wal and -shm to 0600 where they exist (a crashed writer's)."""
    for suffix in ("-wal", "-shm", "-journal"):
        path = db_path.with_name(db_path.name + suffix)
        if path.exists():
            owner_only(path, 0o600)
