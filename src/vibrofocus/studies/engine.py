"""Running the trials of a stored session on a rig: the one study loop.

The store is the only memory of progress: :meth:`StudyEngine.run` asks it for the first
unanswered trial, presents it (event ``cue``, the beep, event ``stimulus_onset``, the
drive on the rig), takes the answer from a :class:`Responder` and commits it before the
next trial starts. A killed or interrupted run resumes by running again.

Every responder (the terminal keypad, the simulated participant, the web participant
page) runs in this loop; what a responder needs beyond ``respond`` it gets through the
optional hooks of :class:`Responder` (wait until a screen can take the cue, cancel a cue
nobody saw, present a trial again, pause, stop). The engine writes every trial event, in
the same form for every responder.
"""

from __future__ import annotations

import hashlib
import inspect
import sys
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, Union

import numpy as np

from ..defaults import DRIVE_LIMIT_V, N_SAMPLES
from ..errors import StudyError, ValidationError
from ..rigs.devices import XrunError
from ..rigs.safety import play_paced
from .markers import send_marker
from .protocol import DEFAULT_LEVELS, PlannedTrial, StudyDesign, level_options
from .storage import AnswerReceipt, StudyStore, session_protocol

__all__ = [
    "check_drive_levels",
    "represent_after_xrun",
    "REPRESENT_AFTER_XRUN",
    "PAUSE",
    "ABORT",
    "STOP",
    "Again",
    "Control",
    "Stimulus",
    "Presentation",
    "Response",
    "Responder",
    "RunSummary",
    "StudyEngine",
    "drive_sha256",
    "check_stimulus",
    "calibration_renderer",
    "CalibrationRenderer",
    "terminal_beep",
    "headphone_beep",
]

#: What a responder returns to pause the session (then :meth:`Responder.wait_resume`).
PAUSE = "pause"
#: What a responder returns to abort the session (answers so far are kept).
ABORT = "abort"
#: What a responder returns to end the run and leave the session's status as it is (a
#: server shutting down, or an experimenter whose stop is already stored).
STOP = "stop"


#: Times a trial whose stimulus lost samples (an xrun) is presented again by default.
REPRESENT_AFTER_XRUN = 1
#: Most a session may ask for.
MAX_REPRESENT_AFTER_XRUN = 10


def represent_after_xrun(config: Any) -> int:
    """A session's ``represent_after_xrun``: how many times a trial whose stimulus lost samples
    (an xrun) is presented again before the run ends (docs/protocols.md).

    Parameters
    ----------
    config : mapping or None
        The session's config; without the key, :data:`REPRESENT_AFTER_XRUN`.

    Raises
    ------
    StudyError
        Not an integer from 0 to :data:`MAX_REPRESENT_AFTER_XRUN`.
    """
    value = (config or {}).get("represent_after_xrun", REPRESENT_AFTER_XRUN)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (
            0 <= value <= MAX_REPRESENT_AFTER_XRUN):
        raise StudyError(f"represent_after_xrun must be an integer from 0 to {MAX_REPRESENT_AFTER_XRUN}, "
                         f"got {value!r}")
    return int(value)


@dataclass(frozen=True)
class Again:
    """What a responder returns to have the first unanswered trial presented again.

    Attributes
    ----------
    event : str or None
        Event logged for the trial (``cue_cancelled``, ``trial_restarted``), with
        ``reason``; ``None``: nothing to log (the trial was answered meanwhile, say).
    reason : str
        Why, in words.
    """

    event: str | None = None
    reason: str = ""


#: What a hook may return: ``None`` (go on), :data:`PAUSE`, :data:`ABORT`, :data:`STOP` or :class:`Again`.
Control = Union[None, str, Again]
_CONTROLS = (PAUSE, ABORT, STOP)

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


class CalibrationRenderer:
    """``renderer(method, target) -> drives`` built on a participant's calibration, cached.

    Every stimulus is ``rendering.render(method, tm, fs, layout, target, limit_v=...,
    **level_options(levels, limit_v))`` with ``tm = TransferMatrix.from_calibration(calibration,
    n_samples)``, rendered on first use and kept (a trial's stimulus is a pure function of
    the calibration, the level rule and the condition). The transfer matrix is validated
    once and keeps its wrap-around check and inverse operators for every condition. Methods
    are those of the registry (:func:`~vibrofocus.rendering.available_methods`), a lab's own
    included. Safe to share between threads (a web app's sessions and previews of one
    calibration).

    Parameters
    ----------
    calibration : Calibration
        The participant's calibration (``transfer_for``, ``fs``, ``layout``).
    n_samples : int, optional
        Length of each drive, samples. Default: the window this participant's stimuli
        fit (:meth:`prepare`), from the calibration: its own resolution (``n_fft``, where
        its ``H`` is what was measured; 4096 without one), doubled (up to
        :attr:`MAX_SAMPLES`) until every stimulus asked fits it, every stimulus then
        rendered on that one window. A design that does not fit its window (a
        :class:`~vibrofocus.errors.CausalityError`) is first made again with the window's
        ends tapered (``taper_ends=True``: noise in a measured ``H`` spreads a little of an
        inverse design's drive over the whole window). Given explicitly, a window that a
        design does not fit even so is refused.
    limit_v : float
        Drive limit, V peak; designs needing more are scaled down (the rendering layer's
        default ``on_limit="scale"``).
    levels : {"paper", "equal-peak"}
        The level rule (:func:`~vibrofocus.studies.protocol.level_options`); default the
        paper's.
    **render_options
        Passed on to ``rendering.render`` (over the level rule's options).
    """

    #: Longest window the default grows to, samples (6.6 s at 10 kHz).
    MAX_SAMPLES = 16 * N_SAMPLES

    def __init__(self, calibration: Any, *, n_samples: int | None = None, limit_v: float = DRIVE_LIMIT_V,
                 levels: str = DEFAULT_LEVELS, **render_options: Any) -> None:
        self.calibration = calibration
        self._grow = n_samples is None
        from ..rendering.transfer import calibration_window

        # The calibration's resolution: its H as measured.
        self.n_samples = calibration_window(calibration) if n_samples is None else int(n_samples)
        self.limit_v = float(limit_v)
        self.levels = str(levels)
        self._options = {**level_options(self.levels, self.limit_v), **render_options}
        self._lock = threading.RLock()
        self._H: Any = None  # the TransferMatrix of the current window
        self._cache: dict[tuple[str, int], Any] = {}
        #: The stimuli made again to fit a rig's limits: (method, location) -> the options
        #: that made them (:meth:`prepare` with ``rig``).
        self.redesigned: dict[tuple[str, int], dict[str, Any]] = {}

    def _render(self, key: tuple[str, int]) -> Any:
        from ..rendering import TransferMatrix
        from ..rendering.render import render_fitted

        cal = self.calibration
        if self._H is None:
            self._H = TransferMatrix.from_calibration(cal, self.n_samples)
        # Noise in the measured H spreads a little drive over the whole window: a design that
        # does not fit is made again with the window's ends tapered.
        return render_fitted(key[0], self._H, cal.fs, cal.layout, key[1], limit_v=self.limit_v, **self._options)

    #: Regularizations a stimulus over a rig's limits is made again with, in turn
    #: (:meth:`prepare`): the inverse designs' default Tikhonov parameter, then ten times it.
    REDESIGNS: tuple[dict[str, Any], ...] = (
        {"regularization": "tikhonov", "reg_param": 1e-2},
        {"regularization": "tikhonov", "reg_param": 1e-1},
    )

    def prepare(self, methods: Any, locations: Any, *, rig: Any = None) -> int:
        """Render every (method, location) stimulus now, on one window they all fit.

        A study calls this when its session is planned, so that a stimulus that cannot
        be played is refused then, never mid-study. With the default window, the window
        is doubled (every stimulus rendered again on it) until every stimulus fits.
        Given the rig that will play them, every stimulus is also checked against every
        limit of that rig that a drive has by itself (:func:`check_stimulus`); one over
        them is made again with the regularizations of :attr:`REDESIGNS` in turn, where
        its method has that option and the renderer's options do not fix it
        (:attr:`redesigned` records those), or refused.

        Parameters
        ----------
        methods : iterable of str
        locations : iterable of int
            Location numbers.
        rig : Rig, optional
            The rig the stimuli will play on.

        Returns
        -------
        int
            The window, samples.

        Raises
        ------
        StudyError
            A stimulus does not fit the longest window (:attr:`MAX_SAMPLES`, or the
            ``n_samples`` given), or the rig's limits even made again, naming the
            participant, the method, the location and why.
        """
        keys = [(str(m), int(loc)) for m in methods for loc in locations]
        with self._lock:
            n = self._render_all(keys)
            if rig is not None:
                for key in keys:
                    self._fit_limits(key, rig)
            return n

    def _fit_limits(self, key: tuple[str, int], rig: Any) -> None:
        """Check a rendered stimulus against the rig's limits; make it again, or refuse it."""
        from dataclasses import fields

        from ..errors import CausalityError, SafetyError
        from ..rendering.registry import method_class

        try:
            check_stimulus(self._cache[key].drives, rig)
            return
        except SafetyError as exc:
            first = exc
        names = {f.name for f in fields(method_class(key[0]))}
        tries = self.REDESIGNS if {"regularization", "reg_param"} <= names and not (
            {"regularization", "reg_param"} & set(self._options)) else ()
        from ..rendering import TransferMatrix
        from ..rendering.render import render_fitted

        cal = self.calibration
        if self._H is None:
            self._H = TransferMatrix.from_calibration(cal, self.n_samples)
        for options in tries:
            try:
                design = render_fitted(key[0], self._H, cal.fs, cal.layout, key[1], limit_v=self.limit_v,
                                       **{**self._options, **options})
                check_stimulus(design.drives, rig)
            except (SafetyError, CausalityError):
                continue
            self._cache[key], self.redesigned[key] = design, dict(options)
            return
        who = getattr(self.calibration, "participant_id", None)
        tried = (" (also made again with " + ", then ".join(
            f"{o['regularization']} regularization {o['reg_param']:g}" for o in tries) + ")") if tries else ""
        raise StudyError(
            f"the {key[0]} stimulus at location {key[1]}{f' for participant {who}' if who else ''} breaks the limits "
            f"of the {getattr(rig, 'kind', '')} rig{tried}: {first}. Check the calibration, lower the drive limit, "
            "or leave this method out") from None

    def _render_all(self, keys: list[tuple[str, int]]) -> int:
        """Render ``keys`` on one window they all fit (doubling the default window); the window."""
        from ..errors import CausalityError

        with self._lock:
            while True:
                try:
                    for key in keys:
                        if key not in self._cache:
                            self._cache[key] = self._render(key)
                    return self.n_samples
                except CausalityError as exc:
                    if not self._grow or 2 * self.n_samples > self.MAX_SAMPLES:
                        longest = self.n_samples
                        raise StudyError(
                            f"this participant's stimuli do not fit a {longest}-sample design window "
                            f"({longest / self.calibration.fs:g} s, the longest allowed): {exc}. Recalibrate (a "
                            "calibration whose responses ring this long is suspect) or study fewer methods"
                        ) from None
                    # The window follows the arm: every stimulus again, on one longer window.
                    self.n_samples, self._H, self._cache = 2 * self.n_samples, None, {}
                    self.redesigned = {}

    def rendering(self, method: str, target: int) -> Any:
        """The :class:`~vibrofocus.rendering.Rendering` of ``method`` at location number ``target``."""
        key = (str(method), int(target))
        with self._lock:
            if key not in self._cache:
                self.prepare([key[0]], [key[1]])
            return self._cache[key]

    def __call__(self, method: str, target: int) -> np.ndarray:
        """Drives of a condition, shape (n_actuators, n_samples), V."""
        return np.asarray(self.rendering(method, target).drives, dtype=float)


def check_stimulus(drives: np.ndarray, rig: Any) -> None:
    """Check one stimulus against every limit of a rig that a drive has by itself.

    The rig's own check (:meth:`~vibrofocus.rigs.Rig.check`: shape, peak, RMS over the
    short window, DC and slow content, the level at its outputs) and the sustained limit
    played alone (:func:`~vibrofocus.rigs.safety.check_sustained_alone`). What the
    stimulus adds to the plays before it is the energy budget's, when it plays.

    Parameters
    ----------
    drives : ndarray, shape (n_actuators, n_samples)
        V.
    rig : Rig

    Raises
    ------
    SafetyError
        The first limit it breaks.
    """
    from ..rigs.safety import check_on_rig

    check_on_rig(drives, rig)


def _check_rates(calibration: Any, rig: Any) -> None:
    """Refuse a calibration made at another sample rate than the rig plays at.

    Drives designed at one rate and played at another come out at another pitch and
    duration (a 10 kHz design on a 20 kHz rig plays an octave up, in half the time).
    """
    cal_fs, rig_fs = getattr(calibration, "fs", None), getattr(rig, "fs", None)
    if cal_fs is None or rig_fs is None:
        return
    if abs(float(cal_fs) - float(rig_fs)) > 1e-9 * float(rig_fs):
        raise StudyError(
            f"the calibration was made at {float(cal_fs):g} Hz but the {getattr(rig, 'kind', '')} rig plays at "
            f"{float(rig_fs):g} Hz: its drives would play at the wrong pitch and duration. Calibrate on this rig, "
            "or set the rig's fs to the calibration's"
        )


def calibration_renderer(calibration: Any, **options: Any) -> CalibrationRenderer:
    """A ``renderer(method, target) -> drives`` built on a participant's calibration.

    Parameters
    ----------
    calibration : Calibration
        The participant's calibration.
    **options
        ``n_samples``, ``limit_v``, ``levels`` and rendering options, as
        :class:`CalibrationRenderer` takes them.

    Returns
    -------
    CalibrationRenderer
    """
    return CalibrationRenderer(calibration, **options)


def check_drive_levels(renderer: Any, design: StudyDesign, *, limit_v: float | None = None,
                       where: str | None = None) -> None:
    """Refuse a design whose level needs more than the drive limit, before any trial.

    Every stimulus of ``design`` is rendered (``renderer.prepare``) at its level rule, and its
    largest ``|drive|`` times :attr:`StudyDesign.gain` compared with the limit (a threshold
    block's: at its staircase's ``max_db``, the loudest it may play). A level at or below 0 dB
    re the rule never exceeds it (the rules keep every drive within the limit).

    Parameters
    ----------
    renderer : CalibrationRenderer
        The participant's renderer of ``design.levels``.
    design : StudyDesign
        The design to check.
    limit_v : float, optional
        Drive limit, V peak; default the renderer's ``limit_v``.
    where : str, optional
        What to name in the error (a protocol file's field, ``protocol F, line 9,
        blocks[0].levels``); default ``level_db``.

    Raises
    ------
    StudyError
        The stimulus needing the most drive exceeds the limit at this level, naming it.
    """
    level_db = design.staircase.max_db if design.staircase is not None else design.level_db
    if level_db <= 0.0:
        return
    gain = 10.0 ** (level_db / 20.0)
    limit = float(getattr(renderer, "limit_v", DRIVE_LIMIT_V) if limit_v is None else limit_v)
    prepare = getattr(renderer, "prepare", None)
    if prepare is not None:
        prepare(design.methods, design.locations)
    worst, peak = None, -1.0
    for m in design.methods:
        for loc in design.locations:
            p = float(np.max(np.abs(np.asarray(renderer(m, loc), dtype=float)))) * gain
            if p > peak:
                worst, peak = (m, loc), p
    if worst is not None and peak > limit * (1.0 + 1e-9):
        raise StudyError(
            f"{where or 'level_db'}: {level_db:+g} dB re the {design.levels} levels needs {peak:.3g} V for "
            f"{worst[0]} at location {worst[1]}, over the {limit:g} V drive limit; lower the level"
        )


def staircase_levels(store: Any, session_id: int) -> tuple[float, ...]:
    """The levels of a threshold session's main trials so far, and the next one's, dB re the level rule.

    The staircase replayed over the session's stored main-phase answers
    (:meth:`~vibrofocus.studies.staircase.Staircase.run`): a resumed session plays what an
    uninterrupted one would have.
    """
    info = store.session(session_id)
    staircase = info.design.staircase
    if staircase is None:
        raise StudyError(f"session {session_id} is not a threshold block (no staircase)")
    n_training = info.design.n_training
    felt = [a.response for a in store.answers(session_id) if a.trial_index >= n_training]
    return staircase.run(felt).levels_db


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
        that may be the rig's own audio interface (which drives the actuators), on any
        host API, is refused (:class:`vibrofocus.rigs.cue.CueTone`).

    Returns
    -------
    callable
        ``cue()``, blocking until the tone has played.

    Raises
    ------
    ValidationError
        If ``device`` may be the rig's actuator interface.
    """
    from ..rigs.cue import CueTone

    return CueTone(device, rig=rig)


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
    drive_peak_v : float or None
        Largest ``|drive|`` over the actuators, V (computed from ``drives`` when None).
    target_peak_m : float or None
        Peak displacement at the target predicted from the calibration, m; None when the
        renderer gives no prediction.
    redesign : dict or None
        The rendering options the stimulus was made again with to fit the rig's limits
        (:attr:`CalibrationRenderer.redesigned`); None for the design as asked.
    """

    method: str
    target: int
    drives: np.ndarray
    sha256: str
    drive_peak_v: float | None = None
    target_peak_m: float | None = None
    redesign: dict | None = None

    def __post_init__(self) -> None:
        if self.drive_peak_v is None:
            peak = float(np.max(np.abs(self.drives))) if np.size(self.drives) else 0.0
            object.__setattr__(self, "drive_peak_v", peak)


@dataclass(frozen=True)
class Presentation:
    """A trial as it was presented.

    Attributes
    ----------
    session_id : int
    study : int
    trial : PlannedTrial
        The planned trial.
    stimulus : Stimulus or None
        What was played; ``None`` in a dry run (nothing is played).
    onset_s : float
        Stimulus onset, ``time.monotonic()``, s: just before the drive went to the rig
        (what reaction times count from).
    design : StudyDesign
        The session's design.
    onset_device_s : float or None
        The drive's first sample on the rig's device clock, s
        (:class:`~vibrofocus.rigs.DeviceOnset`); None in a dry run or on a rig without one.
    onset_clock : str or None
        That clock's name (:data:`vibrofocus.rigs.CLOCKS`).
    onset_latency_s : float or None
        How long after ``onset_s`` the drive left the device's output, s, where the rig
        knows it (:attr:`vibrofocus.rigs.DeviceOnset.latency_s`).
    block : int
        The session's block of its protocol (0 for the paper's studies and a session
        planned without a protocol; docs/protocols.md).
    """

    session_id: int
    study: int
    trial: PlannedTrial
    stimulus: Stimulus | None
    onset_s: float
    design: StudyDesign
    onset_device_s: float | None = None
    onset_clock: str | None = None
    onset_latency_s: float | None = None
    block: int = 0


@dataclass(frozen=True)
class Response:
    """An answer.

    Attributes
    ----------
    locations : int, str or sequence of int
        Selected location(s): an int, a string like ``"4 5"`` or a sequence.
    rt_s : float
        Reaction time from the stimulus onset, s.
    answer_id : str, optional
        The answer's id; a new one is made when it is committed if ``None``. A responder
        whose answers arrive already committed (the web page's, by its answer route)
        gives that answer's id, so that committing it again stores nothing new.
    point_mm : (float, float), optional
        A point answer's place in the layout frame, mm (a point session's answers:
        ``locations`` is then None or the point's nearest location).
    """

    locations: Any
    rt_s: float
    answer_id: str | None = None
    point_mm: Any = None


class Responder(Protocol):
    """Who answers trials: a person at a keypad or a web page, or a simulated participant.

    ``respond`` and ``wait_resume`` are required. The other methods are optional hooks
    (the engine calls them when a responder has them): each returns a :data:`Control`,
    ``None`` to go on.
    """

    def respond(self, presentation: Presentation) -> Response | str | Again:
        """Answer a presented trial, or return :data:`PAUSE`, :data:`ABORT`, :data:`STOP` or :class:`Again`."""

    def wait_resume(self) -> bool | str:
        """Block while paused; True to resume (the trial is presented again), False to abort, :data:`STOP` to stop."""

    # Optional hooks (not required by the protocol; documented here):
    #
    # before_cue(trial) -> Control
    #     Before a trial's cue: e.g. show "get ready" and wait until a screen can take
    #     the cue. Again: present the first unanswered trial again.
    # cue_shown(trial) -> Control
    #     After the cue is logged and beeped, until the stimulus moment: e.g. wait until
    #     the screens show the cue. Again("cue_cancelled", reason): nobody saw the cue,
    #     nothing is played, the trial is presented again.
    # cooling(trial, wait_s) -> None
    #     Before the stimulus waits wait_s seconds for the actuators to cool (the rig's
    #     limit over time): e.g. show the wait.
    # xrun(trial, n, limit) -> None
    #     The stimulus lost samples and the trial is presented again, the n-th time of
    #     at most limit: e.g. say so.
    # answered(presentation, receipt) -> None
    #     After the answer is committed: e.g. show "taken".


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
    rig : Rig or None
        Where stimuli play (``rig.play``); may be ``None`` in a dry run.
    calibration : Calibration, optional
        The participant's calibration; stimuli are rendered from it with
        :func:`calibration_renderer`. Required unless ``renderer`` is given or
        ``dry_run``.
    renderer : callable, optional
        ``renderer(method, target) -> drives`` instead of the calibration.
    cue : callable, optional
        Called with no argument just before each stimulus to beep in the participant's
        headphones (e.g. :func:`terminal_beep`). ``None``: the responder beeps (a web
        page), or the cue is only logged (the simulated rig, whose participant has no ears).
    cue_by : str, optional
        What the ``cue`` event says of the beep when ``cue`` is ``None``:
        ``"event-only"`` (default) or ``"page"`` (the participant page beeps).
    dry_run : bool
        Present without stimuli (no calibration): cues and answers work, nothing is
        played, ``stimulus_onset`` says ``played: false``.
    n_samples, limit_v :
        Drive length (samples) and limit (V peak) for the calibration renderer.

    Raises
    ------
    StudyError
        A stimulus of the session's design does not fit the participant
        (:meth:`CalibrationRenderer.prepare`: every stimulus is rendered when the engine
        is made, before any trial), or breaks a limit of ``rig`` that a drive has by itself
        even made again (:func:`check_stimulus`, naming the participant, method and
        location), or a given renderer plays another level rule than the session's.

    Notes
    -----
    Drives are rendered once per (method, target) and cached: a trial's stimulus is a
    pure function of the calibration and the condition.

    Events written for each presentation (payload keys): ``cue`` (``trial_index``,
    ``beep``), ``stimulus_onset`` (``trial_index``, ``method``, ``target``, ``played``,
    ``drive_sha256``, ``levels``, ``drive_peak_v``, ``target_peak_um``), and when a responder asks for a trial again ``cue_cancelled`` or
    ``trial_restarted`` (``trial_index``, ``reason``); ``xrun`` (``trial_index``, ``message``,
    ``represented``, ``onset_device_s``) when the stream lost samples during a stimulus
    (the trial is then presented again, up to the session's ``represent_after_xrun`` times;
    ``represented`` false: the run ended there); ``cooling`` (``trial_index``, ``wait_s``,
    ``reason``) before a wait for the actuators to cool; ``error`` (``message``) when the
    run fails. The ``answer`` event (the store's) carries the onset: ``onset_s`` (host),
    ``onset_device_s`` and ``onset_clock`` (the rig's device clock). An answer committed
    before the engine had the onset (the web page's, by its answer route) gets an
    ``answer_onset`` event with them (``trial_index``, ``answer_id``, the same keys).
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
        cue_by: str = "event-only",
        dry_run: bool = False,
        n_samples: int | None = None,
        limit_v: float = DRIVE_LIMIT_V,
    ) -> None:
        self.store = store
        self._onset_counts: Counter | None = None  # stimulus onsets logged per trial index
        info = store.session(session_id)  # unknown session -> StudyError now, not mid-run
        self.session_id = info.session_id
        self.participant_id = info.participant_id
        self.study = info.study
        self.design = info.design
        self.rig = rig
        self._marked = _protocol_fields(info)
        #: Times a trial whose stimulus lost samples (an xrun) is presented again
        #: (the session's ``represent_after_xrun``; default :data:`REPRESENT_AFTER_XRUN`).
        self.represent_after_xrun = represent_after_xrun(info.config)
        if renderer is None and not dry_run:
            if calibration is None:
                raise StudyError("a study engine needs the participant's calibration (or a renderer)")
            if calibration.layout.n_locations < max(self.design.locations):
                raise StudyError(
                    f"the calibration's layout has {calibration.layout.n_locations} locations, but the "
                    f"study uses locations up to {max(self.design.locations)}"
                )
            renderer = calibration_renderer(calibration, n_samples=n_samples, limit_v=limit_v,
                                            levels=self.design.levels)
        prepare = None
        if renderer is not None and not dry_run:
            own = getattr(renderer, "levels", None)
            if own is not None and own != self.design.levels:
                raise StudyError(f"session {self.session_id} was planned with the {self.design.levels!r} level rule, "
                                 f"but its renderer plays {own!r}")
            prepare = getattr(renderer, "prepare", None)
            if prepare is not None:  # every stimulus now, never a refusal mid-study
                if rig is not None and "rig" in inspect.signature(prepare).parameters:
                    prepare(self.design.methods, self.design.locations, rig=rig)
                else:
                    prepare(self.design.methods, self.design.locations)
            check_drive_levels(renderer, self.design)
        self._renderer = None if dry_run else renderer
        _check_rates(calibration if calibration is not None else getattr(renderer, "calibration", None), rig)
        self.cue = cue
        self._beep = "played" if cue is not None else str(cue_by)
        self._cache: dict[tuple[str, int], Stimulus] = {}
        if prepare is not None and rig is not None and not dry_run:
            self._check_limits()

    def _check_limits(self) -> None:
        """Every prepared stimulus against the rig's limits, before any trial."""
        from ..errors import SafetyError

        staircase = self.design.staircase
        loudest = None if staircase is None else staircase.max_db  # a threshold block's loudest level
        for method in self.design.methods:
            for target in self.design.locations:
                stim = self.stimulus(method, target, loudest)
                try:
                    check_stimulus(stim.drives, self.rig)
                except SafetyError as exc:
                    raise StudyError(
                        f"the {method} stimulus at location {target} for participant {self.participant_id} breaks "
                        f"the limits of the {getattr(self.rig, 'kind', '')} rig: {exc}") from None

    # ------------------------------------------------------------------ pieces
    def stimulus(self, method: str, target: int, level_db: float | None = None) -> Stimulus | None:
        """The (cached) stimulus of a condition; ``None`` in a dry run.

        ``level_db``: the level re the level rule, dB (a threshold block's trial level,
        :meth:`trial_level`); default the design's.
        """
        if self._renderer is None:
            return None
        level = self.design.level_db if level_db is None else float(level_db)
        key = (str(method), int(target))
        if key + (level,) not in self._cache:
            drives = np.asarray(self._renderer(*key), dtype=float)
            gain = float(10.0 ** (level / 20.0))
            if gain != 1.0:  # the block's level re its rule (a protocol file's levels)
                drives = drives * gain
            drives.setflags(write=False)
            rendering = getattr(self._renderer, "rendering", None)
            reached = getattr(rendering(*key), "reached_peak_m", None) if rendering is not None else None
            if reached is not None:
                reached = float(reached) * gain
            redesign = getattr(self._renderer, "redesigned", {}).get(key)
            self._cache[key + (level,)] = Stimulus(key[0], key[1], drives, drive_sha256(drives),
                                                   target_peak_m=None if reached is None else float(reached),
                                                   redesign=None if redesign is None else dict(redesign))
        return self._cache[key + (level,)]

    def trial_level(self, trial: PlannedTrial) -> float:
        """The level of a trial, dB re the level rule: the design's, or in a threshold block
        the staircase's after the main trials answered so far (training: its start)."""
        staircase = self.design.staircase
        if staircase is None:
            return self.design.level_db
        if trial.phase != "main":
            return staircase.start_db
        return staircase_levels(self.store, self.session_id)[trial.trial_index - self.design.n_training]

    def _presented_before(self, trial: PlannedTrial) -> bool:
        """Whether this session logged more than one stimulus onset of ``trial`` (the one just logged included).

        The log is read once per engine (a resumed run's earlier onsets), then counted here.
        """
        if self._onset_counts is None:
            self._onset_counts = Counter(
                e.payload.get("trial_index") for e in self.store.events(self.session_id, kind="stimulus_onset")
                if isinstance(e.payload, dict))
        else:
            self._onset_counts[trial.trial_index] += 1
        return self._onset_counts[trial.trial_index] > 1

    def _cooling(self, trial: PlannedTrial, responder: Any, wait_s: float, why: str) -> None:
        """A wait for the actuators to cool before the trial's stimulus: logged, and told to the responder."""
        self._log("cooling", trial, wait_s=wait_s, reason=why)
        hook = getattr(responder, "cooling", None)
        if hook is not None:
            hook(trial, wait_s)

    def _log(self, kind: str, trial: PlannedTrial, **fields: Any) -> None:
        self.store.log_event(self.session_id, kind, {"trial_index": trial.trial_index, **fields})

    def _marker(self, event: str, host_time_s: float, trial: PlannedTrial, **fields: Any) -> None:
        """Send the marker of a cue, stimulus onset or answer (:mod:`.markers`; ``--lsl``)."""
        send_marker(event, host_time_s, participant=self.participant_id, study=self.study, session=self.session_id,
                    trial=trial.trial, trial_index=trial.trial_index, phase=trial.phase, method=trial.method,
                    target=trial.target, **{"response": None, **self._marked, **fields})

    def present(self, trial: PlannedTrial, responder: Any = None) -> Presentation | str | Again:
        """Cue, then play the trial's stimulus; both are logged before they happen.

        With a ``responder`` that has the ``cue_shown`` hook, the stimulus waits for it
        and is not played when it returns a control (returned here instead). The
        stimulus onset's marker follows the play, stamped with the onset's host time and
        carrying its device time (``onset_device_s``, ``onset_clock``).
        """
        level_db = self.trial_level(trial)
        stim = self.stimulus(trial.method, trial.target, level_db)
        self._log("cue", trial, beep=self._beep)
        self._marker("cue", time.monotonic(), trial)
        if self.cue is not None:
            self.cue()
        control = _hook(responder, "cue_shown", trial)
        if control is not None:
            return control
        self._log(
            "stimulus_onset", trial, method=trial.method, target=trial.target,
            played=stim is not None, drive_sha256=None if stim is None else stim.sha256,
            levels=self.design.levels, level_db=level_db, drive_peak_v=None if stim is None else stim.drive_peak_v,
            target_peak_um=None if stim is None or stim.target_peak_m is None else stim.target_peak_m * 1e6,
            **({} if stim is None or stim.redesign is None else {"redesign": stim.redesign}),
        )
        onset = time.monotonic()
        # A limit over time pauses the trial for the wait it names (not the run's end).
        try:
            played = play_paced(self.rig, stim.drives, lambda wait_s, why: self._cooling(trial, responder, wait_s, why)
                                ) if stim is not None else None
        except XrunError as exc:  # samples lost: the trial again, not the run's end
            return self._xrun(trial, responder, exc, onset, level_db)
        onset, device_s, clock, latency = _device_onset(played, onset)
        # The marker at the drive's first sample leaving the device: the hand-over plus the
        # output latency where the rig knows it. A trial presented before (a resumed run,
        # a pause) says so, so that a recording keeps one onset per answer.
        self._marker("stimulus_onset", onset + (latency or 0.0), trial, played=stim is not None, level_db=level_db,
                     onset_device_s=device_s, onset_clock=clock, onset_latency_s=latency,
                     replay=self._presented_before(trial))
        return Presentation(self.session_id, self.study, trial, stim, onset, self.design, device_s, clock, latency,
                            block=int(self._marked["block"]))

    def _xrun(self, trial: PlannedTrial, responder: Any, exc: Exception, onset: float, level_db: float) -> Again:
        """A stimulus whose stream lost samples: logged (event ``xrun``), and the trial presented again.

        Up to :attr:`represent_after_xrun` times per trial (the session's
        ``represent_after_xrun``, counted over every run of the session); one more xrun
        ends the run with the :class:`~vibrofocus.rigs.XrunError`, as before.
        """
        earlier = sum(1 for e in self.store.events(self.session_id, kind="xrun")
                      if isinstance(e.payload, dict) and e.payload.get("trial_index") == trial.trial_index
                      and e.payload.get("represented"))
        again = earlier < self.represent_after_xrun
        # What the participant felt is marked too, as lost (a recording keeps one onset per answer).
        onset, device_s, clock, latency = _device_onset(getattr(exc, "onset", None), onset)
        self._marker("stimulus_onset", onset + (latency or 0.0), trial, played=True, level_db=level_db,
                     onset_device_s=device_s, onset_clock=clock, onset_latency_s=latency,
                     replay=self._presented_before(trial), xrun=True)
        self._log("xrun", trial, message=str(exc), represented=again, onset_device_s=device_s)
        if not again:
            raise exc
        hook = getattr(responder, "xrun", None)
        if hook is not None:
            hook(trial, earlier + 1, self.represent_after_xrun)
        return Again(None, "the audio stream lost samples during the stimulus")

    def submit(self, presentation: Presentation, response: Response, *, answer_id: str | None = None) -> AnswerReceipt:
        """Commit the answer to a presented trial (with the drive hash and the onset) before returning.

        The answer's marker is stamped with its own time, the stimulus onset plus the
        response time, kept between the stimulus onset's marker and now: a simulated
        participant's modelled response time may be longer than the time that really
        passed (``--pace 0``), and no answer is stamped before its stimulus or after the
        next cue.
        """
        stim = presentation.stimulus
        onsets = {"onset_s": presentation.onset_s, "onset_device_s": presentation.onset_device_s,
                  "onset_clock": presentation.onset_clock}
        receipt = self.store.record_answer(
            self.session_id, presentation.trial.trial_index, response.locations, response.rt_s,
            answer_id=answer_id or response.answer_id or uuid.uuid4().hex,
            drive_sha256=None if stim is None else stim.sha256, point_mm=response.point_mm, **onsets,
        )
        if receipt.duplicate:
            # Committed before the engine had the onset (the web page's answer route): its onset apart.
            self._log("answer_onset", presentation.trial, answer_id=receipt.answer_id, **onsets)
        shown = presentation.onset_s + (presentation.onset_latency_s or 0.0)
        stamp = min(max(presentation.onset_s + float(receipt.rt_s), shown), max(time.monotonic(), shown))
        self._marker("answer", stamp, presentation.trial, response=list(receipt.response), rt_s=float(receipt.rt_s))
        return receipt

    def _trial(self, responder: Responder, trial: PlannedTrial) -> AnswerReceipt | str | Again:
        """Present one trial and commit its answer; or the control a responder returned."""
        control = _hook(responder, "before_cue", trial)
        if control is not None:
            return control
        presentation = self.present(trial, responder)
        if not isinstance(presentation, Presentation):
            return presentation
        reply = responder.respond(presentation)
        if isinstance(reply, (str, Again)):
            return _checked(reply)
        receipt = self.submit(presentation, reply)
        answered = getattr(responder, "answered", None)
        if answered is not None:
            answered(presentation, receipt)
        return receipt

    # ------------------------------------------------------------------ loop
    def run(
        self,
        responder: Responder,
        *,
        pace_s: float = 0.0,
        max_trials: int | None = None,
        progress: Callable[[PlannedTrial, AnswerReceipt], None] | None = None,
    ) -> RunSummary:
        """Run from the first unanswered trial until the end, an abort, a stop or ``max_trials``.

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

        Notes
        -----
        An exception (a rig or a renderer failing) is logged as an ``error`` event and
        raised; the session keeps its status, so running again resumes it.
        """
        try:
            n_run = self._run(responder, pace_s, max_trials, progress)
        except Exception as exc:
            self.store.log_event(self.session_id, "error", {"message": f"{type(exc).__name__}: {exc}"})
            raise
        info = self.store.session(self.session_id)
        return RunSummary(self.session_id, info.status, info.n_answered, info.n_trials, n_run)

    def _run(self, responder: Responder, pace_s: float, max_trials: int | None, progress: Any) -> int:
        info = self.store.session(self.session_id)
        if info.status == "completed":
            return 0
        self.store.set_status(self.session_id, "running")
        n_run = 0
        while max_trials is None or n_run < max_trials:
            trial = self.store.next_trial(self.session_id)
            if trial is None:
                self.store.set_status(self.session_id, "completed")  # no-op when the last answer did it
                break
            outcome = self._trial(responder, trial)
            if isinstance(outcome, Again):
                if outcome.event is not None:
                    self._log(outcome.event, trial, reason=outcome.reason)
                continue
            if outcome == PAUSE:
                self.store.set_status(self.session_id, "paused")
                resume = responder.wait_resume()
                if resume is True:
                    self.store.set_status(self.session_id, "running")
                    continue  # the same trial is presented again
                outcome = STOP if resume == STOP else ABORT
            if outcome == ABORT:
                self.store.set_status(self.session_id, "aborted")
                break
            if outcome == STOP:
                break
            n_run += 1
            if progress is not None:
                progress(trial, outcome)
            if pace_s > 0:
                time.sleep(pace_s)
        return n_run


def _device_onset(played: Any, onset: float) -> tuple[float, Any, Any, float | None]:
    """(host onset, device onset, its clock, output latency) of a play's DeviceOnset, s.

    Rig.play's DeviceOnset; a rig of the caller's own may return nothing (then ``onset``,
    the host time before the play, and None). Its host time is when the device took the
    first sample (the audio rig's first callback, tens of ms after the call): reaction
    times count from there.
    """
    host_s = getattr(played, "host_s", None)
    if isinstance(host_s, (int, float)) and np.isfinite(host_s):
        onset = float(host_s)
    device_s, clock = getattr(played, "device_s", None), getattr(played, "clock", None)
    latency = getattr(played, "latency_s", None)
    latency = float(latency) if isinstance(latency, (int, float)) and np.isfinite(latency) else None
    return onset, device_s, clock, latency


def _protocol_fields(info: Any) -> dict[str, Any]:
    """What every marker of a session says of its protocol (docs/lab-streaming-layer.md): its
    name and block, and ``task`` ``threshold`` for a threshold block (its taps' own code)."""
    protocol, block = session_protocol(info.study, info.config)
    return {"protocol": protocol, "block": block, **({"task": "threshold"} if info.design.detection else {})}


def _hook(responder: Any, name: str, trial: PlannedTrial) -> Control:
    """Call a responder's optional hook ``name(trial)``; ``None`` when it has none."""
    hook = getattr(responder, name, None)
    return None if hook is None else _checked(hook(trial))


def _checked(control: Control) -> Control:
    if control is None or isinstance(control, Again) or control in _CONTROLS:
        return control
    raise StudyError(f"a responder returned {control!r}; expected a Response, 'pause', 'abort', 'stop' or Again")
