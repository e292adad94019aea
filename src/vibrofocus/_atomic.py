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
- :func:`output_target` holds the rules of what an output may replace, and every writer
  above applies it (before writing and again just before the rename): never a folder, a
  device, a FIFO or a socket; through a symbolic link only to a regular file, which is
  replaced while the link stays; never a file this command reads (an input, the study
  database, a calibration), compared by device and inode; and, inside a command
  (:func:`output_guard`), an existing file of another kind (a calibration under a CSV's
  name) only with ``--force`` (:func:`allow_overwrite`).

Interrupts: the commit (rename) runs with SIGINT/SIGTERM deferred (see
:func:`critical_section`), so an interrupt leaves either the old file or the complete
new one. An interrupt noted while a library swallowed it (:func:`interrupt_pending`)
stops the save before the commit.
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import errno as _errno
import os
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
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
    "output_target",
    "output_guard",
    "protect",
    "guarding",
    "allow_overwrite",
    "file_kind",
    "make_output_folder",
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


# ---------------------------------------------------------------------- output targets
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
    return _TEXT


@dataclass
class _Guard:
    """What the running command reads (by device and inode, or by path before it exists) and ``--force``."""

    inodes: dict[tuple[int, int], str] = field(default_factory=dict)
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
            guard.inodes.setdefault((st.st_dev, st.st_ino), what)


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
    if st is not None:
        for test, name in _NOT_REGULAR:
            if test(st.st_mode):
                raise refuse(f"{'it points to' if path.is_symlink() else 'it is'} {name}, not a regular file; "
                             "choose a file name", _errno.EISDIR if name == "a folder" else _errno.EINVAL)
    guard = _guard.get()
    if guard is None:
        return real
    # By inode; by path too, for a file protected before it existed (a new database).
    same = (guard.inodes.get((st.st_dev, st.st_ino)) if st is not None else None) or guard.paths.get(str(real))
    if same is not None:
        raise refuse(f"it is the {same} this command reads (the same file); choose another name", _errno.EEXIST)
    if st is not None and kind is not None and not guard.force:
        old = file_kind(real)
        if old is not None and old != kind:
            raise refuse(f"it holds a {old}, not a {kind}; choose another name, or pass --force to replace it",
                         _errno.EEXIST)
    return real


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


def _mkstemp(path: Path, what: str) -> tuple[int, str]:
    try:
        return tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise output_error(exc, path, what) from exc


def _commit(tmp: str, path: Path, what: str) -> None:
    """Rename ``tmp`` over ``path`` with interrupts deferred; an interrupt noted before aborts.

    The rules of :func:`output_target` are checked again first, with the kind of the
    file just written (the target may have changed while it was written).
    """
    with critical_section():
        if interrupt_pending() is not None:
            # An interrupt arrived while a library was writing (and may have swallowed
            # it): do not commit a file the user asked to stop.
            _unlink_quietly(tmp)
            raise KeyboardInterrupt
        real = output_target(path, what, kind=file_kind(tmp))
        try:
            os.replace(tmp, real)
        except OSError as exc:
            _unlink_quietly(tmp)
            raise output_error(exc, path, what) from exc
        _fsync_dir(real.parent)


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
    real = output_target(path, what, kind=_suffix_kind(path))
    fd, tmp = _mkstemp(real, what)
    os.close(fd)
    with _replacing(tmp, path, what):
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDWR)
        try:
            os.fchmod(fd, new_file_mode(real))
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
    real = output_target(path, what, kind=_suffix_kind(path))
    fd, tmp = _mkstemp(real, what)
    with _replacing(tmp, path, what):
        if mode == "wb":
            fh = _open_fd(fd, "wb")
        else:
            fh = _open_fd(fd, "w", encoding=encoding, newline=newline)
        with fh:
            yield fh
            fh.flush()
            os.fchmod(fh.fileno(), new_file_mode(real))
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
        The folder to produce; its parent must exist (a mistyped parent is reported,
        not created).
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


# ---------------------------------------------------------------------- checks
def check_writable(path: str | os.PathLike, *, expected_bytes: int = 0, what: str = "file",
                   written_as: str | None = None) -> Path:
    """Check, before a long job, that ``path`` can be written and its folder has room.

    Checks the rules of :func:`output_target`, that the folder exists, that a file can
    be created and removed there (which also catches a read-only file system, even for
    root) and that the free space is at least ``expected_bytes`` plus a margin
    (:data:`SPACE_MARGIN_BYTES`).

    Parameters
    ----------
    path : path-like
        The file that will be written (it is not created).
    expected_bytes : int
        Estimated size of the file, bytes.
    what : str
        For error messages.
    written_as : str, optional
        The suffix whose kind of file will be written (``".csv"``), when the name's own
        suffix does not say it.

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
    kind = _suffix_kind(Path(f"x{written_as}") if written_as else path)
    folder = output_target(path, what, kind=kind).parent
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
