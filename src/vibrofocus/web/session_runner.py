"""The participant pages of one running session, as a responder of the study engine.

One thread per running session runs :meth:`vibrofocus.studies.StudyEngine.run` (the one
study loop, shared with the keypad and the simulated participant) with a
:class:`SessionRunner` as its responder. The runner's hooks give the loop what the web
needs: "get ready" and a wait until a participant page can take the cue; the stimulus
only while the connected pages show that cue; a trial presented again when a reloaded
page asks for it; pause, resume and stop from the experimenter page. Answers are
committed by the answer route (:meth:`StudyStore.record_answer`, before it replies); the
runner hears of them through :meth:`SessionRunner.notify_answer`. The database is the
only memory of progress: a restarted server builds a new runner that starts again at
the first unanswered trial.

The participant page learns about state changes by long-polling :meth:`SessionRunner.snapshot`;
each change increments ``seq`` so the page can tell a new cue from the same one seen again.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import VibrofocusError
from ..studies.engine import PAUSE, STOP, Again, Control, Presentation, Response, StudyEngine, drive_sha256

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
    """Run the trials of one session in a background thread, answered on participant pages.

    Parameters
    ----------
    store : StudyStore
        The study database; every progress decision is read from it.
    session_id : int
        The session to run.
    renderer : callable, optional
        ``renderer(method, target) -> drives`` with drives of shape (n_actuators,
        n_samples), V (e.g. :class:`~vibrofocus.studies.engine.CalibrationRenderer`).
    stimulus : callable, optional
        The older form of ``renderer``: ``stimulus(trial) -> drives``.
        Neither given: a dry run (no calibration: the cue and answers still work, but
        nothing is played).
    rig : Rig, optional
        Where the drives play. Required with ``renderer`` or ``stimulus``.
    pace : Pace
        Trial timing.
    require_page : bool
        Hold each cue until a participant page that can play the beep is connected, and
        play the stimulus only while a page is showing that cue, so that no stimulus is
        played to nobody (the experimenter may press Start before the participant page
        is open, or the page may be closed or reloaded during "get ready" or the cue).
    model : Responder, optional
        A simulated participant
        (:class:`~vibrofocus.simulation.SimulatedParticipant`) who answers every trial
        instead of a participant page: no page is waited for, and the answer route
        refuses answers for the session. The trial timing (``pace``) stays, so the
        experimenter page shows the session running as it would with a person.
    """

    def __init__(
        self,
        store: Any,
        session_id: int,
        *,
        renderer: Callable[[str, int], np.ndarray] | None = None,
        stimulus: Callable[[Any], np.ndarray] | None = None,
        rig: Any = None,
        pace: Pace = PACES["normal"],
        require_page: bool = True,
        model: Any = None,
    ) -> None:
        if stimulus is not None and renderer is None:
            renderer = lambda method, target: stimulus(_Condition(method, target))  # noqa: E731
        if renderer is not None and rig is None:
            raise ValueError("a runner with a stimulus needs a rig to play it on")
        self.store = store
        self.session_id = int(session_id)
        self.rig = rig
        self.pace = pace
        self.engine = StudyEngine(store, session_id, rig, renderer=renderer, dry_run=renderer is None, cue_by="page")
        self._cond = threading.Condition()
        self._paused = False
        self._stopping = False
        self._answered: dict[int, Any] = {}  # trial index -> its receipt (None: read it from the store)
        self._restart: int | None = None  # trial a page asked to present again
        self._drive_sha: dict[int, str] = {}
        # seq starts at the clock in ms, so that a page that saw an earlier runner of this
        # session (before a stop or a server restart) never mistakes a new state for one
        # it has already seen.
        self._state: dict[str, Any] = {
            "state": "idle", "trial_index": None, "phase": None, "seq": int(time.time() * 1000), "error": None,
        }
        self._thread: threading.Thread | None = None
        self.model = model
        self.require_page = bool(require_page) and model is None
        self._polls: dict[int, int] = {}  # open state requests of ready pages: token -> seq they have seen
        self._cooling_until: float | None = None  # monotonic end of a wait for the actuators to cool
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
        """Pause before the next stimulus.

        A trial waiting for its answer stays open, but the pages learn of the pause at
        once (``seq`` changes): they show the break and stop the trial's clock until
        :meth:`resume`, so the pause is not counted in the response time.
        """
        self._set_paused(True)

    def resume(self) -> None:
        """Resume after :meth:`pause`."""
        self._set_paused(False)

    def _set_paused(self, paused: bool) -> None:
        with self._cond:
            if self._paused != paused:
                self._paused = paused
                self._state["seq"] += 1  # news for the pages' long-polls
            self._cond.notify_all()

    def stop(self, timeout: float = 5.0) -> None:
        """End the loop (the session keeps its status), leave the rig silent, and wait for the thread."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        self._silence()

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def notify_answer(self, trial_index: int, receipt: Any = None) -> None:
        """Tell the loop that the answer to ``trial_index`` is committed (its receipt, if at hand)."""
        with self._cond:
            self._answered[int(trial_index)] = receipt
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

    def drive_sha_for(self, trial_index: int) -> str | None:
        """Hash of the drive played for ``trial_index`` in this run, if one was played."""
        with self._cond:
            return self._drive_sha.get(int(trial_index))

    def snapshot(self) -> dict[str, Any]:
        """A copy of the current state (``state``, ``trial_index``, ``phase``, ``seq``, ...; ``cooling_s``,
        the seconds left of a wait for the actuators to cool, while one lasts)."""
        with self._cond:
            snap = dict(self._state)
            snap["paused"] = self._paused
            left = None if self._cooling_until is None else self._cooling_until - time.monotonic()
            if left is not None and left > 0:
                snap["cooling_s"] = round(left, 1)  # the experimenter page's "cooling: 9 s"
            return snap

    # ------------------------------------------------------------------ engine hooks
    def before_cue(self, trial: Any) -> Control:
        """ "Get ready", then hold the cue until a page that can beep is connected."""
        index = int(trial.trial_index)
        held = self._held()
        if held is not None:
            return held
        self._set("ready", trial_index=index, phase=trial.phase, waiting_for_page=False)
        if not self._wait(self.pace.ready_s, index):
            return self._held() or Again()  # answered meanwhile: the next trial
        with self._cond:
            while not self._page_present() and not self._stopping and not self._paused:
                if not self._state.get("waiting_for_page"):
                    self._set("ready", trial_index=index, phase=trial.phase, waiting_for_page=True)
                self._cond.wait(0.2)
            self._state["waiting_for_page"] = False
        return self._held()

    def cue_shown(self, trial: Any) -> Control:
        """Show the cue (the page beeps); at the stimulus moment, go on only if pages show it."""
        index = int(trial.trial_index)
        self._set("cue", trial_index=index, phase=trial.phase)
        cue_seq = self.snapshot()["seq"]
        if not self._wait(self.pace.cue_to_stimulus_s, index):
            return self._held() or Again()
        # Nothing plays unless a page is connected and showing this cue (it has seen it
        # and is waiting for what comes next); a page closed or reloaded since then gets
        # the trial again from "get ready".
        if not self._wait_showing(cue_seq, PAGE_GRACE_S):
            return self._held() or Again("cue_cancelled", "no participant page showing the cue")
        return self._held()

    def respond(self, presentation: Presentation) -> Response | str | Again:
        """Wait until the answer route has committed the answer (or a page asks for the trial again)."""
        index = int(presentation.trial.trial_index)
        if presentation.stimulus is not None:
            with self._cond:
                self._drive_sha[index] = presentation.stimulus.sha256
        self._set("respond", trial_index=index, phase=presentation.trial.phase)
        if self.model is not None:
            held = self._held()
            if held == STOP:
                return STOP
            return self.model.respond(presentation)  # the engine commits it
        with self._cond:
            while not self._stopping and index not in self._answered and self._restart != index:
                self._cond.wait(1.0)
            answered = index in self._answered
            receipt = self._answered.get(index)
            self._restart = None
        if answered:
            if receipt is None:  # told by trial index only: the store has the answer
                receipt = next(a for a in self.store.answers(self.session_id) if a.trial_index == index)
            # Already committed: the engine's commit finds the same answer_id and stores nothing new.
            return Response(receipt.response, receipt.rt_s, answer_id=receipt.answer_id,
                            point_mm=getattr(receipt, "point_mm", None))
        if self._stopping:
            return STOP
        return Again("trial_restarted", "the participant page did not see the stimulus onset (reloaded)")

    def cooling(self, trial: Any, wait_s: float) -> None:
        """The stimulus waits ``wait_s`` s for the actuators to cool: the snapshot's ``cooling_s`` counts it down."""
        with self._cond:
            self._cooling_until = time.monotonic() + float(wait_s)

    def answered(self, presentation: Presentation, receipt: Any) -> None:
        """Show "taken" for a while before the next trial."""
        self._set("taken", trial_index=int(presentation.trial.trial_index), phase=presentation.trial.phase)
        self._wait(self.pace.after_answer_s)

    def wait_resume(self) -> bool | str:
        """Show "paused" until the experimenter resumes (True) or stops (:data:`STOP`)."""
        self._set("paused")
        with self._cond:
            while self._paused and not self._stopping:
                self._cond.wait(0.5)
            return STOP if self._stopping else True

    # ------------------------------------------------------------------ waiting
    def _held(self) -> Control:
        """STOP or PAUSE when the experimenter asked for it, else None."""
        with self._cond:
            return STOP if self._stopping else PAUSE if self._paused else None

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

    def _set(self, state: str, **fields: Any) -> None:
        with self._cond:
            self._state.update(fields)
            self._state["state"] = state
            self._state["seq"] += 1
            self._state["since"] = time.time()
            self._cond.notify_all()

    def _wait(self, seconds: float, trial_index: int | None = None) -> bool:
        """Sleep ``seconds``; False early on stop, pause, or when the trial got its answer."""
        deadline = time.monotonic() + seconds
        with self._cond:
            while True:
                if self._stopping or (trial_index is not None and (self._paused or trial_index in self._answered)):
                    return False
                left = deadline - time.monotonic()
                if left <= 0:
                    return True
                self._cond.wait(left)

    # ------------------------------------------------------------------ thread
    def _run(self) -> None:
        from ..workflows import run_session

        try:
            # A runner rebuilt for a paused session (a server restart) waits before the
            # engine starts, which would set the session running.
            if self._held() != PAUSE or self.wait_resume() is True:
                with self._reserved():  # one job on the hardware at a time
                    summary = run_session(self.engine, self)
                if summary.status == "completed":
                    self._set("done", trial_index=None)
                    return
            self._set("stopped", trial_index=None)
        except Exception as exc:  # noqa: BLE001 - reported to the experimenter page (the engine logged it)
            log.exception("session %s failed", self.session_id)
            # Shown on the experimenter page: the trace stays in the terminal.
            from .public_text import public_text

            shown = str(exc) if isinstance(exc, VibrofocusError) else "an unexpected error; the terminal running 'vibrofocus serve' says why"
            self._set("error", error=public_text(shown))
        finally:
            self._silence()

    def _reserved(self):
        # Any object with play/stop can serve as the rig; a vibrofocus Rig is also held.
        reserve = getattr(self.rig, "reserve", None)
        return contextlib.nullcontext() if reserve is None else reserve(f"session {self.session_id}")

    def _silence(self) -> None:
        if self.rig is not None:
            try:
                self.rig.stop()
            except Exception:  # noqa: BLE001 - stopping must never raise
                log.exception("rig.stop failed")


@dataclass(frozen=True)
class _Condition:
    """What a ``stimulus(trial)`` callable reads of a trial: its method and target."""

    method: str
    target: int
