"""SQLite storage of localization studies that loses no acknowledged answer.

Design (why each part is there):

- WAL journal with ``synchronous=FULL``: a committed transaction survives a killed
  process and a power cut; readers (the experimenter page, an export) never block the
  trial loop.
- One transaction per answer, committed before :meth:`StudyStore.record_answer`
  returns: what the participant saw acknowledged is on disk.
- ``UNIQUE(session_id, trial_index)`` and a client-supplied, ``UNIQUE`` ``answer_id``:
  a retried request (same ``answer_id``) gets the same receipt and no second row; a
  second, different answer to a trial is refused.
- The full trial list is written before the first stimulus, so a resumed session runs
  the same plan and continues at the first unanswered trial.
- Answers, planned trials and the event log are append-only (triggers refuse UPDATE and
  DELETE); participants, calibrations and sessions cannot be deleted. Aborting a
  session only changes its status.
- The schema version lives in ``PRAGMA user_version`` and the file is marked with a
  vibrofocus ``application_id``; a database from a newer vibrofocus is refused rather
  than misread.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import sqlite3
import threading
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..errors import AnswerRefused, StudyError
from .protocol import PlannedTrial, StudyDesign, format_response, parse_response, plan_trials
from .session_status import SESSION_STATUSES, check_transition, status_after_answer, transition_event

__all__ = [
    "SCHEMA_VERSION",
    "APPLICATION_ID",
    "SESSION_STATUSES",
    "StudyStore",
    "AnswerReceipt",
    "SessionInfo",
    "CalibrationRecord",
    "ParticipantInfo",
    "Event",
    "file_sha256",
]

#: Version of the database layout written by this vibrofocus (``PRAGMA user_version``).
SCHEMA_VERSION = 1
#: ``PRAGMA application_id`` marking a vibrofocus study database ("VBFC").
APPLICATION_ID = 0x56424643

_PARTICIPANT_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$")
_EVENT_RE = re.compile(r"^[a-z][a-z0-9_]{0,39}$")
_ANSWER_ID_RE = re.compile(r"^[\x21-\x7e]{1,128}$")  # printable ASCII, no spaces

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
    )
    for op in ops
)


# ---------------------------------------------------------------------- records
@dataclass(frozen=True)
class AnswerReceipt:
    """What :meth:`StudyStore.record_answer` returns once the answer is on disk.

    Attributes
    ----------
    answer_id : str
        The client-supplied id.
    session_id, trial_index : int
        Which trial it answers.
    response : tuple of int
        The locations, ascending.
    rt_s : float
        Response time, s.
    drive_sha256 : str or None
        Hash of the drive signals played for the trial.
    calibration_id : int or None
        Calibration the session used.
    recorded_at : str
        UTC time of the commit, ISO 8601.
    duplicate : bool
        True when this receipt answers a re-send (the same ``answer_id`` again): nothing
        new was stored. Not part of equality: a re-send's receipt equals the original's.
    """

    answer_id: str
    session_id: int
    trial_index: int
    response: tuple[int, ...]
    rt_s: float
    drive_sha256: str | None
    calibration_id: int | None
    recorded_at: str
    duplicate: bool = field(default=False, compare=False)


@dataclass(frozen=True)
class SessionInfo:
    """A session as stored, with its progress (``n_answered`` of ``n_trials``).

    Attributes
    ----------
    session_id : int
    participant_id : str
    study : int
        1 or 2.
    seed : int
        Seed of the trial order.
    status : str
        The session's state (planned, running, paused, finished, aborted, ...).
    calibration_id : int or None
        The calibration the stimuli are rendered from.
    config : dict
        Design and run settings the session was planned with.
    software_version : str
        vibrofocus version that planned it.
    created_at, updated_at : str
        ISO 8601 times, UTC.
    n_trials, n_answered : int
        Planned and answered trials.
    """

    session_id: int
    participant_id: str
    study: int
    seed: int
    status: str
    calibration_id: int | None
    config: dict[str, Any]
    software_version: str
    created_at: str
    updated_at: str
    n_trials: int
    n_answered: int

    @property
    def design(self) -> StudyDesign:
        """The study design the session was planned with."""
        return StudyDesign.from_config(self.study, self.config)

    @property
    def finished(self) -> bool:
        """Every planned trial has an answer."""
        return self.n_answered >= self.n_trials


@dataclass(frozen=True)
class CalibrationRecord:
    """A calibration file registered for a participant.

    Attributes
    ----------
    calibration_id : int
    participant_id : str
    path : str
        The file.
    sha256 : str
        Hex SHA-256 of its bytes when registered (checked before use).
    created_at : str
        ISO 8601 time, UTC.
    """

    calibration_id: int
    participant_id: str
    path: str
    sha256: str
    created_at: str


@dataclass(frozen=True)
class ParticipantInfo:
    """A participant.

    Attributes
    ----------
    participant_id : str
    simulated : bool
        True when the answers come from the perceptual model (not a person).
    created_at : str
        ISO 8601 time, UTC.
    """

    participant_id: str
    simulated: bool
    created_at: str


@dataclass(frozen=True)
class Event:
    """One entry of a session's append-only event log.

    Attributes
    ----------
    event_id : int
    session_id : int
    kind : str
        What happened (``cue``, ``stimulus_onset``, ``answer``, ...).
    payload : Any
        Its details, as stored (JSON).
    created_at : str
        ISO 8601 time, UTC.
    """

    event_id: int
    session_id: int
    kind: str
    payload: Any
    created_at: str


# ---------------------------------------------------------------------- helpers
def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    str
        Hex digest.
    """
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


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


def _software_version() -> str:
    from .. import __version__

    return __version__


class StudyStore:
    """The study database: participants, calibrations, sessions, planned trials, answers
    and an append-only event log, in one SQLite file.

    Parameters
    ----------
    path : path-like
        Database file; created with the current schema if it does not exist.
    create : bool
        ``False`` to open an existing study database only (an export): a missing or
        empty file is refused and left as it is.

    Raises
    ------
    StudyError
        The file is not a vibrofocus study database, comes from a newer vibrofocus
        (schema version above :data:`SCHEMA_VERSION`), or cannot be opened.

    Notes
    -----
    One instance may be shared between threads (calls are serialised by a lock); several
    processes may open the same file (SQLite locking, 30 s busy timeout). Every write is
    one transaction; :meth:`record_answer` commits with ``synchronous=FULL`` before it
    returns. A full disk surfaces as :class:`StudyError` and leaves every committed
    answer intact. Use as a context manager or call :meth:`close`.
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
                f"vibrofocus ({_software_version()}) understands ({SCHEMA_VERSION}); upgrade vibrofocus "
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
        if version == 0:
            with self._write("create the study database"):
                # Statement by statement: executescript() would COMMIT our transaction early.
                for statement in (_SCHEMA + _TRIGGERS).split(";\n"):
                    if statement.strip():
                        conn.execute(statement)
                conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def close(self) -> None:
        """Close the connection (committed data is already on disk)."""
        with self._lock:
            self._conn.close()
            self._drop_snapshot()

    def __enter__(self) -> "StudyStore":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"StudyStore({str(self.path)!r})"

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

    # ------------------------------------------------------------------ participants
    def add_participant(self, participant_id: str, *, simulated: bool = False) -> ParticipantInfo:
        """Register a participant; returns the existing record if already registered.

        Parameters
        ----------
        participant_id : str
            1-64 characters: letters, digits, ``_ . -``, starting with a letter or digit.
        simulated : bool
            Whether answers come from the simulated perceptual model.

        Raises
        ------
        StudyError
            Malformed id, or the id exists with a different ``simulated`` flag.
        """
        if not isinstance(participant_id, str) or not _PARTICIPANT_RE.match(participant_id):
            raise StudyError(
                f"participant id must be 1-64 letters, digits, '_', '.' or '-' starting with a "
                f"letter or digit, got {participant_id!r}"
            )
        with self._write(f"add participant {participant_id!r}") as conn:
            row = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
            if row is None:
                conn.execute(
                    "INSERT INTO participants (participant_id, simulated, created_at) VALUES (?, ?, ?)",
                    (participant_id, int(bool(simulated)), _now()),
                )
                row = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
            elif bool(row["simulated"]) != bool(simulated):
                kind = "simulated" if row["simulated"] else "real"
                raise StudyError(f"participant {participant_id!r} already exists as a {kind} participant")
        return ParticipantInfo(row["participant_id"], bool(row["simulated"]), row["created_at"])

    def participants(self) -> list[ParticipantInfo]:
        """All participants, in the order they were added."""
        with self._read("list participants") as conn:
            rows = conn.execute("SELECT * FROM participants ORDER BY rowid").fetchall()
        return [ParticipantInfo(r["participant_id"], bool(r["simulated"]), r["created_at"]) for r in rows]

    def participant(self, participant_id: str) -> ParticipantInfo:
        """One participant; StudyError if unknown."""
        with self._read("look up a participant") as conn:
            self._require_participant(conn, participant_id)
            r = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
        return ParticipantInfo(r["participant_id"], bool(r["simulated"]), r["created_at"])

    def _require_participant(self, conn: sqlite3.Connection, participant_id: Any) -> None:
        row = conn.execute("SELECT 1 FROM participants WHERE participant_id = ?", (str(participant_id),)).fetchone()
        if row is None:
            raise StudyError(f"unknown participant {participant_id!r} in {self.path}; add the participant first")

    # ------------------------------------------------------------------ calibrations
    def add_calibration(self, participant_id: str, path: str | os.PathLike) -> int:
        """Register a calibration file (absolute path and SHA-256) for a participant.

        Returns
        -------
        int
            The calibration id; the existing id when the same file content is already
            registered for this participant.
        """
        file = Path(path)
        try:
            sha = file_sha256(file)
        except OSError as exc:
            raise StudyError(f"cannot read the calibration file {file}: {exc.strerror or exc}") from exc
        with self._write(f"add a calibration for {participant_id!r}") as conn:
            self._require_participant(conn, participant_id)
            row = conn.execute(
                "SELECT calibration_id FROM calibrations WHERE participant_id = ? AND sha256 = ?",
                (participant_id, sha),
            ).fetchone()
            if row is not None:
                return int(row[0])
            cur = conn.execute(
                "INSERT INTO calibrations (participant_id, path, sha256, created_at) VALUES (?, ?, ?, ?)",
                (participant_id, str(file.resolve()), sha, _now()),
            )
            return int(cur.lastrowid)

    def calibration(self, calibration_id: int) -> CalibrationRecord:
        """A registered calibration; StudyError if unknown."""
        with self._read("look up a calibration") as conn:
            r = conn.execute("SELECT * FROM calibrations WHERE calibration_id = ?", (_as_int(calibration_id, "calibration id"),)).fetchone()
        if r is None:
            raise StudyError(f"unknown calibration {calibration_id!r} in {self.path}")
        return CalibrationRecord(r["calibration_id"], r["participant_id"], r["path"], r["sha256"], r["created_at"])

    def calibrations(self, participant_id: str) -> list[CalibrationRecord]:
        """Calibrations of a participant, oldest first."""
        with self._read("list calibrations") as conn:
            self._require_participant(conn, participant_id)
            rows = conn.execute(
                "SELECT * FROM calibrations WHERE participant_id = ? ORDER BY calibration_id", (participant_id,)
            ).fetchall()
        return [CalibrationRecord(r["calibration_id"], r["participant_id"], r["path"], r["sha256"], r["created_at"]) for r in rows]

    def verify_calibration(self, calibration_id: int) -> Path:
        """Path of a registered calibration file after checking it still has its SHA-256.

        Raises
        ------
        StudyError
            The file is missing or its content changed since it was registered.
        """
        rec = self.calibration(calibration_id)
        path = Path(rec.path)
        try:
            sha = file_sha256(path)
        except OSError as exc:
            raise StudyError(f"calibration {calibration_id} file {path} cannot be read: {exc.strerror or exc}") from exc
        if sha != rec.sha256:
            raise StudyError(
                f"calibration {calibration_id} file {path} changed since it was registered "
                f"(sha256 {sha[:12]}..., expected {rec.sha256[:12]}...)"
            )
        return path

    # ------------------------------------------------------------------ sessions
    def create_session(
        self,
        participant_id: str,
        study: int,
        *,
        seed: int,
        calibration_id: int | None = None,
        config: Mapping[str, Any] | None = None,
    ) -> int:
        """Create a session and write its full planned trial list (training, then main).

        Parameters
        ----------
        participant_id : str
            A registered participant.
        study : {1, 2}
            Study 1 (one location per answer) or Study 2 (several allowed).
        seed : int
            Seed of the trial order, stored with the session.
        calibration_id : int, optional
            The participant's calibration used to render the stimuli.
        config : mapping, optional
            JSON-serialisable settings stored with the session. The design keys
            ``methods``, ``locations``, ``repetitions``, ``n_training`` change the
            design (default: 3 methods x 9 locations x 3 repetitions after 5 training
            trials).

        Returns
        -------
        int
            The session id. Status ``planned``.
        """
        if isinstance(study, bool) or study not in (1, 2):
            raise StudyError(f"study must be 1 or 2, got {study!r}")
        design = StudyDesign.from_config(int(study), config)
        stored_config = dict(config or {})
        stored_config.update(design.to_dict())
        try:
            config_json = json.dumps(stored_config, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise StudyError(f"session config must be JSON-serialisable: {exc}") from exc
        trials = plan_trials(design, seed)
        now = _now()
        with self._write(f"create a study {study} session for {participant_id!r}") as conn:
            self._require_participant(conn, participant_id)
            if calibration_id is not None:
                cal = conn.execute(
                    "SELECT participant_id FROM calibrations WHERE calibration_id = ?",
                    (_as_int(calibration_id, "calibration id"),),
                ).fetchone()
                if cal is None:
                    raise StudyError(f"unknown calibration {calibration_id!r} in {self.path}")
                if cal[0] != participant_id:
                    raise StudyError(
                        f"calibration {calibration_id} belongs to participant {cal[0]!r}, not {participant_id!r}"
                    )
            cur = conn.execute(
                "INSERT INTO sessions (participant_id, study, seed, calibration_id, status, config, "
                "software_version, created_at, updated_at) VALUES (?, ?, ?, ?, 'planned', ?, ?, ?, ?)",
                (participant_id, int(study), int(seed), calibration_id, config_json, _software_version(), now, now),
            )
            session_id = int(cur.lastrowid)
            conn.executemany(
                "INSERT INTO planned_trials (session_id, trial_index, phase, trial, method, target) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                [(session_id, t.trial_index, t.phase, t.trial, t.method, t.target) for t in trials],
            )
            self._insert_event(conn, session_id, "created", {"study": int(study), "seed": int(seed), "n_trials": len(trials)})
        return session_id

    def session(self, session_id: int) -> SessionInfo:
        """A session with its progress; StudyError if unknown."""
        with self._read("look up a session") as conn:
            return self._session(conn, session_id)

    def sessions(self, participant_id: str | None = None, *, study: int | None = None) -> list[SessionInfo]:
        """Sessions, oldest first; optionally of one participant and/or one study."""
        with self._read("list sessions") as conn:
            sql, args = "SELECT session_id FROM sessions WHERE 1 = 1", []
            if participant_id is not None:
                self._require_participant(conn, participant_id)
                sql += " AND participant_id = ?"
                args.append(participant_id)
            if study is not None:
                sql += " AND study = ?"
                args.append(int(study))
            ids = [r[0] for r in conn.execute(sql + " ORDER BY session_id", args)]
            return [self._session(conn, i) for i in ids]

    def _session(self, conn: sqlite3.Connection, session_id: Any) -> SessionInfo:
        sid = _as_int(session_id, "session id")
        r = conn.execute("SELECT * FROM sessions WHERE session_id = ?", (sid,)).fetchone()
        if r is None:
            raise StudyError(f"unknown session {session_id!r} in {self.path}")
        n_trials = conn.execute("SELECT COUNT(*) FROM planned_trials WHERE session_id = ?", (sid,)).fetchone()[0]
        n_answered = conn.execute("SELECT COUNT(*) FROM answers WHERE session_id = ?", (sid,)).fetchone()[0]
        return SessionInfo(
            r["session_id"], r["participant_id"], r["study"], r["seed"], r["status"], r["calibration_id"],
            json.loads(r["config"]), r["software_version"], r["created_at"], r["updated_at"], n_trials, n_answered,
        )

    def set_status(self, session_id: int, status: str) -> None:
        """Change a session's status and log it (``pause``, ``resume``, ``abort``, ``complete``).

        Setting the current status again does nothing. ``completed`` needs every planned
        trial answered, and a completed session keeps that status. Aborting keeps all data;
        an aborted session can be resumed by setting ``running``.
        """
        with self._write(f"set the status of session {session_id!r}") as conn:
            info = self._session(conn, session_id)
            check_transition(info.session_id, info.status, status, n_answered=info.n_answered, n_trials=info.n_trials)
            if info.status == status:
                return
            self._change_status(conn, info, status, _now())

    def _change_status(self, conn: sqlite3.Connection, info: SessionInfo, status: str, now: str) -> None:
        """Write an allowed status change and its event (inside the caller's transaction)."""
        conn.execute("UPDATE sessions SET status = ?, updated_at = ? WHERE session_id = ?", (status, now, info.session_id))
        self._insert_event(conn, info.session_id, transition_event(info.status, status), {"from": info.status, "to": status})

    # ------------------------------------------------------------------ trials
    def planned_trials(self, session_id: int) -> list[PlannedTrial]:
        """The full planned trial list of a session, in order."""
        with self._read("read the planned trials") as conn:
            self._session(conn, session_id)
            rows = conn.execute(
                "SELECT * FROM planned_trials WHERE session_id = ? ORDER BY trial_index", (int(session_id),)
            ).fetchall()
        return [_trial(r) for r in rows]

    def next_trial(self, session_id: int) -> PlannedTrial | None:
        """The first unanswered trial of a session, or ``None`` when all are answered."""
        with self._read("find the next trial") as conn:
            self._session(conn, session_id)
            r = self._next_row(conn, int(session_id))
        return None if r is None else _trial(r)

    @staticmethod
    def _next_row(conn: sqlite3.Connection, sid: int) -> sqlite3.Row | None:
        return conn.execute(
            "SELECT p.* FROM planned_trials p LEFT JOIN answers a "
            "ON a.session_id = p.session_id AND a.trial_index = p.trial_index "
            "WHERE p.session_id = ? AND a.answer_pk IS NULL ORDER BY p.trial_index LIMIT 1",
            (sid,),
        ).fetchone()

    # ------------------------------------------------------------------ answers
    def record_answer(
        self,
        session_id: int,
        trial_index: int,
        response: Any,
        rt_s: float,
        *,
        answer_id: str,
        drive_sha256: str | None = None,
        require_presented: bool = False,
    ) -> AnswerReceipt:
        """Validate an answer and commit it in its own transaction before returning.

        This is the one place where the rules of answers are enforced, for every
        responder (keypad, simulated participant, web page).

        Parameters
        ----------
        session_id : int
            The session.
        trial_index : int
            0-based index of the trial answered; it must be the session's first
            unanswered trial (answers come in order: nothing is skipped).
        response : int, str or iterable of int
            Locations (see :func:`parse_response`): Study 1 exactly one, Study 2 one or
            more distinct, each within the design's locations.
        rt_s : float
            Response time, s (finite, >= 0).
        answer_id : str
            Client-supplied id (printable ASCII, no spaces, <= 128 characters). The same
            id sent again returns the same receipt (``duplicate=True``) and stores
            nothing new.
        drive_sha256 : str, optional
            SHA-256 (hex) of the drive signals played for this trial. Default with
            ``require_presented``: the hash in the trial's last ``stimulus_onset`` event.
        require_presented : bool
            Refuse an answer to a trial whose ``stimulus_onset`` is not logged (an answer
            sent before the stimulus is not data): for answers that arrive from outside
            the trial loop, such as the web participant page.

        Returns
        -------
        AnswerReceipt

        Raises
        ------
        AnswerRefused
            Invalid response, rt or answer id, unknown trial, a trial already answered
            under another ``answer_id``, an ``answer_id`` reused for another trial or
            response, a trial out of order, or (``require_presented``) a trial not
            presented; :attr:`AnswerRefused.reason` says which. Nothing is stored.
        StudyError
            Unknown session, or a database failure (disk full, ...): the answer is
            then *not* stored and earlier answers are intact.

        Notes
        -----
        Answers are accepted whatever the session's status (an answer to a stimulus felt
        just before a pause or abort is data). The status then changes as
        :func:`~vibrofocus.studies.session_status.status_after_answer` says (the first
        answer starts a planned session, the last completes it), in the same
        transaction. Each answer is also logged as an ``answer`` event.
        """
        if not isinstance(answer_id, str) or not _ANSWER_ID_RE.match(answer_id):
            raise AnswerRefused(f"answer_id must be 1-128 printable ASCII characters without spaces, got {answer_id!r}", "invalid")
        tidx = _as_int(trial_index, "trial index")
        if drive_sha256 is not None and (not isinstance(drive_sha256, str) or not re.fullmatch(r"[0-9a-f]{64}", drive_sha256)):
            raise StudyError(f"drive_sha256 must be 64 lowercase hex digits, got {drive_sha256!r}")
        with self._write(f"record the answer to trial {trial_index!r} of session {session_id!r}") as conn:
            info = self._session(conn, session_id)
            sid = info.session_id
            try:
                locations = parse_response(response, info.design)
            except StudyError as exc:
                raise AnswerRefused(str(exc), "invalid") from None
            prior = conn.execute("SELECT * FROM answers WHERE answer_id = ?", (answer_id,)).fetchone()
            if prior is not None:
                receipt = _receipt(prior)
                if (receipt.session_id, receipt.trial_index, receipt.response) != (sid, tidx, locations):
                    same_trial = (receipt.session_id, receipt.trial_index) == (sid, tidx)
                    raise AnswerRefused(
                        f"answer_id {answer_id!r} was already used for session {receipt.session_id} trial "
                        f"{receipt.trial_index} (response {format_response(receipt.response)!r}); "
                        "send a new answer_id for a new answer", "answered" if same_trial else "reused_id",
                    )
                return _receipt(prior, duplicate=True)  # idempotent retry: same receipt, nothing written
            rt = _check_rt(rt_s)
            if not 0 <= tidx < info.n_trials:
                raise AnswerRefused(
                    f"trial_index {tidx} is out of range: session {sid} has no trial {tidx} (trials 0..{info.n_trials - 1})",
                    "unknown_trial",
                )
            existing = conn.execute(
                "SELECT answer_id, response FROM answers WHERE session_id = ? AND trial_index = ?", (sid, tidx)
            ).fetchone()
            if existing is not None:
                raise AnswerRefused(
                    f"trial {tidx} of session {sid} is already answered ({existing['response']!r}, "
                    f"answer_id {existing['answer_id']!r}); a trial takes one answer", "answered",
                )
            nxt = self._next_row(conn, sid)
            if nxt is not None and nxt["trial_index"] != tidx:
                raise AnswerRefused(
                    f"trial {tidx} of session {sid} is not the next trial: answer trial {nxt['trial_index']} first",
                    "not_current",
                )
            if require_presented:
                onset = self._last_onset(conn, sid, tidx)
                if onset is None:
                    raise AnswerRefused(f"trial {tidx} of session {sid} has not been presented (no stimulus onset)", "not_presented")
                if drive_sha256 is None:
                    drive_sha256 = onset.get("drive_sha256")
            now = _now()
            conn.execute(
                "INSERT INTO answers (answer_id, session_id, trial_index, response, rt_s, drive_sha256, "
                "calibration_id, recorded_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (answer_id, sid, tidx, format_response(locations), rt, drive_sha256, info.calibration_id, now),
            )
            self._insert_event(conn, sid, "answer", {
                "trial_index": tidx, "answer_id": answer_id, "response": list(locations), "rt_s": rt,
            })
            new_status = status_after_answer(info.status, finished=info.n_answered + 1 >= info.n_trials)
            if new_status != info.status:
                self._change_status(conn, info, new_status, now)
            else:
                conn.execute("UPDATE sessions SET updated_at = ? WHERE session_id = ?", (now, sid))
            row = conn.execute("SELECT * FROM answers WHERE answer_id = ?", (answer_id,)).fetchone()
        return _receipt(row)

    @staticmethod
    def _last_onset(conn: sqlite3.Connection, sid: int, tidx: int) -> dict[str, Any] | None:
        """Payload of the last ``stimulus_onset`` event of a trial, or None if it was never presented."""
        row = conn.execute(
            "SELECT payload FROM events WHERE session_id = ? AND kind = 'stimulus_onset' "
            "AND json_extract(payload, '$.trial_index') = ? ORDER BY event_id DESC LIMIT 1",
            (sid, tidx),
        ).fetchone()
        return None if row is None else json.loads(row["payload"])

    def answers(self, session_id: int) -> list[AnswerReceipt]:
        """Committed answers of a session, by trial index."""
        with self._read("read the answers") as conn:
            self._session(conn, session_id)
            rows = conn.execute(
                "SELECT * FROM answers WHERE session_id = ? ORDER BY trial_index", (int(session_id),)
            ).fetchall()
        return [_receipt(r) for r in rows]

    # ------------------------------------------------------------------ events
    def log_event(self, session_id: int, kind: str, payload: Any = None) -> int:
        """Append an event (``cue``, ``stimulus_onset``, ``pause``, ...) to the session's log.

        Parameters
        ----------
        kind : str
            Lower-case identifier, ``[a-z][a-z0-9_]*``, at most 40 characters.
        payload : JSON-serialisable, optional
            Details (trial index, drive hash, ...).

        Returns
        -------
        int
            The event id (increasing).
        """
        if not isinstance(kind, str) or not _EVENT_RE.match(kind):
            raise StudyError(f"event kind must be a lower-case identifier like 'cue', got {kind!r}")
        with self._write(f"log a {kind!r} event") as conn:
            info = self._session(conn, session_id)
            return self._insert_event(conn, info.session_id, kind, payload)

    @staticmethod
    def _insert_event(conn: sqlite3.Connection, sid: int, kind: str, payload: Any) -> int:
        try:
            text = None if payload is None else json.dumps(payload, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise StudyError(f"event payload must be JSON-serialisable: {exc}") from exc
        cur = conn.execute(
            "INSERT INTO events (session_id, kind, payload, created_at) VALUES (?, ?, ?, ?)", (sid, kind, text, _now())
        )
        return int(cur.lastrowid)

    def events(self, session_id: int, *, kind: str | None = None) -> list[Event]:
        """The session's event log, oldest first (optionally one kind)."""
        with self._read("read the event log") as conn:
            info = self._session(conn, session_id)
            sql, args = "SELECT * FROM events WHERE session_id = ?", [info.session_id]
            if kind is not None:
                sql += " AND kind = ?"
                args.append(kind)
            rows = conn.execute(sql + " ORDER BY event_id", args).fetchall()
        return [
            Event(r["event_id"], r["session_id"], r["kind"], None if r["payload"] is None else json.loads(r["payload"]), r["created_at"])
            for r in rows
        ]

    # ------------------------------------------------------------------ export
    def trial_rows(self, *, participant_id: str | None = None) -> list[dict[str, Any]]:
        """Answered trials joined with their plan, one dict per trial.

        Keys: the trials-file columns (``participant, study, phase, trial, method,
        target, response, rt_s``) plus ``session_id``, ``trial_index``, ``answer_id``,
        ``drive_sha256``, ``calibration_id``, ``recorded_at``, the session columns of
        the trials file: ``session`` (id), ``session_status``, ``dry_run`` (1 for a session
        planned without a calibration: nothing was played), and ``simulated`` (1: the
        participant is simulated, answers from the perceptual model). Ordered by participant
        (as added), study, session and trial index.
        """
        with self._read("read the trials") as conn:
            sql = (
                "SELECT s.participant_id AS participant, s.study AS study, p.phase AS phase, p.trial AS trial, "
                "p.method AS method, p.target AS target, a.response AS response, a.rt_s AS rt_s, "
                "s.session_id AS session_id, p.trial_index AS trial_index, a.answer_id AS answer_id, "
                "a.drive_sha256 AS drive_sha256, a.calibration_id AS calibration_id, a.recorded_at AS recorded_at, "
                "s.session_id AS session, s.status AS session_status, (s.calibration_id IS NULL) AS dry_run, "
                "pt.simulated AS simulated "
                "FROM answers a JOIN planned_trials p ON p.session_id = a.session_id AND p.trial_index = a.trial_index "
                "JOIN sessions s ON s.session_id = a.session_id "
                "JOIN participants pt ON pt.participant_id = s.participant_id "
            )
            args: list[Any] = []
            if participant_id is not None:
                self._require_participant(conn, participant_id)
                sql += "WHERE s.participant_id = ? "
                args.append(participant_id)
            sql += "ORDER BY pt.rowid, s.study, s.session_id, p.trial_index"
            return [dict(r) for r in conn.execute(sql, args).fetchall()]

    def export_trials_csv(self, path: str | os.PathLike, *, participant_id: str | None = None) -> int:
        """Write the trials file of docs/file-formats.md, trials file (every answered trial); returns the row count.

        The file has the session columns after the contract's (see
        :data:`~vibrofocus.studies.export.SESSION_COLUMNS`), so that an analysis can leave
        out aborted sessions and dry runs.
        """
        from .export import write_trials_csv

        return write_trials_csv(self.trial_rows(participant_id=participant_id), path, sessions=True)


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool):
        raise StudyError(f"{name} must be an integer, got {value!r}")
    try:
        if isinstance(value, float) and not value.is_integer():
            raise ValueError
        return int(value)
    except (TypeError, ValueError):
        raise StudyError(f"{name} must be an integer, got {value!r}") from None


def _trial(r: sqlite3.Row) -> PlannedTrial:
    return PlannedTrial(r["session_id"], r["trial_index"], r["phase"], r["trial"], r["method"], r["target"])


def _check_rt(rt_s: Any) -> float:
    try:
        rt = float(rt_s)
    except (TypeError, ValueError):
        raise AnswerRefused(f"rt_s must be a number of seconds, got {rt_s!r}", "invalid") from None
    if not math.isfinite(rt) or rt < 0:
        raise AnswerRefused(f"rt_s must be finite and >= 0 s, got {rt_s!r}", "invalid")
    return rt


def _receipt(r: sqlite3.Row, *, duplicate: bool = False) -> AnswerReceipt:
    return AnswerReceipt(
        answer_id=r["answer_id"],
        session_id=r["session_id"],
        trial_index=r["trial_index"],
        response=tuple(int(x) for x in r["response"].split()),
        rt_s=float(r["rt_s"]),
        drive_sha256=r["drive_sha256"],
        calibration_id=r["calibration_id"],
        recorded_at=r["recorded_at"],
        duplicate=duplicate,
    )
