"""Atomic output: every file vibrofocus writes appears whole under its name, or not at all.

One family of helpers used by every writer of the package (calibration netCDF, drives
``.npz``/``.csv``/``.wav``, JSON, HTML, PNG, trials CSV, report folders):

- :func:`atomic_write` / :func:`atomic_path` write to a temporary file in the target's
  folder, flush and ``fsync`` it, then ``os.replace`` it over the target and ``fsync``
  the folder. Whatever fails (no space, no permission, an exception, Ctrl-C), the
  temporary file is removed and the previous file under the target name is untouched.
- :func:`atomic_directory` builds a folder (a report) beside the target and swaps it in
  as a whole (``renameat2(RENAME_EXCHANGE)`` where the system has it).
- :func:`check_writable` checks, before a long measurement, that a file can be written
  at a path and that its folder has room for it.
- :func:`output_error` turns an :class:`OSError` (``ENOSPC``, ``EDQUOT``, ``EACCES``,
  ``EPERM``, ``EROFS``, ...) into an :class:`~vibrofocus.errors.OutputError` with one
  clear line.

Interrupts: the commit (rename) runs with SIGINT/SIGTERM deferred (see
:func:`critical_section`), so an interrupt leaves either the old file or the complete
new one. An interrupt noted while a library swallowed it (:func:`interrupt_pending`)
stops the save before the commit.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno as _errno
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from .errors import OutputError

__all__ = [
    "atomic_write",
    "atomic_path",
    "atomic_directory",
    "write_bytes",
    "write_text",
    "save_figure",
    "check_writable",
    "output_error",
    "describe_os_error",
    "critical_section",
    "interrupt_pending",
    "clear_interrupt",
    "install_signal_handlers",
    "new_file_mode",
]

#: Errors that mean "this location cannot take the file", reported as one line.
OUTPUT_ERRNOS = {
    _errno.ENOSPC: "no space left on the device",
    _errno.EDQUOT: "the disk quota is exceeded",
    _errno.EACCES: "permission denied",
    _errno.EPERM: "operation not permitted",
    _errno.EROFS: "the file system is read-only",
    _errno.EFBIG: "the file is too large for the file system",
    _errno.EIO: "input/output error on the device",
    _errno.ENOENT: "no such file or folder",
    _errno.ENOTDIR: "a part of the path is not a folder",
    _errno.EISDIR: "it is a folder",
    _errno.ENAMETOOLONG: "the name is too long",
}

#: Opens the temporary file's descriptor (a seam for tests that inject a full disk).
_open_fd = os.fdopen

#: Headroom asked of a folder beyond the expected size of a file, bytes.
SPACE_MARGIN_BYTES = 1 << 20


# ---------------------------------------------------------------------- errors
def describe_os_error(exc: OSError) -> str:
    """A short human phrase for an :class:`OSError` (``"no space left on the device"``)."""
    if exc.errno in OUTPUT_ERRNOS:
        return OUTPUT_ERRNOS[exc.errno]
    return exc.strerror or str(exc) or type(exc).__name__


def output_error(exc: OSError, path: str | os.PathLike, what: str = "file") -> OutputError:
    """The :class:`OutputError` to raise when writing ``what`` to ``path`` failed with ``exc``.

    Parameters
    ----------
    exc : OSError
        The error from the system.
    path : path-like
        The target (not the temporary file).
    what : str
        What was being written, for the message (``"calibration"``, ``"drives file"``).

    Returns
    -------
    OutputError
        With ``errno`` and ``path`` set; the message ends by saying the previous file is
        unchanged.
    """
    path = Path(path)
    hint = ""
    if exc.errno in (_errno.ENOSPC, _errno.EDQUOT):
        hint = "; free some space or choose another location"
    elif exc.errno in (_errno.EACCES, _errno.EPERM, _errno.EROFS):
        hint = "; choose a writable location"
    return OutputError(
        f"cannot write the {what} {path}: {describe_os_error(exc)}{hint} (nothing was written under that name; "
        "a previous file there is unchanged)",
        errno=exc.errno,
        path=str(path),
    )


# ---------------------------------------------------------------------- interrupts
_lock = threading.Lock()
_critical_depth = 0
_pending_signal: int | None = None
_HANDLED = (signal.SIGINT, signal.SIGTERM)


def _handler(signum: int, frame: Any) -> None:
    """SIGINT/SIGTERM: note it; raise KeyboardInterrupt unless inside a critical section."""
    global _pending_signal
    _pending_signal = signum
    if _critical_depth == 0:
        raise KeyboardInterrupt(signal.Signals(signum).name)


def interrupt_pending() -> int | None:
    """The signal number of an interrupt noted since :func:`clear_interrupt`, else None.

    Set by the handlers of :func:`install_signal_handlers` (and inside
    :func:`critical_section`), even where a library caught the KeyboardInterrupt.
    """
    return _pending_signal


def clear_interrupt() -> None:
    """Forget a noted interrupt (a command starting)."""
    global _pending_signal
    _pending_signal = None


def install_signal_handlers() -> Callable[[], None]:
    """Route SIGINT and SIGTERM to a handler that notes them and raises KeyboardInterrupt.

    Only in the main thread (elsewhere nothing is changed).

    Returns
    -------
    callable
        Restores the previous handlers.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {}
    for sig in _HANDLED:
        try:
            previous[sig] = signal.signal(sig, _handler)
        except (ValueError, OSError):  # pragma: no cover - not settable here
            pass

    def restore() -> None:
        for sig, old in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(sig, old if old is not None else signal.SIG_DFL)

    return restore


@contextlib.contextmanager
def critical_section() -> Iterator[None]:
    """Defer SIGINT/SIGTERM for the body; a deferred one takes effect right after it.

    Under the handlers of :func:`install_signal_handlers` (the CLI) a deferred signal
    is raised as KeyboardInterrupt when the outermost section ends. Elsewhere (the
    Python API) the handlers are ours only for the body, and a signal that arrived is
    raised again once the caller's handlers are back (so SIGTERM still terminates,
    after the commit). In a thread other than the main thread the body simply runs
    (signals are handled in the main thread).
    """
    global _critical_depth
    main = threading.current_thread() is threading.main_thread()
    restore = None
    if main:
        with contextlib.suppress(ValueError, OSError):
            if signal.getsignal(signal.SIGINT) is not _handler or signal.getsignal(signal.SIGTERM) is not _handler:
                restore = install_signal_handlers()
    with _lock:
        _critical_depth += 1
    try:
        yield
    finally:
        with _lock:
            _critical_depth -= 1
        depth = _critical_depth
        if restore is not None:
            restore()
            if depth == 0 and _pending_signal is not None:
                sig = _pending_signal
                clear_interrupt()
                signal.raise_signal(sig)
        elif main and depth == 0 and _pending_signal is not None:
            raise KeyboardInterrupt(signal.Signals(_pending_signal).name)


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
    folder = path.parent
    if not folder.exists():
        raise OutputError(f"cannot write the {what} {path}: the folder {folder} does not exist",
                          errno=_errno.ENOENT, path=str(path))
    if not folder.is_dir():
        raise OutputError(f"cannot write the {what} {path}: {folder} is not a folder",
                          errno=_errno.ENOTDIR, path=str(path))
    if path.is_dir():
        raise OutputError(f"cannot write the {what} {path}: a folder of that name is in the way",
                          errno=_errno.EISDIR, path=str(path))


def _mkstemp(path: Path, what: str) -> tuple[int, str]:
    try:
        return tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise output_error(exc, path, what) from exc


def _commit(tmp: str, path: Path, what: str) -> None:
    """Rename ``tmp`` over ``path`` with interrupts deferred; an interrupt noted before aborts."""
    with critical_section():
        if interrupt_pending() is not None:
            # An interrupt arrived while a library was writing (and may have swallowed
            # it): do not commit a file the user asked to stop.
            _unlink_quietly(tmp)
            raise KeyboardInterrupt
        try:
            os.replace(tmp, path)
        except OSError as exc:
            _unlink_quietly(tmp)
            raise output_error(exc, path, what) from exc
        _fsync_dir(path.parent)


# ---------------------------------------------------------------------- files
@contextlib.contextmanager
def _replacing(tmp: str, path: Path, what: str) -> Iterator[None]:
    """Around the body that writes and fsyncs ``tmp``: an ``OSError`` becomes an
    :class:`OutputError`; success renames ``tmp`` over ``path``; any failure (Ctrl-C
    included) removes ``tmp`` and leaves ``path`` as it was."""
    try:
        try:
            yield
        except OSError as exc:
            raise output_error(exc, path, what) from exc
        _commit(tmp, path, what)
    except BaseException:
        with critical_section():
            _unlink_quietly(tmp)
        raise


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, what: str = "file") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    For libraries that want a file name (h5netcdf, matplotlib). The body writes the
    temporary file (it exists, empty, and may be overwritten); afterwards it is fsynced,
    given the target's mode and renamed over ``path``.

    Parameters
    ----------
    path : path-like
        Final file name; its folder must exist.
    what : str
        What is written, for error messages.

    Raises
    ------
    OutputError
        The folder is missing or read-only, the disk is full, ... (``OSError`` from the
        body is converted too). The previous file at ``path`` is unchanged.
    """
    path = Path(path)
    _check_folder(path, what)
    fd, tmp = _mkstemp(path, what)
    os.close(fd)
    with _replacing(tmp, path, what):
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDWR)
        try:
            os.fchmod(fd, new_file_mode(path))
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike,
    mode: str = "wb",
    *,
    encoding: str | None = "utf-8",
    newline: str | None = None,
    what: str = "file",
) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path`` for writing; on success it replaces ``path``.

    Parameters
    ----------
    path : path-like
        Final file name; its folder must exist.
    mode : {"wb", "w"}
        Binary or text.
    encoding, newline : str, optional
        For text mode (default UTF-8).
    what : str
        What is written, for error messages.

    Yields
    ------
    file object
        Write to it; do not close it.

    Raises
    ------
    OutputError
        See :func:`atomic_path`.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    _check_folder(path, what)
    fd, tmp = _mkstemp(path, what)
    with _replacing(tmp, path, what):
        if mode == "wb":
            fh = _open_fd(fd, "wb")
        else:
            fh = _open_fd(fd, "w", encoding=encoding, newline=newline)
        with fh:
            yield fh
            fh.flush()
            os.fchmod(fh.fileno(), new_file_mode(path))
            os.fsync(fh.fileno())


def write_bytes(path: str | os.PathLike, data: bytes, *, what: str = "file") -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`); returns the path."""
    with atomic_write(path, "wb", what=what) as fh:
        fh.write(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str, *, what: str = "file", encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`); returns the path."""
    with atomic_write(path, "w", encoding=encoding, what=what) as fh:
        fh.write(text)
    return Path(path)


def save_figure(fig: Any, path: str | os.PathLike, *, what: str = "figure", **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure atomically (format from the suffix, default PNG); returns the path."""
    path = Path(path)
    fmt = savefig_kwargs.pop("format", None) or (path.suffix.lstrip(".").lower() or "png")
    with atomic_write(path, "wb", what=what) as fh:
        fig.savefig(fh, format=fmt, **savefig_kwargs)
    return path


# ---------------------------------------------------------------------- folders
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically with ``renameat2(RENAME_EXCHANGE)``; False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
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


@contextlib.contextmanager
def atomic_directory(
    path: str | os.PathLike,
    *,
    owned: Iterable[str] | Callable[[str], bool] | None = None,
    what: str = "folder",
) -> Iterator[Path]:
    """Build a folder beside ``path`` and put it in place as a whole, or not at all.

    The body writes plain files into the yielded temporary folder (a sibling of
    ``path``). On success:

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
        The folder to produce; its parent must exist (it is created if missing).
    owned : set of str or callable, optional
        Names of the entries a build produces (or a predicate); default: every name the
        new build holds.
    what : str
        For error messages (``"report folder"``).

    Raises
    ------
    OutputError
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(exc, path, what) from exc
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
                if existing is None:
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


# ---------------------------------------------------------------------- checks
def check_writable(path: str | os.PathLike, *, expected_bytes: int = 0, what: str = "file") -> Path:
    """Check, before a long job, that ``path`` can be written and its folder has room.

    Checks that the folder exists, that a file can be created and removed there (which
    also catches a read-only file system, even for root) and that the free space is at
    least ``expected_bytes`` plus a margin (:data:`SPACE_MARGIN_BYTES`).

    Parameters
    ----------
    path : path-like
        The file that will be written (it is not created).
    expected_bytes : int
        Estimated size of the file, bytes.
    what : str
        For error messages.

    Returns
    -------
    Path

    Raises
    ------
    OutputError
        Naming the path and the problem.
    """
    path = Path(path)
    _check_folder(path, what)
    folder = path.parent
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
    except OSError as exc:
        raise OutputError(
            f"cannot write the {what} {path}: {describe_os_error(exc)} in the folder {folder}; choose a writable "
            "location (checked before starting)",
            errno=exc.errno, path=str(path),
        ) from exc
    os.close(fd)
    _unlink_quietly(probe)
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):
        return path
    free = st.f_bavail * st.f_frsize
    needed = int(expected_bytes) + SPACE_MARGIN_BYTES
    if free < needed:
        raise OutputError(
            f"cannot write the {what} {path}: the folder {folder} has {_size(free)} free, the file needs about "
            f"{_size(needed)}; free some space or choose another location (checked before starting)",
            errno=_errno.ENOSPC, path=str(path),
        )
    return path


def _size(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover
