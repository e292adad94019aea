"""Routes of the participant page: the page itself, its state (long-poll) and answers.

Every route needs the session's participant key; nothing here accepts the experimenter
token, so answers can only come from a participant page.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from fastapi import APIRouter, Header, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse

from ..errors import AnswerRefused
from ..studies.session_status import LIVE_STATUSES
from .api_models import AnswerIn, AnswerReceipt, RestartIn, SessionId
from .state import KEY_HEADER, WebState, render_template, trial_position

router = APIRouter()

#: Longest a state request waits for a change, s (the page asks again at once).
MAX_WAIT_S = 10.0


def _web(request: Request) -> WebState:
    return request.app.state.web


def planned(web: WebState, session_id: int) -> list[Any]:
    """The planned trials of a session (immutable once written, so cached)."""
    cache = web.planned
    if session_id not in cache:
        with web.db:
            cache[session_id] = list(web.store.planned_trials(session_id))
    return cache[session_id]


def _live_runner(web: WebState, session_id: int, status: str):
    """The runner of a session the store calls running or paused, built after a restart if needed."""
    runner = web.runner(session_id)
    if runner is None and status in LIVE_STATUSES:
        runner = web.runner(session_id, create=True)
        if runner is None:  # being aborted
            return None
        if status == "paused":
            runner.pause()
        runner.start()
    return runner


def _state(web: WebState, session_id: int) -> dict[str, Any]:
    info = web.session(session_id)
    status = info["status"]
    runner = _live_runner(web, session_id, status)
    snap = runner.snapshot() if runner is not None else {"state": "idle", "trial_index": None, "seq": 0, "paused": False}
    trials = planned(web, session_id)
    index = snap.get("trial_index")
    state = snap["state"]
    if status in ("aborted", "completed"):
        state = "done" if status == "completed" else "stopped"
    elif status == "planned" or runner is None:
        state = "waiting"
    return {
        "session_id": session_id,
        "study": int(info["study"]),
        "multi_select": int(info["study"]) == 2,
        "status": status,
        "state": state,
        "seq": snap.get("seq", 0),
        "paused": bool(snap.get("paused")),
        "trial_index": index,
        **trial_position(trials, index),
        "n_trials": len(trials),
        "n_answered": int(info["n_answered"]),
        "error": snap.get("error"),
        "simulated": web.is_simulated(info["participant_id"]),
        "point": bool((info.get("config") or {}).get("point")),
        "detection": is_detection(info),
    }


def is_detection(info: dict[str, Any]) -> bool:
    """Whether a session is a threshold block: its trials ask whether the tap was felt."""
    return (info.get("config") or {}).get("staircase") is not None


@router.get("/participant/{session_id}", response_class=HTMLResponse, include_in_schema=False)
def participant_page(request: Request, session_id: SessionId, key: str = Query("", max_length=64)) -> HTMLResponse:
    """The full-screen participant page of a session (needs ``?key=``)."""
    web = _web(request)
    web.check_key(session_id, key)
    info = web.session(session_id)
    config = info.get("config") or {}
    area = config.get("point_area") if config.get("point") else None
    return HTMLResponse(render_template("participant.html", session_id=session_id, study=int(info["study"]),
                                        area=None if area is None else arm_picture(area),
                                        detection=is_detection(info)))


def arm_picture(area: dict[str, Any]) -> dict[str, Any]:
    """What the page's picture of the arm area draws (an SVG in mm; its y axis points down,
    so the layout's y, toward the wrist, is drawn as -y), from a session's point area."""
    (x0, x1), (y0, y1) = area["x_mm"], area["y_mm"]
    return {
        "view_box": f"{x0:g} {-y1:g} {x1 - x0:g} {y1 - y0:g}",
        "x0": x0, "x1": x1, "y0": y0, "y1": y1, "width": x1 - x0, "height": y1 - y0,
        "locations": [(int(n), float(x), -float(y)) for n, (x, y) in sorted(area["locations_mm"].items(),
                                                                            key=lambda kv: int(kv[0]))],
        "actuators": [(float(x), -float(y)) for x, y in area["actuators_mm"]],
        "unit": max(x1 - x0, y1 - y0) / 100.0,  # 1 % of the picture, mm: strokes and radii scale with it
    }


@router.get("/api/participant/{session_id}/state")
async def participant_state(
    request: Request,
    session_id: SessionId,
    after: int = Query(-1, description="return as soon as seq differs from this"),
    wait: float = Query(0.0, ge=0.0, le=MAX_WAIT_S, description="longest wait for a change, s"),
    ready: bool = Query(False, description="the page can play the beep (its audio is started)"),
    key: str | None = Header(None, alias=KEY_HEADER),
) -> dict[str, Any]:
    """State of the session as the page shows it; long-polls up to ``wait`` s for a change.

    A page that says it is ``ready`` (audio started) counts as present while its
    request is open: the runner holds the next cue until one is, and plays a stimulus
    only while a page whose request has seen the cue (``after`` is the cue's ``seq``)
    is connected.
    """
    web = _web(request)
    web.check_key(session_id, key)
    state = await run_in_threadpool(_state, web, session_id)
    runner = web.runner(session_id)
    token = runner.page_attach(after) if ready and runner is not None else None
    try:
        return await _wait_change(request, web, session_id, state, after, wait)
    finally:
        if token is not None:
            runner.page_detach(token)


async def _wait_change(request: Request, web: WebState, session_id: int, state: dict[str, Any], after: int, wait: float) -> dict[str, Any]:
    deadline = time.monotonic() + wait
    first = web.runner(session_id)
    # The runner's seq changes on every step of a trial; polling the in-memory runner
    # every 40 ms keeps the beep within a frame or two of the cue without a thread per client.
    while state["seq"] == after and time.monotonic() < deadline:
        await asyncio.sleep(0.04)
        runner = web.runner(session_id)
        if runner is not first or (runner is not None and runner.snapshot()["seq"] != after):
            # A stop (runner gone) or a restart (new runner) is news too.
            state = await run_in_threadpool(_state, web, session_id)
            break
        if await request.is_disconnected():
            break
    return state


@router.post("/api/participant/{session_id}/restart")
def participant_restart(
    request: Request,
    session_id: SessionId,
    body: RestartIn,
    key: str | None = Header(None, alias=KEY_HEADER),
) -> dict[str, Any]:
    """Present the waiting trial again from "get ready" (the page did not see its onset).

    ``restarted`` is False when that trial no longer waits for an answer; the page then
    simply follows the state it is sent.
    """
    web = _web(request)
    web.check_key(session_id, key)
    if body.session_id != session_id:
        raise HTTPException(422, detail=f"body.session_id {body.session_id} does not match the session {session_id} of the URL")
    runner = web.runner(session_id)
    return {"restarted": bool(runner is not None and runner.restart_trial(body.trial_index))}


#: How the participant page words each refusal of the store (AnswerRefused.reason):
#: (HTTP status, sentence); None: the store's own message. The rules are the store's.
_REFUSALS: dict[str, tuple[int, str | None]] = {
    "invalid": (422, None),
    "unknown_trial": (422, None),
    "answered": (409, "This trial was already answered (perhaps on another screen), so this answer was not recorded."),
    "not_current": (409, "This answer is not for the current trial, so it was not recorded."),
    "not_presented": (409, "This trial has not been presented yet (no stimulus was played), so this answer was not recorded."),
}


#: What a participant page of a simulated participant's session reads.
SIMULATED_MESSAGE = ("This session belongs to a simulated participant: the perceptual model answers it, "
                     "so answers from this page are not recorded.")


@router.post("/api/participant/{session_id}/answer", response_model=AnswerReceipt)
def participant_answer(
    request: Request,
    session_id: SessionId,
    body: AnswerIn,
    key: str | None = Header(None, alias=KEY_HEADER),
) -> AnswerReceipt:
    """Commit one answer; the reply comes only after the commit.

    Idempotent on ``answer_id`` (a re-send gets the same receipt, ``duplicate``). Every
    rule (the current trial, presented, answered once) is the store's
    (:meth:`StudyStore.record_answer`); this route only words its refusals.
    """
    web = _web(request)
    web.check_key(session_id, key)
    if body.session_id != session_id:
        raise HTTPException(422, detail=f"body.session_id {body.session_id} does not match the session {session_id} of the URL")
    info = web.session(session_id)  # 404 for an unknown session
    if info["status"] == "aborted":
        raise HTTPException(409, detail="The experimenter has ended this session, so this answer was not recorded.")
    if web.is_simulated(info["participant_id"]):
        # Its answers are the perceptual model's: one from a person would be stored as model output.
        raise HTTPException(409, detail=SIMULATED_MESSAGE)
    response = None if body.response is None else list(body.response)
    if body.felt is not None:
        if not is_detection(info):
            raise HTTPException(422, detail=f"session {session_id} asks where the tap was felt, not whether; "
                                            "answer locations")
        response = [int(body.felt)]  # stored as a threshold block's answer: 1 felt, 0 not felt
    try:
        receipt = web.store.record_answer(
            session_id, body.trial_index, response, float(body.rt_s),
            answer_id=body.answer_id, require_presented=True,
            point_mm=None if body.point_mm is None else [float(v) for v in body.point_mm],
        )
    except AnswerRefused as exc:
        status, words = _REFUSALS.get(exc.reason, (409, None))
        raise HTTPException(status, detail=words or str(exc)) from None
    runner = web.runner(session_id)
    if runner is not None:
        runner.notify_answer(receipt.trial_index, receipt)
    nxt = web.store.next_trial(session_id)
    return AnswerReceipt(
        session_id=session_id, trial_index=receipt.trial_index, answer_id=receipt.answer_id,
        response=list(receipt.response), duplicate=receipt.duplicate,
        point_mm=None if receipt.point_mm is None else list(receipt.point_mm),
        next_trial_index=None if nxt is None else nxt.trial_index,
    )
