"""Writing a file atomically, under the rules vibrofocus writes its own files by.

The public face of the package's atomic writers, for scripts and other programs: the file
appears whole under its name or not at all, and the rules of what an output may replace
(never a folder, a device or a FIFO, never an input of the command) hold.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .. import _atomic

__all__ = ["write_text", "save_figure", "atomic_path"]


def write_text(path: str | os.PathLike, text: str, *, what: str = "file", encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically.

    Parameters
    ----------
    path : path-like
        The file; its folder must exist.
    text : str
        The whole content.
    what : str
        What is written, for error messages.
    encoding : str
        The text encoding.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    OutputError
        The folder is missing or read-only, the disk is full, the target may not be
        replaced, ... The previous file at ``path`` is unchanged.
    """
    return _atomic.write_text(path, text, what=what, encoding=encoding)


def save_figure(fig: Any, path: str | os.PathLike, *, what: str = "figure", **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure atomically (format from the suffix, default PNG).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : path-like
        The file; its folder must exist.
    what : str
        What is written, for error messages.
    **savefig_kwargs
        Passed to ``fig.savefig`` (``dpi``, ``format``, ...).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    OutputError
        As :func:`write_text`.
    """
    return _atomic.save_figure(fig, path, what=what, **savefig_kwargs)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, what: str = "file") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    For libraries that want a file name (``numpy.savez``, h5netcdf): the body writes the
    temporary file, which afterwards is synced and renamed over ``path``.

    Parameters
    ----------
    path : path-like
        The final file; its folder must exist.
    what : str
        What is written, for error messages.

    Yields
    ------
    pathlib.Path
        The temporary file to write.

    Raises
    ------
    OutputError
        As :func:`write_text`.
    """
    with _atomic.atomic_path(path, what=what) as tmp:
        yield tmp
