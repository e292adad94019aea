"""Folders put in place as a whole: :func:`atomic_directory` and :func:`make_output_folder`.

A report folder is built beside its target and swapped in with
``renameat2(RENAME_EXCHANGE)`` where the system has it. Part of the atomic-output
family (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno as _errno
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from ._interrupts import critical_section, interrupt_pending
from ._oserrors import output_error
from ._output_rules import _check_parent, _fsync_dir, _umask
from .errors import OutputError

__all__ = ["atomic_directory", "make_output_folder", "resolve_folder_link"]

_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path, flags: int = _RENAME_EXCHANGE) -> bool:
    """Swap two paths atomically with ``renameat2(RENAME_EXCHANGE)``; False where unsupported.

    With ``flags=RENAME_NOREPLACE``: rename ``a`` to ``b`` only if ``b`` does not exist
    (``FileExistsError`` if it does).
    """
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (_errno.ENOSYS, _errno.EINVAL, _errno.ENOTSUP, _errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _fsync_tree(folder: Path) -> None:
    for entry in folder.iterdir():
        if entry.is_file():
            fd = os.open(entry, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    _fsync_dir(folder)


def resolve_folder_link(path: str | os.PathLike, *, what: str = "folder") -> Path:
    """``path``, or the folder it points to when it is a symbolic link (the link stays).

    A folder given as a link is written through, as a single file is (see
    :func:`vibrofocus._atomic.output_target`): the target's content is replaced or
    merged, and no folder takes the link's place.

    Raises
    ------
    OutputError
        ``path`` is a link to nothing.
    """
    path = Path(path)
    if not path.is_symlink():
        return path
    real = Path(os.path.realpath(path))
    if not real.exists():
        raise OutputError(f"cannot write the {what} {path}: it is a symbolic link to a missing folder ({real}); "
                          "give the folder's own name or create it", errno=_errno.ENOENT, path=str(path))
    return real


@contextlib.contextmanager
def atomic_directory(
    path: str | os.PathLike,
    *,
    owned: Iterable[str] | Callable[[str], bool] | None = None,
    what: str = "folder",
    exclusive: bool = False,
) -> Iterator[Path]:
    """Build a folder beside ``path`` and put it in place as a whole, or not at all.

    The body writes plain files into the yielded temporary folder (a sibling of
    ``path``; a symbolic link to a folder is written through: the folder it points to
    is the one produced, and the link stays). On success:

    - if ``path`` is missing, or holds only entries this writer owns (``owned``), the
      new folder replaces it in one atomic swap (``renameat2(RENAME_EXCHANGE)``; where
      that is missing, two renames); the old folder is removed after the swap;
    - if ``path`` also holds other files (a user's own), those are left alone: the owned
      entries are swapped in one by one with interrupts deferred, old ones kept aside
      until every rename succeeded and put back if one fails; owned entries the new
      build lacks are removed.

    On any failure (no space, read-only, an exception, Ctrl-C) the temporary folder is
    removed and ``path`` is as it was.

    Parameters
    ----------
    path : path-like
        The folder to produce; its parent must exist (a mistyped parent is reported,
        not created).
    owned : set of str or callable, optional
        Names of the entries a build produces (or a predicate); default: every name the
        new build holds.
    what : str
        For error messages (``"report folder"``).
    exclusive : bool
        Only create ``path``: if it exists when the build is done (another process made
        it meanwhile), nothing is replaced and ``OutputError`` with ``errno`` ``EEXIST``
        is raised (``renameat2(RENAME_NOREPLACE)`` where the system has it).

    Raises
    ------
    OutputError
    """
    path = resolve_folder_link(path, what=what)
    _check_parent(path, what)
    if path.exists() and not path.is_dir():
        raise OutputError(f"cannot write the {what} {path}: a file of that name is in the way",
                          errno=_errno.ENOTDIR, path=str(path))
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as exc:
        raise output_error(exc, path, what) from exc
    try:
        try:
            yield tmp
            new_names = {p.name for p in tmp.iterdir()}
            if owned is None:
                is_owned = new_names.__contains__
            elif callable(owned):
                is_owned = owned
            else:
                owned_set = set(owned)
                is_owned = owned_set.__contains__
            os.chmod(tmp, os.stat(path).st_mode & 0o7777 if path.exists() else 0o777 & ~_umask())
            for entry in tmp.iterdir():
                if entry.is_file():
                    os.chmod(entry, 0o666 & ~_umask())
            _fsync_tree(tmp)
        except OSError as exc:
            raise output_error(exc, path, what) from exc
        with critical_section():
            if interrupt_pending() is not None:
                raise KeyboardInterrupt
            try:
                existing = [p.name for p in path.iterdir()] if path.exists() else None
                if exclusive and (existing is not None or not _create_only(tmp, path)):
                    raise OutputError(f"cannot write the {what} {path}: another process created it meanwhile; "
                                      "nothing was written", errno=_errno.EEXIST, path=str(path))
                if exclusive:
                    _fsync_dir(path.parent)
                elif existing is None:
                    os.rename(tmp, path)
                    _fsync_dir(path.parent)
                elif all(is_owned(name) for name in existing):
                    _swap_whole(tmp, path)
                else:
                    _swap_entries(tmp, path, [n for n in existing if is_owned(n)])
            except OSError as exc:
                raise output_error(exc, path, what) from exc
    finally:
        with critical_section():
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _create_only(new: Path, path: Path) -> bool:
    """Rename folder ``new`` to ``path`` unless ``path`` exists; False if it does."""
    try:
        if _exchange(new, path, _RENAME_NOREPLACE):
            return True
    except FileExistsError:
        return False
    if path.exists() or path.is_symlink():  # no renameat2: the check and the rename are two steps
        return False
    os.rename(new, path)
    return True


def _swap_whole(new: Path, path: Path) -> None:
    """Put folder ``new`` at ``path`` (which exists); the old one ends up at ``new`` and is removed."""
    if _exchange(new, path):
        _fsync_dir(path.parent)
        shutil.rmtree(new, ignore_errors=True)  # the old folder, now under the temp name
        return
    aside = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
    os.rmdir(aside)
    os.rename(path, aside)
    try:
        os.rename(new, path)
    except OSError:
        os.rename(aside, path)
        raise
    _fsync_dir(path.parent)
    shutil.rmtree(aside, ignore_errors=True)


def _swap_entries(new: Path, path: Path, stale: list[str]) -> None:
    """Move the entries of ``new`` into ``path``, replacing/removing ``stale`` ones, all or nothing."""
    aside = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
    moved_aside: list[str] = []
    moved_in: list[str] = []
    try:
        for name in stale:
            os.rename(path / name, aside / name)
            moved_aside.append(name)
        for entry in sorted(new.iterdir()):
            os.rename(entry, path / entry.name)
            moved_in.append(entry.name)
    except OSError:
        for name in reversed(moved_in):
            with contextlib.suppress(OSError):
                os.rename(path / name, new / name)
        for name in reversed(moved_aside):
            with contextlib.suppress(OSError):
                os.rename(aside / name, path / name)
        shutil.rmtree(aside, ignore_errors=True)
        raise
    _fsync_dir(path)
    shutil.rmtree(aside, ignore_errors=True)


def make_output_folder(path: str | os.PathLike, *, what: str = "output folder") -> Path:
    """Create the output folder ``path`` if missing; its parent must exist (a typo is reported, not created).

    Parameters
    ----------
    path : path-like
    what : str
        For error messages.

    Returns
    -------
    Path

    Raises
    ------
    OutputError
        The parent is missing, a file is in the way, or the folder cannot be made.
    """
    path = Path(path)
    if path.is_dir():
        return path
    _check_parent(path, what)
    if path.exists() or path.is_symlink():
        raise OutputError(f"cannot make the {what} {path}: a file of that name is in the way",
                          errno=_errno.EEXIST, path=str(path))
    try:
        path.mkdir()
    except OSError as exc:
        raise output_error(exc, path, what) from exc
    return path
