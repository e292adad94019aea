"""Array layout files (JSON): where the actuators sit, the numbered locations and the guards.

One format (docs/file-formats.md, "Layout files"): ``{"format": "vibrofocus layout", "version": 1,
"layout": {...}}``, the layout as :meth:`vibrofocus.layout.ArrayLayout.to_dict` gives it (metres),
plus an optional ``about`` object (how the layout was made). ``vibrofocus design-layout`` writes
it; ``vibrofocus calibrate --layout FILE`` reads it, and the calibration carries the layout on to
``render``, the studies and the web app. This module reads and writes the plain description; the
:class:`~vibrofocus.layout.ArrayLayout` is built above it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import ValidationError
from ._capped import read_capped_json
from .jsonsafe import json_safe

__all__ = ["LAYOUT_FORMAT", "read_layout_json", "write_layout_json"]

#: The ``format`` field of a layout file.
LAYOUT_FORMAT = "vibrofocus layout"
#: Largest layout file read, bytes (a 1024-actuator layout is about 100 kB).
_MAX_BYTES = 4 * 1024 * 1024
_NEEDED = ("actuators_xy", "locations_xy")


def write_layout_json(layout: Mapping[str, Any], path: str | os.PathLike, *,
                      about: Mapping[str, Any] | None = None) -> Path:
    """Write a layout description as an indented UTF-8 JSON file, atomically.

    Parameters
    ----------
    layout : mapping
        :meth:`~vibrofocus.layout.ArrayLayout.to_dict` of the layout, metres.
    path : path-like
        Destination (conventionally ``layout.json``); its folder must exist.
    about : mapping, optional
        How the layout was made (method, score, settings); stored as is, never read back
        into the layout.

    Returns
    -------
    Path
        ``path``.
    """
    from .._atomic import write_text

    _check(layout, where="layout")
    content = {"format": LAYOUT_FORMAT, "version": 1, "layout": dict(layout), "about": dict(about or {})}
    text = json.dumps(json_safe(content), indent=2, ensure_ascii=False, allow_nan=False)
    return write_text(path, text + "\n", what="layout")


def read_layout_json(path: str | os.PathLike) -> dict[str, Any]:
    """Read a layout file: the layout's description, for :meth:`ArrayLayout.from_dict`.

    Parameters
    ----------
    path : path-like
        A file written by :func:`write_layout_json`, or a bare ``ArrayLayout.to_dict()`` JSON object.

    Returns
    -------
    dict
        The layout description (``actuators_xy``, ``locations_xy``, ``guards_xy``, ... in metres).

    Raises
    ------
    ValidationError
        The file cannot be read, is too large, is not JSON or lacks the layout's keys.
    """
    path = Path(path)
    content = read_capped_json(path, max_bytes=_MAX_BYTES, what="layout file")
    if isinstance(content, dict) and "format" in content:
        if content["format"] != LAYOUT_FORMAT or content.get("version") != 1:
            raise ValidationError(f"{path} is a {content['format']!r} file version {content.get('version')!r}, "
                                  f"not a {LAYOUT_FORMAT!r} file version 1")
        content = content.get("layout")
    _check(content, where=str(path))
    return dict(content)


def _check(layout: Any, *, where: str) -> None:
    if not isinstance(layout, Mapping):
        raise ValidationError(f"{where}: a layout must be a JSON object, got {type(layout).__name__}")
    for key in _NEEDED:
        if key not in layout:
            raise ValidationError(f"{where}: the layout lacks the key {key!r}")
