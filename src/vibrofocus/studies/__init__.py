"""Localization studies (SPEC §6): planning, storage that loses nothing, export.

Public API
----------
Planning (:mod:`.protocol`)
    :class:`StudyDesign` (study 1 or 2; methods x locations x repetitions after training
    trials), :class:`PlannedTrial`, :func:`plan_trials`, :func:`parse_response`,
    :func:`format_response`.
Storage (:mod:`.storage`)
    :class:`StudyStore` (SQLite, WAL, ``synchronous=FULL``)::

        StudyStore(path)
        .add_participant(participant_id, *, simulated=False) -> ParticipantInfo
        .add_calibration(participant_id, path) -> int
        .create_session(participant_id, study, *, seed, calibration_id=None, config=None) -> int
        .planned_trials(session_id) -> list[PlannedTrial]
        .next_trial(session_id) -> PlannedTrial | None        # first unanswered
        .record_answer(session_id, trial_index, response, rt_s, *, answer_id,
                       drive_sha256=None) -> AnswerReceipt     # one committed transaction
        .log_event(session_id, kind, payload=None) -> int
        .set_status(session_id, status)                        # logs pause/resume/abort/complete
        .answers(session_id) -> list[AnswerReceipt]
        .export_trials_csv(path, *, participant_id=None) -> int
        # more: participants(), participant(id), calibration(id), calibrations(pid),
        # verify_calibration(id), session(id) -> SessionInfo, sessions(pid, study=),
        # events(session_id, kind=None), trial_rows(), close(), context manager

    Answers must come in trial order; the same ``answer_id`` again returns the same
    receipt; the first answer sets status ``running`` and the last ``completed``.
Export (:mod:`.export`)
    :data:`TRIALS_COLUMNS`, :func:`write_trials_csv`, :func:`read_trials_csv`.
"""

from .export import TRIALS_COLUMNS, read_trials_csv, write_trials_csv
from .protocol import PHASES, STUDIES, PlannedTrial, StudyDesign, format_response, parse_response, plan_trials
from .storage import (
    APPLICATION_ID,
    SCHEMA_VERSION,
    SESSION_STATUSES,
    AnswerReceipt,
    CalibrationRecord,
    Event,
    ParticipantInfo,
    SessionInfo,
    StudyStore,
    file_sha256,
)

__all__ = [
    "STUDIES",
    "PHASES",
    "StudyDesign",
    "PlannedTrial",
    "plan_trials",
    "parse_response",
    "format_response",
    "StudyStore",
    "AnswerReceipt",
    "SessionInfo",
    "CalibrationRecord",
    "ParticipantInfo",
    "Event",
    "SCHEMA_VERSION",
    "APPLICATION_ID",
    "SESSION_STATUSES",
    "file_sha256",
    "TRIALS_COLUMNS",
    "write_trials_csv",
    "read_trials_csv",
]
