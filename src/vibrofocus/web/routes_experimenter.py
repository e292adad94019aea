"""Routes of the experimenter page: participants, calibration, preview, sessions, export.

Everything under ``/api`` and ``/reports`` needs the experimenter token
(``X-Vibrofocus-Token`` header, for scripts) or the login cookie (``vf_token``, set by a
one-time login link or the login form; it holds a value derived from the token, never
the token itself).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import secrets
import threading
import time
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi import Path as FPath
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response

from .._db_files import calibrations_dir
from ..errors import StudyError, VibrofocusError
from ..studies.session_status import SESSION_ACTIONS, action_status
from .api_models import MAX_ID, AnalysisIn, CalibrationId, CalibrationIn, ParticipantIn, SessionId, SessionIn
from .public_text import public_text
from .state import TOKEN_COOKIE, CalibrationCancelled, CalibrationJob, WebState, login_cookie, private_dir, render_template, trial_position
from .routes_participant import planned
from .throttle import THROTTLED_MESSAGE, counts_as_guess

log = logging.getLogger(__name__)

router = APIRouter()


def _web(request: Request) -> WebState:
    return request.app.state.web


def require_token(request: Request) -> WebState:
    """Dependency: the app state, after checking the experimenter token."""
    web = _web(request)
    web.check_token(request)
    return web


def _study_error(exc: StudyError, status: int = 409) -> HTTPException:
    return HTTPException(status, detail=public_text(str(exc)))


# ---------------------------------------------------------------------- page and login
def _logged_in(web: WebState) -> Response:
    """Set the login cookie and go to the experimenter page."""
    resp = RedirectResponse("/", status_code=303)
    # A random id per login (logout revokes it). HttpOnly: no script can read it;
    # SameSite=Strict: no other site's page sends it (other local ports are refused by
    # the origin checks of web.security).
    resp.set_cookie(TOKEN_COOKIE, web.logins.new(), httponly=True, samesite="strict", path="/")
    return resp


def _wrong_secret(web: WebState, request: Request, kind: str, given: str, message: str) -> Response:
    """The login page for a wrong secret of ``kind``: 401, or 429 while this client is throttled.

    The wrong secret counts (see :mod:`.throttle`) unless another site's page sent it.
    """
    wait = web.throttle.retry_after(_client(request), kind)
    if wait is not None:
        resp = _login_page(THROTTLED_MESSAGE, status=429)
        resp.headers["Retry-After"] = str(wait)
        return resp
    if given and counts_as_guess(request.headers.get("sec-fetch-site")):
        web.throttle.failed(_client(request), kind)
    return _login_page(message)


def _client(request: Request) -> str:
    return request.client.host if request.client is not None else "unknown"


def _login_page(message: str = "", status: int = 401) -> HTMLResponse:
    return HTMLResponse(render_template("login.html", message=message), status_code=status)


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def experimenter_page(request: Request) -> Response:
    """The experimenter page, or the login page when not logged in."""
    web = _web(request)
    if not web.cookie_ok(request.headers.get("cookie")):
        return _login_page()
    from ..rendering.registry import available_methods

    # The preview lists the registry's methods: a lab's own appear beside the built-in ones.
    return HTMLResponse(render_template("experimenter.html", rig=web.rig_kind, rig_label=web.rig_label,
                                        methods=available_methods()))


@router.get("/login/{code}", include_in_schema=False)
def login_link(request: Request, code: str = FPath(..., max_length=64)) -> Response:
    """Exchange a one-time login link printed by ``vibrofocus serve`` for the login cookie."""
    web = _web(request)
    if not web.use_login_code(code):
        return _wrong_secret(web, request, "login-link", code, (
            "That login link has been used already or has expired. Log in with the experimenter token instead."))
    return _logged_in(web)


@router.post("/login", include_in_schema=False)
async def login_form(request: Request) -> Response:
    """The login form: the experimenter token in a POST body (never in a URL)."""
    from urllib.parse import parse_qs

    web = _web(request)
    try:
        fields = parse_qs((await request.body()).decode("utf-8", "replace"), max_num_fields=4)
    except ValueError:  # more fields than the form has
        return _login_page("The login form was not filled in as expected. Reload the page and try again.", status=400)
    given = (fields.get("token") or [""])[0].strip()
    if not web.token_ok(given):
        return _wrong_secret(web, request, "token", given,
                             "That is not the experimenter token this server printed. Check it and try again.")
    return _logged_in(web)


@router.post("/logout", include_in_schema=False)
def logout(request: Request) -> Response:
    """End this login on the server (its cookie stops working everywhere) and forget it here."""
    _web(request).logins.revoke(login_cookie(request.headers.get("cookie")))
    resp = RedirectResponse("/", status_code=303)
    resp.delete_cookie(TOKEN_COOKIE, path="/", httponly=True, samesite="strict")
    return resp


# ---------------------------------------------------------------------- participants and rigs
@router.get("/api/participants")
def list_participants(web: WebState = Depends(require_token)) -> list[dict[str, Any]]:
    """All participants with their calibrations and sessions."""
    with web.db:
        people = web.store.participants()
        out = []
        for p in people:
            cals = web.store.calibrations(p.participant_id)
            out.append({
                **dataclasses.asdict(p),
                "calibrations": [{"calibration_id": c.calibration_id, "created_at": c.created_at} for c in cals],
            })
    return out


@router.post("/api/participants", status_code=201)
def add_participant(body: ParticipantIn, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """Register a participant (returns the existing one if the id is known)."""
    try:
        with web.db:
            info = web.store.add_participant(body.participant_id, simulated=body.simulated)
    except StudyError as exc:
        raise _study_error(exc) from None
    return dataclasses.asdict(info)


@router.get("/api/rigs")
def list_rigs(web: WebState = Depends(require_token)) -> dict[str, Any]:
    """The rig kinds this server can use, its own rig first, and how it is shown."""
    return {"kinds": web.rig_kinds, "default": web.rig_kind, "label": web.rig_label}


@router.get("/api/rigs/straps")
def read_straps(
    rig: str = Query(..., min_length=1, max_length=32),
    seed: int | None = Query(None, ge=0, le=2**32 - 1),
    web: WebState = Depends(require_token),
) -> dict[str, Any]:
    """Read the strap forces of a rig now, with a verdict per strap and one line to show."""
    from ..rigs.force import check_straps, has_strap_sensors

    r = web.make_rig(rig, seed)
    if not has_strap_sensors(r):
        raise HTTPException(409, detail=f"The {rig} rig has no strap force sensors; check the straps by hand before calibrating.")
    try:
        reading = check_straps(r)
    except VibrofocusError as exc:
        raise HTTPException(409, detail=f"The strap forces could not be read: {exc}") from None
    return {**reading.to_dict(), "message": reading.message}


def _check_participant(web: WebState, participant_id: str) -> None:
    with web.db:
        try:
            web.store.participant(participant_id)
        except StudyError:
            raise HTTPException(404, detail=f"unknown participant {participant_id!r}; add the participant first") from None


# ---------------------------------------------------------------------- calibration
@router.post("/api/calibrations", status_code=202)
def start_calibration(body: CalibrationIn, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """Calibrate a participant on a rig in the background; poll the returned job."""
    _check_participant(web, body.participant_id)
    rig = web.make_rig(body.rig, _rig_seed(body.rig, body.seed, body.participant_id))
    _refuse_if_busy(rig)
    _plan(rig, body.points)  # a subset the layout cannot give is refused now, not in the job
    job = CalibrationJob(job_id=secrets.token_hex(8), participant_id=body.participant_id, rig=body.rig,
                         points=body.points, _rig=rig)
    with web.lock:
        busy = [j for j in web.jobs.values() if j.status in ("running", "waiting")]
        if busy:
            raise HTTPException(409, detail=f"calibration {busy[0].job_id} of {busy[0].participant_id} is still running; wait for it")
        web.jobs[job.job_id] = job
    web.start_job(_calibrate, web, job, rig, name=f"calibration-{job.job_id}")
    return {"job_id": job.job_id}


def _plan(rig: Any, points: int | None) -> Any:
    """The calibration plan measuring ``points`` points (None: all), or 422 saying why not."""
    from ..calibration import plan_calibration

    try:
        return plan_calibration(rig, measure=points)
    except VibrofocusError as exc:
        raise HTTPException(422, detail=public_text(str(exc))) from None


@router.get("/api/calibrations/plans")
def calibration_plans(
    rig: str = Query(..., min_length=1, max_length=32),
    seed: int | None = Query(None, ge=0, le=2**32 - 1),
    web: WebState = Depends(require_token),
) -> dict[str, Any]:
    """The calibration plans the page offers: every point, or a subset with the rest predicted.

    ``{"plans": [{"points": K or None, "label", "description", "measured": [labels],
    "predicted": [labels], "aims_saved", "seconds_saved"}]}``: every point first, then
    9, 7 and 5 points (those the layout has).
    """
    from ..calibration.plan import MIN_MEASURED_POINTS

    r = web.make_rig(rig, seed)
    labels = r.layout.point_labels
    n = r.layout.n_points
    plans = []
    for k in [None, *(k for k in (9, 7, 5) if MIN_MEASURED_POINTS <= k < n)]:
        plan = _plan(r, k)
        measured = [labels[i] for i in plan.point_indices]
        predicted = [labels[i] for i in plan.predicted_indices]
        plans.append({
            "points": k, "label": f"all {n} points" if k is None else f"{k} points, predict {n - k}",
            "description": plan.describe(), "measured": measured, "predicted": predicted,
            "aims_saved": plan.positions_saved, "seconds_saved": plan.seconds_saved})
    return {"plans": plans}


def _rig_seed(rig: str, seed: int | None, participant_id: str) -> int | None:
    """The simulated forearm's seed: the one given, else derived from the participant id.

    As ``vibrofocus calibrate --rig simulated`` does: each participant gets an arm of
    their own, and the same one every time. Hardware rigs take no seed.
    """
    if seed is not None or rig != "simulated":
        return seed
    from ..defaults import participant_seed

    return participant_seed(participant_id)


#: What makes one simulated forearm another, as a calibration file's ``rig`` records it.
_ARM_KEYS = ("seed", "skin", "geometry")


def _calibration_arm(web: WebState, calibration_id: int, given: int | None, participant_id: str) -> int | None:
    """The seed of the simulated forearm a session on this calibration plays on: the calibration's own.

    The drives are designed from the calibration's transfer, so they play on the arm it
    was measured on (and a simulated participant feels that arm): no seed given takes
    the calibration's; another seed is refused (422). A calibration measured on hardware
    has no simulated arm: a simulated participant's session on it is refused (409); a
    person's rehearsal on the simulated rig keeps the seed rule of a dry run. An arm this
    server cannot build again (another ``serve --skin``) is refused (409).
    """
    made_on = getattr(web.calibration(calibration_id), "rig", None) or {}
    if made_on.get("kind") != "simulated" or made_on.get("seed") is None:
        if web.is_simulated(participant_id):
            raise HTTPException(409, detail=(
                f"Calibration {calibration_id} was not made on the simulated rig, so it has no simulated forearm for "
                f"the simulated participant {participant_id} to feel. Calibrate {participant_id} on the simulated rig."))
        return _rig_seed("simulated", given, participant_id)
    seed = int(made_on["seed"])
    if given is not None and int(given) != seed:
        raise HTTPException(422, detail=(
            f"Calibration {calibration_id} was made on the simulated forearm of seed {seed}, and a session on it "
            f"plays on that forearm; the rig seed {given} would be another arm. Leave the seed empty or give {seed}."))
    arm = web.make_rig("simulated", seed)
    describe = getattr(arm, "describe", None)
    built = describe() if callable(describe) else {}
    differs = [k for k in _ARM_KEYS if k in made_on and k in built and made_on[k] != built[k]]
    if differs:
        what = ", ".join(f"{k} {made_on[k]!r} (this server's: {built[k]!r})" for k in differs)
        raise HTTPException(409, detail=(
            f"Calibration {calibration_id} was made on a simulated forearm this server does not build: {what}. "
            "Restart 'vibrofocus serve' with that --skin, or calibrate again."))
    return seed


def _refuse_if_busy(rig: Any) -> None:
    """409 when a hardware job holds the rig (one job uses a device at a time)."""
    busy = getattr(rig, "busy_with", None) if getattr(rig, "one_job_at_a_time", False) else None
    if busy:
        raise HTTPException(409, detail=f"The {rig.kind} rig is busy with {busy}. Wait until it ends, or stop it first.")


class _JobProgress:
    """The calibration workflow's :class:`~vibrofocus.workflows.Progress` as the job's live card."""

    def __init__(self, job: CalibrationJob):
        self.job = job

    def step(self, done: int, total: int, message: str) -> None:
        if total:
            self.job.progress = float(done) / float(total)
        self.job.message = message

    def note(self, message: str, **details: Any) -> None:
        reading = details.get("straps")
        if reading is not None:  # shown before the first sweep, so loose straps are seen now
            self.job.straps = {**reading.to_dict(), "message": reading.message}

    def judged(self, result: Any) -> None:
        pass

    def cancelled(self) -> bool:
        return self.job.cancelled

    def aim(self, label: str, xy: Any) -> None:
        self.job.wait_for_experimenter(
            f"Aim the vibrometer at point {label} (x {xy[0] * 1e3:+.1f} mm, y {xy[1] * 1e3:+.1f} mm), then press Continue."
        )

    def begin_saving(self) -> None:
        # The point of no return: a cancel until here (a stop during the estimation too)
        # saves nothing; from here on the calibration is saved and a cancel is refused.
        self.job.begin_saving()
        self.job.message = "saving"


def _calibrate(web: WebState, job: CalibrationJob, rig: Any) -> None:
    from ..workflows import calibrate_participant

    card = _JobProgress(job)
    try:
        private_dir(web.data_dir)  # the files folder, then its calibrations/ (_db_files)
        folder = calibrations_dir(web.db_path)
        private_dir(folder)
        # .nc, as the CLI's: the file is netCDF4 (docs/file-formats.md).
        path = folder / f"{job.participant_id}-{time.strftime('%Y%m%d-%H%M%S')}-{job.job_id[:6]}.nc"
        done = calibrate_participant(rig, job.participant_id, path, points=job.points, progress=card, aim=card.aim,
                                     before_saving=card.begin_saving, store=web.store, store_lock=web.db)
        cal = done.calibration
        with web.lock:
            web.calibrations[done.calibration_id] = cal
        job.calibration_id = done.calibration_id
        job.verdicts = _verdicts(cal)
        job.n_errors = sum(v["severity"] == "error" for v in job.verdicts)
        job.progress = 1.0
        job.message = "done" if not job.n_errors else f"done, with {job.n_errors} error verdict(s)"
        job.status = "done"
    except Exception as exc:  # noqa: BLE001 - shown on the experimenter page
        if isinstance(exc, CalibrationCancelled) or job.cancelled:
            # Cancelled, whatever the cancel interrupted: the emergency stop stops the rig
            # too, so a recording ends with the rig's "stopped" error; that is the cancel.
            job.status = "cancelled"
            job.message = "cancelled: nothing was saved"
            log.info("calibration %s of %s cancelled: nothing was saved", job.job_id, job.participant_id)
            return
        job.status = "failed"
        if isinstance(exc, VibrofocusError):
            job.error = public_text(str(exc))
        else:  # a bug: the trace goes to the terminal, not to the page
            log.exception("calibration %s failed", job.job_id)
            job.error = "an unexpected error; the terminal running 'vibrofocus serve' says why"
        job.message = "failed"


@router.get("/api/calibrations/jobs/{job_id}")
def calibration_job(job_id: str, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """Progress of a calibration job."""
    return _job(web, job_id).to_dict()


def _job(web: WebState, job_id: str) -> CalibrationJob:
    job = web.jobs.get(job_id)
    if job is None:
        raise HTTPException(404, detail="There is no such calibration.")
    return job


@router.post("/api/calibrations/jobs/{job_id}/{action}")
def calibration_step(job_id: str, action: str, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """``continue`` (the vibrometer is aimed at the point asked for) or ``cancel`` a calibration."""
    job = _job(web, job_id)
    if action == "continue":
        if job.status != "waiting":
            raise HTTPException(409, detail="This calibration is not waiting for you.")
        job.go_on()
    elif action == "cancel":
        if job.status not in ("running", "waiting"):
            raise HTTPException(409, detail=f"This calibration has already ended ({job.status}).")
        if not job.cancel():
            raise HTTPException(409, detail=(
                "This calibration's recordings are finished and it is being saved: it can no longer be cancelled."))
    else:
        raise HTTPException(404, detail="Unknown calibration action; use continue or cancel.")
    return job.to_dict()


def _verdicts(cal: Any) -> list[dict[str, str]]:
    """A calibration's quality verdicts, errors first: ``[{"severity", "check", "message"}]``."""
    order = {"error": 0, "warning": 1, "info": 2}
    issues = sorted(cal.quality.issues, key=lambda i: order.get(i.severity, 3))
    return [{"severity": i.severity, "check": i.check, "message": public_text(i.message)} for i in issues]


def _calibration_errors(web: WebState, calibration_id: int) -> list[str]:
    """The error verdicts of a calibration (dead or reversed actuator, clipping, ...), as sentences."""
    return [v["message"] for v in _verdicts(web.calibration(calibration_id)) if v["severity"] == "error"]


def _refuse_calibration_errors(web: WebState, calibration_id: int, allowed: bool) -> list[str]:
    """409 when a calibration has error verdicts and the experimenter has not accepted them; the errors."""
    errors = _calibration_errors(web, calibration_id)
    if errors and not allowed:
        raise HTTPException(409, detail=(
            f"Calibration {calibration_id} has {len(errors)} error verdict(s): {' '.join(errors)} "
            "Fix the setup and calibrate again, or use it anyway by ticking 'use despite its errors' "
            "(allow_calibration_errors)."))
    return errors


@router.get("/api/calibrations/{calibration_id}/quality")
def calibration_quality(calibration_id: CalibrationId, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """The quality verdicts of a calibration (errors first), how many are errors, and which
    points were measured and which predicted by the fitted skin model (labels)."""
    cal = web.calibration(calibration_id)
    verdicts = _verdicts(cal)
    labels = cal.layout.point_labels
    return {"calibration_id": calibration_id, "verdicts": verdicts,
            "n_errors": sum(v["severity"] == "error" for v in verdicts),
            "measured": [label for label, m in zip(labels, cal.measured_points) if m],
            "predicted": [labels[i] for i in cal.predicted_points]}


@router.get("/api/calibrations/{calibration_id}/figure.png")
def calibration_figure(calibration_id: CalibrationId, web: WebState = Depends(require_token)) -> Response:
    """|H| and coherence of a calibration (PNG)."""
    from .figures import calibration_png

    return Response(calibration_png(web.calibration(calibration_id)), media_type="image/png")


@router.get("/api/preview.png")
def preview(
    calibration_id: int = Query(..., ge=1, le=MAX_ID),
    method: str = Query(..., min_length=1, max_length=32),
    location: int = Query(..., ge=1),
    web: WebState = Depends(require_token),
) -> Response:
    """Drive signals and predicted field of one method at one location (PNG)."""
    from ..rendering.registry import available_methods
    from .figures import preview_png

    known = available_methods()
    if method not in known:
        raise HTTPException(422, detail=f"unknown method {method!r}; known: {', '.join(known)}")
    cal = web.calibration(calibration_id)
    n_loc = cal.layout.n_locations
    if location > n_loc:
        raise HTTPException(422, detail=f"location {location} is outside the calibrated locations 1-{n_loc}")
    try:
        rendering = web.bank(calibration_id).rendering(method, location)
    except VibrofocusError as exc:
        raise HTTPException(422, detail=str(exc)) from None
    return Response(preview_png(rendering, cal.layout, cal.fs, method=method, location=location), media_type="image/png")


# ---------------------------------------------------------------------- sessions
def _session_out(web: WebState, session_id: int) -> dict[str, Any]:
    info = web.session(session_id)
    runner = web.runner(session_id)
    info["live"] = runner.snapshot() if runner is not None else None
    if info["live"] is not None:
        info["live"].update(trial_position(planned(web, session_id), info["live"].get("trial_index")))
    info["dry_run"] = info.get("calibration_id") is None
    info["participant_url"] = f"/participant/{session_id}?key={web.participant_key(session_id)}"
    info["staircase"] = _staircase_out(web, session_id)
    return info


def _staircase_out(web: WebState, session_id: int) -> dict[str, Any] | None:
    """A threshold session's staircase and threshold (web/protocols.py); None for other sessions."""
    from .protocols import staircase_state

    with web.db:
        return staircase_state(web.store, web.store.session(session_id))


@router.get("/api/sessions")
def list_sessions(participant_id: str | None = Query(None, max_length=64), web: WebState = Depends(require_token)) -> list[dict[str, Any]]:
    """Sessions (of one participant, if given), with progress and participant link."""
    try:
        with web.db:
            ids = [s.session_id for s in web.store.sessions(participant_id)]
    except StudyError as exc:
        raise _study_error(exc, 404) from None
    return [_session_out(web, sid) for sid in ids]


@router.post("/api/sessions", status_code=201)
def create_session(body: SessionIn, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """Plan a session: the full trial list is stored; it starts with ``/start``."""
    from ..rigs import RIG_KINDS

    if body.rig not in RIG_KINDS:
        raise HTTPException(422, detail=f"Unknown rig {body.rig!r}; this server knows: {', '.join(RIG_KINDS)}.")
    web.check_rig_kind(body.rig)
    _check_participant(web, body.participant_id)
    accepted: list[str] = []
    if body.calibration_id is not None:
        web.calibration(body.calibration_id)  # 404 / 409 before anything is written
        accepted = _refuse_calibration_errors(web, body.calibration_id, body.allow_calibration_errors)
    if web.is_simulated(body.participant_id) and (body.calibration_id is None or body.rig != "simulated"):
        raise HTTPException(409, detail=(
            f"{body.participant_id} is a simulated participant: the perceptual model answers their sessions from what the "
            "simulated forearm feels, so plan it with a calibration on the simulated rig."))
    if body.calibration_id is not None and body.rig == "simulated":
        rig_seed = _calibration_arm(web, body.calibration_id, body.rig_seed, body.participant_id)
    else:
        rig_seed = _rig_seed(body.rig, body.rig_seed, body.participant_id)
    if body.protocol is not None:
        return _create_protocol_session(web, body, rig_seed, accepted)
    if body.study is None:
        raise HTTPException(422, detail="Give the study (1 or 2), or a protocol and its block.")
    config: dict[str, Any] = {"rig": body.rig, "rig_seed": rig_seed}
    if body.repetitions is not None:
        config["repetitions"] = body.repetitions
    if body.n_training is not None:
        config["n_training"] = body.n_training
    if accepted:
        config["calibration_errors_accepted"] = accepted  # the record of the override
    if body.levels is not None:
        config["levels"] = body.levels
    if body.point:
        if body.study != 1:
            raise HTTPException(422, detail="A point answer stands for one location: plan it as study 1.")
        config["point"] = True
        if body.calibration_id is not None:  # the picture the participant points on: this arm's layout
            config["layout"] = web.calibration(body.calibration_id).layout.to_dict()
    seed = body.seed if body.seed is not None else secrets.randbelow(2**31)
    try:
        renderer = None
        if body.calibration_id is not None:
            # Every stimulus now: a design that cannot fit this participant is refused when the
            # session is planned, never mid-study.
            from ..studies.protocol import StudyDesign

            renderer = web.bank(body.calibration_id, levels=StudyDesign.from_config(body.study, config).levels)
        from ..workflows import plan_session

        sid, _ = plan_session(web.store, body.participant_id, body.study, seed=seed,
                              calibration_id=body.calibration_id, config=config, renderer=renderer, store_lock=web.db)
    except StudyError as exc:
        raise _study_error(exc) from None
    return _session_out(web, sid)


def _create_protocol_session(web: WebState, body: SessionIn, rig_seed: int | None, accepted: list[str]) -> dict[str, Any]:
    """Plan a session of a protocol's block (web/protocols.py), as ``study run --protocol`` does."""
    from .protocols import find_protocol, plan_block

    given = [k for k in ("study", "repetitions", "n_training", "levels") if getattr(body, k) is not None]
    if given or body.point:
        raise HTTPException(422, detail=(f"The protocol {body.protocol!r} sets the study and the design: leave out "
                                         f"{', '.join(given + (['point'] if body.point else []))}."))
    assert body.protocol is not None
    protocol = find_protocol(web, body.protocol)
    try:
        study, block, config = plan_block(web, protocol, body.participant_id, body.block, body.calibration_id)
        config.update(rig=body.rig, rig_seed=rig_seed)
        if accepted:
            config["calibration_errors_accepted"] = accepted
        seed = protocol.blocks[block].session_seed(body.seed if body.seed is not None else secrets.randbelow(2**31))
        from ..workflows import plan_session

        # The block's levels were checked against the drive limit by plan_block: nothing to render here.
        sid, _ = plan_session(web.store, body.participant_id, study, seed=seed, calibration_id=body.calibration_id,
                              config=config, store_lock=web.db)
    except StudyError as exc:
        raise _study_error(exc) from None
    return _session_out(web, sid)


@router.get("/api/sessions/{session_id}")
def get_session(session_id: SessionId, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """A session with its live state and its answers so far."""
    out = _session_out(web, session_id)
    with web.db:
        trials = web.store.planned_trials(session_id)
        answers = web.store.answers(session_id)
    out["answers"] = [
        {
            "trial_index": a.trial_index, "phase": trials[a.trial_index].phase, "trial": trials[a.trial_index].trial,
            "method": trials[a.trial_index].method, "target": trials[a.trial_index].target,
            "response": list(a.response), "rt_s": a.rt_s, "recorded_at": a.recorded_at,
        }
        for a in answers
    ]
    return out


@router.post("/api/sessions/{session_id}/{action}")
def session_action(session_id: SessionId, action: str, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """``start``, ``pause``, ``resume`` or ``stop`` a session.

    Which control applies to which status is the session state machine's
    (:func:`~vibrofocus.studies.session_status.action_status`). The status is stored
    first and the runner follows it, except for a stop: the runner has ended before
    ``aborted`` is stored, so that it cannot write a status after the stop's.
    """
    if action not in SESSION_ACTIONS:
        raise HTTPException(404, detail=f"unknown session action {action!r}; use start, pause, resume or stop")
    info = web.session(session_id)
    if info["status"] == "aborted" and action != "stop":
        raise HTTPException(409, detail=(
            f"Session {session_id} was aborted, and an abort is final. To go on with this participant, plan a new session."))
    try:
        status = action_status(action, session_id, info["status"])
        if status == "running" and info.get("calibration_id") is not None:
            web.calibration(int(info["calibration_id"]))  # its hash, before anything plays
            # Error verdicts: only with the override recorded when the session was planned.
            _refuse_calibration_errors(web, int(info["calibration_id"]),
                                       bool((info.get("config") or {}).get("calibration_errors_accepted")))
        if status == "aborted":
            with web.lock:
                web.aborted.add(session_id)  # before the pop: nothing builds it a runner again
                runner = web.runners.pop(session_id, None)
            if runner is not None:
                runner.stop()
        elif status == "running":
            runner = web.runner(session_id, create=True)
            if runner is None:
                raise HTTPException(409, detail=f"Session {session_id} is being aborted; an abort is final.")
            if runner.rig is not None and not runner.running:
                _refuse_if_busy(runner.rig)  # before the status is stored
        with web.db:
            web.store.set_status(session_id, status)
    except StudyError as exc:
        raise _study_error(exc) from None
    if status == "running":
        runner.resume()
        runner.start()
    elif status == "paused":
        runner = web.runner(session_id)
        if runner is not None:
            runner.pause()
    return _session_out(web, session_id)


@router.post("/api/emergency-stop")
def emergency_stop(request: Request, web: WebState = Depends(require_token)) -> Any:
    """Every output to 0 V now; calibrations cancelled, running sessions paused (resume them later).

    JSON for the page's script; a page saying what stopped for the button's plain form
    (a browser navigating asks for HTML), which works before the script has run.
    """
    from .emergency import stop_all

    stopped = stop_all(web)
    if "text/html" in request.headers.get("accept", ""):
        return HTMLResponse(render_template("stopped.html", stopped=stopped))
    return {"stopped": stopped}


# ---------------------------------------------------------------------- export and analysis
@router.get("/api/export/trials.csv")
def export_trials(participant_id: str | None = Query(None, max_length=64), web: WebState = Depends(require_token)) -> Response:
    """Every answered trial as the docs/file-formats.md, trials file trials file."""
    import shutil
    import tempfile

    folder = web.data_dir / "exports"
    private_dir(folder)
    # Each request writes in a folder of its own (mkdtemp: a unique name, mode 0700) and
    # is served from memory: two exports at once never read each other's file.
    scratch = tempfile.mkdtemp(prefix="trials-", dir=folder)
    try:
        path = os.path.join(scratch, "trials.csv")
        with web.db:
            web.store.export_trials_csv(path, participant_id=participant_id)
        with open(path, "rb") as fh:
            content = fh.read()
    except StudyError as exc:
        raise _study_error(exc, 404 if "unknown participant" in str(exc) else 409) from None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return Response(content, media_type="text/csv",
                    headers={"Content-Disposition": 'attachment; filename="trials.csv"'})


@router.post("/api/analysis", status_code=202)
def run_analysis(body: AnalysisIn | None = None, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """Export the trials and analyse them in the background (what ``vibrofocus analyze`` does), in a child process."""
    name = time.strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)
    job = {"name": name, "status": "running", "rows": 0, "url": f"/reports/{name}/report.html", "log": ""}
    with web.lock:
        # One analysis at a time: each takes a core and memory (pingouin, matplotlib).
        if any(j["status"] == "running" for j in web.analyses.values()):
            raise HTTPException(409, detail="An analysis is already running. Wait for it to finish, then run it again.")
        web.analyses[name] = job
    try:
        private_dir(web.data_dir / "reports")  # ours alone, never a link
        out = web.data_dir / "reports" / name
        out.mkdir(mode=0o700)
        trials = out / "trials.csv"
        with web.db:
            n = web.store.export_trials_csv(trials)
        if n == 0:
            raise HTTPException(409, detail="No answered trials yet: there is nothing to analyse.")
    except BaseException:
        with web.lock:
            web.analyses.pop(name, None)
        raise
    job["rows"] = n

    def work() -> None:
        from .analysis_job import analyse_in_child

        try:
            lines = analyse_in_child(trials, out, kind=body.kind if body is not None else "people")
        except VibrofocusError as exc:
            job["log"] = public_text(f"error: {exc}")[-4000:]
            job["status"] = "failed"
            return
        except Exception:  # a bug or a dead child must not leave the job 'running' forever
            log.exception("analysis %s failed", name)
            job["log"] = "the analysis failed because of an unexpected error; the terminal running 'vibrofocus serve' says why"
            job["status"] = "failed"
            return
        job["log"] = public_text("\n".join(lines))[-4000:]
        job["status"] = "done"

    threading.Thread(target=work, name=f"analysis-{name}", daemon=True).start()
    return job


@router.get("/api/analysis/{name}")
def analysis_job(name: str, web: WebState = Depends(require_token)) -> dict[str, Any]:
    """State of an analysis run."""
    job = web.analyses.get(name)
    if job is None:
        raise HTTPException(404, detail=f"unknown analysis {name!r}")
    return job


@router.get("/reports/{name}/{file_path:path}", include_in_schema=False)
def report_file(name: str, file_path: str, web: WebState = Depends(require_token)) -> FileResponse:
    """Files of an analysis report (HTML, PNG, JSON)."""
    reports = web.data_dir / "reports"
    private_dir(reports)  # a link would serve another folder as the lab's reports
    root = reports.resolve()
    missing = HTTPException(404, detail="There is no such report file.")
    if "\x00" in name or "\x00" in file_path:  # the file system cannot even look such a name up
        raise missing
    target = (root / name / file_path).resolve()
    # Refuse anything that resolves outside the reports folder (../ tricks).
    if root not in target.parents or not target.is_file():
        raise missing
    return FileResponse(target)
