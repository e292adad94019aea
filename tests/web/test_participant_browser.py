"""The participant page in a real chromium against a real server and a real SQLite file."""

from __future__ import annotations

import json
import time

import pytest

pytestmark = pytest.mark.browser


def start(server, participant: str, study: int, **plan) -> dict:
    s = server.plan(participant, study, **plan)
    r = server.api("POST", f"/api/sessions/{s['session_id']}/start")
    assert r.status_code == 200, r.text
    return s


def open_page(page, server, session) -> None:
    page.goto(server.base_url + session["participant_url"])
    page.click("#begin")


#: Whether the page offers trial ``i`` for an answer now (a JavaScript function of ``i``).
OFFERS_TRIAL = ("i => document.body.dataset.state === 'respond' && document.body.dataset.trial === String(i)"
                " && document.body.classList.contains('answerable')")


def wait_respond(page, trial_index: int) -> None:
    page.wait_for_function(OFFERS_TRIAL, arg=trial_index)


def wait_answers(server, sid: int, n: int, timeout: float = 20.0) -> list[tuple]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        rows = server.rows(
            "SELECT trial_index, response, rt_s, answer_id FROM answers WHERE session_id = ? ORDER BY trial_index", sid)
        if len(rows) >= n:
            return rows
        time.sleep(0.05)
    raise AssertionError(f"expected {n} answers in the database, found {rows}")


def trial_events(server, sid: int, i: int) -> list[str]:
    """The kinds of the events of trial ``i``, in order."""
    return [k for (k,) in server.rows(
        "SELECT kind FROM events WHERE session_id = ? AND json_extract(payload, '$.trial_index') = ? ORDER BY event_id",
        sid, i)]


def pending(page, sid: int) -> list[dict]:
    return json.loads(page.evaluate(f"localStorage.getItem('vibrofocus.pending.{sid}') || '[]'"))


def test_study1_training_and_trials_by_keyboard(server, page):
    s = start(server, "P01", 1)
    sid = s["session_id"]
    open_page(page, server, s)
    keys = ["4", "Numpad7", "3", "Numpad1", "9"]  # top-row digits and the keypad
    expected = ["4", "7", "3", "1", "9"]
    for i, key in enumerate(keys):
        wait_respond(page, i)
        page.keyboard.press(key)
        page.wait_for_function("document.getElementById('message').textContent.includes('Answer taken')")
        if i == 0:
            # A key pressed before the next stimulus has played must not answer it.
            page.keyboard.press("8")
    rows = wait_answers(server, sid, 5)
    assert [r[0] for r in rows] == [0, 1, 2, 3, 4]
    assert [r[1] for r in rows] == expected
    assert all(r[2] > 0 for r in rows), "reaction times are measured"
    assert len({r[3] for r in rows}) == 5, "each answer has its own id"
    phases = server.rows(
        "SELECT p.phase FROM answers a JOIN planned_trials p USING (session_id, trial_index) ORDER BY a.trial_index")
    assert [p[0] for p in phases] == ["training", "training", "main", "main", "main"]
    # Each answered trial had its cue and stimulus logged before the answer, and the page beeped.
    for i in range(5):
        kinds = trial_events(server, sid, i)
        assert kinds[:3] == ["cue", "stimulus_onset", "answer"], kinds
    assert page.evaluate("window.vfBeeps") >= 5
    assert pending(page, sid) == []


def test_study2_multi_select_with_enter_and_clicks(server, page):
    s = start(server, "P02", 2)
    sid = s["session_id"]
    open_page(page, server, s)
    wait_respond(page, 0)
    for key in ("2", "7", "5", "5"):  # 5 toggled on and off again
        page.keyboard.press(key)
    assert page.locator(".cell.selected").all_inner_texts() == ["2", "7"]
    page.keyboard.press("Enter")
    wait_respond(page, 1)
    page.click(".cell[data-loc='1']")
    page.click(".cell[data-loc='3']")
    page.click("#confirm")
    wait_respond(page, 2)
    page.keyboard.press("Enter")  # nothing selected: a hint, no answer
    assert "at least one" in page.inner_text("#hint")
    page.keyboard.press("Numpad9")
    page.keyboard.press("Enter")
    rows = wait_answers(server, sid, 3)
    assert [(r[0], r[1]) for r in rows] == [(0, "2 7"), (1, "1 3"), (2, "9")]
    csv = server.api("GET", "/api/export/trials.csv")
    assert csv.status_code == 200
    lines = csv.text.strip().splitlines()
    assert lines[0].startswith("participant,study,phase,trial,method,target,response,rt_s,session,")
    assert [line.split(",")[6] for line in lines[1:]] == ["2 7", "1 3", "9"]


def test_reload_mid_trial_and_unconfirmed_answer_is_resent(server, page):
    s = start(server, "P03", 1)
    sid = s["session_id"]
    open_page(page, server, s)
    wait_respond(page, 0)
    page.keyboard.press("2")
    # Reload while trial 1 waits for its answer: the page comes back to the same trial.
    wait_respond(page, 1)
    page.reload()
    page.click("#begin")
    wait_respond(page, 1)
    page.keyboard.press("6")
    # Trial 2: the answer cannot reach the server, so the page keeps it and does not advance.
    wait_respond(page, 2)
    page.route("**/answer", lambda route: route.abort())
    page.keyboard.press("8")
    page.wait_for_timeout(800)
    kept = pending(page, sid)
    assert [(a["trial_index"], a["response"]) for a in kept] == [(2, [8])]
    assert "Answer taken" not in page.inner_text("#message")
    assert [r[0] for r in wait_answers(server, sid, 2)] == [0, 1]
    assert server.rows("SELECT COUNT(*) FROM answers WHERE trial_index = 2") == [(0,)]
    # After a reload the stored answer is sent again and committed, exactly once.
    page.unroute("**/answer")
    page.reload()
    rows = wait_answers(server, sid, 3)
    assert [(r[0], r[1]) for r in rows] == [(0, "2"), (1, "6"), (2, "8")]
    assert rows[2][3] == kept[0]["answer_id"], "the answer id made by the page is the one stored"
    page.wait_for_function(f"(localStorage.getItem('vibrofocus.pending.{sid}') || '[]') === '[]'")
    page.click("#begin")
    wait_respond(page, 3)  # the session went on to the next trial
    assert server.rows("SELECT COUNT(*) FROM answers") == [(3,)]


def test_kill_and_restart_server_mid_session(server, page):
    s = start(server, "P04", 1)
    sid = s["session_id"]
    open_page(page, server, s)
    wait_respond(page, 0)
    page.keyboard.press("1")
    wait_respond(page, 1)
    server.kill()
    # The participant answers while the server is down: the answer waits in localStorage.
    page.keyboard.press("3")
    page.wait_for_function("document.getElementById('message').textContent.includes('saved on this computer')")
    assert [(a["trial_index"], a["response"]) for a in pending(page, sid)] == [(1, [3])]
    assert server.rows("SELECT trial_index, response FROM answers") == [(0, "1")]
    server.start()
    rows = wait_answers(server, sid, 2)
    assert [(r[0], r[1]) for r in rows] == [(0, "1"), (1, "3")]
    # The restarted server resumed the session at the first unanswered trial.
    wait_respond(page, 2)
    page.keyboard.press("5")
    rows = wait_answers(server, sid, 3)
    assert [(r[0], r[1]) for r in rows] == [(0, "1"), (1, "3"), (2, "5")]
    assert server.rows("SELECT COUNT(*), COUNT(DISTINCT trial_index) FROM answers") == [(3, 3)]
    assert server.rows("SELECT COUNT(*) FROM events WHERE kind = 'resumed_after_restart'") == [(1,)]
    # The server commits before it answers, so the page clears its copy a moment after
    # the row appears: wait for the confirmation to arrive, then nothing is pending.
    page.wait_for_function(f"(localStorage.getItem('vibrofocus.pending.{sid}') || '[]') === '[]'")
    assert pending(page, sid) == []


def test_nothing_plays_when_the_page_is_closed_or_reloaded_before_the_stimulus(server, chromium):
    s = start(server, "P05", 1)
    sid = s["session_id"]

    def onsets(i: int) -> list:
        return server.rows("SELECT event_id FROM events WHERE session_id = ? AND kind = 'stimulus_onset' "
                           "AND json_extract(payload, '$.trial_index') = ?", sid, i)

    context = chromium.new_context()
    context.set_default_timeout(15_000)
    try:
        page = context.new_page()
        open_page(page, server, s)
        wait_respond(page, 0)
        page.keyboard.press("5")
        # Trial 1 says "Get ready": the participant reloads the page and does not begin.
        page.wait_for_function("document.body.dataset.trial === '1' && ['ready', 'cue'].includes(document.body.dataset.state)")
        page.reload()
        page.wait_for_timeout(2000)
        assert onsets(1) == [], "a stimulus played while the page showed 'Click here to begin'"
        page.click("#begin")
        wait_respond(page, 1)
        assert len(onsets(1)) == 1
        page.keyboard.press("6")
        # Trial 2: the page is closed during "Get ready".
        page.wait_for_function("document.body.dataset.trial === '2' && ['ready', 'cue'].includes(document.body.dataset.state)")
        page.close()
        time.sleep(2.0)
        assert onsets(2) == [], "a stimulus played with no participant page open"
        assert [r[0] for r in wait_answers(server, sid, 2)] == [0, 1]
    finally:
        context.close()


def test_no_answer_behind_the_begin_overlay_and_enter_never_repeats_a_click(server, page):
    s = start(server, "P06", 1)
    sid = s["session_id"]
    open_page(page, server, s)
    wait_respond(page, 0)
    page.click(".cell[data-loc='4']")
    wait_respond(page, 1)
    for key in ("Enter", " "):  # the clicked cell must not answer trial 1 again
        page.keyboard.press(key)
    page.wait_for_timeout(500)
    assert [(r[0], r[1]) for r in wait_answers(server, sid, 1)] == [(0, "4")]
    assert server.rows("SELECT COUNT(*) FROM answers") == [(1,)]
    page.reload()  # trial 1 is still open; the overlay asks to begin
    page.wait_for_function("document.body.dataset.state === 'respond'")
    page.keyboard.press("7")
    page.wait_for_timeout(500)
    assert server.rows("SELECT COUNT(*) FROM answers") == [(1,)], "a key answered behind the overlay"
    assert pending(page, sid) == []
    page.click("#begin")
    wait_respond(page, 1)
    page.keyboard.press("2")
    assert [(r[0], r[1]) for r in wait_answers(server, sid, 2)] == [(0, "4"), (1, "2")]


#: Left and right of the text itself (not its box) of an element, and the window's width, px.
_INSIDE_JS = """(sel) => { const range = document.createRange();
  range.selectNodeContents(document.querySelector(sel)); const r = range.getBoundingClientRect();
  return [r.left, r.right, window.innerWidth]; }"""


def test_study2_on_a_phone_says_several_may_be_chosen_and_marks_the_main_trials(server, chromium):
    # Issue 38, bench items: the words of Study 2, a Confirm button to tap, the switch from
    # training to the main trials, and texts clear of the screen's edges at 390 px.
    s = start(server, "P40", 2, n_training=1, repetitions=1)
    sid = s["session_id"]
    context = chromium.new_context(viewport={"width": 390, "height": 844}, has_touch=True, is_mobile=True)
    context.set_default_timeout(15_000)
    try:
        page = context.new_page()
        page.goto(server.base_url + s["participant_url"])
        intro = page.inner_text("#overlay-text")
        assert "every" in intro and "several" in intro and "Confirm" in intro, intro
        left, right, width = page.evaluate(_INSIDE_JS, "#overlay-text")
        assert left >= 12 and right <= width - 12, (left, right, width)
        page.tap("#begin")
        wait_respond(page, 0)
        message = page.inner_text("#message")
        assert "several" in message and "Confirm" in message and "Enter" not in message, message
        assert page.is_visible("#confirm") and page.inner_text("#confirm") == "Confirm"
        left, right, width = page.evaluate(_INSIDE_JS, "#message")
        assert left >= 12 and right <= width - 12, (left, right, width)
        page.tap(".cell[data-loc='4']")
        page.tap(".cell[data-loc='6']")
        page.tap("#confirm")  # no Enter key on a phone
        page.wait_for_function("document.body.dataset.phase === 'main' && document.body.dataset.state === 'ready'")
        assert "main trials begin" in page.inner_text("#message"), page.inner_text("#message")
        assert wait_answers(server, sid, 1)[0][1] == "4 6"
        wait_respond(page, 1)
        assert "main trials begin" not in page.inner_text("#message")
    finally:
        context.close()
