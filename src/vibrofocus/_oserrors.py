"""One clear line for a failed write: :func:`describe_os_error` and :func:`output_error`.

An :class:`OSError` (``ENOSPC``, ``EDQUOT``, ``EACCES``, ``EPERM``, ``EROFS``, ...) from
writing an output becomes an :class:`~vibrofocus.errors.OutputError` that names the file
and the problem. Part of the atomic-output family (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import errno as _errno
import os
from pathlib import Path

from .errors import OutputError

__all__ = ["OUTPUT_ERRNOS", "describe_os_error", "output_error"]

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
