"""The sessions, planned trials and answers of the study database (:class:`~vibrofocus.studies.storage.StudyStore`).

One part of the store, split along its row types; the transaction rule is the database's.
The rules of answers (:meth:`SessionRows.record_answer`) are described in
:mod:`vibrofocus.studies.storage`.
"""

from __future__ import annotations

import json
import math
import os
import re
import sqlite3
from collections.abc import Mapping
from typing import Any

from .._validation import shorten
from ..errors import AnswerRefused, StudyError, ValidationError
from ..io.responses import parse_response_text
from .database import StudyDatabase, now_utc, software_version
from .protocol import PlannedTrial, StudyDesign, format_response, parse_response, plan_trials
from .records import AnswerReceipt, SessionInfo, receipt_from_row, trial_from_row
from .session_status import check_transition, status_after_answer, transition_event
from .staircase import parse_detection

__all__ = ["SessionRows", "session_protocol"]

_ANSWER_ID_RE = re.compile(r"[\x21-\x7e]{1,128}")  # printable ASCII, no spaces


class SessionRows(StudyDatabase):
    """Sessions, their planned trials and their answers (a part of :class:`~vibrofocus.studies.storage.StudyStore`).

    Uses the participants' part (``_require_participant``) and the event log's
    (``_insert_event``) of the store it is mixed into.
    """

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

        Notes
        -----
        A participant may have several sessions of a study (the web app plans them,
        tests run them side by side). To run "the" session of a participant, as the
        commands do, use :meth:`open_session`: its check and its creation are one
        transaction.
        """
        session_id, _ = self._plan_session(participant_id, study, seed=seed, calibration_id=calibration_id,
                                           config=config, reuse=None)
        return session_id

    def open_session(
        self,
        participant_id: str,
        study: int,
        *,
        seed: int,
        calibration_id: int | None = None,
        config: Mapping[str, Any] | None = None,
        reuse: str = "open",
    ) -> tuple[int, bool]:
        """The participant's session of ``study`` to run: an existing one, or a new one; atomic.

        The check and the creation are one ``BEGIN IMMEDIATE`` transaction, so two
        processes on one database never both create a session (the loser gets the
        winner's).

        Parameters
        ----------
        participant_id, study, seed, calibration_id, config
            As :meth:`create_session`, for a new session.
        reuse : {"open", "latest"}
            ``"open"``: the latest unfinished session (a trial unanswered, whatever its
            status: an aborted session is resumed too), else a new one (``study run``);
            ``"latest"``: the latest session, finished or not, else a new one
            (``simulate-study``, which runs each study once).

        Returns
        -------
        (int, bool)
            The session id, and whether it was created now.
        """
        if reuse not in ("open", "latest"):
            raise StudyError(f"reuse must be 'open' or 'latest', got {reuse!r}")
        return self._plan_session(participant_id, study, seed=seed, calibration_id=calibration_id, config=config,
                                  reuse=reuse)

    def _plan_session(self, participant_id: str, study: int, *, seed: int, calibration_id: int | None,
                      config: Mapping[str, Any] | None, reuse: str | None) -> tuple[int, bool]:
        if isinstance(study, bool) or study not in (1, 2):
            raise StudyError(f"study must be 1 or 2, got {study!r}")
        design = StudyDesign.from_config(int(study), config)
        stored_config = dict(config or {})
        stored_config.update(design.to_dict())
        if design.point:
            # The picture the participant points on, stored with the session: every answer
            # is checked against it (the config's ``layout``, an ArrayLayout.to_dict(), or
            # the reference layout).
            from ..layout import ArrayLayout
            from .points import point_area

            layout = stored_config.get("layout")
            try:
                the_layout = ArrayLayout.from_dict(layout) if isinstance(layout, Mapping) else ArrayLayout.reference()
            except (ValidationError, KeyError, TypeError, ValueError) as exc:  # one line
                raise StudyError(f"session config layout is not a layout: {exc}") from None
            stored_config["point_area"] = point_area(the_layout, design.locations)
        # The protocol the session was planned from, and its block: a session planned without
        # one is the paper's study (its shipped protocol file, block 0), as every session
        # stored before sessions named their protocol is read (session_protocol).
        protocol, block = session_protocol(int(study), stored_config)
        stored_config.update(protocol=protocol, block=block)
        try:
            config_json = json.dumps(stored_config, sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise StudyError(f"session config must be JSON-serialisable: {exc}") from exc
        trials = plan_trials(design, seed)
        now = now_utc()
        with self._write(f"create a study {study} session for {shorten(participant_id)}") as conn:
            self._require_participant(conn, participant_id)
            if reuse is not None:
                # Inside the write transaction (BEGIN IMMEDIATE): no other process can
                # create a session between this check and the insert below.
                unfinished = (" AND (SELECT COUNT(*) FROM answers a WHERE a.session_id = s.session_id) < "
                              "(SELECT COUNT(*) FROM planned_trials p WHERE p.session_id = s.session_id)"
                              if reuse == "open" else "")
                # The same protocol and block only (a session stored without them: the paper's).
                prior = conn.execute(
                    "SELECT session_id FROM sessions s WHERE participant_id = ? AND study = ?"
                    " AND COALESCE(json_extract(config, '$.protocol'), 'paper-study' || study) = ?"
                    " AND COALESCE(json_extract(config, '$.block'), 0) = ?" + unfinished
                    + " ORDER BY session_id DESC LIMIT 1", (participant_id, int(study), protocol, block),
                ).fetchone()
                if prior is not None:
                    return int(prior[0]), False
            if calibration_id is not None:
                cal = conn.execute(
                    "SELECT participant_id FROM calibrations WHERE calibration_id = ?",
                    (_as_int(calibration_id, "calibration id"),),
                ).fetchone()
                if cal is None:
                    raise StudyError(f"unknown calibration {calibration_id!r} in {self.path}")
                if cal[0] != participant_id:
                    raise StudyError(
                        f"calibration {calibration_id} belongs to participant {cal[0]!r}, not {shorten(participant_id)}"
                    )
            cur = conn.execute(
                "INSERT INTO sessions (participant_id, study, seed, calibration_id, status, config, "
                "software_version, created_at, updated_at) VALUES (?, ?, ?, ?, 'planned', ?, ?, ?, ?)",
                (participant_id, int(study), int(seed), calibration_id, config_json, software_version(), now, now),
            )
            session_id = int(cur.lastrowid)
            conn.executemany(
                "INSERT INTO planned_trials (session_id, trial_index, phase, trial, method, target) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                [(session_id, t.trial_index, t.phase, t.trial, t.method, t.target) for t in trials],
            )
            self._insert_event(conn, session_id, "created", {"study": int(study), "seed": int(seed), "n_trials": len(trials)})
        return session_id, True

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
            self._change_status(conn, info, status, now_utc())

    def _change_status(self, conn: sqlite3.Connection, info: SessionInfo, status: str, now: str) -> None:
        """Write an allowed status change and its event (inside the caller's transaction)."""
        conn.execute("UPDATE sessions SET status = ?, updated_at = ? WHERE session_id = ?", (status, now, info.session_id))
        self._insert_event(conn, info.session_id, transition_event(info.status, status), {"from": info.status, "to": status})

    # ------------------------------------------------------------------ trials
    def planned_trials(self, session_id: int) -> list[PlannedTrial]:
        """The full planned trial list of a session, in order."""
        return [trial_from_row(r) for r in self._session_rows("planned_trials", session_id, "read the planned trials")]

    def next_trial(self, session_id: int) -> PlannedTrial | None:
        """The first unanswered trial of a session, or ``None`` when all are answered."""
        with self._read("find the next trial") as conn:
            self._session(conn, session_id)
            r = self._next_row(conn, int(session_id))
        return None if r is None else trial_from_row(r)

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
        onset_s: float | None = None,
        onset_device_s: float | None = None,
        onset_clock: str | None = None,
        point_mm: Any = None,
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
        response : int, str, iterable of int or None
            Locations (see :func:`parse_response`): Study 1 exactly one, Study 2 one or
            more distinct, each within the design's locations. In a point session
            (the design's ``point``): None, or the point's nearest location.
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
        onset_s : float, optional
            The stimulus onset, host ``time.monotonic()``, s (the study engine's; the time
            its LSL marker carries), kept in the ``answer`` event's payload.
        onset_device_s : float, optional
            The stimulus onset on the rig's device clock, s
            (:class:`~vibrofocus.rigs.DeviceOnset`), kept beside ``onset_s``.
        onset_clock : str, optional
            That clock's name (``simulated_samples``, ``portaudio_dac``,
            ``nidaq_start_trigger``, ``nidaq_samples``); given with ``onset_device_s``.
        point_mm : (float, float), optional
            A point answer's place ``(x, y)`` in the layout frame, mm: required in a point
            session, refused in another. It must lie in the session's picture
            (:func:`~vibrofocus.studies.points.check_point`); its nearest location is
            stored as the response.

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
        if not isinstance(answer_id, str) or not _ANSWER_ID_RE.fullmatch(answer_id):
            raise AnswerRefused(f"answer_id must be 1-128 printable ASCII characters without spaces, got {answer_id!r}", "invalid")
        tidx = _as_int(trial_index, "trial index")
        onsets = _check_onsets(onset_s, onset_device_s, onset_clock)
        if drive_sha256 is not None and (not isinstance(drive_sha256, str) or not re.fullmatch(r"[0-9a-f]{64}", drive_sha256)):
            raise StudyError(f"drive_sha256 must be 64 lowercase hex digits, got {drive_sha256!r}")
        with self._write(f"record the answer to trial {trial_index!r} of session {session_id!r}") as conn:
            info = self._session(conn, session_id)
            sid = info.session_id
            try:
                point, locations = self._answer_place(info, response, point_mm)
            except StudyError as exc:
                raise AnswerRefused(str(exc), "invalid") from None
            prior = conn.execute("SELECT * FROM answers WHERE answer_id = ?", (answer_id,)).fetchone()
            if prior is not None:
                receipt = receipt_from_row(prior)
                if (receipt.session_id, receipt.trial_index, receipt.response, receipt.point_mm) != (
                        sid, tidx, locations, point):
                    same_trial = (receipt.session_id, receipt.trial_index) == (sid, tidx)
                    raise AnswerRefused(
                        f"answer_id {answer_id!r} was already used for session {receipt.session_id} trial "
                        f"{receipt.trial_index} (response {format_response(receipt.response)!r}); "
                        "send a new answer_id for a new answer", "answered" if same_trial else "reused_id",
                    )
                return receipt_from_row(prior, duplicate=True)  # idempotent retry: same receipt, nothing written
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
            now = now_utc()
            conn.execute(
                "INSERT INTO answers (answer_id, session_id, trial_index, response, rt_s, drive_sha256, "
                "calibration_id, recorded_at, response_x_mm, response_y_mm) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (answer_id, sid, tidx, format_response(locations), rt, drive_sha256, info.calibration_id, now,
                 None if point is None else point[0], None if point is None else point[1]),
            )
            self._insert_event(conn, sid, "answer", {
                "trial_index": tidx, "answer_id": answer_id, "response": list(locations), "rt_s": rt, **onsets,
                **({} if point is None else {"point_mm": list(point)}),
            })
            finished = info.n_answered + 1 >= info.n_trials
            if finished and info.design.detection:
                self._store_threshold(conn, info)
            new_status = status_after_answer(info.status, finished=finished)
            if new_status != info.status:
                self._change_status(conn, info, new_status, now)
            else:
                conn.execute("UPDATE sessions SET updated_at = ? WHERE session_id = ?", (now, sid))
            row = conn.execute("SELECT * FROM answers WHERE answer_id = ?", (answer_id,)).fetchone()
        return receipt_from_row(row)

    @staticmethod
    def _answer_place(info: SessionInfo, response: Any,
                      point_mm: Any) -> tuple[tuple[float, float] | None, tuple[int, ...]]:
        """The answer's point (None for a location answer) and its locations, checked against the session."""
        design = info.design
        if design.detection:
            if point_mm is not None:
                raise StudyError(f"session {info.session_id} asks whether the tap was felt, not where; answer 1 or 0")
            return None, (parse_detection(response),)
        if not design.point:
            if point_mm is not None:
                raise StudyError(f"session {info.session_id} takes locations, not a point; answer a location")
            return None, parse_response(response, design)
        if point_mm is None:
            raise StudyError(f"session {info.session_id} takes a point answer [x, y] in mm; none was given")
        from .points import check_point, point_area

        area = info.config.get("point_area") or point_area(None, design.locations)
        point, nearest = check_point(point_mm, area)
        if response is not None and parse_response(response, design) != (nearest,):
            raise StudyError(f"response {shorten(response)} is not the point's nearest location {nearest}")
        return point, (nearest,)

    @staticmethod
    def _store_threshold(conn: sqlite3.Connection, info: SessionInfo) -> None:
        """Store a finished threshold session's threshold (inside its last answer's transaction)."""
        design = info.design
        assert design.staircase is not None
        felt = [parse_response_text(r[0])[0] for r in conn.execute(
            "SELECT response FROM answers WHERE session_id = ? AND trial_index >= ? ORDER BY trial_index",
            (info.session_id, design.n_training))]
        run = design.staircase.run(felt)
        conn.execute("INSERT INTO thresholds (session_id, participant_id, threshold_db, reversals_db, recorded_at) "
                     "VALUES (?, ?, ?, ?, ?)", (info.session_id, info.participant_id, run.threshold_db,
                                                json.dumps(list(run.reversals_db)), now_utc()))

    def threshold(self, participant_id: str, *, protocol: str | None = None, block: int | None = None,
                  ) -> tuple[int, float | None] | None:
        """The participant's latest measured detection threshold: ``(session id, dB re the level
        rule)`` (the dB value None where the staircase had too few reversals), or None when no
        threshold session of theirs has finished (only of ``protocol``'s block ``block`` when
        given). Aborted sessions are left out."""
        with self._read("read the thresholds") as conn:
            self._require_participant(conn, participant_id)
            rows = conn.execute(
                "SELECT t.session_id, t.threshold_db, s.study, s.config FROM thresholds t "
                "JOIN sessions s ON s.session_id = t.session_id WHERE t.participant_id = ? AND s.status != 'aborted' "
                "ORDER BY t.session_id DESC", (participant_id,)).fetchall()
        for sid, value, study, config in rows:
            if protocol is None or session_protocol(study, json.loads(config)) == (protocol, block):
                return int(sid), None if value is None else float(value)
        return None

    def threshold_rows(self, *, participant_id: str | None = None) -> list[dict[str, Any]]:
        """The answered trials of threshold sessions, one dict per trial, with the staircase replayed.

        Keys: ``participant``, ``session``, ``protocol``, ``block``, ``phase``, ``trial``,
        ``method``, ``target``, ``level_db`` (dB re the level rule), ``levels`` (the rule),
        ``felt`` (1 / 0), ``rt_s``, ``drive_peak_v`` (None where nothing was played),
        ``reversal`` (1 where the staircase reversed after this answer) and ``threshold_db``
        (the session's stored threshold; None before it finished or with too few reversals).
        Ordered by participant (as added), session and trial.
        """
        out: list[dict[str, Any]] = []
        with self._read("read the threshold trials") as conn:
            sql = ("SELECT s.session_id FROM sessions s JOIN participants pt ON pt.participant_id = s.participant_id "
                   "WHERE json_extract(s.config, '$.staircase') IS NOT NULL ")
            args: list[Any] = []
            if participant_id is not None:
                self._require_participant(conn, participant_id)
                sql, args = sql + "AND s.participant_id = ? ", [participant_id]
            ids = [r[0] for r in conn.execute(sql + "ORDER BY pt.rowid, s.session_id", args)]
            stored = dict(conn.execute("SELECT session_id, threshold_db FROM thresholds").fetchall())
        for sid in ids:
            info = self.session(sid)
            staircase, n_training = info.design.staircase, info.design.n_training
            assert staircase is not None
            plan = {t.trial_index: t for t in self.planned_trials(sid)}
            answers = self.answers(sid)
            run = staircase.run([a.response for a in answers if a.trial_index >= n_training])
            peaks = {e.payload.get("trial_index"): e.payload.get("drive_peak_v")
                     for e in self.events(sid, kind="stimulus_onset") if isinstance(e.payload, dict)}
            protocol, block = session_protocol(info.study, info.config)
            for a in answers:
                t, k = plan[a.trial_index], a.trial_index - n_training
                out.append({"participant": info.participant_id, "session": sid, "protocol": protocol, "block": block,
                            "phase": t.phase, "trial": t.trial, "method": t.method, "target": t.target,
                            "level_db": staircase.start_db if k < 0 else run.levels_db[k],
                            "levels": info.design.levels, "felt": a.response[0], "rt_s": a.rt_s,
                            "drive_peak_v": peaks.get(a.trial_index), "reversal": int(k in run.reversal_trials),
                            "threshold_db": stored.get(sid)})
        return out

    def export_thresholds_csv(self, path: str | os.PathLike, *, participant_id: str | None = None) -> int:
        """Write the threshold trials (:meth:`threshold_rows`) as a CSV file
        (docs/file-formats.md, threshold file); returns the row count."""
        from ..io.thresholds_csv import write_thresholds_csv

        return write_thresholds_csv(self.threshold_rows(participant_id=participant_id), path)

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
        return [receipt_from_row(r) for r in self._session_rows("answers", session_id, "read the answers")]

    def _session_rows(self, table: str, session_id: int, doing: str) -> list[sqlite3.Row]:
        # table is one of this module's own table names, never user input.
        with self._read(doing) as conn:
            self._session(conn, session_id)
            return conn.execute(
                f"SELECT * FROM {table} WHERE session_id = ? ORDER BY trial_index", (int(session_id),)
            ).fetchall()


def session_protocol(study: int, config: Mapping[str, Any]) -> tuple[str, int]:
    """The protocol name and block index a session was planned from, from its config.

    A session stored without them (planned by vibrofocus before protocol files, or without
    one) is the paper's study: ``("paper-study<study>", 0)``, the shipped protocol file its
    design comes from (:meth:`~vibrofocus.studies.protocol.StudyDesign.from_config`).
    """
    name = config.get("protocol") if isinstance(config, Mapping) else None
    block = config.get("block", 0) if isinstance(config, Mapping) else 0
    if not isinstance(name, str) or not name:
        name = f"paper-study{int(study)}"
    if isinstance(block, bool) or not isinstance(block, int):
        block = 0
    return name, int(block)


def _check_onsets(onset_s: Any, onset_device_s: Any, onset_clock: Any) -> dict[str, Any]:
    """The onset keys of an answer event (those given), checked by the rigs' one rule for onsets."""
    from ..rigs.onset import check_onset

    try:
        host, device, clock = check_onset(onset_s, onset_device_s, onset_clock, host_required=False,
                                          names=("onset_s", "onset_device_s", "onset_clock"))
    except ValidationError as exc:
        raise StudyError(str(exc)) from None
    return {k: v for k, v in (("onset_s", host), ("onset_device_s", device), ("onset_clock", clock)) if v is not None}


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool):
        raise StudyError(f"{name} must be an integer, got {value!r}")
    try:
        if isinstance(value, float) and not value.is_integer():
            raise ValueError
        return int(value)
    except (TypeError, ValueError):
        raise StudyError(f"{name} must be an integer, got {value!r}") from None


def _check_rt(rt_s: Any) -> float:
    try:
        rt = float(rt_s)
    except (TypeError, ValueError):
        raise AnswerRefused(f"rt_s must be a number of seconds, got {rt_s!r}", "invalid") from None
    if not math.isfinite(rt) or rt < 0:
        raise AnswerRefused(f"rt_s must be finite and >= 0 s, got {rt_s!r}", "invalid")
    return rt
