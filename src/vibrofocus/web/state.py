"""The web app's shared state and helpers: the running sessions, calibration jobs,
secrets, templates and owner-only files, used by the app factory and both routers.

The routers import from here, never from :mod:`.app`, so imports run one way:
``app`` -> ``routes_*`` -> ``state``.

:class:`WebState` holds the shared fields; its methods live in parts split along its
jobs: :mod:`.state_access` (secrets, logins), :mod:`.state_rigs` (rigs, calibrations,
renderers), :mod:`.state_sessions` (sessions, runners) and :mod:`.state_jobs`
(calibration jobs, the emergency stop, the shutdown).
"""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._templates import template_environment
from .logins import LoginSessions
from .private import load_or_make_secret, private_dir, private_file, private_journal
from .session_runner import Pace, SessionRunner
from .state_access import KEY_HEADER, TOKEN_COOKIE, TOKEN_HEADER, AccessState, login_cookie
from .state_jobs import CalibrationCancelled, CalibrationJob, JobState
from .state_rigs import RigState
from .state_sessions import SessionState
from .throttle import Throttle

__all__ = ["WebState", "CalibrationJob", "CalibrationCancelled", "render_template", "trial_position", "private_dir", "private_file", "private_journal", "login_cookie", "TOKEN_HEADER", "TOKEN_COOKIE", "KEY_HEADER"]

log = logging.getLogger(__name__)

_HERE = Path(__file__).parent


@dataclass
class WebState(AccessState, RigState, SessionState, JobState):
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
    aborted : set
        Sessions aborted here: none of them gets a runner again (a page polling
        while the abort waits for the old runner must not build a new one).
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
    aborted: set[int] = field(default_factory=set)
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
        from .._db_files import files_dir

        d = files_dir(self.db_path)
        private_dir(d, "files folder")
        return d


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
