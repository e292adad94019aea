"""The web app's shared state and helpers: the running sessions, calibration jobs,
secrets, templates and owner-only files, used by the app factory and both routers.

The routers import from here, never from :mod:`.app`, so imports run one way:
``app`` -> ``routes_*`` -> ``state``.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import logging
import os
import secrets
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fastapi import HTTPException, Request

from .._templates import template_environment
from ..errors import StudyError, VibrofocusError
from .logins import LoginSessions
from .private import load_or_make_secret, private_dir, private_file, private_journal
from .public_text import public_text
from .security import same_secret
from .session_runner import Pace, SessionRunner
from .throttle import Throttle

__all__ = ["WebState", "CalibrationJob", "CalibrationCancelled", "render_template", "trial_position", "private_dir", "private_file", "private_journal", "login_cookie", "TOKEN_HEADER", "TOKEN_COOKIE", "KEY_HEADER"]

log = logging.getLogger(__name__)

TOKEN_HEADER = "X-Vibrofocus-Token"
TOKEN_COOKIE = "vf_token"
KEY_HEADER = "X-Participant-Key"
#: How long a one-time login link printed by ``vibrofocus serve`` stays valid, s.
LOGIN_CODE_TTL_S = 15 * 60.0

_HERE = Path(__file__).parent


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


@dataclass
class WebState:
    """Everything the routes share; one per app.

    Attributes
    ----------
    store : StudyStore
        The study database. SQLite connections are not shared between threads safely,
        so every use goes through ``db`` (a lock): request handlers run in a thread pool
        and each running session has its own thread.
    db_path : Path
        The database file (calibrations, exports and reports go beside it).
    token : str
        The experimenter token.
    secret : bytes
        Server secret from which the cookie value is derived.
    rig_kind : str
        The rig the server was started for (``simulated``, ``audio``, ``nidaq``).
    pace : Pace
        Timing of the participant page.
    rig_factory : callable, optional
        Builds a rig (tests pass their own).
    rig_config : path or RigConfig, optional
        Hardware rig settings given to ``serve``.
    db, lock : threading.RLock
        Guard the database and the shared dictionaries below.
    runners : dict
        Session id to its running :class:`SessionRunner`.
    calibrations : dict
        Loaded calibrations, by calibration id.
    banks : dict
        Renderers (cached stimuli) by (calibration id, drive limit in V, level rule).
    jobs : dict
        Calibration jobs in progress, by job id.
    rigs : dict
        Open rigs by (kind, seed).
    job_threads : list of threading.Thread
        The background jobs' threads (calibrations), which :meth:`shutdown` waits for.
    planned : dict
        Planned trials by session id.
    analyses : dict
        Analyses run from the page, by id (one at a time).
    login_codes : dict
        One-time login codes and their expiry (``time.monotonic()``, s).
    logins : LoginSessions
        The experimenter logins (the cookie's random ids).
    throttle : Throttle
        Wrong secrets per client.
    """

    store: Any
    db_path: Path
    token: str
    secret: bytes
    rig_kind: str
    pace: Pace
    rig_factory: Any = None
    rig_config: Any = None
    db: threading.RLock = field(default_factory=threading.RLock)
    runners: dict[int, SessionRunner] = field(default_factory=dict)
    calibrations: dict[int, Any] = field(default_factory=dict)
    banks: dict[tuple[int, float], Any] = field(default_factory=dict)
    jobs: dict[str, CalibrationJob] = field(default_factory=dict)
    rigs: dict[tuple[str, int], Any] = field(default_factory=dict)
    job_threads: list[threading.Thread] = field(default_factory=list)
    planned: dict[int, list] = field(default_factory=dict)
    analyses: dict[str, dict] = field(default_factory=dict)
    lock: threading.RLock = field(default_factory=threading.RLock)
    login_codes: dict[str, float] = field(default_factory=dict)
    logins: LoginSessions | None = None
    throttle: Throttle = field(default_factory=Throttle)

    def __post_init__(self) -> None:
        if self.logins is None:
            self.logins = LoginSessions(self.db_path.with_name(self.db_path.name + ".web-logins"), self.secret, self.token)

    @property
    def rig_label(self) -> str:
        """The server's rig as the experimenter page shows it (kind, and config file)."""
        if self.rig_config is None:
            return self.rig_kind
        name = Path(self.rig_config).name if isinstance(self.rig_config, (str, os.PathLike)) else "given config"
        return f"{self.rig_kind} ({name})"

    # ------------------------------------------------------------------ paths
    @property
    def data_dir(self) -> Path:
        """Folder for calibrations, exports and reports, beside the database."""
        d = self.db_path.parent / f"{self.db_path.stem}-files"
        private_dir(d, "files folder")
        return d

    # ------------------------------------------------------------------ access
    TOKEN_MESSAGE = (
        "You are not logged in as the experimenter. Open the login link that 'vibrofocus serve' "
        "printed, or log in with the experimenter token."
    )
    KEY_MESSAGE = "This participant link does not belong to this session. Ask the experimenter for the right link."

    def participant_key(self, session_id: int) -> str:
        """The participant key of a session (URL-safe, 22 characters)."""
        mac = hmac.new(self.secret, f"participant-session:{int(session_id)}".encode(), hashlib.sha256).digest()
        return base64.urlsafe_b64encode(mac[:16]).decode().rstrip("=")

    def key_ok(self, session_id: int, key: str | None) -> bool:
        """True if ``key`` is the participant key of ``session_id`` (constant time)."""
        return same_secret(key, self.participant_key(session_id))

    def check_key(self, session_id: int, key: str | None) -> None:
        """Raise 403 unless ``key`` is the participant key of ``session_id``."""
        if not self.key_ok(session_id, key):
            raise HTTPException(403, detail=self.KEY_MESSAGE)

    def token_ok(self, given: str | None) -> bool:
        """True if ``given`` is the experimenter token (constant time)."""
        return same_secret(given, self.token)

    def cookie_ok(self, cookie_header: str | None) -> bool:
        """True if a ``Cookie`` header carries a current experimenter login."""
        return self.logins.valid(login_cookie(cookie_header))

    def check_token(self, request: Request) -> None:
        """Raise 401 unless the request carries the experimenter token or login cookie."""
        if not (self.token_ok(request.headers.get(TOKEN_HEADER)) or self.cookie_ok(request.headers.get("cookie"))):
            raise HTTPException(401, detail=self.TOKEN_MESSAGE)

    def new_login_code(self, ttl_s: float = LOGIN_CODE_TTL_S) -> str:
        """A one-time login code, valid for ``ttl_s`` seconds (see ``GET /login/{code}``)."""
        code = secrets.token_urlsafe(24)
        with self.lock:
            now = time.monotonic()
            for old in [c for c, until in self.login_codes.items() if until < now]:
                del self.login_codes[old]
            self.login_codes[code] = now + ttl_s
        return code

    def use_login_code(self, code: str) -> bool:
        """Spend a login code: True once for a valid, unexpired code, False otherwise."""
        with self.lock:
            match = next((c for c in self.login_codes if same_secret(code, c)), None)
            if match is None:
                return False
            until = self.login_codes.pop(match)
        return until >= time.monotonic()

    # ------------------------------------------------------------------ store helpers
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

    @property
    def rig_kinds(self) -> list[str]:
        """Rig kinds this server can use: its own, and the simulated forearm for rehearsals."""
        return [self.rig_kind] + (["simulated"] if self.rig_kind != "simulated" else [])

    def check_rig_kind(self, kind: str) -> None:
        """Raise 409 unless this server can use rigs of ``kind``."""
        if kind not in self.rig_kinds:
            raise HTTPException(409, detail=(
                f"This server was started for the {self.rig_label} rig. To use the {kind} rig, restart it with "
                f"'vibrofocus serve --rig {kind} --rig-config FILE'."
            ))

    def make_rig(self, kind: str, seed: int | None):
        """A rig by kind and seed, made once and reused (a hardware rig holds a device).

        A hardware rig is the one the server was started with (``serve --rig KIND
        --rig-config FILE``), built from that config file.
        """
        self.check_rig_kind(kind)
        # One rig per physical device: a hardware rig is the same object whatever the seed.
        key = (kind, -1 if seed is None or kind != "simulated" else int(seed))
        with self.lock:
            if key not in self.rigs:
                factory = self.rig_factory
                if factory is None:
                    from ..rigs import make_rig as factory
                extra = {"config": self.rig_config} if kind != "simulated" and self.rig_config is not None else {}
                try:
                    self.rigs[key] = factory(kind, seed=seed, **extra)
                except VibrofocusError as exc:
                    raise HTTPException(400, detail=str(exc)) from None
            return self.rigs[key]

    def calibration(self, calibration_id: int):
        """A calibration by id, after checking its file's SHA-256; 404 if unknown, 409 if changed.

        Every use checks the hash, the cached copy's too: a file changed on disk is
        refused at once, not after a restart.
        """
        calibration_id = int(calibration_id)
        with self.db:
            try:
                rec = self.store.calibration(calibration_id)
            except StudyError:
                raise HTTPException(404, detail=f"unknown calibration {calibration_id}") from None
            name = Path(rec.path).name
            try:
                path = self.store.verify_calibration(calibration_id)
            except StudyError:
                with self.lock:  # a file that changed is never used again from memory
                    self.calibrations.pop(calibration_id, None)
                    for key in [k for k in self.banks if k[0] == calibration_id]:
                        del self.banks[key]
                raise HTTPException(409, detail=(
                    f"Calibration {calibration_id} ({name}) is missing or has changed since it was saved, so it is not "
                    "used. Calibrate again, or put the original file back."
                )) from None
        with self.lock:
            if calibration_id in self.calibrations:
                return self.calibrations[calibration_id]
        from ..calibration import load_calibration

        try:
            cal = load_calibration(path)
        except VibrofocusError as exc:
            raise HTTPException(409, detail=public_text(f"Calibration {calibration_id} ({name}) cannot be loaded: {exc}")) from None
        with self.lock:
            self.calibrations[calibration_id] = cal
        return cal

    def bank(self, calibration_id: int, limit_v: float | None = None, levels: str | None = None):
        """The renderer of a calibration (renders each condition once; previews and sessions share it).

        Parameters
        ----------
        calibration_id : int
            A registered calibration.
        limit_v : float, optional
            Drive limit, V peak (a rig's limit); default the rendering layer's.
        levels : {"paper", "equal-peak"}, optional
            The level rule (a session's); default the paper's
            (:data:`~vibrofocus.studies.protocol.DEFAULT_LEVELS`).

        Returns
        -------
        CalibrationRenderer
        """
        from ..defaults import DRIVE_LIMIT_V
        from ..studies.engine import CalibrationRenderer
        from ..studies.protocol import DEFAULT_LEVELS

        limit = DRIVE_LIMIT_V if limit_v is None else float(limit_v)
        levels = DEFAULT_LEVELS if levels is None else str(levels)
        key = (int(calibration_id), limit, levels)
        cal = self.calibration(calibration_id)  # the hash, checked at every use
        with self.lock:
            bank = self.banks.get(key)
        if bank is None:
            bank = CalibrationRenderer(cal, limit_v=limit, levels=levels)
            with self.lock:
                bank = self.banks.setdefault(key, bank)
        return bank

    def runner(self, session_id: int, *, create: bool = False) -> SessionRunner | None:
        """The runner of a session; with ``create``, build it from the stored session."""
        with self.lock:
            runner = self.runners.get(session_id)
            if runner is not None or not create:
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

    def rig_name(self, kind: str, rig: Any) -> str:
        """A rig as the emergency stop names it: its kind, and its seed or config file."""
        if kind == "simulated":
            seed = getattr(rig, "seed", None)
            return "simulated rig" + (f" (seed {seed})" if seed is not None else "")
        if isinstance(self.rig_config, (str, os.PathLike)):
            return f"{kind} rig ({Path(self.rig_config).name})"
        return f"{kind} rig"

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


#: What people call the fields of the requests, for the messages of refused requests.
FIELD_NAMES = {
    "participant_id": "The participant id", "study": "The study", "repetitions": "Repetitions",
    "n_training": "Training trials", "seed": "The seed", "calibration_id": "The calibration",
    "rig": "The rig", "rig_seed": "The rig seed", "response": "The answer", "rt_s": "The reaction time",
    "answer_id": "The answer id", "trial_index": "The trial", "session_id": "The session",
    "location": "The location", "method": "The method", "wait": "The wait", "after": "The state number",
    "simulated": "'simulated'", "allow_calibration_errors": "'allow_calibration_errors'", "points": "The points",
}


def plain_problem(err: dict[str, Any]) -> str:
    """One validation error of pydantic as a sentence a person can act on."""
    loc = [p for p in err.get("loc", ()) if p not in ("body", "query", "path", "header")]
    names = [p for p in loc if isinstance(p, str)]
    what = FIELD_NAMES.get(names[-1], f"The field '{names[-1]}'") if names else "The request"
    if any(isinstance(p, int) for p in loc):
        what += f" (item {next(p for p in loc if isinstance(p, int)) + 1})"
    kind, ctx = err.get("type", ""), err.get("ctx") or {}
    if kind == "json_invalid":
        return "The request is not valid JSON."
    if kind == "missing":
        return f"{what} is missing."
    if kind == "extra_forbidden":
        return f"'{names[-1] if names else '?'}' is not something this request takes."
    bounds = {"greater_than_equal": "at least", "greater_than": "more than", "less_than_equal": "at most", "less_than": "less than"}
    if kind in bounds:
        return f"{what} must be {bounds[kind]} {next(iter(ctx.values()), '?')}."
    if kind in ("too_short", "string_too_short"):
        n = ctx.get("min_length", 1)
        return f"{what} is empty." if n == 1 and kind == "string_too_short" else f"{what} needs at least {n}."
    if kind in ("too_long", "string_too_long"):
        return f"{what} is too long (at most {ctx.get('max_length', '?')})."
    if kind == "string_pattern_mismatch":
        return f"{what} may hold only letters, digits, '.', '_' and '-', and starts with a letter or digit."
    if kind == "literal_error" and "expected" in ctx:
        return f"{what} must be {ctx['expected']}."
    if kind in ("bool_type", "int_type", "float_type", "string_type"):
        # Strict types (api_models): say what was sent and what is wanted.
        wanted = {"bool_type": "true or false", "int_type": "a whole number", "float_type": "a number",
                  "string_type": "text"}[kind]
        return f"{what} is not a valid value here: it must be {wanted}, not {_shown(err.get('input'))}."
    if kind.startswith(("int_", "float_", "bool_", "string_")) or kind == "enum":
        return f"{what} is not a valid value here."
    msg = str(err.get("msg", "is not valid")).removeprefix("Value error, ")
    return f"{what}: {msg[:1].lower() + msg[1:]}" + ("" if msg.endswith(".") else ".")


def _shown(value: Any) -> str:
    """A refused value as JSON, cut short (it comes from the request)."""
    import json

    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = type(value).__name__
    return text if len(text) <= 40 else text[:37] + "..."


def trial_position(trials: list[Any], index: int | None) -> dict[str, Any]:
    """Where trial ``index`` stands, in the one numbering shown everywhere.

    That numbering is the trials file's: the ``phase`` (training or main) and ``trial``,
    the trial's number within its phase from 1, out of ``n_in_phase``. The 0-based
    ``trial_index`` stays internal (routes and the database).
    """
    if index is None or not 0 <= index < len(trials):
        return {"phase": None, "trial": None, "n_in_phase": None}
    phase = trials[index].phase
    return {"phase": phase, "trial": trials[index].trial, "n_in_phase": sum(1 for t in trials if t.phase == phase)}


def render_template(name: str, **values: Any) -> str:
    """Render ``web/templates/<name>`` with Jinja2 (autoescaped: every value is HTML-escaped).

    Parameters
    ----------
    name : str
        Template file name, e.g. ``"participant.html"``.
    **values
        The template's values.

    Returns
    -------
    str
        The page.
    """
    return template_environment(_HERE / "templates").get_template(name).render(**values)


def _as_dict(obj: Any) -> dict[str, Any]:
    if isinstance(obj, dict):
        return obj
    if hasattr(obj, "_asdict"):
        return obj._asdict()
    if hasattr(obj, "__dataclass_fields__"):
        import dataclasses

        return dataclasses.asdict(obj)
    return dict(obj)


def login_cookie(cookie_header: str | None) -> str | None:
    """The login cookie's value in a ``Cookie`` header, if any."""
    for part in (cookie_header or "").split(";"):
        name, _, value = part.strip().partition("=")
        if name == TOKEN_COOKIE:
            return value
    return None
