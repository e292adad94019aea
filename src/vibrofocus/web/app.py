"""The FastAPI application: one factory and the access checks (the shared state is in :mod:`.state`).

Two kinds of client talk to the app:

- the experimenter page, which holds the experimenter token (printed by ``vibrofocus
  serve``; sent as the ``X-Vibrofocus-Token`` header or the ``vf_token`` cookie);
- the participant page of one session, which holds that session's participant key
  (in its URL; sent as the ``X-Participant-Key`` header). The key is an HMAC of the
  session id under a secret kept next to the database, so a participant link keeps
  working after a server restart and cannot be guessed from the session id. The key
  lets the page read its state and answer, nothing else; the token cannot answer.
"""

from __future__ import annotations

import logging
import os
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from ..errors import StudyError
from . import routes_experimenter, routes_participant, routes_protocols
from .security import BODY_TIMEOUT_S, LOCAL_HOSTS, SecurityMiddleware
from .session_runner import PACES, Pace
from .state import (
    KEY_HEADER,
    TOKEN_COOKIE,
    TOKEN_HEADER,
    WebState,
    load_or_make_secret,
    plain_problem,
    private_journal,
    render_template,
)
from .private import private_database
from .public_text import public_text

__all__ = ["create_app", "render_template", "WebState", "TOKEN_HEADER", "TOKEN_COOKIE", "KEY_HEADER"]

_HERE = Path(__file__).parent

log = logging.getLogger(__name__)

def create_app(
    db_path: str | os.PathLike,
    *,
    token: str,
    rig: str = "simulated",
    pace: str | Pace = "normal",
    rig_factory: Any = None,
    rig_config: str | os.PathLike | None = None,
    resume: bool = True,
    allowed_hosts: tuple[str, ...] = (),
    body_timeout_s: float = BODY_TIMEOUT_S,
    stop_socket: bool = False,
) -> FastAPI:
    """Build the web app.

    Parameters
    ----------
    db_path : path-like
        The study database (SQLite), created if missing.
    token : str
        The experimenter token; at least 16 characters.
    rig : str
        The rig of this server (``simulated``, ``audio``, ``nidaq``); a hardware rig
        needs ``rig_config``. The simulated forearm stays available for rehearsals.
    pace : {"normal", "fast"} or Pace
        Trial timing; ``fast`` for tests and demonstrations.
    rig_factory : callable, optional
        ``rig_factory(kind, seed=..., [config=...]) -> Rig``; default
        :func:`vibrofocus.rigs.make_rig`.
    rig_config : path-like, optional
        The hardware rig's config file (``.toml``/``.json``, see ``examples/rigs/``).
    resume : bool
        Restart the sessions stored as running when the app starts.
    allowed_hosts : tuple of str
        Host names the server answers to besides 127.0.0.1, localhost and ::1 (the
        ``--host`` it is bound to); requests naming any other host are refused.
    body_timeout_s : float
        Longest wait for a whole request body, s; a body that does not come in time gets 408.
    stop_socket : bool
        While the app runs, be the one server of this database and answer ``vibrofocus
        stop`` on an owner-only Unix socket beside it (:class:`.emergency.ServerGuard`);
        the app does not start if either fails. ``vibrofocus serve`` does the same itself,
        before it prints how to stop it.

    Returns
    -------
    FastAPI
        With ``app.state.web`` the :class:`WebState`.

    Raises
    ------
    StudyError
        The database, its journals, secret, list of logins or files folder is a link,
        another user's or writable by other users, or the database is in a folder other
        users can write in.
    """
    from ..studies import StudyStore

    if not isinstance(token, str) or len(token) < 16:
        raise ValueError("token must be a string of at least 16 characters")
    if isinstance(pace, str):
        if pace not in PACES:
            raise ValueError(f"pace must be one of {', '.join(PACES)}, got {pace!r}")
        pace = PACES[pace]
    db_path = Path(db_path).resolve()
    db_path.parent.mkdir(parents=True, exist_ok=True)
    # Before SQLite opens them: the database, its journals, logins and files folder are
    # this user's alone, in a folder no other user can write in (docs/security.md).
    private_database(db_path)
    secret = load_or_make_secret(db_path)
    store = StudyStore(db_path)
    private_journal(db_path)
    state = WebState(
        store=store, db_path=db_path, token=token, secret=secret,
        rig_kind=rig, pace=pace, rig_factory=rig_factory, rig_config=rig_config,
    )

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        guard = None
        if stop_socket:
            from .emergency import ServerGuard

            guard = ServerGuard(state)
            guard.claim()
            try:
                guard.open_stop_socket()
            except BaseException:
                guard.close()
                raise
        if resume:
            started = state.resume_running_sessions()
            if started:
                log.warning("resumed sessions %s at their first unanswered trial", started)
        yield
        state.shutdown()
        if guard is not None:
            guard.close()  # after the shutdown: 'vibrofocus stop' answers until the end
        close = getattr(store, "close", None)
        if close is not None:
            close()

    app = FastAPI(title="vibrofocus", lifespan=lifespan, docs_url=None, redoc_url=None, openapi_url=None)
    app.state.web = state
    app.add_middleware(SecurityMiddleware, web=state, allowed_hosts=(*LOCAL_HOSTS, *allowed_hosts),
                       body_timeout_s=body_timeout_s)
    app.mount("/static", StaticFiles(directory=str(_HERE / "static")), name="static")

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        # One plain sentence per problem ("Repetitions must be at most 10.") instead of
        # pydantic's nested structure and wording.
        problems = [plain_problem(err) for err in exc.errors()]
        return JSONResponse(status_code=422, content={"detail": " ".join(problems) or "This request is not valid."})

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        # Messages of the layers below may name files by their absolute paths.
        detail = public_text(exc.detail) if isinstance(exc.detail, str) else exc.detail
        return JSONResponse(status_code=exc.status_code, content={"detail": detail}, headers=getattr(exc, "headers", None))

    @app.exception_handler(StudyError)
    async def _study_error(request: Request, exc: StudyError) -> JSONResponse:
        return JSONResponse(status_code=409, content={"detail": public_text(str(exc))})

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        # The trace goes to the server's log, never to a page.
        log.error("unexpected error on %s %s", request.method, request.url.path, exc_info=exc)
        return JSONResponse(status_code=500, content={"detail": (
            "The server could not do this because of an unexpected error; the terminal running "
            "'vibrofocus serve' says why.")})

    app.include_router(routes_participant.router)
    app.include_router(routes_experimenter.router)
    app.include_router(routes_protocols.router)
    return app
