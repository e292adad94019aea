"""The calibrations' rows of the study database (:class:`~vibrofocus.studies.storage.StudyStore`).

One part of the store, split along its row types; the transaction rule is the database's.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from .._validation import shorten
from ..errors import StudyError
from .database import StudyDatabase, now_utc
from .records import CalibrationRecord, calibration_from_row
from .store_sessions import _as_int

__all__ = ["CalibrationRows", "file_sha256"]


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


class CalibrationRows(StudyDatabase):
    """Calibration files registered by path and SHA-256 (a part of :class:`~vibrofocus.studies.storage.StudyStore`).

    Uses the participants' part (``_require_participant``) of the store it is mixed into.
    """

    def add_calibration(self, participant_id: str, path: str | os.PathLike) -> int:
        """Register a calibration file (absolute path and SHA-256) for a participant.

        Returns
        -------
        int
            The calibration id; the existing id when the same file content is already
            registered for this participant.
        """
        from .._atomic import protect

        file = Path(path)
        protect(file, "calibration of the study database")
        try:
            sha = file_sha256(file)
        except OSError as exc:
            raise StudyError(f"cannot read the calibration file {file}: {exc.strerror or exc}") from exc
        with self._write(f"add a calibration for {shorten(participant_id)}") as conn:
            self._require_participant(conn, participant_id)
            row = conn.execute(
                "SELECT calibration_id FROM calibrations WHERE participant_id = ? AND sha256 = ?",
                (participant_id, sha),
            ).fetchone()
            if row is not None:
                return int(row[0])
            cur = conn.execute(
                "INSERT INTO calibrations (participant_id, path, sha256, created_at) VALUES (?, ?, ?, ?)",
                (participant_id, str(file.resolve()), sha, now_utc()),
            )
            return int(cur.lastrowid)

    def calibration(self, calibration_id: int) -> CalibrationRecord:
        """A registered calibration; StudyError if unknown."""
        with self._read("look up a calibration") as conn:
            r = conn.execute("SELECT * FROM calibrations WHERE calibration_id = ?", (_as_int(calibration_id, "calibration id"),)).fetchone()
        if r is None:
            raise StudyError(f"unknown calibration {calibration_id!r} in {self.path}")
        return calibration_from_row(r)

    def calibrations(self, participant_id: str) -> list[CalibrationRecord]:
        """Calibrations of a participant, oldest first."""
        with self._read("list calibrations") as conn:
            self._require_participant(conn, participant_id)
            rows = conn.execute(
                "SELECT * FROM calibrations WHERE participant_id = ? ORDER BY calibration_id", (participant_id,)
            ).fetchall()
        return [calibration_from_row(r) for r in rows]

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
