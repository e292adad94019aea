"""Files below a root folder, written and read without following any link below it.

An export into a folder another person can write (a shared lab dataset, an archive from
someone else) must not let a link inside it send a write or a read elsewhere: a link at
``sub-01/beh/x.tsv`` to another file, or a folder ``sub-02`` that is a link to another
folder. The functions here walk every component below ``root`` with folder descriptors
(``openat`` with ``O_NOFOLLOW``), refuse any link on the way, create missing folders
there with ``mkdirat``, write the new file in the final folder's descriptor and rename it
over the old name in that same folder, so what is replaced is always the name itself (a
link that appears meanwhile is replaced, its target never touched). ``root`` itself may
be a link (the folder the user named).

- :func:`atomic_write_below` is :func:`vibrofocus._atomic.atomic_write` with this rule
  (``atomic_write(..., within=root)`` calls it);
- :func:`read_below` reads a regular file below ``root`` (no link, FIFO or device);
- :func:`link_below` names the first link on a path below ``root``, for a check before
  anything is written;
- :func:`lock_folder` holds an exclusive lock on a folder (another writer of it is told
  at once, not made to wait).

Part of the atomic-output family (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import contextlib
import errno as _errno
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from ._interrupts import critical_section, interrupt_pending
from ._oserrors import output_error
from ._output_rules import _kind_of_head, _umask, check_existing
from .errors import OutputError

__all__ = ["atomic_write_below", "read_below", "link_below", "lock_folder"]

_DIR_FLAGS = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)


def _parts(root: Path, path: Path, what: str) -> list[str]:
    """The components of ``path`` below ``root`` (lexically; no ``..``, none empty)."""
    try:
        rel = path.relative_to(root)
    except ValueError:
        raise OutputError(f"cannot write the {what} {path}: it is not inside {root}; nothing was written",
                          errno=_errno.EINVAL, path=str(path)) from None
    parts = list(rel.parts)
    if not parts or any(p in ("", ".", "..") for p in parts):
        raise OutputError(f"cannot write the {what} {path}: not a file name inside {root}; nothing was written",
                          errno=_errno.EINVAL, path=str(path))
    return parts


def _link_refusal(root: Path, parts: list[str], i: int, path: Path, what: str) -> OutputError:
    link = root.joinpath(*parts[: i + 1])
    return OutputError(f"cannot write the {what} {path}: {link} is a link: refused (nothing is written through a "
                       "link inside the folder); nothing was written", errno=_errno.ELOOP, path=str(path))


def _open_folder(root: Path, parts: list[str], path: Path, what: str, *, create: bool) -> int:
    """A descriptor of the folder ``root/parts...``, no component below ``root`` a link.

    Missing folders are made when ``create`` (in their parent's descriptor).
    """
    try:
        fd = os.open(root, _DIR_FLAGS)
    except OSError as exc:
        raise output_error(exc, path, what) from exc
    try:
        for i, name in enumerate(parts):
            try:
                st = os.stat(name, dir_fd=fd, follow_symlinks=False)
            except FileNotFoundError:
                if not create:
                    raise OutputError(f"cannot write the {what} {path}: the folder {root.joinpath(*parts[: i + 1])} "
                                      "does not exist", errno=_errno.ENOENT, path=str(path)) from None
                with contextlib.suppress(FileExistsError):
                    os.mkdir(name, 0o777, dir_fd=fd)
                st = os.stat(name, dir_fd=fd, follow_symlinks=False)
            if stat.S_ISLNK(st.st_mode):
                raise _link_refusal(root, parts, i, path, what)
            if not stat.S_ISDIR(st.st_mode):
                raise OutputError(f"cannot write the {what} {path}: {root.joinpath(*parts[: i + 1])} is not a folder",
                                  errno=_errno.ENOTDIR, path=str(path))
            try:
                child = os.open(name, _DIR_FLAGS | _NOFOLLOW, dir_fd=fd)
            except OSError as exc:
                if exc.errno in (_errno.ELOOP, _errno.ENOTDIR):  # made a link since the check
                    raise _link_refusal(root, parts, i, path, what) from None
                raise
            os.close(fd)
            fd = child
        return fd
    except OSError as exc:
        os.close(fd)
        raise output_error(exc, path, what) from exc
    except BaseException:
        os.close(fd)
        raise


def _lstat(dfd: int, name: str) -> os.stat_result | None:
    try:
        return os.stat(name, dir_fd=dfd, follow_symlinks=False)
    except FileNotFoundError:
        return None


def _head(dfd: int, name: str) -> bytes:
    try:
        fd = os.open(name, os.O_RDONLY | _NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0), dir_fd=dfd)
    except OSError:
        return b""
    try:
        return os.read(fd, 4096) if stat.S_ISREG(os.fstat(fd).st_mode) else b""
    except OSError:
        return b""
    finally:
        os.close(fd)


def _check_target(root: Path, parts: list[str], dfd: int, path: Path, what: str, kind: str | None
                  ) -> os.stat_result | None:
    """The rules of :func:`vibrofocus._atomic.output_target` for ``parts[-1]`` in ``dfd``; a link is refused."""
    st = _lstat(dfd, parts[-1])
    if st is not None and stat.S_ISLNK(st.st_mode):
        raise _link_refusal(root, parts, len(parts) - 1, path, what)
    check_existing(path, what, st, kind=kind, head=lambda: _head(dfd, parts[-1]))
    return st


def link_below(root: str | os.PathLike, path: str | os.PathLike) -> Path | None:
    """The first component of ``path`` below ``root`` that is a symbolic link, or None.

    The walk stops at the first missing component (nothing below it exists) or at one
    that is not a folder. ``root`` itself is not checked.

    Parameters
    ----------
    root, path : path-like
        ``path`` is ``root`` joined with relative names.

    Returns
    -------
    Path or None
        The link (``root/...``), or None when no component below ``root`` is one.
    """
    root, path = Path(root), Path(path)
    parts = _parts(root, path, "file")
    try:
        fd = os.open(root, _DIR_FLAGS)
    except OSError:
        return None
    try:
        for i, name in enumerate(parts):
            st = _lstat(fd, name)
            if st is None:
                return None
            if stat.S_ISLNK(st.st_mode):
                return root.joinpath(*parts[: i + 1])
            if not stat.S_ISDIR(st.st_mode) or i == len(parts) - 1:
                return None
            try:
                child = os.open(name, _DIR_FLAGS | _NOFOLLOW, dir_fd=fd)
            except OSError as exc:
                if exc.errno in (_errno.ELOOP, _errno.ENOTDIR):
                    return root.joinpath(*parts[: i + 1])
                return None
            os.close(fd)
            fd = child
        return None
    finally:
        os.close(fd)


def read_below(root: str | os.PathLike, path: str | os.PathLike, *, what: str = "file",
               limit: int | None = None) -> bytes | None:
    """The bytes of the regular file ``path`` below ``root``, no component a link; None if missing.

    Parameters
    ----------
    root, path : path-like
        ``path`` is ``root`` joined with relative names.
    what : str
        What the file is, for messages.
    limit : int, optional
        Most bytes read, else the file is refused as too large.

    Raises
    ------
    OutputError
        A link on the way, a folder, FIFO, device or socket at ``path`` (never opened
        for reading, so a FIFO cannot block), a file larger than ``limit``, or a read error.
    """
    root, path = Path(root), Path(path)
    parts = _parts(root, path, what)
    try:
        dfd = _open_folder(root, parts[:-1], path, what, create=False)
    except OutputError as exc:
        if exc.errno == _errno.ENOENT:
            return None
        raise
    try:
        st = _lstat(dfd, parts[-1])
        if st is None:
            return None
        if stat.S_ISLNK(st.st_mode):
            raise _link_refusal(root, parts, len(parts) - 1, path, what)
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"cannot read the {what} {path}: it is not a regular file", errno=_errno.EINVAL,
                              path=str(path))
        try:
            fd = os.open(parts[-1], os.O_RDONLY | _NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0),
                         dir_fd=dfd)
        except OSError as exc:
            if exc.errno == _errno.ELOOP:
                raise _link_refusal(root, parts, len(parts) - 1, path, what) from None
            raise output_error(exc, path, what) from exc
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped since the check
                raise OutputError(f"cannot read the {what} {path}: it is not a regular file", errno=_errno.EINVAL,
                                  path=str(path))
            chunks, total = [], 0
            while chunk := os.read(fd, 1 << 20):
                chunks.append(chunk)
                total += len(chunk)
                if limit is not None and total > limit:
                    raise OutputError(f"cannot read the {what} {path}: it is larger than {limit:,} bytes",
                                      errno=_errno.EFBIG, path=str(path))
            return b"".join(chunks)
        except OSError as exc:
            raise output_error(exc, path, what) from exc
        finally:
            os.close(fd)
    finally:
        os.close(dfd)


@contextlib.contextmanager
def atomic_write_below(
    root: str | os.PathLike,
    path: str | os.PathLike,
    mode: str = "wb",
    *,
    encoding: str | None = "utf-8",
    newline: str | None = None,
    what: str = "file",
    kind: str | None = None,
    parents: bool = False,
) -> Iterator[IO[Any]]:
    """Write ``path`` below ``root`` atomically, refusing any link below ``root`` on its way.

    As :func:`vibrofocus._atomic.atomic_write` (a temporary file beside the target,
    fsynced, renamed over it; nothing changes on failure or Ctrl-C; the rules of
    :func:`vibrofocus._atomic.output_target`), except that a symbolic link at the target
    or at any folder between ``root`` and it is refused (``"... is a link: refused"``),
    checked again just before the rename, and the rename is made in the folder's
    descriptor, so a link that appears meanwhile is replaced itself, never its target.

    Parameters
    ----------
    root : path-like
        The folder the file must stay in (itself may be a link).
    path : path-like
        The file, ``root`` joined with relative names.
    mode : {"wb", "w"}
        Binary or text.
    encoding, newline : str, optional
        For text mode.
    what : str
        What is written, for messages.
    kind : str, optional
        The kind of the new file, for the rule on replacing a file of another kind.
    parents : bool
        Make missing folders below ``root`` (never through a link).

    Yields
    ------
    file object

    Raises
    ------
    OutputError
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write_below mode must be 'w' or 'wb', got {mode!r}")
    root, path = Path(root), Path(path)
    parts = _parts(root, path, what)
    name = parts[-1]
    dfd = _open_folder(root, parts[:-1], path, what, create=parents)
    try:
        old = _check_target(root, parts, dfd, path, what, kind)
        file_mode = old.st_mode & 0o7777 if old is not None else 0o666 & ~_umask()
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
        while True:
            tmp = f".{name}.{secrets.token_hex(4)}.tmp"
            try:
                fd = os.open(tmp, flags, 0o600, dir_fd=dfd)
                break
            except FileExistsError:
                continue
            except OSError as exc:
                raise output_error(exc, path, what) from exc
        try:
            try:
                fh = os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": encoding, "newline": newline}))
                with fh:
                    yield fh
                    fh.flush()
                    os.fchmod(fh.fileno(), file_mode)
                    os.fsync(fh.fileno())
            except OSError as exc:
                raise output_error(exc, path, what) from exc
            with critical_section():
                if interrupt_pending() is not None:
                    raise KeyboardInterrupt
                _check_target(root, parts, dfd, path, what, _kind_of_head(_head(dfd, tmp)))
                try:
                    os.replace(tmp, name, src_dir_fd=dfd, dst_dir_fd=dfd)
                except OSError as exc:
                    raise output_error(exc, path, what) from exc
                with contextlib.suppress(OSError):
                    os.fsync(dfd)
        except BaseException:
            with critical_section(), contextlib.suppress(OSError):
                os.unlink(tmp, dir_fd=dfd)
            raise
    finally:
        os.close(dfd)


@contextlib.contextmanager
def lock_folder(folder: str | os.PathLike, busy: str) -> Iterator[None]:
    """Hold an exclusive lock (``flock``) on ``folder`` for the body; refuse at once if another holds it.

    The lock is on the folder itself (no lock file is left in it) and ends with the
    process, however it ends.

    Parameters
    ----------
    folder : path-like
        An existing folder.
    busy : str
        The message when another process holds the lock.

    Raises
    ------
    OutputError
        ``busy`` (``EWOULDBLOCK``), or the folder cannot be opened.
    """
    import fcntl

    folder = Path(folder)
    try:
        fd = os.open(folder, _DIR_FLAGS)
    except OSError as exc:
        raise output_error(exc, folder, "folder") from exc
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(busy, errno=_errno.EWOULDBLOCK, path=str(folder)) from None
        except OSError as exc:  # a file system without locks: go on unlocked
            if exc.errno not in (_errno.ENOLCK, _errno.EINVAL, _errno.EOPNOTSUPP):
                raise output_error(exc, folder, "folder") from exc
        yield
    finally:
        os.close(fd)
