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

Inside a folder others may write (an export into an existing dataset), ``within=root``
confines a write to ``root``: a link at the target or on any folder between ``root`` and
it is refused, and the file is renamed over its name in the folder's descriptor, so
nothing is ever written through a link (:mod:`._confined`).

This module writes the files; each other job of the family has a module of its own, whose
public names are re-exported here: :mod:`._oserrors` (error wording),
:mod:`._interrupts` (signals), :mod:`._output_rules` (what an output may replace, file
modes), :mod:`._atomic_folders` (folders), :mod:`._confined` (files below a root, no
link followed) and :mod:`._disk_checks` (room on the disk).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

# The family's other parts, each with one job; their public names are this module's too.
from ._atomic_folders import atomic_directory, make_output_folder
from ._confined import atomic_write_below, link_below, lock_folder, read_below
from ._disk_checks import SPACE_MARGIN_BYTES, check_writable
from ._interrupts import clear_interrupt, critical_section, install_signal_handlers, interrupt_pending
from ._oserrors import OUTPUT_ERRNOS, describe_os_error, output_error
from ._output_rules import (
    DRIVES_CSV,
    REPORT_JSON,
    TRIALS_CSV,
    _check_folder,
    _fsync_dir,
    _suffix_kind,
    _umask,  # noqa: F401 - read by tests of the file modes
    _unlink_quietly,
    allow_overwrite,
    file_kind,
    guarding,
    new_file_mode,
    output_guard,
    output_target,
    protect,
)

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
    "TRIALS_CSV",
    "DRIVES_CSV",
    "REPORT_JSON",
    "make_output_folder",
    "read_below",
    "link_below",
    "lock_folder",
    "OUTPUT_ERRNOS",
    "SPACE_MARGIN_BYTES",
]

#: Opens the temporary file's descriptor (a seam for tests that inject a full disk).
_open_fd = os.fdopen


# ---------------------------------------------------------------------- files
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
    within: str | os.PathLike | None = None,
    parents: bool = False,
    kind: str | None = None,
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
    within : path-like, optional
        A folder ``path`` must stay in, others may write (a shared dataset): a symbolic
        link at ``path`` or on any folder between it and ``within`` is refused ("... is
        a link: refused"), before writing and again at the rename, which replaces the
        name itself (:func:`vibrofocus._confined.atomic_write_below`). Without it, a
        link to a regular file is written through (:func:`output_target`).
    parents : bool
        With ``within``: make missing folders below it (never through a link).
    kind : str, optional
        What the new file is, for the rule on replacing a file of another kind
        (:func:`~vibrofocus._output_rules.output_target`): a kind told by the content,
        such as ``"trials CSV"``; default: from the suffix (``"text file"`` for ``.csv``).

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
    if within is not None:
        with atomic_write_below(within, path, mode, encoding=encoding, newline=newline, what=what,
                                kind=kind or _suffix_kind(path), parents=parents) as fh:
            yield fh
        return
    if parents:
        raise ValueError("atomic_write(parents=True) needs within=")
    _check_folder(path, what)
    real = output_target(path, what, kind=kind or _suffix_kind(path))
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


def write_bytes(path: str | os.PathLike, data: bytes, *, what: str = "file",
                within: str | os.PathLike | None = None, parents: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`, also for ``within`` and ``parents``)."""
    with atomic_write(path, "wb", what=what, within=within, parents=parents) as fh:
        fh.write(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str, *, what: str = "file", encoding: str = "utf-8",
               within: str | os.PathLike | None = None, parents: bool = False, kind: str | None = None) -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`, also for ``within``, ``parents`` and ``kind``)."""
    with atomic_write(path, "w", encoding=encoding, what=what, within=within, parents=parents, kind=kind) as fh:
        fh.write(text)
    return Path(path)


def save_figure(fig: Any, path: str | os.PathLike, *, what: str = "figure", **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure atomically (format from the suffix, default PNG); returns the path."""
    path = Path(path)
    fmt = savefig_kwargs.pop("format", None) or (path.suffix.lstrip(".").lower() or "png")
    with atomic_write(path, "wb", what=what) as fh:
        fig.savefig(fh, format=fmt, **savefig_kwargs)
    return path
