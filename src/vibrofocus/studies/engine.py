"""Running the trials of a stored session on a rig.

The store is the only memory of progress: :meth:`StudyEngine.run` asks it for the first
unanswered trial, presents it (event ``cue``, the beep, event ``stimulus_onset``, the
drive on the rig), takes the answer from a :class:`Responder` and commits it before the
next trial starts. A killed or interrupted run resumes by running again.
"""

from __future__ import annotations

import hashlib
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..defaults import DRIVE_LIMIT_V, N_SAMPLES
from ..errors import StudyError, ValidationError
from .protocol import PlannedTrial, StudyDesign
from .storage import AnswerReceipt, StudyStore

__all__ = [
    "PAUSE",
    "ABORT",
    "Stimulus",
    "Presentation",
    "Response",
    "Responder",
    "RunSummary",
    "StudyEngine",
    "drive_sha256",
    "calibration_renderer",
    "terminal_beep",
    "headphone_beep",
]

#: What a responder returns to pause the session (then :meth:`Responder.wait_resume`).
PAUSE = "pause"
#: What a responder returns to abort the session (answers so far are kept).
ABORT = "abort"

Renderer = Callable[[str, int], np.ndarray]


def drive_sha256(drives: np.ndarray) -> str:
    """SHA-256 of drive signals: their shape, then their float64 C-order bytes, hex.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n_samples)
        Voltages, V.
    """
    arr = np.ascontiguousarray(np.asarray(drives, dtype=np.float64))
    digest = hashlib.sha256(repr(arr.shape).encode())
    digest.update(arr.tobytes())
    return digest.hexdigest()


def calibration_renderer(
    calibration: Any,
    *,
    n_samples: int = N_SAMPLES,
    limit_v: float = DRIVE_LIMIT_V,
    **render_options: Any,
) -> Renderer:
    """A ``renderer(method, target) -> drives`` built on a participant's calibration.

    Every stimulus is ``rendering.render(method, H, fs, layout, target, limit_v=...)``
    with ``H = calibration.transfer_for(n_samples)``.

    Parameters
    ----------
    calibration : Calibration
        The participant's calibration (``transfer_for``, ``fs``, ``layout``).
    n_samples : int
        Length of each drive, samples.
    limit_v : float
        Drive limit, V peak; designs needing more are scaled down (the rendering layer's
        default ``on_limit="scale"``).
    **render_options
        Passed on to ``rendering.render``.
    """
    from ..rendering import render  # imported here: planning and storage do not need it

    H = calibration.transfer_for(int(n_samples))

    def renderer(method: str, target: int) -> np.ndarray:
        out = render(method, H, calibration.fs, calibration.layout, int(target), limit_v=limit_v, **render_options)
        return np.asarray(out.drives, dtype=float)

    return renderer


def terminal_beep() -> None:
    """The default cue: the terminal bell.

    It needs no audio device, so it can never reach an actuator. For a tone in the
    participant's headphones use :func:`headphone_beep` with the headphones' device.
    """
    sys.stdout.write("\a")
    sys.stdout.flush()


def headphone_beep(device: str | int, *, rig: object | None = None) -> Callable[[], None]:
    """A cue that plays 1 kHz for 0.1 s on the participant's headphones.

    Parameters
    ----------
    device : str or int
        The headphones' PortAudio output device (index or part of its name, as listed
        by ``vibrofocus devices``).
    rig : Rig, optional
        The rig of the study. The cue plays outside the rig's safety layer, so a device
        that is the rig's own audio interface (which drives the actuators) is refused.

    Returns
    -------
    callable
        ``cue()``, blocking until the tone has played.

    Raises
    ------
    ValidationError
        If ``device`` is the rig's actuator interface.
    """
    import sounddevice as sd

    from ..rigs.audio import resolve_audio_device

    index = resolve_audio_device(device, outputs=1)
    if index == getattr(rig, "device_index", None):
        raise ValidationError(
            f"the cue device {device!r} is the audio interface that drives the actuators; name the "
            "participant's headphones instead (a cue must never reach an actuator)"
        )
    fs = 44_100
    t = np.arange(int(0.1 * fs)) / fs
    tone = (0.2 * np.sin(2 * np.pi * 1000.0 * t) * np.hanning(t.size)).astype(np.float32)

    def cue() -> None:
        sd.play(tone, fs, device=index, blocking=True)

    return cue


@dataclass(frozen=True)
class Stimulus:
    """The drive signals of one condition.

    Attributes
    ----------
    method : str
    target : int
        Location number.
    drives : ndarray, shape (n_actuators, n_samples)
        V.
    sha256 : str
        :func:`drive_sha256` of ``drives``, stored with the answer.
    """

    method: str
    target: int
    drives: np.ndarray
    sha256: str


@dataclass(frozen=True)
class Presentation:
    """A trial as it was presented.

    Attributes
    ----------
    session_id : int
    study : int
    trial : PlannedTrial
        The planned trial.
    stimulus : Stimulus
        What was played.
    onset_s : float
        Stimulus onset, ``time.monotonic()``, s.
    design : StudyDesign
        The session's design.
    """

    session_id: int
    study: int
    trial: PlannedTrial
    stimulus: Stimulus
    onset_s: float
    design: StudyDesign


@dataclass(frozen=True)
class Response:
    """An answer.

    Attributes
    ----------
    locations : int, str or sequence of int
        Selected location(s): an int, a string like ``"4 5"`` or a sequence.
    rt_s : float
        Reaction time from the stimulus onset, s.
    """

    locations: Any
    rt_s: float


class Responder(Protocol):
    """Who answers trials: a person at a keypad or a simulated participant."""

    def respond(self, presentation: Presentation) -> Response | str:
        """Answer a presented trial, or return :data:`PAUSE` / :data:`ABORT`."""

    def wait_resume(self) -> bool:
        """Block while paused; True to resume (the trial is presented again), False to abort."""


@dataclass(frozen=True)
class RunSummary:
    """Where a run left the session.

    Attributes
    ----------
    session_id : int
    status : str
        The session's state after the run.
    n_answered, n_trials : int
        Answered and planned trials of the session.
    n_run : int
        Trials answered during this run.
    """

    session_id: int
    status: str
    n_answered: int
    n_trials: int
    n_run: int


class StudyEngine:
    """Present the planned trials of one session and store the answers.

    Parameters
    ----------
    store : StudyStore
        The study database.
    session_id : int
        A session of ``store``.
    rig : Rig
        Where stimuli play (``rig.play``).
    calibration : Calibration, optional
        The participant's calibration; stimuli are rendered from it with
        :func:`calibration_renderer`. Required unless ``renderer`` is given.
    renderer : callable, optional
        ``renderer(method, target) -> drives`` instead of the calibration.
    cue : callable, optional
        Called with no argument just before each stimulus to beep in the participant's
        headphones (e.g. :func:`terminal_beep`). ``None``: the cue is only logged (the
        simulated rig, whose participant has no ears).
    n_samples, limit_v :
        Drive length (samples) and limit (V peak) for the calibration renderer.

    Notes
    -----
    Drives are rendered once per (method, target) and cached: a trial's stimulus is a
    pure function of the calibration and the condition.
    """

    def __init__(
        self,
        store: StudyStore,
        session_id: int,
        rig: Any,
        calibration: Any | None = None,
        *,
        renderer: Renderer | None = None,
        cue: Callable[[], None] | None = None,
        n_samples: int = N_SAMPLES,
        limit_v: float = DRIVE_LIMIT_V,
    ) -> None:
        self.store = store
        info = store.session(session_id)  # unknown session -> StudyError now, not mid-run
        self.session_id = info.session_id
        self.study = info.study
        self.design = info.design
        self.rig = rig
        if renderer is None:
            if calibration is None:
                raise StudyError("a study engine needs the participant's calibration (or a renderer)")
            if calibration.layout.n_locations < max(self.design.locations):
                raise StudyError(
                    f"the calibration's layout has {calibration.layout.n_locations} locations, but the "
                    f"study uses locations up to {max(self.design.locations)}"
                )
            renderer = calibration_renderer(calibration, n_samples=n_samples, limit_v=limit_v)
        self._renderer = renderer
        self.cue = cue
        self._cache: dict[tuple[str, int], Stimulus] = {}

    # ------------------------------------------------------------------ pieces
    def stimulus(self, method: str, target: int) -> Stimulus:
        """The (cached) stimulus of a condition."""
        key = (str(method), int(target))
        if key not in self._cache:
            drives = np.asarray(self._renderer(*key), dtype=float)
            drives.setflags(write=False)
            self._cache[key] = Stimulus(key[0], key[1], drives, drive_sha256(drives))
        return self._cache[key]

    def present(self, trial: PlannedTrial) -> Presentation:
        """Cue, then play the trial's stimulus; both are logged before they happen."""
        stim = self.stimulus(trial.method, trial.target)
        self.store.log_event(self.session_id, "cue", {
            "trial_index": trial.trial_index, "beep": "played" if self.cue is not None else "event-only",
        })
        if self.cue is not None:
            self.cue()
        self.store.log_event(self.session_id, "stimulus_onset", {
            "trial_index": trial.trial_index, "method": trial.method, "target": trial.target,
            "drive_sha256": stim.sha256,
        })
        onset = time.monotonic()
        self.rig.play(stim.drives)
        return Presentation(self.session_id, self.study, trial, stim, onset, self.design)

    def submit(self, presentation: Presentation, response: Response, *, answer_id: str | None = None) -> AnswerReceipt:
        """Commit the answer to a presented trial (with the drive hash) before returning."""
        return self.store.record_answer(
            self.session_id, presentation.trial.trial_index, response.locations, response.rt_s,
            answer_id=answer_id or uuid.uuid4().hex, drive_sha256=presentation.stimulus.sha256,
        )

    # ------------------------------------------------------------------ loop
    def run(
        self,
        responder: Responder,
        *,
        pace_s: float = 0.0,
        max_trials: int | None = None,
        progress: Callable[[PlannedTrial, AnswerReceipt], None] | None = None,
    ) -> RunSummary:
        """Run from the first unanswered trial until the end, an abort or ``max_trials``.

        Parameters
        ----------
        responder : Responder
            Answers each presented trial.
        pace_s : float
            Pause after each committed answer, s.
        max_trials : int, optional
            Stop after this many answers in this run (the session stays ``running``).
        progress : callable, optional
            ``progress(trial, receipt)`` after each committed answer.

        Returns
        -------
        RunSummary
        """
        info = self.store.session(self.session_id)
        if info.status == "completed":
            return RunSummary(self.session_id, info.status, info.n_answered, info.n_trials, 0)
        if info.status != "running":
            self.store.set_status(self.session_id, "running")
        n_run = 0
        while max_trials is None or n_run < max_trials:
            trial = self.store.next_trial(self.session_id)
            if trial is None:
                break
            presentation = self.present(trial)
            reply = responder.respond(presentation)
            if isinstance(reply, str):
                if reply == PAUSE:
                    self.store.set_status(self.session_id, "paused")
                    if responder.wait_resume():
                        self.store.set_status(self.session_id, "running")
                        continue  # the same trial is presented again
                    reply = ABORT
                if reply == ABORT:
                    self.store.set_status(self.session_id, "aborted")
                    break
                raise StudyError(f"a responder returned {reply!r}; expected a Response, 'pause' or 'abort'")
            receipt = self.submit(presentation, reply)
            n_run += 1
            if progress is not None:
                progress(trial, receipt)
            if pace_s > 0:
                time.sleep(pace_s)
        info = self.store.session(self.session_id)
        return RunSummary(self.session_id, info.status, info.n_answered, info.n_trials, n_run)
