"""The trials file: the CSV contract between the studies and the analysis (docs/file-formats.md, trials file).

One row per answered trial with the columns :data:`TRIALS_COLUMNS`, in that order:
``participant`` (id), ``study`` (1 or 2), ``phase`` (``training`` | ``main``), ``trial``
(1-based within the phase), ``method``, ``target`` (1-9), ``response`` (the chosen
locations, ascending, separated by spaces: ``5``, ``4 5``), ``rt_s`` (seconds).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import StudyError

__all__ = ["TRIALS_COLUMNS", "SESSION_COLUMNS", "write_trials_csv", "read_trials_csv"]

#: Columns of the trials file, in order.
TRIALS_COLUMNS = ("participant", "study", "phase", "trial", "method", "target", "response", "rt_s")
#: Columns a study database's export adds after :data:`TRIALS_COLUMNS`: the session id,
#: its status (``planned``, ``running``, ``paused``, ``aborted``, ``completed``) and
#: ``dry_run`` (1 when the session had no calibration, so nothing was played; else 0).
SESSION_COLUMNS = ("session", "session_status", "dry_run")


def write_trials_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike, *, sessions: bool = False) -> int:
    """Write trial rows to ``path`` atomically (:func:`vibrofocus._atomic.atomic_write`).

    A reader never sees half a file; after a failure (a full disk, a read-only folder,
    Ctrl-C) a previous file at ``path`` is unchanged and
    :class:`~vibrofocus.errors.OutputError` says why.

    Parameters
    ----------
    rows : iterable of mapping
        Each with at least the keys of :data:`TRIALS_COLUMNS`; others are ignored.
        ``response`` may be a string or a sequence of location numbers; ``rt_s`` in s.
    path : path-like
        Destination CSV file; its folder must exist.
    sessions : bool
        Also write :data:`SESSION_COLUMNS` (then each row needs those keys too).

    Returns
    -------
    int
        Number of rows written.
    """
    from .._atomic import atomic_write

    path = Path(path)
    if not path.parent.is_dir():
        raise StudyError(f"cannot write the trials file {path}: the folder {path.parent} does not exist")
    n = 0
    with atomic_write(path, "w", newline="", what="trials file") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(TRIALS_COLUMNS + (SESSION_COLUMNS if sessions else ()))
        for row in rows:
            response = row["response"]
            if not isinstance(response, str):
                response = " ".join(str(int(x)) for x in sorted(response))
            # repr keeps every digit of the stored float: the file round-trips exactly.
            values = [
                row["participant"], int(row["study"]), row["phase"], int(row["trial"]),
                row["method"], int(row["target"]), response, repr(float(row["rt_s"])),
            ]
            if sessions:
                values += [int(row["session"]), row["session_status"], int(bool(row["dry_run"]))]
            writer.writerow(values)
            n += 1
    return n


def read_trials_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Read a trials file back, checking the header; values typed as written.

    Parameters
    ----------
    path : path-like
        A trials CSV (docs/file-formats.md, trials file).

    Returns
    -------
    list of dict
        ``study``, ``trial``, ``target`` as int, ``rt_s`` as float, ``response`` as a
        tuple of int; the rest as str. A file with :data:`SESSION_COLUMNS` also gives
        ``session`` (int), ``session_status`` (str) and ``dry_run`` (bool).
    """
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            if header is None or tuple(header) not in (TRIALS_COLUMNS, TRIALS_COLUMNS + SESSION_COLUMNS):
                raise StudyError(f"{path} is not a trials file: header {header!r}, expected {list(TRIALS_COLUMNS)}")
            columns = tuple(header)
            out = []
            for line_no, rec in enumerate(reader, start=2):
                if len(rec) != len(columns):
                    raise StudyError(f"{path}:{line_no}: expected {len(columns)} fields, got {len(rec)}")
                row = dict(zip(columns, rec))
                try:
                    if "session" in row:
                        row["session"] = int(row["session"])
                        row["dry_run"] = bool(int(row["dry_run"]))
                    row["study"] = int(row["study"])
                    row["trial"] = int(row["trial"])
                    row["target"] = int(row["target"])
                    row["rt_s"] = float(row["rt_s"])
                    row["response"] = tuple(int(x) for x in row["response"].split())
                except ValueError as exc:
                    raise StudyError(f"{path}:{line_no}: {exc}") from None
                out.append(row)
            return out
    except OSError as exc:
        raise StudyError(f"cannot read the trials file {path}: {exc.strerror or exc}") from exc
