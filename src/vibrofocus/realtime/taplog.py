"""Every tap ``serve-osc`` plays, kept on disk: :class:`TapLog` (``serve-osc --log FILE``).

A tap asked by another program (PsychoPy, Unity, Max/MSP) is recorded here with its id,
what was asked, the level, the method and its onset on the host's and the device's
clocks, so that the experiment's own data file can be joined to it by ``tap_id``.

Two formats, chosen by the file's suffix:

- SQLite (``.db``, ``.sqlite``, ``.sqlite3``): one ``taps`` table; each tap is one
  transaction, committed (WAL journal, ``synchronous=FULL``) before ``/played`` is sent.
  The file is marked with its own ``application_id``, so a study database or another
  program's SQLite file is never written to.
- CSV (``.csv``): a header, then one row per tap, appended with one ``write`` of the
  whole line and ``fsync``-ed before ``/played`` is sent. A row cut by a crash in the
  middle of that write (a tap that was never acknowledged) is removed when the log is
  opened again.

An existing log is continued (its tap ids go on); a file that is not a tap log of the
same format is refused, never changed.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import re
import sqlite3
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .._validation import shorten
from ..errors import OutputError, ValidationError

__all__ = ["TapLog", "TAP_LOG_COLUMNS", "TAP_LOG_APPLICATION_ID", "read_tap_log"]

#: The columns of a tap log, in order (CSV header; SQLite ``taps`` table).
TAP_LOG_COLUMNS = ("tap_id", "run_started_utc", "received_utc", "sender", "address", "location", "x_mm", "y_mm",
                   "level_db", "method", "drive_peak_v", "onset_host_s", "onset_device_s", "onset_clock")
#: ``PRAGMA application_id`` of a SQLite tap log ("VBTL").
TAP_LOG_APPLICATION_ID = 0x5642544C
_SQLITE_SUFFIXES = (".db", ".sqlite", ".sqlite3")
_SCHEMA_VERSION = 1
_SQL_TYPES = {"tap_id": "INTEGER PRIMARY KEY", "location": "INTEGER", "x_mm": "REAL", "y_mm": "REAL",
              "level_db": "REAL NOT NULL", "drive_peak_v": "REAL", "onset_host_s": "REAL NOT NULL",
              "onset_device_s": "REAL"}
_SQLITE_MAGIC = b"SQLite format 3\x00"
#: Longest tap id a log may hold (SQLite's INTEGER is 64-bit), and its form: ASCII digits only.
_TAP_ID_DIGITS = 18
_TAP_ID = re.compile(rf"[0-9]{{1,{_TAP_ID_DIGITS}}}")


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


class TapLog:
    """An append-only log of played taps, SQLite or CSV (by the suffix of ``path``).

    Parameters
    ----------
    path : path-like
        ``.csv``, ``.db``, ``.sqlite`` or ``.sqlite3``. Created if missing; continued if
        it is a tap log of that format already.

    Attributes
    ----------
    path : Path
    last_tap_id : int
        The highest tap id in the log (0 for a new one); a server numbers its taps on
        from it.
    run_started_utc : str
        When this log was opened (ISO 8601, UTC): the ``run_started_utc`` of every tap
        appended through it, which tells runs apart (the host clock of ``onset_host_s``
        starts again at every boot).

    Raises
    ------
    ValidationError
        An unknown suffix.
    OutputError
        A path that cannot hold the log (a folder, a device, a dangling link) or a file
        that is not a tap log of that format.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        from .._atomic import output_target

        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix != ".csv" and suffix not in _SQLITE_SUFFIXES:
            raise ValidationError(f"a tap log is a .csv or a SQLite file ({', '.join(_SQLITE_SUFFIXES)}), "
                                  f"got {shorten(str(self.path))}")
        self._real = output_target(self.path, "tap log")
        self._sqlite = suffix in _SQLITE_SUFFIXES
        self._lock = threading.Lock()
        self._conn: sqlite3.Connection | None = None
        self._fd: int | None = None
        self.run_started_utc = _now()
        self.last_tap_id = self._open_sqlite() if self._sqlite else self._open_csv()

    # -- opening --------------------------------------------------------------------------
    def _refuse(self, reason: str) -> OutputError:
        return OutputError(f"cannot log taps to {self.path}: {reason}; it was not changed (give a new file name)",
                           path=str(self.path))

    def _open_sqlite(self) -> int:
        existing = self._real.exists() and self._real.stat().st_size > 0
        if existing:
            with open(self._real, "rb") as fh:
                if fh.read(16) != _SQLITE_MAGIC:
                    raise self._refuse("it is not a SQLite database")
        try:
            conn = sqlite3.connect(self._real, isolation_level=None, check_same_thread=False, timeout=10.0)
        except sqlite3.Error as exc:
            raise self._refuse(str(exc)) from None
        try:
            app_id = conn.execute("PRAGMA application_id").fetchone()[0]
            if existing or app_id:
                if app_id != TAP_LOG_APPLICATION_ID:
                    raise self._refuse("it is a SQLite database of another kind (a study database?), not a tap log")
                version = conn.execute("PRAGMA user_version").fetchone()[0]
                if version != _SCHEMA_VERSION:
                    raise self._refuse(f"its layout is version {version}; this vibrofocus writes version "
                                       f"{_SCHEMA_VERSION}")
                names = tuple(r[1] for r in conn.execute("PRAGMA table_info(taps)"))
                if names != TAP_LOG_COLUMNS:
                    raise self._refuse("its taps table has other columns")
            else:
                columns = ", ".join(f"{c} {_SQL_TYPES.get(c, 'TEXT')}" for c in TAP_LOG_COLUMNS)
                conn.execute("BEGIN")
                conn.execute(f"CREATE TABLE taps ({columns})")
                # Append-only: a tap once acknowledged is never changed or removed through vibrofocus.
                conn.execute("CREATE TRIGGER taps_no_update BEFORE UPDATE ON taps "
                             "BEGIN SELECT RAISE(ABORT, 'the tap log is append-only'); END")
                conn.execute("CREATE TRIGGER taps_no_delete BEFORE DELETE ON taps "
                             "BEGIN SELECT RAISE(ABORT, 'the tap log is append-only'); END")
                conn.execute(f"PRAGMA application_id = {TAP_LOG_APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version = {_SCHEMA_VERSION}")
                conn.execute("COMMIT")
            conn.execute("PRAGMA journal_mode = WAL")
            conn.execute("PRAGMA synchronous = FULL")
            last = conn.execute("SELECT COALESCE(MAX(tap_id), 0) FROM taps").fetchone()[0]
        except sqlite3.Error as exc:
            conn.close()
            raise self._refuse(str(exc)) from None
        except BaseException:
            conn.close()
            raise
        self._conn = conn
        return int(last)

    def _open_csv(self) -> int:
        header = ",".join(TAP_LOG_COLUMNS) + "\n"
        if not self._real.exists() or self._real.stat().st_size == 0:
            from .._atomic import write_text

            write_text(self._real, header, what="tap log")
            last = 0
        else:
            last = self._check_csv(header)
        try:
            self._fd = os.open(self._real, os.O_WRONLY | os.O_APPEND | getattr(os, "O_NOFOLLOW", 0))
        except OSError as exc:
            from .._atomic import output_error

            raise output_error(exc, self.path, "tap log") from exc
        return last

    def _check_csv(self, header: str) -> int:
        with open(self._real, "rb") as fh:
            data = fh.read()
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise self._refuse("it is not a text file") from None
        if not text.startswith(header):
            raise self._refuse(f"it is not a tap log (its first line is not {header.strip()!r})")
        if not text.endswith("\n"):
            # A row cut by a crash during its one write: its tap was never acknowledged.
            keep = len(text[: text.rfind("\n") + 1].encode("utf-8"))
            with open(self._real, "r+b") as fh:
                fh.truncate(keep)
                fh.flush()
                os.fsync(fh.fileno())
            text = text[: text.rfind("\n") + 1]
        last = 0
        reader = csv.DictReader(io.StringIO(text))
        for row in reader:
            line = reader.line_num
            tap_id = row.get("tap_id")
            if not isinstance(tap_id, str) or not _TAP_ID.fullmatch(tap_id):
                # A hand-edited id (a Unicode digit such as '²', thousands of digits): not this log's own.
                raise self._refuse(f"it is not a tap log (line {line}: the tap_id {shorten(tap_id)} is not "
                                   f"a whole number of 1 to {_TAP_ID_DIGITS} digits 0-9)")
            last = max(last, int(tap_id))
        return last

    # -- appending ------------------------------------------------------------------------
    def row(self, record: Any) -> dict[str, Any]:
        """One tap's row (:data:`TAP_LOG_COLUMNS`) from a :class:`~vibrofocus.realtime.TapRecord`.

        Parameters
        ----------
        record : TapRecord

        Returns
        -------
        dict
        """
        return {"tap_id": int(record.tap_id), "run_started_utc": self.run_started_utc, "received_utc": _now(),
                "sender": record.sender, "address": record.address, "location": record.location,
                "x_mm": record.x_mm, "y_mm": record.y_mm, "level_db": float(record.level_db),
                "method": record.method, "drive_peak_v": record.drive_peak_v, "onset_host_s": record.onset_host_s,
                "onset_device_s": record.onset_device_s, "onset_clock": record.onset_clock}

    def append(self, record: Any) -> None:
        """Keep one played tap; when this returns, the tap is on disk.

        Parameters
        ----------
        record : TapRecord

        Raises
        ------
        OutputError
            When it cannot be written (no space, the log closed); nothing partial stays.
        """
        row = self.row(record)
        with self._lock:
            if self._sqlite:
                if self._conn is None:
                    raise OutputError(f"the tap log {self.path} is closed", path=str(self.path))
                try:
                    with self._conn:  # one transaction per tap
                        self._conn.execute("BEGIN")
                        self._conn.execute(f"INSERT INTO taps ({', '.join(TAP_LOG_COLUMNS)}) VALUES "
                                           f"({', '.join('?' * len(TAP_LOG_COLUMNS))})",
                                           [_sql_value(row[c]) for c in TAP_LOG_COLUMNS])
                except sqlite3.Error as exc:
                    raise OutputError(f"cannot write tap {row['tap_id']} to {self.path}: {exc}",
                                      path=str(self.path)) from None
                return
            if self._fd is None:
                raise OutputError(f"the tap log {self.path} is closed", path=str(self.path))
            line = io.StringIO()
            csv.writer(line, lineterminator="\n").writerow([_csv_value(row[c]) for c in TAP_LOG_COLUMNS])
            data = line.getvalue().encode("utf-8")
            size = os.fstat(self._fd).st_size
            try:
                written = os.write(self._fd, data)  # O_APPEND: the whole row in one write
                if written != len(data):
                    raise OSError(28, "short write")
                os.fsync(self._fd)
            except OSError as exc:
                with contextlib.suppress(OSError):
                    os.ftruncate(self._fd, size)  # no cut row stays behind
                from .._atomic import output_error

                raise output_error(exc, self.path, "tap log") from exc

    def close(self) -> None:
        """Close the file (a second call does nothing)."""
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None

    def __enter__(self) -> "TapLog":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _sql_value(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _csv_value(value: Any) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, float):
        return repr(value)  # every digit: an onset is compared to other clocks to the microsecond
    return str(value)


def read_tap_log(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The taps of a log, oldest first, with numbers as numbers and empty cells as None.

    Parameters
    ----------
    path : path-like
        A tap log (``.csv`` or SQLite).

    Returns
    -------
    list of dict
        One dict per tap, keyed by :data:`TAP_LOG_COLUMNS`.
    """
    path = Path(path)
    if path.suffix.lower() in _SQLITE_SUFFIXES:
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            if conn.execute("PRAGMA application_id").fetchone()[0] != TAP_LOG_APPLICATION_ID:
                raise ValidationError(f"{shorten(str(path))} is not a tap log")
            cur = conn.execute(f"SELECT {', '.join(TAP_LOG_COLUMNS)} FROM taps ORDER BY tap_id")
            return [dict(zip(TAP_LOG_COLUMNS, r)) for r in cur]
        finally:
            conn.close()
    numbers = {"tap_id": int, "location": int, "x_mm": float, "y_mm": float, "level_db": float,
               "drive_peak_v": float, "onset_host_s": float, "onset_device_s": float}
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        rows = [(reader.line_num, r) for r in reader]
    out = []
    for line, r in rows:
        cells = {}
        for c in TAP_LOG_COLUMNS:
            value = r.get(c)
            if not isinstance(value, str):
                raise ValidationError(f"{shorten(str(path))} is not a tap log (line {line} has no {c})")
            if c == "tap_id" and not _TAP_ID.fullmatch(value):
                raise ValidationError(f"{shorten(str(path))} is not a tap log (line {line}: the tap_id "
                                      f"{shorten(value)} is not a whole number of 1 to {_TAP_ID_DIGITS} "
                                      "digits 0-9)")
            try:
                cells[c] = None if value == "" else numbers.get(c, str)(value)
            except ValueError:
                raise ValidationError(f"{shorten(str(path))} is not a tap log (line {line}: {c} "
                                      f"{shorten(value)} is not a number)") from None
        out.append(cells)
    return out
