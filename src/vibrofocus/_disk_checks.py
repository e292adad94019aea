"""Before a long job: can the output be written, and does its folder have room for it?

:func:`check_writable` checks the rules of :func:`~vibrofocus._output_rules.output_target`,
that a file can be made in the folder and that the free space covers the expected size.
Part of the atomic-output family (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import errno as _errno
import os
import tempfile
from pathlib import Path

from ._oserrors import describe_os_error
from ._output_rules import _check_folder, _suffix_kind, _unlink_quietly, output_target
from .errors import OutputError

__all__ = ["SPACE_MARGIN_BYTES", "check_writable"]

#: Headroom asked of a folder beyond the expected size of a file, bytes.
SPACE_MARGIN_BYTES = 1 << 20


def check_writable(path: str | os.PathLike, *, expected_bytes: int = 0, what: str = "file",
                   written_as: str | None = None, kind: str | None = None) -> Path:
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
    kind : str, optional
        What will be written, when its content tells it apart from other text files
        (``"trials CSV"``, ``"drives CSV"``, ``"report JSON"``; see :func:`file_kind`).

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
    kind = kind or _suffix_kind(Path(f"x{written_as}") if written_as else path)
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
