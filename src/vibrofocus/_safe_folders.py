"""Folders in the shared temporary folder that another local user may have made first.

``/tmp`` is writable by every user: a folder of a fixed name there may already exist,
made by someone else, or be a symbolic link to somewhere else. Two kinds are used:

- a **private** folder (the error logs): ours, not a link, and closed to other users;
- a **shared** folder (the device locks, machine-wide on purpose): not a link, and, when
  other users may write in it, sticky, so that none of them can remove or replace the
  files of another.

Both checks are POSIX ones; on Windows the temporary folder is per user and these return
no problem.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["private_folder_problem", "shared_folder_problem"]


def _owner(uid: int) -> str:
    try:
        import pwd

        return f"user {pwd.getpwuid(uid).pw_name} (uid {uid})"
    except (ImportError, KeyError):
        return f"uid {uid}"


def _open_folder(path: Path) -> tuple[int | None, str | None]:
    """The folder opened without following a link (checks and mode changes on the descriptor
    cannot be turned elsewhere meanwhile), or the problem."""
    import errno

    try:
        return os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW), None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return None, "is a symbolic link (refused: it could lead anywhere)"
        if exc.errno == errno.ENOTDIR:
            return None, ("is a symbolic link (refused: it could lead anywhere)" if os.path.islink(path)
                          else "is not a folder")
        return None, f"cannot be opened ({exc.strerror or exc})"


def private_folder_problem(path: Path) -> str | None:
    """Make ``path`` (mode 0700) if missing; say what is wrong with it if it is not ours alone.

    Parameters
    ----------
    path : Path
        The folder; its parent must exist.

    Returns
    -------
    str or None
        None when it is a folder (not a link) owned by this user and closed to the others
        (a group or other permission on a folder of ours is taken away); else the problem,
        as the end of a sentence that starts with the folder's name.
    """
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        return f"cannot be made ({exc.strerror or exc})"
    if os.name == "nt":
        return None
    fd, problem = _open_folder(path)
    if problem:
        return problem
    try:
        st = os.fstat(fd)
        if st.st_uid != os.geteuid():
            return f"belongs to {_owner(st.st_uid)}, not to you"
        if stat.S_IMODE(st.st_mode) & 0o077:
            try:
                os.fchmod(fd, 0o700)
            except OSError as exc:
                return f"is open to other users and its mode cannot be changed ({exc.strerror or exc})"
        return None
    finally:
        os.close(fd)


def shared_folder_problem(path: Path) -> str | None:
    """Make ``path`` (mode 1777: every user's, sticky) if missing; say what is wrong with it.

    Parameters
    ----------
    path : Path
        The folder; missing parents are made.

    Returns
    -------
    str or None
        None when it is a folder (not a link) that either no one else may write in, or
        that has the sticky bit (each user may remove only the files they own); else the
        problem, as the end of a sentence that starts with the folder's name.
    """
    try:
        os.makedirs(path.parent, exist_ok=True)
        os.mkdir(path, 0o700)
    except FileExistsError:
        made = False
    except OSError as exc:
        return f"cannot be made ({exc.strerror or exc})"
    else:
        made = True
    if os.name == "nt":
        return None
    fd, problem = _open_folder(path)
    if problem:
        return problem
    try:
        st = os.fstat(fd)
        if made and st.st_uid == os.geteuid():
            try:  # the umask narrowed the mode mkdir was given; every user locks here
                os.fchmod(fd, 0o1777)
            except OSError as exc:
                return f"cannot be opened to every user ({exc.strerror or exc})"
            st = os.fstat(fd)
        mode = stat.S_IMODE(st.st_mode)
        if mode & 0o022 and not mode & stat.S_ISVTX:
            return (f"belongs to {_owner(st.st_uid)} with mode {mode:04o}: other users may write in it without "
                    "the sticky bit, so any of them could remove or replace its files")
        return None
    finally:
        os.close(fd)
