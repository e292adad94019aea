"""The records a study database hands out: answers, sessions, calibrations, participants, events.

Plain frozen dataclasses (and how each is read from its SQLite row), so that callers
never hold a database row.
"""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass, field
from typing import Any

from ..io.responses import parse_response_text
from .protocol import PlannedTrial, StudyDesign

__all__ = ["AnswerReceipt", "SessionInfo", "CalibrationRecord", "ParticipantInfo", "Event"]


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
    point_mm : (float, float) or None
        A point answer's place in the layout frame, mm (``response`` is its nearest
        location); None for a location answer.
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
    point_mm: tuple[float, float] | None = None
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
        return StudyDesign.from_config(self.study, self.config, stored=True)

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


# ---------------------------------------------------------------------- from rows
def trial_from_row(r: sqlite3.Row) -> PlannedTrial:
    """A ``planned_trials`` row as a :class:`PlannedTrial`."""
    return PlannedTrial(r["session_id"], r["trial_index"], r["phase"], r["trial"], r["method"], r["target"])


def receipt_from_row(r: sqlite3.Row, *, duplicate: bool = False) -> AnswerReceipt:
    """An ``answers`` row as an :class:`AnswerReceipt` (``duplicate``: it answers a re-send)."""
    return AnswerReceipt(
        answer_id=r["answer_id"],
        session_id=r["session_id"],
        trial_index=r["trial_index"],
        response=parse_response_text(r["response"]),
        rt_s=float(r["rt_s"]),
        drive_sha256=r["drive_sha256"],
        calibration_id=r["calibration_id"],
        recorded_at=r["recorded_at"],
        point_mm=None if r["response_x_mm"] is None else (float(r["response_x_mm"]), float(r["response_y_mm"])),
        duplicate=duplicate,
    )


def event_from_row(r: sqlite3.Row) -> Event:
    """An ``events`` row as an :class:`Event` (its JSON payload decoded)."""
    return Event(r["event_id"], r["session_id"], r["kind"], None if r["payload"] is None else json.loads(r["payload"]), r["created_at"])


def calibration_from_row(r: sqlite3.Row) -> CalibrationRecord:
    """A ``calibrations`` row as a :class:`CalibrationRecord`."""
    return CalibrationRecord(r["calibration_id"], r["participant_id"], r["path"], r["sha256"], r["created_at"])


def participant_from_row(r: sqlite3.Row) -> ParticipantInfo:
    """A ``participants`` row as a :class:`ParticipantInfo`."""
    return ParticipantInfo(r["participant_id"], bool(r["simulated"]), r["created_at"])
