"""The participants' rows of the study database (:class:`~vibrofocus.studies.storage.StudyStore`).

One part of the store, split along its row types; the transaction rule is the database's
(:meth:`~vibrofocus.studies.database.StudyDatabase._write`, one ``BEGIN IMMEDIATE`` per write).
"""

from __future__ import annotations

import re
import sqlite3
from typing import Any

from .._validation import shorten
from ..errors import StudyError
from .database import StudyDatabase, now_utc
from .records import ParticipantInfo, participant_from_row

__all__ = ["ParticipantRows", "check_participant_id"]

# Used with fullmatch: "$" also matches before a trailing newline, so "P01\n" passed re.match.
_PARTICIPANT_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")


def check_participant_id(participant_id: Any) -> str:
    """Return ``participant_id`` if it is 1-64 letters, digits, ``_ . -``, starting with a letter or digit.

    Parameters
    ----------
    participant_id : str
        The id, as stored in the study database and in calibration files.

    Returns
    -------
    str

    Raises
    ------
    StudyError
        Naming the rule and (cut to a few dozen characters) the id given.
    """
    if not isinstance(participant_id, str) or not _PARTICIPANT_RE.fullmatch(participant_id):
        raise StudyError(
            f"participant id must be 1-64 letters, digits, '_', '.' or '-' starting with a "
            f"letter or digit, got {shorten(participant_id)}"
        )
    return participant_id


class ParticipantRows(StudyDatabase):
    """Participants: register, list, look up (a part of :class:`~vibrofocus.studies.storage.StudyStore`)."""

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
        check_participant_id(participant_id)
        with self._write(f"add participant {shorten(participant_id)}") as conn:
            row = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
            if row is None:
                conn.execute(
                    "INSERT INTO participants (participant_id, simulated, created_at) VALUES (?, ?, ?)",
                    (participant_id, int(bool(simulated)), now_utc()),
                )
                row = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
            elif bool(row["simulated"]) != bool(simulated):
                kind = "simulated" if row["simulated"] else "real"
                raise StudyError(f"participant {shorten(participant_id)} already exists as a {kind} participant")
        return participant_from_row(row)

    def participants(self) -> list[ParticipantInfo]:
        """All participants, in the order they were added."""
        with self._read("list participants") as conn:
            rows = conn.execute("SELECT * FROM participants ORDER BY rowid").fetchall()
        return [participant_from_row(r) for r in rows]

    def participant(self, participant_id: str) -> ParticipantInfo:
        """One participant; StudyError if unknown."""
        with self._read("look up a participant") as conn:
            self._require_participant(conn, participant_id)
            r = conn.execute("SELECT * FROM participants WHERE participant_id = ?", (participant_id,)).fetchone()
        return participant_from_row(r)

    def _require_participant(self, conn: sqlite3.Connection, participant_id: Any) -> None:
        row = conn.execute("SELECT 1 FROM participants WHERE participant_id = ?", (str(participant_id),)).fetchone()
        if row is None:
            raise StudyError(f"unknown participant {shorten(participant_id)} in {self.path}; add the participant first")
