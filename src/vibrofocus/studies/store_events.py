"""The event log and the trials' export of the study database (:class:`~vibrofocus.studies.storage.StudyStore`).

One part of the store, split along its row types; the transaction rule is the database's.
"""

from __future__ import annotations

import json
import os
import re
import sqlite3
from typing import Any

from ..errors import StudyError
from .database import StudyDatabase, now_utc
from .protocol import LEGACY_LEVELS, StudyDesign
from .records import Event, event_from_row
from .store_sessions import session_protocol

__all__ = ["EventRows"]

_EVENT_RE = re.compile(r"[a-z][a-z0-9_]{0,39}")


class EventRows(StudyDatabase):
    """The append-only event log, and the answered trials joined with their plan for export
    (a part of :class:`~vibrofocus.studies.storage.StudyStore`).

    Uses the sessions' part (``_session``) and the participants' (``_require_participant``)
    of the store it is mixed into.
    """

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
        if not isinstance(kind, str) or not _EVENT_RE.fullmatch(kind):
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
            "INSERT INTO events (session_id, kind, payload, created_at) VALUES (?, ?, ?, ?)", (sid, kind, text, now_utc())
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
        return [event_from_row(r) for r in rows]

    # ------------------------------------------------------------------ export
    def trial_rows(self, *, participant_id: str | None = None) -> list[dict[str, Any]]:
        """Answered trials joined with their plan, one dict per trial.

        Keys: the trials-file columns (``participant, study, phase, trial, method,
        target, response, rt_s``) plus ``session_id``, ``trial_index``, ``answer_id``,
        ``drive_sha256``, ``calibration_id``, ``recorded_at``, the session columns of
        the trials file: ``session`` (id), ``session_status``, ``dry_run`` (1 for a session
        planned without a calibration: nothing was played), ``rig`` (the session's rig:
        ``simulated``, ``audio``, ``nidaq``; None where the session did not store it), and ``simulated`` (1: the
        participant is simulated, answers from the perceptual model), and the onset columns
        ``onset_host_s``, ``onset_device_s``, ``onset_clock`` (the stimulus onset on the
        host's ``time.monotonic()`` and on the rig's device clock, from the ``answer`` or
        ``answer_onset`` event; None where the database holds none: the device time of a
        dry run or of a rig without a device clock, both times of an answer stored by
        vibrofocus 0.1.0), and the stimulus columns ``levels`` (the session's level rule),
        ``drive_peak_v`` (largest |drive| of the stimulus played, V) and ``target_peak_um``
        (its peak at the target predicted from the calibration, µm), from the trial's
        ``stimulus_onset`` event (None where none holds them), and for a simulated
        participant ``model`` (the label of the model and hypothesis that answered, from the
        session), and ``protocol`` (the name of the protocol the session was planned from:
        :func:`session_protocol`), and ``response_x_mm``, ``response_y_mm`` (a point answer's
        place in the layout frame, mm; None for a location answer), and ``xrun_represented`` (how many times
        the trial was presented again because its stimulus lost samples: its ``xrun`` events that
        re-presented it), and the block columns ``level_db`` (the session's level re its level
        rule, dB: a block in dB SL already at the participant's threshold plus its level) and
        ``allowed`` (the locations the session could be answered with, ``"1 3 7 9"``), what
        the fit of hypotheses reads. Ordered by participant (as added), study, session and trial index.
        """
        with self._read("read the trials") as conn:
            sql = (
                "SELECT s.participant_id AS participant, s.study AS study, p.phase AS phase, p.trial AS trial, "
                "p.method AS method, p.target AS target, a.response AS response, a.rt_s AS rt_s, "
                "s.session_id AS session_id, p.trial_index AS trial_index, a.answer_id AS answer_id, "
                "a.drive_sha256 AS drive_sha256, a.calibration_id AS calibration_id, a.recorded_at AS recorded_at, "
                "a.response_x_mm AS response_x_mm, a.response_y_mm AS response_y_mm, "
                "s.session_id AS session, s.status AS session_status, (s.calibration_id IS NULL) AS dry_run, "
                "pt.simulated AS simulated "
                "FROM answers a JOIN planned_trials p ON p.session_id = a.session_id AND p.trial_index = a.trial_index "
                "JOIN sessions s ON s.session_id = a.session_id "
                "JOIN participants pt ON pt.participant_id = s.participant_id "
            )
            # Threshold sessions' answers (felt or not) are no localization trials: their own file.
            sql += "WHERE json_extract(s.config, '$.staircase') IS NULL "
            args: list[Any] = []
            if participant_id is not None:
                self._require_participant(conn, participant_id)
                sql += "AND s.participant_id = ? "
                args.append(participant_id)
            sql += "ORDER BY pt.rowid, s.study, s.session_id, p.trial_index"
            rows = [dict(r) for r in conn.execute(sql, args).fetchall()]
            onsets = self._answer_onsets(conn, participant_id)
            stimuli = self._played_stimuli(conn, participant_id)
        # The simulation floor sits above the studies: its label imported where a row names it.
        from ..simulation.perception import MODEL_LABEL as legacy_model

        for row in rows:
            row.update(onsets.get(row["answer_id"], _NO_ONSET))
            row.update(stimuli.get((row["session_id"], row["trial_index"]), _NO_STIMULUS))
            row["levels"], model = stimuli.get(row["session_id"], (LEGACY_LEVELS, None))
            row["protocol"] = stimuli.get(("protocol", row["session_id"]))
            row["level_db"], row["allowed"] = stimuli[("block", row["session_id"])]
            row["xrun_represented"] = stimuli.get(("xrun", row["session_id"], row["trial_index"]), 0)
            # A simulated participant's session stored before sessions named their rig ran on the simulated one.
            row["rig"] = stimuli.get(("rig", row["session_id"])) or ("simulated" if row["simulated"] else None)
            if row["simulated"]:
                # A simulated session stored before sessions named their model: v3, its only one then.
                row["model"] = model or legacy_model
        return rows

    @staticmethod
    def _played_stimuli(conn: sqlite3.Connection, participant_id: str | None = None) -> dict[Any, Any]:
        """The level rule and the simulated participants' model label (None: not stored) of
        each session (by session id), its protocol, rig and block (level, allowed answers),
        and the stimulus columns of each trial's last ``stimulus_onset`` event (by
        (session id, trial index))."""
        where, args = "", ()
        if participant_id is not None:
            where, args = "WHERE participant_id = ? ", (participant_id,)
        out: dict[Any, Any] = {}
        for sid, study, text in conn.execute("SELECT session_id, study, config FROM sessions " + where, args):
            config = json.loads(text)  # the stored rule as it is (the design's rules: StudyDesign.from_config)
            config = config if isinstance(config, dict) else {}
            out[sid] = (str(config.get("levels", LEGACY_LEVELS)), config.get("model"))
            out[("protocol", sid)] = session_protocol(study, config)[0]
            out[("rig", sid)] = config.get("rig")
            design = StudyDesign.from_config(study, config, stored=True)
            out[("block", sid)] = (design.level_db, " ".join(str(x) for x in sorted(design.locations)))
        sql = ("SELECT session_id, payload FROM events WHERE kind = 'stimulus_onset' "
               + ("AND session_id IN (SELECT session_id FROM sessions WHERE participant_id = ?) " if args else ""))
        for sid, text in conn.execute(sql + "ORDER BY event_id", args):
            payload = json.loads(text)
            out[(sid, payload.get("trial_index"))] = {key: payload.get(key) for key in _NO_STIMULUS}
        # How many times each trial was presented again after an xrun (the engine's ``xrun`` events).
        sql = ("SELECT session_id, json_extract(payload, '$.trial_index'), COUNT(*) FROM events WHERE kind = 'xrun' "
               "AND json_extract(payload, '$.represented') "
               + ("AND session_id IN (SELECT session_id FROM sessions WHERE participant_id = ?) " if args else ""))
        for sid, index, count in conn.execute(sql + "GROUP BY 1, 2", args):
            out[("xrun", sid, index)] = int(count)
        return out

    @staticmethod
    def _answer_onsets(conn: sqlite3.Connection, participant_id: str | None = None) -> dict[str, dict[str, Any]]:
        """Each answer's stimulus onset by answer id (the columns of :data:`_ONSET_KEYS`), from
        its events; only the participant's sessions' events when one is named."""
        sql = "SELECT payload FROM events WHERE kind IN ('answer', 'answer_onset') "
        args: tuple[Any, ...] = ()
        if participant_id is not None:  # through the session index, not the whole log
            sql += "AND session_id IN (SELECT session_id FROM sessions WHERE participant_id = ?) "
            args = (participant_id,)
        out: dict[str, dict[str, Any]] = {}
        for (text,) in conn.execute(sql + "ORDER BY event_id", args):
            payload = json.loads(text)
            slot = out.setdefault(payload.get("answer_id"), dict(_NO_ONSET))
            for key, column in _ONSET_KEYS.items():
                if payload.get(key) is not None:
                    slot[column] = payload[key]
        return out

    def export_trials_csv(self, path: str | os.PathLike, *, participant_id: str | None = None) -> int:
        """Write the trials file of docs/file-formats.md, trials file (every answered trial); returns the row count.

        The file has the session columns after the contract's (see
        :data:`~vibrofocus.io.trials_csv.SESSION_COLUMNS`), so that an analysis can leave
        out aborted sessions and dry runs, then the onset columns
        (:data:`~vibrofocus.io.trials_csv.ONSET_COLUMNS`) and the stimulus columns
        (:data:`~vibrofocus.io.trials_csv.STIMULUS_COLUMNS`), the protocol column and the point
        columns (:data:`~vibrofocus.io.trials_csv.POINT_COLUMNS`) and the xrun column
        (:data:`~vibrofocus.io.trials_csv.XRUN_COLUMNS`) and the block columns
        (:data:`~vibrofocus.io.trials_csv.BLOCK_COLUMNS`: level and allowed answers).
        """
        from ..io.trials_csv import write_trials_csv

        return write_trials_csv(self.trial_rows(participant_id=participant_id), path, sessions=True, onsets=True,
                                stimuli=True, protocols=True, points=True, xruns=True, blocks=True)


#: Payload key of the ``answer`` / ``answer_onset`` events -> column of :meth:`StudyStore.trial_rows`.
_ONSET_KEYS = {"onset_s": "onset_host_s", "onset_device_s": "onset_device_s", "onset_clock": "onset_clock"}
_NO_ONSET: dict[str, Any] = dict.fromkeys(_ONSET_KEYS.values())
#: Stimulus columns of :meth:`StudyStore.trial_rows` from the ``stimulus_onset`` event (None: not stored).
_NO_STIMULUS: dict[str, Any] = {"drive_peak_v": None, "target_peak_um": None}
