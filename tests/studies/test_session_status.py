"""The session state machine: the one table of allowed status changes, and the experimenter's controls."""

import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies.session_status import (
    SESSION_STATUSES,
    TRANSITIONS,
    action_status,
    check_transition,
    status_after_answer,
    transition_event,
)


def test_every_change_not_in_the_table_is_refused():
    for old in SESSION_STATUSES:
        for new in SESSION_STATUSES:
            allowed = new == old or new in TRANSITIONS[old]
            if allowed:
                check_transition(1, old, new, n_answered=5, n_trials=5)
            else:
                with pytest.raises(StudyError):
                    check_transition(1, old, new, n_answered=5, n_trials=5)
    assert TRANSITIONS["completed"] == (), "completed is final"
    assert all("planned" not in targets for targets in TRANSITIONS.values()), "nothing goes back to planned"


def test_completing_needs_every_answer_and_unknown_statuses_are_refused():
    with pytest.raises(StudyError, match="4 of 5 trials answered"):
        check_transition(3, "running", "completed", n_answered=4, n_trials=5)
    with pytest.raises(StudyError, match="status must be one of"):
        check_transition(3, "running", "exploded", n_answered=0, n_trials=5)


def test_events_and_the_status_after_an_answer():
    assert transition_event("planned", "running") == "start"
    assert [transition_event("paused", s) for s in ("running", "aborted", "completed")] == ["resume", "abort", "complete"]
    assert transition_event("running", "paused") == "pause"
    assert status_after_answer("planned", finished=False) == "running"
    assert status_after_answer("paused", finished=False) == "paused"  # a late answer changes nothing
    assert status_after_answer("aborted", finished=True) == "completed"


@pytest.mark.parametrize("action, status, expected", [
    ("start", "planned", "running"), ("resume", "paused", "running"), ("resume", "aborted", "running"),
    ("resume", "running", "running"), ("pause", "running", "paused"), ("stop", "running", "aborted"),
    ("stop", "paused", "aborted"), ("stop", "aborted", "aborted"),
])
def test_controls_lead_to_their_status(action, status, expected):
    assert action_status(action, 7, status) == expected


@pytest.mark.parametrize("action, status, words", [
    ("start", "running", "not planned; use resume"), ("resume", "planned", "has not started; use start"),
    ("pause", "paused", "only a running session can pause"), ("stop", "planned", "has not started"),
    ("start", "completed", "is completed"), ("jump", "running", "unknown session action"),
])
def test_controls_that_do_not_apply_are_refused_with_the_reason(action, status, words):
    with pytest.raises(StudyError, match=words):
        action_status(action, 7, status)
