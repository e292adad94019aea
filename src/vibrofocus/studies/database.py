"""The SQLite mechanics of a study database: the file, its schema, its transactions.

Design (why each part is there):

- WAL journal with ``synchronous=FULL``: a committed transaction survives a killed
  process and a power cut; readers (the experimenter page, an export) never block the
  trial loop.
- Answers, planned trials and the event log are append-only (triggers refuse UPDATE and
  DELETE); participants, calibrations and sessions cannot be deleted.
- The schema version lives in ``PRAGMA user_version`` and the file is marked with a
  vibrofocus ``application_id``; a database from a newer vibrofocus is refused rather
  than misread. An older one is upgraded when opened (:data:`_MIGRATIONS`: additive
  changes only, so that every row it held reads as before).
- A database in a read-only place can still be read (an export): a private copy is.

The study rules on top of it are :class:`~vibrofocus.studies.storage.StudyStore`'s.
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import threading
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path

from ..errors import StudyError

__all__ = ["SCHEMA_VERSION", "APPLICATION_ID", "StudyDatabase", "now_utc", "software_version"]

#: Version of the database layout written by this vibrofocus (``PRAGMA user_version``).
SCHEMA_VERSION = 3
#: ``PRAGMA application_id`` marking a vibrofocus study database ("VBFC").
APPLICATION_ID = 0x56424643

_SCHEMA = """
CREATE TABLE participants (
    participant_id TEXT PRIMARY KEY,
    simulated      INTEGER NOT NULL CHECK (simulated IN (0, 1)),
    created_at     TEXT NOT NULL
);
CREATE TABLE calibrations (
    calibration_id INTEGER PRIMARY KEY,
    participant_id TEXT NOT NULL REFERENCES participants(participant_id),
    path           TEXT NOT NULL,
    sha256         TEXT NOT NULL,
    created_at     TEXT NOT NULL,
    UNIQUE (participant_id, sha256)
);
CREATE TABLE sessions (
    session_id       INTEGER PRIMARY KEY,
    participant_id   TEXT NOT NULL REFERENCES participants(participant_id),
    study            INTEGER NOT NULL CHECK (study IN (1, 2)),
    seed             INTEGER NOT NULL,
    calibration_id   INTEGER REFERENCES calibrations(calibration_id),
    status           TEXT NOT NULL CHECK (status IN ('planned', 'running', 'paused', 'aborted', 'completed')),
    config           TEXT NOT NULL,
    software_version TEXT NOT NULL,
    created_at       TEXT NOT NULL,
    updated_at       TEXT NOT NULL
);
CREATE TABLE planned_trials (
    session_id  INTEGER NOT NULL REFERENCES sessions(session_id),
    trial_index INTEGER NOT NULL CHECK (trial_index >= 0),
    phase       TEXT NOT NULL CHECK (phase IN ('training', 'main')),
    trial       INTEGER NOT NULL CHECK (trial >= 1),
    method      TEXT NOT NULL,
    target      INTEGER NOT NULL CHECK (target >= 1),
    PRIMARY KEY (session_id, trial_index)
);
CREATE TABLE answers (
    answer_pk      INTEGER PRIMARY KEY,
    answer_id      TEXT NOT NULL UNIQUE,
    session_id     INTEGER NOT NULL,
    trial_index    INTEGER NOT NULL,
    response       TEXT NOT NULL,
    rt_s           REAL NOT NULL CHECK (rt_s >= 0),
    drive_sha256   TEXT,
    calibration_id INTEGER REFERENCES calibrations(calibration_id),
    recorded_at    TEXT NOT NULL,
    response_x_mm  REAL,
    response_y_mm  REAL,
    UNIQUE (session_id, trial_index),
    FOREIGN KEY (session_id, trial_index) REFERENCES planned_trials(session_id, trial_index)
);
CREATE TABLE events (
    event_id   INTEGER PRIMARY KEY,
    session_id INTEGER NOT NULL REFERENCES sessions(session_id),
    kind       TEXT NOT NULL,
    payload    TEXT,
    created_at TEXT NOT NULL
);
CREATE INDEX events_by_session ON events(session_id, event_id);
"""
#: 3: a participant's detection threshold, one per finished threshold session (docs/protocols.md).
_THRESHOLDS = """CREATE TABLE thresholds (
    session_id     INTEGER PRIMARY KEY REFERENCES sessions(session_id),
    participant_id TEXT NOT NULL REFERENCES participants(participant_id),
    threshold_db   REAL,
    reversals_db   TEXT NOT NULL,
    recorded_at    TEXT NOT NULL
);
"""

_TRIGGERS = "".join(
    f"CREATE TRIGGER {table}_no_{op.lower()} BEFORE {op} ON {table} "
    f"BEGIN SELECT RAISE(ABORT, '{table} are append-only in a vibrofocus study database'); END;\n"
    for table, ops in (
        ("answers", ("UPDATE", "DELETE")),
        ("planned_trials", ("UPDATE", "DELETE")),
        ("events", ("UPDATE", "DELETE")),
        ("participants", ("DELETE",)),
        ("calibrations", ("DELETE",)),
        ("sessions", ("DELETE",)),
        ("thresholds", ("UPDATE", "DELETE")),
    )
    for op in ops
)


#: Upgrades of an older database, by the version they lead to: additive statements only.
#: 2: a point answer's place, mm in the layout frame (NULL for a location answer).
_MIGRATIONS: dict[int, tuple[str, ...]] = {
    2: ("ALTER TABLE answers ADD COLUMN response_x_mm REAL",
        "ALTER TABLE answers ADD COLUMN response_y_mm REAL"),
    3: (_THRESHOLDS.strip().rstrip(";"),
        *(t.strip().rstrip(";") for t in _TRIGGERS.splitlines() if " ON thresholds " in t)),
}


def now_utc() -> str:
    """The current time, UTC, ISO 8601 with microseconds (every stored time)."""
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


def _folder_writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (a real probe: also right for root and read-only mounts)."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".vibrofocus-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return True


def software_version() -> str:
    """The vibrofocus version, stored with each session it plans."""
    from .. import __version__

    return __version__


class StudyDatabase:
    """One SQLite study database file, opened with its schema checked (or created).

    Its parameters and errors are :class:`~vibrofocus.studies.storage.StudyStore`'s,
    which adds the study rules. Calls are serialised by a lock, so one instance may be
    shared between threads. :meth:`_write` is one ``BEGIN IMMEDIATE`` ... ``COMMIT``
    transaction; SQLite errors come out as :class:`StudyError` in words (a full disk, a
    lock, a read-only file).
    """

    def __init__(self, path: str | os.PathLike, *, create: bool = True) -> None:
        self.path = Path(path)
        self._create = bool(create)
        if self.path.is_dir():
            raise StudyError(f"study database {self.path} is a folder, not a file")
        if not self._create and not self.path.is_file():
            raise StudyError(f"no study database at {self.path}")
        if not self.path.parent.is_dir():
            raise StudyError(f"cannot create the study database {self.path}: the folder {self.path.parent} does not exist")
        self._lock = threading.RLock()
        self._snapshot: Path | None = None
        connect_path = self.path
        writable = _folder_writable(self.path.parent) and (not self.path.exists() or os.access(self.path, os.W_OK))
        if not writable:
            if self._create:
                raise StudyError(
                    f"cannot write the study database {self.path}: its folder {self.path.parent} (or the file) is "
                    "read-only; SQLite keeps its journal beside the database, so a study needs a writable folder "
                    "(copy the database somewhere writable, or fix the permissions)"
                )
            # Reading only (an export) from a read-only place: SQLite cannot create the
            # WAL index beside the file, so read a private copy of the database (and of
            # its write-ahead log, which may hold committed answers).
            connect_path = self._snapshot_copy()
        try:
            self._conn = sqlite3.connect(
                str(connect_path), isolation_level=None, check_same_thread=False, timeout=30.0
            )
        except sqlite3.Error as exc:
            self._drop_snapshot()
            raise StudyError(f"cannot open the study database {self.path}: {exc}") from exc
        try:
            self._conn.row_factory = sqlite3.Row
            self._open_schema()
        except BaseException:
            self._conn.close()
            self._drop_snapshot()
            raise
        self._protect_files()

    def _protect_files(self) -> None:
        """Within a command, no output may replace this database, its journal or a calibration it lists."""
        from .._atomic import guarding, protect

        if not guarding():  # the Python API and the web app: no command's outputs to check
            return
        protect([self.path, Path(str(self.path) + "-wal"), Path(str(self.path) + "-shm")], "study database")
        try:
            rows = self._conn.execute("SELECT path FROM calibrations").fetchall()
        except sqlite3.Error:  # an old schema without the table: nothing more to protect
            return
        protect([str(r[0]) for r in rows], "calibration of the study database")

    def _snapshot_copy(self) -> Path:
        """Copy the database (and its ``-wal``) into a private temporary folder; return the copy's path."""
        import shutil
        import tempfile

        folder = Path(tempfile.mkdtemp(prefix="vibrofocus-readonly-db-"))
        self._snapshot = folder
        try:
            for suffix in ("", "-wal"):
                src = Path(str(self.path) + suffix)
                if src.exists():
                    shutil.copyfile(src, folder / (self.path.name + suffix))
        except OSError as exc:
            self._drop_snapshot()
            raise StudyError(f"cannot read the study database {self.path}: {exc.strerror or exc}") from exc
        return folder / self.path.name

    def _drop_snapshot(self) -> None:
        if self._snapshot is not None:
            import shutil

            shutil.rmtree(self._snapshot, ignore_errors=True)
            self._snapshot = None

    # ------------------------------------------------------------------ lifecycle
    def _open_schema(self) -> None:
        conn = self._conn
        try:
            conn.execute("PRAGMA busy_timeout = 30000")
            app_id = conn.execute("PRAGMA application_id").fetchone()[0]
            version = conn.execute("PRAGMA user_version").fetchone()[0]
            tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        except sqlite3.OperationalError as exc:
            # "unable to open database file", "disk I/O error", locks: not a format problem.
            raise StudyError(f"cannot open the study database {self.path}: {exc}") from exc
        except sqlite3.DatabaseError as exc:
            raise StudyError(f"{self.path} is not a vibrofocus study database: {exc}") from exc
        if app_id not in (0, APPLICATION_ID) or (version == 0 and tables) or (version > 0 and app_id != APPLICATION_ID):
            raise StudyError(
                f"{self.path} is not a vibrofocus study database (application_id {app_id:#x}, "
                f"schema version {version}, tables: {', '.join(tables) or 'none'})"
            )
        if version == 0 and not self._create:
            # Only reading (an export): an empty file is not turned into a database.
            raise StudyError(f"{self.path} is not a vibrofocus study database (an empty file); nothing was changed")
        if version > SCHEMA_VERSION:
            raise StudyError(
                f"the study database {self.path} has schema version {version}, newer than this "
                f"vibrofocus ({software_version()}) understands ({SCHEMA_VERSION}); upgrade vibrofocus "
                "to open it (the file was left untouched)"
            )
        try:
            mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
            conn.execute("PRAGMA synchronous = FULL")
            conn.execute("PRAGMA foreign_keys = ON")
        except sqlite3.OperationalError as exc:
            raise StudyError(f"cannot open the study database {self.path}: {exc}") from exc
        if str(mode).lower() != "wal":
            raise StudyError(f"the study database {self.path} cannot use WAL journaling (got {mode!r})")
        if 0 < version < SCHEMA_VERSION:
            self._migrate()
        if version == 0:
            with self._write("create the study database"):
                if conn.execute("PRAGMA user_version").fetchone()[0] != 0:
                    # Another process created it between our first look and this
                    # transaction (two commands started on a new database at once).
                    return
                # Statement by statement: executescript() would COMMIT our transaction early.
                for statement in (_SCHEMA + _THRESHOLDS + _TRIGGERS).split(";\n"):
                    if statement.strip():
                        conn.execute(statement)
                conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def _migrate(self) -> None:
        """Upgrade an older database to :data:`SCHEMA_VERSION` in one transaction (additive changes)."""
        conn = self._conn
        with self._write("upgrade the study database"):
            version = conn.execute("PRAGMA user_version").fetchone()[0]  # another process may have done it
            for target in range(version + 1, SCHEMA_VERSION + 1):
                for statement in _MIGRATIONS[target]:
                    conn.execute(statement)
            conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def close(self) -> None:
        """Close the connection (committed data is already on disk)."""
        with self._lock:
            self._conn.close()
            self._drop_snapshot()

    def __enter__(self) -> "StudyDatabase":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({str(self.path)!r})"

    @contextlib.contextmanager
    def _write(self, what: str) -> Iterator[sqlite3.Connection]:
        """One write transaction (BEGIN IMMEDIATE ... COMMIT); SQLite errors -> StudyError."""
        with self._lock:
            conn = self._conn
            try:
                conn.execute("BEGIN IMMEDIATE")
                try:
                    yield conn
                    conn.execute("COMMIT")
                except BaseException:
                    if conn.in_transaction:
                        conn.execute("ROLLBACK")
                    raise
            except sqlite3.Error as exc:
                raise self._translate(exc, what) from exc

    @contextlib.contextmanager
    def _read(self, what: str) -> Iterator[sqlite3.Connection]:
        with self._lock:
            try:
                yield self._conn
            except sqlite3.Error as exc:
                raise self._translate(exc, what) from exc

    def _translate(self, exc: sqlite3.Error, what: str) -> StudyError:
        msg = str(exc)
        if "full" in msg.lower():
            return StudyError(
                f"could not {what}: the disk holding {self.path} is full. Nothing of this request "
                "was stored; every answer committed before is intact. Free some space and retry."
            )
        if "locked" in msg.lower() or "busy" in msg.lower():
            return StudyError(f"could not {what}: the study database {self.path} is locked by another program ({msg})")
        if "readonly" in msg.lower():
            return StudyError(f"could not {what}: the study database {self.path} is read-only ({msg})")
        return StudyError(f"could not {what}: database error in {self.path}: {msg}")
