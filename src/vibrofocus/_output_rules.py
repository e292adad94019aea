"""What an output may replace, and the file modes and folder checks every writer shares.

:func:`output_target` holds the rules (never a folder, a device, a FIFO or a socket;
through a symbolic link only to a regular file; never a file the running command reads,
:func:`protect`; inside a command, :func:`output_guard`, an existing file of another kind
only with ``--force``, :func:`allow_overwrite`). Part of the atomic-output family
(:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno as _errno
import os
import re
import stat
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ._oserrors import output_error
from .errors import OutputError

__all__ = ["TRIALS_CSV", "DRIVES_CSV", "REPORT_JSON", "new_file_mode", "file_kind", "output_guard", "allow_overwrite", "guarding", "protect", "output_target"]


# ---------------------------------------------------------------------- file modes
def _umask() -> int:
    """The process umask, read without changing it where the system tells (Linux)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    umask = os.umask(0o022)  # elsewhere: set and restore at once
    os.umask(umask)
    return umask


def new_file_mode(target: Path) -> int:
    """Mode for a file replacing ``target``: the old file's, else ``0o666 & ~umask``."""
    try:
        return os.stat(target).st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


#: Leading bytes of the kinds of file a command may meet at an output name.
_MAGIC = (
    (b"SQLite format 3\x00", "SQLite database"),
    (b"\x89HDF\r\n\x1a\n", "HDF5/netCDF file (a calibration?)"),
    (b"PK\x03\x04", "zip/npz archive"),
    (b"PK\x05\x06", "zip/npz archive"),
    (b"\x89PNG\r\n\x1a\n", "PNG image"),
    (b"GIF8", "GIF image"),
    (b"%PDF", "PDF document"),
)
#: The kind each output suffix is written as (for the check before writing).
_SUFFIX_KIND = {
    ".nc": "HDF5/netCDF file (a calibration?)", ".npz": "zip/npz archive", ".png": "PNG image",
    ".gif": "GIF image", ".wav": "WAV audio", ".csv": "text file", ".json": "text file", ".html": "text file",
    ".txt": "text file", ".md": "text file",
}
_TEXT = "text file"

#: Text files told apart by their first lines, so that one command's CSV or JSON never
#: silently replaces another's (both are "text" by their bytes).
TRIALS_CSV = "trials CSV"
DRIVES_CSV = "drives CSV"
REPORT_JSON = "report JSON"
_TEXT_KINDS = (
    (re.compile(rb"\A(\xef\xbb\xbf)?participant,study,phase,trial,"), TRIALS_CSV),
    (re.compile(rb'\A# software: "vibrofocus"\n|^# time_s,', re.M), DRIVES_CSV),
    (re.compile(rb'\A\s*\{\s*"generator":\s*"vibrofocus [^"]*",\s*"source":[^\n]*\n\s*"n_trials":'), REPORT_JSON),
)


def file_kind(path: str | os.PathLike) -> str | None:
    """What a file holds, from its first bytes: ``"SQLite database"``, ``"text file"``, ...

    Parameters
    ----------
    path : path-like
        A regular file.

    Returns
    -------
    str or None
        None for an empty or unreadable file (nothing to lose by its kind).
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    return _kind_of_head(head)


def _kind_of_head(head: bytes) -> str | None:
    """:func:`file_kind` from a file's first 4096 bytes."""
    if not head:
        return None
    for magic, kind in _MAGIC:
        if head.startswith(magic):
            return kind
    if head[:4] == b"RIFF" and head[8:12] == b"WAVE":
        return "WAV audio"
    if b"\x00" in head:
        return "binary file"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 3:  # not just a character cut at the 4096th byte
            return "binary file"
    for pattern, kind in _TEXT_KINDS:
        if pattern.search(head):
            return kind
    return _TEXT


@dataclass
class _Guard:
    """What the running command reads (by device and inode, or by path before it exists) and ``--force``."""

    inodes: dict[tuple[int, int], tuple[str, str]] = field(default_factory=dict)
    paths: dict[str, str] = field(default_factory=dict)
    force: bool = False


_guard: contextvars.ContextVar[_Guard | None] = contextvars.ContextVar("vibrofocus_output_guard", default=None)


@contextlib.contextmanager
def output_guard(*, force: bool = False) -> Iterator[None]:
    """Within the body (one command), outputs never replace what :func:`protect` named.

    Also turns on the kind rule of :func:`output_target`: an existing file of another
    kind is replaced only when ``force`` (or :func:`allow_overwrite`) says so.

    Parameters
    ----------
    force : bool
        The command's ``--force``.
    """
    token = _guard.set(_Guard(force=bool(force)))
    try:
        yield
    finally:
        _guard.reset(token)


def allow_overwrite(force: bool) -> None:
    """Set ``--force`` for the running command (no effect outside :func:`output_guard`)."""
    guard = _guard.get()
    if guard is not None:
        guard.force = bool(force)


def guarding() -> bool:
    """Whether a command's :func:`output_guard` is active (else :func:`protect` does nothing)."""
    return _guard.get() is not None


def protect(paths: str | os.PathLike | Iterable[str | os.PathLike], what: str) -> None:
    """Name files the running command reads or keeps state in; no output may replace them.

    Compared by device and inode (a second name, a hard link or a symbolic link is the
    same file), and by resolved path for a file not created yet (a new study database).
    Outside :func:`output_guard` (the Python API) this does nothing.

    Parameters
    ----------
    paths : path-like or iterable of path-like
    what : str
        What the file is, for the message (``"study database"``).
    """
    guard = _guard.get()
    if guard is None:
        return
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    for p in paths:
        with contextlib.suppress(OSError, ValueError):
            guard.paths.setdefault(os.path.realpath(p), what)
            st = os.stat(p)
            guard.inodes.setdefault((st.st_dev, st.st_ino), (what, os.path.abspath(p)))


_NOT_REGULAR = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"))


def output_target(path: str | os.PathLike, what: str = "file", *, kind: str | None = None) -> Path:
    """Check that ``path`` may receive a new file; return the real path to write to.

    The one place for these rules (every writer of :mod:`vibrofocus._atomic` applies
    them before writing and again before the rename):

    - a folder, a device, a FIFO or a socket is never replaced;
    - a symbolic link is followed: to a regular file it is written through (the file is
      replaced, the link stays); to nothing it is refused;
    - a file the running command reads or keeps state in (:func:`protect`) is refused,
      compared by device and inode;
    - inside a command (:func:`output_guard`), an existing non-empty file of another
      kind than ``kind`` (see :func:`file_kind`) needs ``--force``.

    Parameters
    ----------
    path : path-like
        The output name the user gave.
    what : str
        What is written, for messages.
    kind : str, optional
        The kind of the new file (:func:`file_kind` of it, or from the suffix); None
        skips the kind rule.

    Returns
    -------
    Path
        Where to put the file: ``path`` itself, or the file a symbolic link points to.

    Raises
    ------
    OutputError
        Naming the path and the rule.
    """
    path = Path(path)
    real = Path(os.path.realpath(path))

    def refuse(reason: str, err: int | None = None) -> OutputError:
        return OutputError(f"cannot write the {what} {path}: {reason}; nothing was written", errno=err,
                           path=str(path))

    if path.is_symlink() and not real.exists():
        raise refuse("it is a symbolic link to a missing file; give the file's own name", _errno.ENOENT)
    try:
        st = os.stat(real)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise output_error(exc, path, what) from exc
    check_existing(path, what, st, kind=kind, real=real, linked=path.is_symlink(),
                   head=lambda: _read_head(real))
    return real


def _read_head(path: Path) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(4096)
    except OSError:
        return b""


def _protected(guard: _Guard, st: os.stat_result | None, real: Path | None) -> str | None:
    """What the running command reads at this inode (or resolved path), if anything.

    An inode counts only while the file protected under it still has it: a journal
    (``-wal``) deleted since, whose inode number a new file reuses, is not the database.
    """
    if st is not None:
        entry = guard.inodes.get((st.st_dev, st.st_ino))
        if entry is not None:
            what, name = entry
            try:
                now = os.stat(name)
            except OSError:
                now = None
            if now is not None and (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino):
                return what
    return guard.paths.get(str(real)) if real is not None else None


def check_existing(path: Path, what: str, st: os.stat_result | None, *, kind: str | None,
                   head: Callable[[], bytes], real: Path | None = None, linked: bool = False) -> None:
    """The rules of :func:`output_target` on the file found at an output name.

    Parameters
    ----------
    path : Path
        The output name, for messages.
    what : str
        What is written.
    st : os.stat_result or None
        The file there (None: none).
    kind : str, optional
        The new file's kind (None skips the kind rule).
    head : callable
        Returns the old file's first bytes (for its kind).
    real : Path, optional
        Its resolved path (for files protected before they existed).
    linked : bool
        Whether ``path`` is a link to it (for the wording).

    Raises
    ------
    OutputError
    """
    def refuse(reason: str, err: int | None = None) -> OutputError:
        return OutputError(f"cannot write the {what} {path}: {reason}; nothing was written", errno=err,
                           path=str(path))

    if st is not None:
        for test, name in _NOT_REGULAR:
            if test(st.st_mode):
                raise refuse(f"{'it points to' if linked else 'it is'} {name}, not a regular file; "
                             "choose a file name", _errno.EISDIR if name == "a folder" else _errno.EINVAL)
    guard = _guard.get()
    if guard is None:
        return
    # By inode; by path too, for a file protected before it existed (a new database).
    same = _protected(guard, st, real)
    if same is not None:
        raise refuse(f"it is the {same} this command reads (the same file); choose another name", _errno.EEXIST)
    if st is not None and kind is not None and not guard.force:
        old = _kind_of_head(head())
        if old is not None and old != kind:
            raise refuse(f"it holds a {old}, not a {kind}; choose another name, or pass --force to replace it",
                         _errno.EEXIST)


def _suffix_kind(path: Path) -> str | None:
    return _SUFFIX_KIND.get(path.suffix.lower())


# ---------------------------------------------------------------------- helpers
def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where folders can be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _unlink_quietly(path: str | os.PathLike) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def _check_folder(path: Path, what: str) -> None:
    _check_parent(path, what)
    if path.is_dir():
        raise OutputError(f"cannot write the {what} {path}: a folder of that name is in the way",
                          errno=_errno.EISDIR, path=str(path))


def _check_parent(path: Path, what: str) -> None:
    folder = path.parent
    if not folder.exists():
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} does not exist",
                          errno=_errno.ENOENT, path=str(path))
    if not folder.is_dir():
        raise OutputError(f"cannot write the {what} {path}: {folder} is not a folder",
                          errno=_errno.ENOTDIR, path=str(path))
