"""The web app's background jobs: the calibration jobs, the emergency stop and the shutdown.

One part of :class:`~vibrofocus.web.state.WebState`, split along its jobs.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from ..errors import StudyError

__all__ = ["CalibrationJob", "CalibrationCancelled", "JobState"]

log = logging.getLogger("vibrofocus.web.state")


@dataclass
class CalibrationJob:
    """A calibration running in a background thread, as the experimenter page sees it.

    On a rig that records one point at a time (a single-spot vibrometer), the job stops
    before each point with ``status = "waiting"`` and a ``prompt`` saying where to aim the
    vibrometer; :meth:`go_on` lets it record, :meth:`cancel` ends it.

    A cancel is honoured until the job starts saving (:meth:`begin_saving`, once every
    recording and the estimation are over): before that, nothing is saved, whatever the
    cancel interrupted (a recording, the estimation); from then on the calibration is
    saved and :meth:`cancel` says it came too late.
    """

    job_id: str
    participant_id: str
    rig: str
    status: str = "running"  # running | waiting | done | failed | cancelled
    progress: float = 0.0
    message: str = "starting"
    calibration_id: int | None = None
    error: str | None = None
    prompt: str | None = None
    straps: dict | None = None
    verdicts: list | None = None
    n_errors: int = 0
    points: int | None = None  # points measured (the rest predicted); None: every point
    _go: threading.Event = field(default_factory=threading.Event, repr=False)
    _cancelled: bool = False
    _saving: bool = False
    _state_lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    #: The rig object it records on (the emergency stop names the rigs in use).
    _rig: Any = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """The job as the page reads it (JSON-ready)."""
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    def wait_for_experimenter(self, prompt: str) -> None:
        """Block the calibration until the experimenter continues (or cancels)."""
        self._go.clear()
        self.prompt, self.status = prompt, "waiting"
        while not self._go.wait(0.25):
            if self._cancelled:
                break
        self.prompt = None
        self.check_cancelled()
        self.status = "running"

    def go_on(self) -> None:
        """The experimenter has aimed the vibrometer: record the point."""
        self._go.set()

    def cancel(self) -> bool:
        """Cancel: the job ends at its next step and nothing is saved.

        Returns
        -------
        bool
            True if the job is cancelled; False if it came too late: the recordings are
            over and the calibration is being saved (:meth:`begin_saving`).
        """
        with self._state_lock:
            if self._saving:
                return False
            self._cancelled = True
        self._go.set()
        return True

    @property
    def cancelled(self) -> bool:
        """Whether the job was cancelled (it saves nothing)."""
        return self._cancelled

    def begin_saving(self) -> None:
        """The point of no return: from now on the calibration is saved and a cancel is refused.

        Raises :class:`CalibrationCancelled` if it was cancelled before (during the
        recordings or the estimation): then nothing is saved.
        """
        with self._state_lock:
            self.check_cancelled()
            self._saving = True

    def check_cancelled(self) -> None:
        """Raise :class:`CalibrationCancelled` if the experimenter cancelled."""
        if self._cancelled:
            raise CalibrationCancelled("cancelled by the experimenter")


class CalibrationCancelled(Exception):
    """The experimenter cancelled a calibration (nothing is saved)."""


class JobState:
    """The jobs' part of :class:`~vibrofocus.web.state.WebState` (its ``jobs``, ``job_threads``), and
    what stops everything: the emergency stop and the shutdown."""

    def emergency_stop(self) -> list[str]:
        """Every rig's outputs to zero now, every calibration cancelled, every runner paused.

        First every runner is told to pause and every calibration to cancel (flags, at
        once), so that nothing starts a new play after its rig is stopped; then every
        open rig is stopped. The caller stores the paused sessions' status (the routes
        own the session state machine).

        Returns
        -------
        list of str
            What was stopped, as people read it, each thing once: each hardware rig and
            each simulated arm that was in use ("simulated rig (seed 5): outputs at 0 V"),
            each calibration that was running ("calibration of P02 cancelled: nothing is
            saved", or, past its recordings, "... not cancelled: its recordings had
            finished; it is being saved") and each session that was running ("session 3
            paused"). A finished session or calibration is not listed; empty when nothing
            was running.
        """
        with self.lock:
            rigs = list(self.rigs.items())
            runners = list(self.runners.items())
            jobs = [j for j in self.jobs.values() if j.status in ("running", "waiting")]
        # Flags first, at once: no runner starts a new play after its rig is stopped.
        playing = {sid: runner.running and not runner.paused for sid, runner in runners}
        for _, runner in runners:
            runner.pause()  # every runner: one that was not running must not start playing now
        cancelled = [(job, job.cancel()) for job in jobs]
        failed = {}
        for key, rig in rigs:  # the outputs, now: nothing before this waits for the database
            try:
                rig.stop()
            except Exception as exc:  # noqa: BLE001 - the others must still be stopped
                log.exception("emergency stop of the %s failed", self.rig_name(key[0], rig))
                failed[key] = exc
        # Which sessions were running: the store says so (the caller stores them as
        # paused), or the runner was playing and its engine has just stored the pause.
        # A session whose last answer is in (completed) is not, even while its runner
        # shows "taken" for the last time.
        paused = []
        for sid, runner in runners:
            with self.db:
                try:
                    status = self.store.session(sid).status
                except StudyError:
                    continue
            if status == "running" or (playing[sid] and status == "paused"):
                paused.append((sid, runner))
        in_use = [runner.rig for _, runner in paused] + [job._rig for job in jobs]
        done = []
        for key, rig in rigs:
            name = self.rig_name(key[0], rig)
            if key in failed:
                done.append(f"{name}: stop FAILED ({failed[key]}); switch the amplifier off")
            elif key[0] != "simulated" or any(rig is used for used in in_use):
                done.append(f"{name}: outputs at 0 V")
        for job, ok in cancelled:
            done.append(f"calibration of {job.participant_id} cancelled: nothing is saved" if ok else
                        f"calibration of {job.participant_id} not cancelled: its recordings had finished; it is being saved")
        done.extend(f"session {sid} paused" for sid, _ in paused)
        return done

    def start_job(self, target: Any, *args: Any, name: str) -> threading.Thread:
        """Run a background job (a calibration) in a thread that :meth:`shutdown` waits for."""
        thread = threading.Thread(target=target, args=args, name=name, daemon=True)
        with self.lock:
            self.job_threads = [t for t in self.job_threads if t.is_alive()]
            self.job_threads.append(thread)
        thread.start()
        return thread

    def shutdown(self, timeout_s: float = 5.0) -> None:
        """The server is going (Ctrl-C, SIGTERM): every output to zero, every job ended, every rig closed.

        The emergency stop comes first (a calibration's sweep must not go on while the
        rest shuts down); then the runners stop (their sessions stay 'running' in the
        store, to resume), the job threads are waited for, and each rig is closed, which
        zeroes its outputs once more and releases its device.
        """
        done = self.emergency_stop()
        if done:
            log.warning("shutting down: %s", "; ".join(done))
        with self.lock:
            runners = list(self.runners.values())
            threads = list(self.job_threads)
        for runner in runners:
            runner.stop(timeout=2.0)
        deadline = time.monotonic() + timeout_s
        for thread in threads:
            thread.join(max(0.0, deadline - time.monotonic()))
            if thread.is_alive():
                log.error("the job %s did not end within %.0f s of the shutdown", thread.name, timeout_s)
        with self.lock:
            rigs = list(self.rigs.items())
            self.rigs.clear()
        for (kind, _), rig in rigs:
            try:
                rig.close()
            except Exception:  # noqa: BLE001 - every rig must still be closed
                log.exception("closing the %s rig at shutdown failed; switch the amplifier off", kind)
