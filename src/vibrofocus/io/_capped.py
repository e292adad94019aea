"""Reading a small JSON file that vibrofocus does not own: size-capped before it is parsed."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .._validation import shorten
from ..errors import ValidationError

__all__ = ["read_capped_json", "read_capped_json_lines"]


def read_capped_json(path: str | os.PathLike, *, max_bytes: int, what: str) -> Any:
    """The JSON value in ``path``, read only if it is at most ``max_bytes`` long.

    Parameters
    ----------
    path : path-like
        The file.
    max_bytes : int
        Largest size accepted, bytes; no more than one byte past it is ever read.
    what : str
        What the file is, for messages ("layout file").

    Raises
    ------
    ValidationError
        Unreadable, larger than ``max_bytes``, or not UTF-8 JSON; the message names the file.
    """
    path = Path(path)
    raw = _read_capped(path, max_bytes, what)
    try:
        return json.loads(raw.decode("utf-8"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise ValidationError(f"the {what} {path} is not UTF-8 JSON ({shorten(str(exc))})") from None


def read_capped_json_lines(path: str | os.PathLike, *, max_bytes: int, what: str) -> list[Any]:
    """The JSON value of each non-blank line of ``path`` (JSON lines), read only if it is at most ``max_bytes`` long.

    Parameters
    ----------
    path, max_bytes, what
        As :func:`read_capped_json`.

    Raises
    ------
    ValidationError
        Unreadable, larger than ``max_bytes``, not UTF-8, or a line that is not JSON (the
        message names the file and the line's number).
    """
    path = Path(path)
    raw = _read_capped(path, max_bytes, what)
    try:
        text = raw.decode("utf-8")
    except ValueError as exc:
        raise ValidationError(f"the {what} {path} is not UTF-8 ({shorten(str(exc))})") from None
    out = []
    for number, line in enumerate(text.splitlines(), start=1):
        if line.strip():
            try:
                out.append(json.loads(line))
            except (ValueError, RecursionError) as exc:
                raise ValidationError(f"line {number} of the {what} {path} is not JSON ({shorten(str(exc))})") from None
    return out


def _read_capped(path: Path, max_bytes: int, what: str) -> bytes:
    try:
        with open(path, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise ValidationError(f"cannot read the {what} {path}: {exc.strerror or exc}") from None
    if len(raw) > max_bytes:
        raise ValidationError(f"the {what} {path} is larger than {max_bytes:,} bytes")
    return raw
