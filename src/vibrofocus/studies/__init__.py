"""Localization studies (docs/file-formats.md, trials file): planning, storage that loses nothing, export.

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
    receipt; the first answer sets status ``running`` and the last ``completed``. A
    refused answer raises :class:`~vibrofocus.errors.AnswerRefused` (``reason``).
Session states (:mod:`.session_status`)
    The one state machine: :data:`SESSION_STATUSES`, :data:`TRANSITIONS`,
    :func:`action_status` (start / pause / resume / stop), used by the store, the
    engine and the web app.
Export (the trials file, :mod:`vibrofocus.io.trials_csv`)
    :data:`TRIALS_COLUMNS`, :func:`write_trials_csv`, :func:`read_trials_csv`.
Running trials (:mod:`.engine`)
    ``StudyEngine(store, session_id, rig, calibration=None, *, renderer=None, cue=None,
    n_samples=4096, limit_v=10.0)`` with ``.stimulus(method, target) -> Stimulus``
    (cached drives + sha256), ``.present(trial) -> Presentation`` (logs ``cue``, beeps,
    logs ``stimulus_onset``, ``rig.play``), ``.submit(presentation, Response(locations, rt_s),
    *, answer_id=None) -> AnswerReceipt`` and ``.run(responder, *, pace_s=0, max_trials=None,
    progress=None) -> RunSummary``: the one study loop of every responder. A responder
    has ``respond(presentation) -> Response | PAUSE | ABORT | STOP | Again`` and
    ``wait_resume() -> bool | STOP``, and may have the hooks ``before_cue(trial)``,
    ``cue_shown(trial)`` and ``answered(presentation, receipt)`` (the web participant
    page uses them). :func:`drive_sha256` (shape, then float64 bytes),
    :func:`calibration_renderer` / :class:`CalibrationRenderer`, :func:`terminal_beep`,
    :func:`headphone_beep`.
Simulated participants
    In :mod:`vibrofocus.simulation`, one floor up: it runs this package's engine with
    a perceptual model in place of a person.
"""

from .engine import (
    ABORT,
    PAUSE,
    STOP,
    Again,
    CalibrationRenderer,
    Presentation,
    Response,
    RunSummary,
    Stimulus,
    StudyEngine,
    calibration_renderer,
    drive_sha256,
    represent_after_xrun,
    terminal_beep,
    headphone_beep,
)
from ..io.trials_csv import TRIALS_COLUMNS, read_trials_csv, write_trials_csv
from .protocol import (DEFAULT_LEVELS, LEGACY_LEVELS, LEVEL_RULES, PHASES, STUDIES, PlannedTrial,
                       level_options, StudyDesign, format_response, parse_response, plan_trials)
from .session_status import SESSION_STATUSES, TRANSITIONS, action_status
from .storage import (
    APPLICATION_ID,
    SCHEMA_VERSION,
    AnswerReceipt,
    CalibrationRecord,
    Event,
    ParticipantInfo,
    SessionInfo,
    StudyStore,
    file_sha256,
)
from .bids import export_bids
from .markers import lsl_markers, send_marker, sending_markers
from .terminal import TerminalResponder

__all__ = [
    "STUDIES",
    "LEVEL_RULES",
    "DEFAULT_LEVELS",
    "LEGACY_LEVELS",
    "level_options",
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
    "TRANSITIONS",
    "action_status",
    "file_sha256",
    "TRIALS_COLUMNS",
    "write_trials_csv",
    "read_trials_csv",
    "StudyEngine",
    "represent_after_xrun",
    "Stimulus",
    "Presentation",
    "Response",
    "RunSummary",
    "PAUSE",
    "ABORT",
    "STOP",
    "Again",
    "drive_sha256",
    "calibration_renderer",
    "CalibrationRenderer",
    "terminal_beep",
    "headphone_beep",
    "TerminalResponder",
    "export_bids",
    "lsl_markers",
    "sending_markers",
    "send_marker",
]
