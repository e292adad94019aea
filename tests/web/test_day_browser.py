"""A lab's day in a real chromium (issue 30): the live panel follows the participant,
the page survives a restart, the participant flow works from the keyboard alone, a
pause is a break that does not count as response time, and axe-core finds nothing.
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from .conftest import login, wait_for_held
from .test_api import answer, wait_state
from .test_participant_browser import open_page, start, wait_answers, wait_respond

pytestmark = pytest.mark.browser


def _key(session: dict) -> str:
    return session["participant_url"].split("key=")[1]


def _live_title(page) -> str:
    return page.evaluate("document.getElementById('live-title').textContent")


def test_the_live_panel_follows_the_chosen_participant(server, page):
    s1 = start(server, "P01", 1)
    s2 = server.plan("P02", 1)
    login(page, server)
    page.select_option("#participant", "P01")
    page.wait_for_function("document.getElementById('live-title').textContent.startsWith('session 1 ')")
    page.select_option("#participant", "P02")
    page.wait_for_function("document.getElementById('live-title').textContent.startsWith('session 2 ')")
    # P02's answers appear in the panel as they come.
    assert server.api("POST", f"/api/sessions/{s2['session_id']}/start").status_code == 200
    wait_state(server, s2["session_id"], _key(s2), "respond")
    assert answer(server, s2["session_id"], _key(s2), answer_id="answer-p02-0").status_code == 200
    page.wait_for_function("document.querySelectorAll('#answers tbody tr').length === 1")
    assert _live_title(page).startswith("session 2 "), _live_title(page)
    assert s1["session_id"] == 1


def test_a_slow_reply_for_another_session_never_reaches_the_panel(server, page):
    server.plan("P03", 1)
    server.api("POST", "/api/sessions", json={"participant_id": "P03", "study": 2, "seed": 5, "n_training": 1, "repetitions": 1})
    held = []
    login(page, server)
    page.wait_for_function("document.getElementById('live-title').textContent.startsWith('session 2 ')")
    # Every reply about session 1 is held back until the panel shows session 2 again.
    page.route("**/api/sessions/1", lambda route: held.append(route))
    page.click("#sessions tr[data-session='1'] td:first-child")
    wait_for_held(page, held, "session 1")
    page.click("#sessions tr[data-session='2'] td:first-child")
    page.wait_for_function("document.getElementById('live-title').textContent.startsWith('session 2 ')")
    assert held, "no request for session 1 was held"
    page.evaluate("""() => { window.vfTitles = [];
      new MutationObserver(() => window.vfTitles.push(document.getElementById('live-title').textContent))
        .observe(document.getElementById('live-title'), { childList: true, characterData: true, subtree: true }); }""")
    for route in list(held):  # the slow replies arrive now
        route.continue_()
    page.unroute("**/api/sessions/1")
    page.wait_for_timeout(1000)
    titles = page.evaluate("window.vfTitles")
    assert not [t for t in titles if t.startswith("session 1")], titles


def test_the_experimenter_page_says_when_the_server_is_gone_and_asks_for_a_new_login(server, page):
    s = start(server, "P04", 1)
    login(page, server)
    wait_state(server, s["session_id"], _key(s), "respond")
    page.wait_for_function("document.querySelector('#sessions td.live').textContent.startsWith('respond')")
    server.kill()
    page.wait_for_function("!document.getElementById('connection').hidden")
    assert "cannot be reached" in page.inner_text("#connection")
    page.wait_for_function("!document.querySelector('#sessions td.live').textContent.includes('respond')")
    # An action while the server is down says so plainly.
    page.click("#new-participant-id")
    page.fill("#new-participant-id", "P05")
    page.click("#new-participant button")
    page.wait_for_function("document.getElementById('flash').textContent.includes('cannot be reached')")
    assert "Failed to fetch" not in page.inner_text("body")
    # Back with a new token (the default of 'vibrofocus serve'): the login form, with no reload by hand.
    server.token = "a-new-token-" + "z" * 20
    server.start()
    page.wait_for_selector("main.login #token")
    login(page, server)
    page.wait_for_function("document.querySelector('#sessions td.live') !== null")
    assert page.evaluate("document.getElementById('connection').hidden")


def _tab_to(page, selector: str, presses: int = 8) -> None:
    for _ in range(presses):
        if page.evaluate(f"document.activeElement === document.querySelector({selector!r})"):
            return
        page.keyboard.press("Tab")
    raise AssertionError(f"Tab never reached {selector}")


@pytest.mark.parametrize("key", ["Enter", " "])
def test_begin_and_answer_from_the_keyboard_alone(server, page, key):
    s = start(server, "P06", 2)
    sid = s["session_id"]
    page.goto(server.base_url + s["participant_url"])
    _tab_to(page, "#begin")
    page.keyboard.press(key)
    page.wait_for_function("document.getElementById('overlay').hidden")
    wait_respond(page, 0)
    for k in ("3", "5", "7", "7", "Enter"):  # Study 2: select 3, 5 and 7, unselect 7, confirm
        page.keyboard.press(k)
    wait_respond(page, 1)
    page.keyboard.press("2")
    page.keyboard.press("Backspace")  # clears the selection
    page.keyboard.press("8")
    page.keyboard.press("Enter")
    rows = wait_answers(server, sid, 2)
    assert [(r[0], r[1]) for r in rows] == [(0, "3 5"), (1, "8")]


def test_a_pause_is_a_break_and_not_response_time(server, page):
    s = start(server, "P07", 1)
    open_page(page, server, s)
    wait_respond(page, 0)  # the answer window is open: the trial's clock runs
    assert server.api("POST", f"/api/sessions/{s['session_id']}/pause").status_code == 200
    page.wait_for_function("document.getElementById('message').textContent.includes('break')")
    assert not page.evaluate("document.body.classList.contains('answerable')")
    page.keyboard.press("4")  # during the break: not taken
    page.wait_for_timeout(3000)
    assert server.rows("SELECT COUNT(*) FROM answers") == [(0,)]
    assert server.api("POST", f"/api/sessions/{s['session_id']}/resume").status_code == 200
    wait_respond(page, 0)
    page.keyboard.press("4")
    (row,) = wait_answers(server, s["session_id"], 1)
    assert row[:2] == (0, "4")
    # The 3 s break is not in it: what is left is the time before and after the break
    # (a fraction of a second in this test), far below the break itself.
    assert row[2] < 1.5, row


def _axe(page) -> list[dict]:
    """axe-core's violations on the page as it is now (WCAG 2.x A and AA rules, best practices)."""
    import axe_playwright_python

    source = (Path(axe_playwright_python.__file__).parent / "axe.min.js").read_text()
    page.evaluate(source)
    result = page.evaluate("axe.run(document, {resultTypes: ['violations']})")
    return [{"id": v["id"], "nodes": [n["target"] for n in v["nodes"]]} for v in result["violations"]]


def test_axe_finds_nothing_on_either_page(server, page):
    pytest.importorskip("axe_playwright_python")
    s = start(server, "P08", 2)
    page.goto(server.base_url + "/")
    assert _axe(page) == []  # the login page
    login(page, server)
    page.wait_for_function("document.querySelectorAll('#sessions tbody tr').length === 1")
    assert _axe(page) == []
    page.goto(server.base_url + s["participant_url"])
    page.wait_for_function("document.body.dataset.state !== 'loading'")
    assert _axe(page) == []  # behind the begin overlay
    _tab_to(page, "#begin")
    page.keyboard.press("Enter")
    wait_respond(page, 0)
    assert _axe(page) == []  # answering
    assert httpx.get(server.base_url + "/static/participant.js").status_code == 200
