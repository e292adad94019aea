"""Owner-only files and folders (0600 / 0700) for the web app's participant data.

Its own module below :mod:`.state` and :mod:`.logins`, which both use it, so neither
imports the other's helpers.

Nothing here trusts a file or folder that another local user could have made or could
change: the study database, its journals (``-wal``, ``-shm``, ``-journal``), the secret of
the participant keys, the list of logins and the files folder (``<db stem>-files/`` and
the folders in it) must be this user's, must not be links, and must not be writable by
other users; the database must sit in a folder that other users cannot write in.
Anything else is refused with one :class:`~vibrofocus.errors.StudyError` naming the file
and what is wrong. A file or folder of this user that others could only *read* is
closed to them (0600 / 0700) with a warning, as before.
"""

from __future__ import annotations

import errno
import logging
import os
import secrets
import stat
from pathlib import Path

from .._owners import owner_name
from ..errors import StudyError

__all__ = [
    "private_dir",
    "private_file",
    "private_journal",
    "check_database_folder",
    "private_database",
    "load_or_make_secret",
    "owner_name",
    "writable_by_others",
]

log = logging.getLogger(__name__)

#: Suffixes of SQLite's journal files beside a database.
JOURNAL_SUFFIXES = ("-wal", "-shm", "-journal")


def _private_group(gid: int) -> bool:
    """True if group ``gid`` is this user's own group (user private groups: only this user is in it).

    Many systems give every user a group of their own and a umask of 002, so the user's
    files and folders are group-writable without anyone else being able to write them.
    """
    if gid != os.getegid():
        return False
    try:
        import grp
        import pwd

        me = pwd.getpwuid(os.geteuid()).pw_name
        if set(grp.getgrgid(gid).gr_mem) - {me}:
            return False
        return not any(p.pw_gid == gid and p.pw_uid != os.geteuid() for p in pwd.getpwall())
    except (ImportError, KeyError):
        return False


def writable_by_others(st: os.stat_result) -> bool:
    """True if a file or folder of status ``st`` may be written by users other than its owner.

    Group write counts, unless the group is this user's own private group.
    """
    mode = stat.S_IMODE(st.st_mode)
    return bool(mode & 0o002) or bool(mode & 0o020 and not _private_group(st.st_gid))


def _refuse(path: Path, what: str, problem: str, advice: str = "") -> StudyError:
    return StudyError(f"the {what} {path} {problem}: refused, as another local user could read or change "
                      f"the study's data through it{'; ' + advice if advice else ''}")


def _check_ours(path: Path, st: os.stat_result, what: str, *, folder: bool) -> None:
    """Refuse ``path`` (already lstat-ed) unless it is this user's plain file or folder, closed to writers."""
    if stat.S_ISLNK(st.st_mode):
        raise _refuse(path, what, "is a symbolic link", "give the real path, or remove the link")
    if folder and not stat.S_ISDIR(st.st_mode):
        raise _refuse(path, what, "is not a folder")
    if not folder and not stat.S_ISREG(st.st_mode):
        raise _refuse(path, what, "is not a plain file")
    if st.st_uid != os.geteuid():
        raise _refuse(path, what, f"belongs to {owner_name(st.st_uid)}, not to you",
                      "remove it (or ask its owner to), then start again")
    if writable_by_others(st):
        raise _refuse(path, what, f"can be written by other users (mode {stat.S_IMODE(st.st_mode):04o})",
                      "check it, then make it yours alone (chmod go-rwx), or remove it")


def _tighten(path: Path, fd: int, st: os.stat_result, mode: int) -> None:
    """Close a file or folder of ours that others could read to ``mode``, with a warning."""
    if stat.S_IMODE(st.st_mode) & 0o077:
        try:
            os.fchmod(fd, mode)
        except OSError:  # a file system without modes
            return
        log.warning("%s could be read by other users; it is now %s", path.name, oct(mode))


def private_dir(path: Path, what: str = "folder") -> None:
    """Create a folder only its owner can enter (0700), or check an existing one.

    Parameters
    ----------
    path : Path
        The folder; missing parents are made.
    what : str
        What it is, for the error message.

    Raises
    ------
    StudyError
        The folder is a link, not a folder, another user's, or writable by other users.
    """
    path = Path(path)
    try:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
    except FileExistsError:  # a link to a missing folder, or a file
        pass
    if os.name == "nt":
        return
    _check_ours(path, os.lstat(path), what, folder=True)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENOTDIR):  # replaced since the check
            raise _refuse(path, what, "is a symbolic link") from None
        raise
    try:
        st = os.fstat(fd)
        _check_ours(path, st, what, folder=True)
        _tighten(path, fd, st, 0o700)
    finally:
        os.close(fd)


def _open_existing(path: Path, what: str, flags: int = os.O_RDONLY) -> int:
    """Open an existing file without following a link, after checking it is ours and closed to writers."""
    try:
        fd = os.open(path, flags | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NOCTTY", 0)
                     | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _refuse(path, what, "is a symbolic link", "give the real path, or remove the link") from None
        raise
    try:
        if os.name != "nt":  # no owners or modes to check there
            st = os.fstat(fd)
            _check_ours(path, st, what, folder=False)
            _tighten(path, fd, st, 0o600)
    except BaseException:
        os.close(fd)
        raise
    return fd


def private_file(path: Path, what: str = "file") -> None:
    """Create an empty file only its owner can read (0600), or check an existing one.

    The study database holds participant data: it is created 0600 before SQLite opens
    it (SQLite gives its journal files the database's mode).

    Parameters
    ----------
    path : Path
        The file.
    what : str
        What it is, for the error message (``study database``, ``list of logins``).

    Raises
    ------
    StudyError
        The file is a link, not a plain file, another user's, or writable by other users.
    """
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600))
        return
    except FileExistsError:
        pass
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EROFS, errno.EPERM) and not os.path.lexists(path):
            return  # a read-only folder: the store says so in its own words
        raise
    os.close(_open_existing(Path(path), what))


def private_journal(db_path: Path) -> None:
    """Check the database's -wal, -shm and -journal where they exist; close them to readers (0600).

    Raises
    ------
    StudyError
        One of them is a link, another user's, or writable by other users (SQLite would
        use it with the database's data).
    """
    # Checked by path, never opened: closing a descriptor of a file that SQLite has open in
    # this process drops SQLite's POSIX locks on it (fcntl semantics), and a -shm whose locks
    # are gone is reset by the next connection under the server's mapping (the server died
    # with SIGBUS in its next commit).
    for suffix in JOURNAL_SUFFIXES:
        path = db_path.with_name(db_path.name + suffix)
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            continue
        _check_ours(path, st, "database journal", folder=False)
        if os.name != "nt" and stat.S_IMODE(st.st_mode) & 0o077:
            try:
                os.chmod(path, 0o600)  # a plain file of ours (lstat above): no link to follow
            except OSError:  # a file system without modes
                continue
            log.warning("%s could be read by other users; it is now %s", path.name, oct(0o600))


def private_database(db_path: Path) -> None:
    """Check (or make) everything a server keeps beside its database, before SQLite opens it.

    The database's folder (:func:`check_database_folder`); the database itself, made 0600
    if missing; its journals; the list of logins and the files folder where they exist.
    The secret is checked when it is read (:func:`load_or_make_secret`).

    Parameters
    ----------
    db_path : Path
        The study database (resolved).

    Raises
    ------
    StudyError
        One of them is a link, another user's, or writable by other users; or the
        database's folder is open to other writers.
    """
    check_database_folder(db_path)
    private_file(db_path, "study database")
    private_journal(db_path)
    logins = db_path.with_name(db_path.name + ".web-logins")
    if os.path.lexists(logins):
        private_file(logins, "list of logins")
    from .._db_files import files_dir

    files = files_dir(db_path)
    if os.path.lexists(files):
        private_dir(files, "files folder")


def check_database_folder(db_path: Path) -> None:
    """Refuse a database directly in a folder that other users can write in.

    In such a folder (a shared ``/tmp``-like one, even sticky) another user can make the
    database, its journals, its secret or its files folder before the server does.

    Parameters
    ----------
    db_path : Path
        The study database (resolved: its folder is a real folder).

    Raises
    ------
    StudyError
        The folder belongs to another user (but root), or other users can write in it.
    """
    if os.name == "nt":
        return
    folder = Path(db_path).parent
    st = os.stat(folder)
    if st.st_uid not in (os.geteuid(), 0):
        raise StudyError(f"the study database {db_path} is in a folder of {owner_name(st.st_uid)}: refused, as "
                         "they could plant or replace the database, its secret or its files; put it in a folder "
                         "of your own")
    if writable_by_others(st):
        raise StudyError(f"the study database {db_path} is in a folder other users can write in "
                         f"(mode {stat.S_IMODE(st.st_mode):04o}): refused, as they could plant or replace the "
                         f"database, its secret or its files; make a folder of your own in it "
                         f"(mkdir -m 700 {folder / 'mine'}) and put the database there")


def load_or_make_secret(db_path: Path) -> bytes:
    """The HMAC secret of participant keys, kept beside the database (mode 0600, enforced).

    Parameters
    ----------
    db_path : Path
        The study database; the secret is ``<db>.web-secret``.

    Returns
    -------
    bytes
        The secret (32 random bytes when it is made).

    Raises
    ------
    StudyError
        The secret file is a link, another user's, writable by other users, or not a secret.
    """
    path = db_path.with_name(db_path.name + ".web-secret")
    if not os.path.lexists(path):
        secret = secrets.token_bytes(32)
        # Written whole under a name of its own, then linked to its name, which fails if the
        # name exists: two servers starting at once never each keep their own secret, and
        # none reads a half-written one.
        scratch = path.with_name(f".{path.name}.{secrets.token_hex(6)}.tmp")
        fd = os.open(scratch, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(secret.hex())
            try:
                os.link(scratch, path)
                return secret
            except FileExistsError:
                pass
        finally:
            os.unlink(scratch)
    with os.fdopen(_open_existing(path, "secret of the participant keys"), "rb") as fh:
        text = fh.read(1024)
    try:
        value = bytes.fromhex(text.decode("ascii").strip())
    except (UnicodeDecodeError, ValueError):
        value = b""
    if len(value) < 16:
        raise StudyError(f"the secret of the participant keys {path} is not one this server wrote; remove it "
                         "(the participant links of existing sessions change)")
    return value
