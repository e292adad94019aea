"""One writer for the study exports' CSV files (trials, thresholds): folder check, atomic
write, exact numbers."""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ..errors import StudyError

__all__ = ["number_cell", "write_rows_csv"]


def number_cell(value: Any) -> Any:
    """A CSV cell for ``value``: empty for None, ``repr`` of a float (every digit, so the
    file round-trips exactly), anything else as it is."""
    if value is None:
        return ""
    return repr(float(value)) if isinstance(value, float) else value


def write_rows_csv(path: str | os.PathLike, header: Sequence[str], rows: Iterable[Sequence[Any]], *,
                   what: str, kind: str | None = None) -> int:
    """Write ``header`` and ``rows`` (already as cells) to ``path`` atomically.

    Parameters
    ----------
    path : path-like
        Destination CSV file; its folder must exist.
    header : sequence of str
        The first line's cells.
    rows : iterable of sequence
        One sequence of cells per line.
    what : str
        What the file is, for messages ("trials file").
    kind : str, optional
        The output kind :func:`vibrofocus._atomic.atomic_write` checks an existing file against.

    Returns
    -------
    int
        Number of rows written (the header not counted).
    """
    from .._atomic import atomic_write

    path = Path(path)
    if not path.parent.is_dir():
        raise StudyError(f"cannot write the {what} {path}: the folder {path.parent} does not exist")
    n = 0
    with atomic_write(path, "w", newline="", what=what, kind=kind) as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        for row in rows:
            writer.writerow(row)
            n += 1
    return n
