"""The threshold file: the trials of threshold blocks, as a study database exports them.

Columns: :data:`THRESHOLD_COLUMNS` (docs/file-formats.md, "Threshold file"). Written atomically
(:func:`vibrofocus._atomic.atomic_write`); numbers keep every digit (``repr``).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import StudyError

__all__ = ["THRESHOLD_COLUMNS", "write_thresholds_csv"]

#: Columns of the threshold file, in this order.
THRESHOLD_COLUMNS = ("participant", "session", "protocol", "block", "phase", "trial", "method", "target", "level_db",
                     "levels", "drive_peak_v", "felt", "rt_s", "reversal", "threshold_db")


def write_thresholds_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike) -> int:
    """Write threshold trials to ``path`` atomically.

    Parameters
    ----------
    rows : iterable of mapping
        Each with the keys of :data:`THRESHOLD_COLUMNS`
        (:meth:`~vibrofocus.studies.StudyStore.threshold_rows`); None is an empty cell.
    path : path-like
        Destination CSV file; its folder must exist.

    Returns
    -------
    int
        Number of rows written.
    """
    from .._atomic import atomic_write

    path = Path(path)
    if not path.parent.is_dir():
        raise StudyError(f"cannot write the threshold file {path}: the folder {path.parent} does not exist")
    n = 0
    with atomic_write(path, "w", newline="", what="threshold file") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(THRESHOLD_COLUMNS)
        for row in rows:
            writer.writerow(["" if row.get(key) is None else (repr(float(row[key])) if isinstance(row[key], float)
                                                               else row[key]) for key in THRESHOLD_COLUMNS])
            n += 1
    return n
