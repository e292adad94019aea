"""The web app's sessions: their rows, their runners, and the simulated participants who answer them.

One part of :class:`~vibrofocus.web.state.WebState`, split along its jobs.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import HTTPException

from ..errors import StudyError
from .session_runner import SessionRunner

__all__ = ["SessionState"]

log = logging.getLogger("vibrofocus.web.state")


class SessionState:
    """The sessions' part of :class:`~vibrofocus.web.state.WebState` (its ``store``, ``runners``)."""

    def session(self, session_id: int) -> dict[str, Any]:
        """The session's row as a dict; 404 if there is no such session."""
        with self.db:
            try:
                info = self.store.session(int(session_id))
            except StudyError:
                info = None
        if info is None:
            raise HTTPException(404, detail=f"unknown session {session_id}")
        return _as_dict(info)

    def runner(self, session_id: int, *, create: bool = False) -> SessionRunner | None:
        """The runner of a session; with ``create``, build it from the stored session.

        None for a session aborted here, even with ``create``: an abort is final.
        """
        with self.lock:
            runner = self.runners.get(session_id)
            if runner is not None or not create or session_id in self.aborted:
                return runner
        from ..studies.protocol import LEGACY_LEVELS

        info = self.session(session_id)
        config = info.get("config") or {}
        renderer = rig = model = None
        cal_id = info.get("calibration_id")
        if cal_id is not None:
            rig = self.make_rig(config.get("rig", self.rig_kind), config.get("rig_seed"))
            renderer = self.bank(int(cal_id), limit_v=getattr(getattr(rig, "limits", None), "peak_v", None),
                                 levels=config.get("levels", LEGACY_LEVELS))  # a session planned before: equal-peak
        if self.is_simulated(info["participant_id"]):
            model = self.simulated_participant(info, rig)
        runner = SessionRunner(self.store, session_id, renderer=renderer, rig=rig, pace=self.pace, model=model)
        with self.lock:
            if session_id in self.aborted:  # aborted while this one was built
                return None
            return self.runners.setdefault(session_id, runner)

    def is_simulated(self, participant_id: str) -> bool:
        """Whether a participant is simulated: the perceptual model answers their sessions."""
        with self.db:
            try:
                return bool(self.store.participant(participant_id).simulated)
            except StudyError:
                return False

    def simulated_participant(self, info: dict[str, Any], rig: Any) -> Any:
        """The perceptual model answering a simulated participant's session, on its simulated forearm.

        As in ``vibrofocus simulate-study``: a :class:`~vibrofocus.simulation.SimulatedParticipant`
        seeded like the forearm it feels with (the session's ``rig_seed``). 409 for a
        session the model cannot answer (no calibration, or not the simulated rig).
        """
        config = info.get("config") or {}
        if rig is None or config.get("rig", "simulated") != "simulated":
            raise HTTPException(409, detail=(
                f"Session {info['session_id']} of the simulated participant {info['participant_id']} needs a calibration on "
                "the simulated rig: the perceptual model answers it from what the simulated forearm feels."))
        from ..simulation import SimulatedParticipant

        return SimulatedParticipant(rig, int(getattr(rig, "seed", config.get("rig_seed") or 0)))

    def resume_running_sessions(self) -> list[int]:
        """After a restart: start a runner for every session stored as running."""
        with self.db:
            rows = [_as_dict(s) for s in self.store.sessions()]
        started = []
        for row in rows:
            if row.get("status") == "running":
                sid = int(row["session_id"])
                try:
                    runner = self.runner(sid, create=True)
                    runner.start()
                    with self.db:
                        self.store.log_event(sid, "resumed_after_restart", None)
                    started.append(sid)
                except Exception:  # noqa: BLE001 - one broken session must not stop the server
                    log.exception("could not resume session %s", sid)
        return started


def _as_dict(obj: Any) -> dict[str, Any]:
    if isinstance(obj, dict):
        return obj
    if hasattr(obj, "_asdict"):
        return obj._asdict()
    if hasattr(obj, "__dataclass_fields__"):
        import dataclasses

        return dataclasses.asdict(obj)
    return dict(obj)
