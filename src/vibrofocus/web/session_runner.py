"""The background trial loop of one running study session.

One thread per running session walks the planned trials in the store: for the first
unanswered trial it shows "get ready", sets the state to ``cue`` (the participant page
plays the beep), waits, plays the stimulus on the rig, sets ``respond`` and waits until
the answer is committed by the answer route. The database is the only memory of progress:
a restarted server builds a new runner that starts again at the first unanswered trial.

The participant page learns about state changes by long-polling :meth:`SessionRunner.snapshot`;
each change increments ``seq`` so the page can tell a new cue from the same one seen again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

# The hash stored with every answer: one definition for the web app and the engine.
from ..studies.engine import drive_sha256

__all__ = ["Pace", "PACES", "SessionRunner", "drive_sha256"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Pace:
    """Timing of one trial, s.

    Attributes
    ----------
    ready_s : float
        "Get ready" shown before the cue.
    cue_to_stimulus_s : float
        From the start of the beep to the stimulus; long enough for the page to learn
        of the cue (one long-poll round trip) and play a 150 ms beep.
    after_answer_s : float
        The "taken" feedback stays this long before the next trial.
    """

    ready_s: float = 1.0
    cue_to_stimulus_s: float = 0.7
    after_answer_s: float = 0.8


#: Longest wait, at the stimulus moment, for the page showing the cue to ask again, s
#: (between two of its requests a page is briefly not connected).
PAGE_GRACE_S = 0.5

#: Named paces: ``normal`` for people, ``fast`` for tests and demonstrations.
PACES = {"normal": Pace(), "fast": Pace(ready_s=0.1, cue_to_stimulus_s=0.25, after_answer_s=0.05)}


class SessionRunner:
    """Run the trials of one session in a background thread.

    Parameters
    ----------
    store : StudyStore
        The study database; every progress decision is read from it.
    session_id : int
        The session to run.
    stimulus : callable, optional
        ``stimulus(trial) -> drives`` with drives of shape (n_actuators, n_samples), V,
        or ``None`` for a dry run (no calibration: the cue and answers still work, but
        nothing is played).
    rig : Rig, optional
        Where the drives play. Required when ``stimulus`` is given.
    pace : Pace
        Trial timing.
    store_lock : threading.Lock, optional
        Serialises database access shared with the request handlers.
    require_page : bool
        Hold each cue until a participant page that can play the beep is connected, and
        play the stimulus only while a page is showing that cue, so that no stimulus is
        played to nobody (the experimenter may press Start before the participant page
        is open, or the page may be closed or reloaded during "get ready" or the cue).
    """

    def __init__(
        self,
        store: Any,
        session_id: int,
        *,
        stimulus: Callable[[Any], np.ndarray] | None = None,
        rig: Any = None,
        pace: Pace = PACES["normal"],
        store_lock: threading.Lock | None = None,
        require_page: bool = True,
    ) -> None:
        if stimulus is not None and rig is None:
            raise ValueError("a runner with a stimulus needs a rig to play it on")
        self.store = store
        self.session_id = int(session_id)
        self.stimulus = stimulus
        self.rig = rig
        self.pace = pace
        self._db = store_lock if store_lock is not None else threading.Lock()
        self._cond = threading.Condition()
        self._paused = False
        self._stopping = False
        self._answered: set[int] = set()
        self._restart: int | None = None  # trial a page asked to present again
        self._drive_sha: dict[int, str] = {}
        # seq starts at the clock in ms, so that a page that saw an earlier runner of this
        # session (before a stop or a server restart) never mistakes a new state for one
        # it has already seen.
        self._state: dict[str, Any] = {
            "state": "idle", "trial_index": None, "phase": None, "seq": int(time.time() * 1000), "error": None,
        }
        self._thread: threading.Thread | None = None
        self.require_page = bool(require_page)
        self._polls: dict[int, int] = {}  # open state requests of ready pages: token -> seq they have seen
        self._next_poll = 0

    # ------------------------------------------------------------------ control
    def start(self) -> None:
        """Start the trial loop (no effect if it already runs)."""
        with self._cond:
            if self._thread is not None and self._thread.is_alive():
                return
            self._stopping = False
            self._thread = threading.Thread(target=self._run, name=f"session-{self.session_id}", daemon=True)
            self._thread.start()

    def pause(self) -> None:
        """Pause before the next stimulus; an answer to a stimulus already felt is still taken."""
        with self._cond:
            self._paused = True
            self._cond.notify_all()

    def resume(self) -> None:
        """Resume after :meth:`pause`."""
        with self._cond:
            self._paused = False
            self._cond.notify_all()

    def stop(self, timeout: float = 5.0) -> None:
        """End the loop, leave the rig silent, and wait for the thread."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        if self.rig is not None:
            try:
                self.rig.stop()
            except Exception:  # noqa: BLE001 - stopping must never raise
                log.exception("rig.stop failed")

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def notify_answer(self, trial_index: int) -> None:
        """Tell the loop that the answer to ``trial_index`` is committed."""
        with self._cond:
            self._answered.add(int(trial_index))
            self._cond.notify_all()

    def restart_trial(self, trial_index: int) -> bool:
        """Present ``trial_index`` again from "get ready", if it waits for its answer.

        A participant page that did not see this trial's stimulus arrive (it was
        reloaded after the onset) cannot time a reaction: it asks for the trial again,
        so that the answer is timed from an onset the page saw. Returns False when the
        trial is not the one waiting for an answer (answered meanwhile, or another trial).
        """
        with self._cond:
            snap = self._state
            if snap["state"] != "respond" or snap["trial_index"] != int(trial_index) or int(trial_index) in self._answered:
                return False
            self._restart = int(trial_index)
            self._cond.notify_all()
            return True

    def page_attach(self, seen_seq: int) -> int:
        """A participant page (ready to play the beep) is waiting for news after ``seen_seq``.

        Returns a token for :meth:`page_detach`. A page whose open request has seen the
        cue's ``seq`` is showing that cue: only then is the stimulus played.
        """
        with self._cond:
            self._next_poll += 1
            self._polls[self._next_poll] = int(seen_seq)
            self._cond.notify_all()
            return self._next_poll

    def page_detach(self, token: int) -> None:
        """That page's request has ended (answered, or the page closed or reloaded)."""
        with self._cond:
            self._polls.pop(token, None)
            self._cond.notify_all()

    def _page_present(self) -> bool:
        # Strict: an open request now, no grace period (a closed page must not get a cue).
        return not self.require_page or bool(self._polls)

    def _pages_showing(self, seq: int) -> tuple[bool, bool]:
        """(some connected page shows ``seq``, every connected page shows it)."""
        if not self.require_page:
            return True, True
        seen = list(self._polls.values())
        return any(s == seq for s in seen), bool(seen) and all(s == seq for s in seen)

    def _wait_showing(self, seq: int, seconds: float) -> bool:
        """Wait up to ``seconds`` for the connected pages to show state ``seq``.

        True as soon as every connected page shows it; at the deadline, True if at least
        one does. Waiting for all of them matters with two screens: a page still catching
        up would otherwise miss the cue, ask for the trial again, and take the trial away
        from the screen the participant is answering on. False on stop or pause.
        """
        deadline = time.monotonic() + seconds
        with self._cond:
            while True:
                if self._stopping or self._paused:
                    return False
                some, every = self._pages_showing(seq)
                left = deadline - time.monotonic()
                if every or left <= 0:
                    return some
                self._cond.wait(left)

    def drive_sha_for(self, trial_index: int) -> str | None:
        """Hash of the drive played for ``trial_index`` in this run, if one was played."""
        with self._cond:
            return self._drive_sha.get(int(trial_index))

    def snapshot(self) -> dict[str, Any]:
        """A copy of the current state (``state``, ``trial_index``, ``phase``, ``seq``, ...)."""
        with self._cond:
            snap = dict(self._state)
            snap["paused"] = self._paused
            return snap

    # ------------------------------------------------------------------ loop
    def _set(self, state: str, **fields: Any) -> None:
        with self._cond:
            self._state.update(fields)
            self._state["state"] = state
            self._state["seq"] += 1
            self._state["since"] = time.time()
            self._cond.notify_all()

    def _wait(self, seconds: float, trial_index: int | None = None) -> bool:
        """Sleep ``seconds``; return False early on stop or when the trial got its answer."""
        deadline = time.monotonic() + seconds
        with self._cond:
            while True:
                if self._stopping or (trial_index is not None and trial_index in self._answered):
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return True
                self._cond.wait(left)

    def _log(self, kind: str, payload: dict[str, Any]) -> None:
        with self._db:
            self.store.log_event(self.session_id, kind, payload)

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # noqa: BLE001 - reported to the experimenter page
            log.exception("session %s failed", self.session_id)
            self._set("error", error=f"{type(exc).__name__}: {exc}")
            try:
                self._log("error", {"message": str(exc)})
            except Exception:  # noqa: BLE001
                log.exception("could not log the error of session %s", self.session_id)
        finally:
            if self.rig is not None:
                try:
                    self.rig.stop()
                except Exception:  # noqa: BLE001
                    log.exception("rig.stop failed")

    def _loop(self) -> None:
        while True:
            with self._cond:
                if self._stopping:
                    self._set("stopped", trial_index=None)
                    return
                if self._paused:
                    if self._state["state"] != "paused":
                        self._set("paused")
                    self._cond.wait(0.5)
                    continue
            with self._db:
                trial = self.store.next_trial(self.session_id)
            if trial is None:
                with self._db:
                    self.store.set_status(self.session_id, "completed")
                self._set("done", trial_index=None)
                return
            index = int(trial.trial_index)
            phase = getattr(trial, "phase", None)
            self._set("ready", trial_index=index, phase=phase, waiting_for_page=False)
            if not self._wait(self.pace.ready_s, index):
                continue
            if self._paused:
                continue  # the trial starts again from "get ready" after resume
            with self._cond:
                while not self._page_present() and not self._stopping and not self._paused:
                    if not self._state.get("waiting_for_page"):
                        self._set("ready", trial_index=index, phase=phase, waiting_for_page=True)
                    self._cond.wait(0.2)
                if self._stopping or self._paused:
                    continue
                self._state["waiting_for_page"] = False
            self._set("cue", trial_index=index, phase=phase)
            cue_seq = self.snapshot()["seq"]
            self._log("cue", {"trial_index": index})
            if not self._wait(self.pace.cue_to_stimulus_s, index):
                continue
            if self._paused:
                continue
            # Nothing plays unless a page is connected and showing this cue (it has
            # seen it and is waiting for what comes next); a page closed or reloaded
            # since then gets the trial again from "get ready".
            if not self._wait_showing(cue_seq, PAGE_GRACE_S):
                if not self._stopping and not self._paused:
                    self._log("cue_cancelled", {"trial_index": index, "reason": "no participant page showing the cue"})
                continue
            payload: dict[str, Any] = {"trial_index": index, "played": False}
            if self.stimulus is not None:
                drives = self.stimulus(trial)
                sha = drive_sha256(drives)
                with self._cond:
                    self._drive_sha[index] = sha
                payload.update(played=True, drive_sha256=sha)
                self._log("stimulus_onset", payload)
                self.rig.play(drives)
            else:
                self._log("stimulus_onset", payload)
            self._set("respond", trial_index=index, phase=phase)
            with self._cond:
                while not self._stopping and index not in self._answered and self._restart != index:
                    self._cond.wait(1.0)
                restart = self._restart == index and index not in self._answered
                self._restart = None
            if self._stopping:
                continue
            if restart:
                self._log("trial_restarted", {"trial_index": index, "reason": "the participant page did not see the stimulus onset (reloaded)"})
                continue
            self._set("taken", trial_index=index, phase=phase)
            self._wait(self.pace.after_answer_s)
