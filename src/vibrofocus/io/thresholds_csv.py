"""The threshold file: the trials of threshold blocks, as a study database exports them.

Columns: :data:`THRESHOLD_COLUMNS` (docs/file-formats.md, "Threshold file"). Written atomically
(:func:`vibrofocus._atomic.atomic_write`); numbers keep every digit (``repr``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from typing import Any

from ._csv_rows import number_cell, write_rows_csv

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
    cells = ([number_cell(row.get(key)) for key in THRESHOLD_COLUMNS] for row in rows)
    return write_rows_csv(path, THRESHOLD_COLUMNS, cells, what="threshold file")
