"""The session state machine: a session's statuses and the changes allowed between them.

One home for these rules: the store checks every change against them
(:meth:`StudyStore.set_status` and the automatic changes of
:meth:`StudyStore.record_answer`), the study engine asks the store for its changes, and
the web app maps the experimenter's buttons (start, pause, resume, stop) onto them
with :func:`action_status`.

Statuses
--------
``planned``
    Created, nothing answered yet.
``running``
    Trials are being presented.
``paused``
    Held by the experimenter or the participant; resumes at the first unanswered trial.
``aborted``
    Stopped by the experimenter; every answer is kept and the session may be resumed.
``completed``
    Every planned trial is answered; final.
"""

from __future__ import annotations

from ..errors import StudyError

__all__ = [
    "SESSION_STATUSES",
    "TRANSITIONS",
    "SESSION_ACTIONS",
    "LIVE_STATUSES",
    "check_transition",
    "transition_event",
    "status_after_answer",
    "action_status",
]

SESSION_STATUSES = ("planned", "running", "paused", "aborted", "completed")

#: Status -> the statuses it may become (setting the current status again is a no-op).
#: ``completed`` is reached only once every planned trial is answered (a guard, checked
#: by :func:`check_transition`), and it is final: a finished session cannot be reopened.
TRANSITIONS: dict[str, tuple[str, ...]] = {
    "planned": ("running", "paused", "aborted", "completed"),
    "running": ("paused", "aborted", "completed"),
    "paused": ("running", "aborted", "completed"),
    "aborted": ("running", "paused", "completed"),
    "completed": (),
}

# The event logged for each new status (a planned session that runs is a "start").
_EVENT_OF = {"running": "resume", "paused": "pause", "aborted": "abort", "completed": "complete"}

#: Statuses of a session that has a trial loop (presenting, or held by a pause): after a
#: server restart its loop is rebuilt, and goes on at the first unanswered trial.
LIVE_STATUSES = ("running", "paused")

#: The experimenter's controls of a session (the web app's buttons).
SESSION_ACTIONS = ("start", "pause", "resume", "stop")


def check_transition(session_id: int, old: str, new: str, *, n_answered: int, n_trials: int) -> None:
    """Refuse a status change the state machine does not allow.

    Parameters
    ----------
    session_id : int
        The session, for the message.
    old, new : str
        Its current and requested status.
    n_answered, n_trials : int
        Answered and planned trials of the session (``completed`` needs all answered).

    Raises
    ------
    StudyError
        ``new`` is not a status, the change is not in :data:`TRANSITIONS`, or
        ``completed`` is requested before every trial is answered.
    """
    if new not in SESSION_STATUSES:
        raise StudyError(f"status must be one of {', '.join(SESSION_STATUSES)}; got {new!r}")
    if old == new:
        return
    if old == "completed":
        raise StudyError(f"session {session_id} is completed; its status cannot become {new!r}")
    if new == "planned":
        raise StudyError(f"session {session_id} cannot go back to 'planned'")
    if new not in TRANSITIONS[old]:  # pragma: no cover - every other change is allowed today
        raise StudyError(f"session {session_id} cannot change from {old!r} to {new!r}")
    if new == "completed" and n_answered < n_trials:
        raise StudyError(f"session {session_id} cannot be completed: {n_answered} of {n_trials} trials answered")


def transition_event(old: str, new: str) -> str:
    """The event kind logged when a session changes from ``old`` to ``new``."""
    return "start" if (old, new) == ("planned", "running") else _EVENT_OF[new]


def status_after_answer(old: str, *, finished: bool) -> str:
    """A session's status once an answer is committed.

    The answer to the last planned trial completes the session; the first answer to a
    planned session starts it; otherwise the status stays (an answer to a stimulus felt
    just before a pause or a stop is data, and changes nothing).
    """
    if finished:
        return "completed"
    return "running" if old == "planned" else old


def action_status(action: str, session_id: int, status: str) -> str:
    """The status an experimenter's control leads to, or why it is refused.

    Parameters
    ----------
    action : {"start", "pause", "resume", "stop"}
        The control.
    session_id : int
        The session, for the message.
    status : str
        Its current status.

    Returns
    -------
    str
        The new status: ``running`` (start, resume), ``paused`` or ``aborted`` (stop).

    Raises
    ------
    StudyError
        The control does not apply to a session in ``status`` (a message for the
        experimenter saying what to do instead).
    """
    if action not in SESSION_ACTIONS:
        raise StudyError(f"unknown session action {action!r}; use {', '.join(SESSION_ACTIONS[:-1])} or stop")
    if status == "completed":
        raise StudyError(f"session {session_id} is completed")
    if action == "start" and status != "planned":
        raise StudyError(f"session {session_id} is {status}, not planned; use resume")
    if action in ("resume", "stop") and status == "planned":
        raise StudyError(f"session {session_id} has not started" + ("; use start" if action == "resume" else ""))
    if action == "pause" and status != "running":
        raise StudyError(f"session {session_id} is {status}; only a running session can pause")
    return {"start": "running", "resume": "running", "pause": "paused", "stop": "aborted"}[action]
