"""The experimenter page in a real chromium: log in, plan, start, pause, resume, stop, export."""

from __future__ import annotations

import time

import pytest

from .conftest import login
from .test_participant_browser import wait_answers, wait_respond

pytestmark = pytest.mark.browser


def session_status(server, sid: int) -> str:
    return server.rows("SELECT status FROM sessions WHERE session_id = ?", sid)[0][0]


def wait_status(server, sid: int, status: str, timeout: float = 30.0) -> str:
    """The session's stored status once it is ``status``, or the last one seen at ``timeout`` (s)."""
    deadline = time.monotonic() + timeout
    while (seen := session_status(server, sid)) != status and time.monotonic() < deadline:
        time.sleep(0.1)
    return seen


def test_experimenter_runs_a_session_from_the_page(server, chromium):
    context = chromium.new_context(viewport={"width": 1280, "height": 900})
    context.set_default_timeout(15_000)
    try:
        exp = context.new_page()
        exp.goto(server.base_url + "/")
        exp.fill("#token", "wrong-token-wrong")
        exp.click("main.login button[type=submit]")
        assert "not the experimenter token" in exp.inner_text("body")
        login(exp, server)
        assert exp.url == server.base_url + "/", "nothing secret in the address bar"
        assert not exp.is_visible("#cal-prompt"), "no calibration prompt when none waits"
        exp.fill("#new-participant-id", "P10")
        exp.click("#new-participant button")
        exp.wait_for_function("document.getElementById('participant').value === 'P10'")
        exp.fill("#repetitions", "1")
        exp.fill("#n-training", "1")
        exp.select_option("#study", "1")
        exp.click("#new-session button")
        row = exp.locator("#sessions tbody tr").first
        row.locator("text=planned").wait_for()
        sid = int(row.get_attribute("data-session"))
        assert server.rows("SELECT participant_id, study, status FROM sessions") == [("P10", 1, "planned")]
        assert server.rows("SELECT COUNT(*) FROM planned_trials") == [(1 + 27,)]

        href = row.locator("a").get_attribute("href")
        exp.click("#sessions button[data-action=start]")
        exp.locator("#sessions td.status.running").wait_for()

        part = context.new_page()
        part.goto(server.base_url + href)
        part.click("#begin")
        for i, key in enumerate(("5", "6")):
            wait_respond(part, i)
            part.keyboard.press(key)
        wait_answers(server, sid, 2)
        exp.wait_for_function("document.querySelectorAll('#answers tbody tr').length === 2")
        assert "training" in exp.inner_text("#answers")

        # Pause while trial 2 waits: the page shows the break and takes no answer until
        # the session resumes (the break is not response time).
        wait_respond(part, 2)
        exp.click("#sessions button[data-action=pause]")
        exp.locator("#sessions td.status.paused").wait_for()
        assert session_status(server, sid) == "paused"
        part.wait_for_function("document.getElementById('message').textContent.toLowerCase().includes('break')")
        part.keyboard.press("7")
        part.wait_for_timeout(500)
        assert server.rows("SELECT COUNT(*) FROM answers") == [(2,)], "nothing is taken or runs while paused"

        exp.click("#sessions button[data-action=resume]")
        wait_respond(part, 2)
        part.keyboard.press("7")
        assert [r[1] for r in wait_answers(server, sid, 3)] == ["5", "6", "7"]
        wait_respond(part, 3)
        exp.click("#sessions button[data-action=stop]")
        exp.click("#sessions button[data-action=stop-confirm]")
        # The server's word first, then the page's: a failure says which of them lagged.
        stored = wait_status(server, sid, "aborted")
        assert stored == "aborted", (
            f"the stop was confirmed but the session is {stored!r}; the page said "
            f"{exp.inner_text('#flash')!r}; server log:\n{server.log.read_text()[-3000:]}")
        exp.locator("#sessions td.status.aborted").wait_for()
        part.wait_for_function("document.body.dataset.state === 'stopped'")
        assert session_status(server, sid) == "aborted"

        csv = exp.request.get(f"{server.base_url}/api/export/trials.csv")  # the login cookie
        assert csv.status == 200
        lines = csv.text().strip().splitlines()
        assert len(lines) == 1 + 3 and lines[1].startswith("P10,1,training,1,")
        kinds = [k for (k,) in server.rows("SELECT kind FROM events WHERE session_id = ? ORDER BY event_id", sid)]
        for kind in ("start", "pause", "resume", "abort"):
            assert kind in kinds
    finally:
        context.close()


def test_stop_asks_first_and_esc_keeps_the_session_while_esc_twice_is_the_emergency_stop(server, page):
    # Issue 38, item 12: Stop ends a session for good, one click from Pause.
    s = server.plan("P11", 1, n_training=1, repetitions=1)
    sid = s["session_id"]
    assert server.api("POST", f"/api/sessions/{sid}/start").status_code == 200
    login(page, server)
    page.select_option("#participant", "P11")
    page.locator("#sessions td.status.running").wait_for()

    page.click("#sessions button[data-action=stop]")
    question = page.locator("#sessions .confirm-stop")
    question.wait_for()
    assert "for good" in question.inner_text() and "Pause" in question.inner_text()
    assert page.evaluate("document.activeElement.dataset.action") == "stop-cancel", "the safe answer has the focus"
    page.wait_for_timeout(300)
    assert session_status(server, sid) == "running", "one click on Stop stopped the session"

    page.keyboard.press("Escape")  # one Esc: the question goes, the session stays
    question.wait_for(state="detached")
    page.wait_for_timeout(900)  # apart from the next Esc, so that it is not a double press
    assert session_status(server, sid) == "running"

    page.click("#sessions button[data-action=stop]")
    page.click("#sessions button[data-action=stop-cancel]")  # "Keep it"
    question.wait_for(state="detached")
    assert session_status(server, sid) == "running"

    page.click("#sessions button[data-action=stop]")
    question.wait_for()
    page.keyboard.press("Escape")
    page.keyboard.press("Escape")  # Esc twice, question open or not: the emergency stop
    page.locator("#sessions td.status.paused").wait_for()
    assert session_status(server, sid) == "paused", "Esc twice is the emergency stop, never a Stop"

    page.click("#sessions button[data-action=stop]")
    page.click("#sessions button[data-action=stop-confirm]")
    page.locator("#sessions td.status.aborted").wait_for()
    assert session_status(server, sid) == "aborted"
