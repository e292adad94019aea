"""The study rules of the database of localization studies, which loses no acknowledged answer.

The file, its schema and its transactions are :mod:`.database`'s; the records it hands
out are :mod:`.records`'; the allowed status changes are :mod:`.session_status`'s.
Design of the rules (why each part is there):

- One transaction per answer, committed before :meth:`StudyStore.record_answer`
  returns: what the participant saw acknowledged is on disk.
- ``UNIQUE(session_id, trial_index)`` and a client-supplied, ``UNIQUE`` ``answer_id``:
  a retried request (same ``answer_id``) gets the same receipt and no second row; a
  second, different answer to a trial is refused.
- The full trial list is written before the first stimulus, so a resumed session runs
  the same plan and continues at the first unanswered trial.
- Nothing is deleted (the database's triggers refuse it): aborting a session only
  changes its status.

:class:`StudyStore` is the one facade; its methods live in parts split along the row
types, each a :class:`~vibrofocus.studies.database.StudyDatabase` whose writes go through
its one transaction rule: :mod:`.store_participants`, :mod:`.store_calibrations`,
:mod:`.store_sessions` (sessions, planned trials, answers) and :mod:`.store_events` (the
event log, the trials' export).
"""

from __future__ import annotations

from .database import APPLICATION_ID, SCHEMA_VERSION
from .records import AnswerReceipt, CalibrationRecord, Event, ParticipantInfo, SessionInfo
from .session_status import SESSION_STATUSES
from .store_calibrations import CalibrationRows, file_sha256
from .store_events import EventRows
from .store_participants import ParticipantRows, check_participant_id
from .store_sessions import SessionRows, session_protocol

# SCHEMA_VERSION, APPLICATION_ID and the records are re-exported: their public home has
# been this module since the first release.
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
    "check_participant_id",
    "session_protocol",
]


class StudyStore(ParticipantRows, CalibrationRows, SessionRows, EventRows):
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
