"""Usability of both pages in a real chromium at 1280x720: what is on screen without
scrolling, one trial numbering, no broken images, messages that clear and read plainly,
a visible focus ring and legible text."""

from __future__ import annotations

import pytest

from .conftest import calibrate, contrast, login, wait_for_held
from .test_participant_browser import open_page, start, wait_answers, wait_respond

pytestmark = pytest.mark.browser

VIEWPORT = {"width": 1280, "height": 720}
BROKEN_IMAGES = "[...document.images].filter((i) => i.offsetParent !== null && !(i.complete && i.naturalWidth > 0)).length"


@pytest.fixture
def exp(chromium):
    context = chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    context.add_init_script("window.vfFlashMs = 400;")
    try:
        yield context.new_page()
    finally:
        context.close()


def add_participant(exp, server, participant: str) -> None:
    """Log in and add ``participant`` through the page."""
    login(exp, server)
    exp.fill("#new-participant-id", participant)
    exp.click("#new-participant button")
    exp.wait_for_function(f"document.getElementById('participant').value === '{participant}'")


def _held_script(exp, server) -> list:
    """Log in with the page's script held (never answered); the held requests."""
    held = []
    exp.route("**/static/experimenter.js", lambda route: held.append(route))
    exp.goto(server.base_url + "/")
    exp.fill("#token", server.token)
    exp.click("main.login button[type=submit]")
    exp.wait_for_selector("#participant-card")
    wait_for_held(exp, held, "its script")  # once it has parsed up to it
    return held


def test_the_page_says_ready_only_once_its_script_has_run(server, exp):
    """The cards are on the page before its script has run: a click on "Add" then submitted
    the form natively (the page reloaded to "/?" and the participant was never added; seen
    once under load). The script marks the page ready once every handler is on, and the
    tests' login waits for that mark."""
    held = _held_script(exp, server)
    assert exp.get_attribute("body", "data-ready") is None
    for route in held:
        route.continue_()
    exp.wait_for_selector("body[data-ready='true']")
    exp.fill("#new-participant-id", "P43")
    exp.click("#new-participant button")
    exp.wait_for_function("document.getElementById('participant').value === 'P43'")
    assert exp.url == server.base_url + "/"


def test_the_emergency_stop_works_before_the_pages_script_has_run(server, exp):
    """The button was a script's only: until experimenter.js had loaded (a slow network, a
    blocked script) a click did nothing. It is now a plain form's, and the server answers
    a browser's form with a page that says what stopped."""
    held = _held_script(exp, server)
    assert exp.get_attribute("body", "data-ready") is None, "the script has not run"
    exp.click("#emergency-stop")
    exp.wait_for_selector("#stopped")
    assert exp.inner_text("#stopped") == "Nothing was running."
    assert exp.url == server.base_url + "/api/emergency-stop"
    assert "emergency stop: nothing was running" in server.log.read_text()
    assert held  # still held: no script ran
    exp.click("text=Back to the experimenter page")
    exp.wait_for_selector("#participant-card")


@pytest.mark.slow
def test_session_controls_on_screen_with_a_calibration_figure_and_no_broken_images(server, exp):
    assert server.api("POST", "/api/participants", json={"participant_id": "P40"}).status_code == 201
    cid = calibrate(server, "P40")
    r = server.api("POST", "/api/sessions", json={"participant_id": "P40", "study": 1, "calibration_id": cid})
    assert r.status_code == 201, r.text
    login(exp, server)
    exp.wait_for_function("document.getElementById('cal-figure').naturalWidth > 0 && !document.getElementById('cal-figure').hidden")
    start_button = exp.locator("#sessions button[data-action=start]")
    start_button.wait_for()
    box = start_button.bounding_box()
    assert exp.evaluate("window.scrollY") == 0
    assert 0 <= box["y"] and box["y"] + box["height"] <= VIEWPORT["height"], box
    assert exp.evaluate(BROKEN_IMAGES) == 0
    # A figure the server cannot draw (here a file that fails its check): the page says
    # so in words instead of showing a broken image.
    exp.route("**/figure.png", lambda route: route.fulfill(
        status=409, content_type="application/json",
        body='{"detail": "The calibration file has changed since it was saved."}'))
    exp.reload()
    exp.wait_for_function("document.getElementById('cal-figure-message').textContent.includes('has changed')")
    assert exp.evaluate(BROKEN_IMAGES) == 0


def test_before_any_calibration_a_plain_message_and_no_image(server, exp):
    add_participant(exp, server, "P41")
    assert "No calibration yet" in exp.inner_text("#cal-figure-message")
    assert exp.is_visible("#cal-figure-message")
    assert exp.evaluate("[...document.images].filter((i) => i.offsetParent !== null).length") == 0
    exp.click("#preview")
    assert "calibrat" in exp.inner_text("#flash").lower()
    assert exp.evaluate(BROKEN_IMAGES) == 0


def test_flash_messages_clear(server, exp):
    login(exp, server)
    exp.fill("#new-participant-id", "P42")
    exp.click("#new-participant button")
    exp.wait_for_function("document.getElementById('flash').textContent.includes('added')")
    exp.wait_for_function("document.getElementById('flash').textContent === ''", timeout=3000)
    # An error stays a while longer than a confirmation, then the next action clears it.
    exp.click("#preview")
    assert exp.inner_text("#flash") != ""
    exp.wait_for_timeout(600)
    assert exp.inner_text("#flash") != "", "an error went before it could be read"
    exp.click("#straps")
    assert exp.inner_text("#flash") == ""


def test_refusals_are_said_in_plain_words(server, exp):
    add_participant(exp, server, "P43")
    # Past the form's own checks (as an old browser or a script would be).
    exp.evaluate("document.getElementById('repetitions').removeAttribute('max')")
    exp.fill("#repetitions", "50")
    exp.click("#new-session button")
    exp.wait_for_function("document.getElementById('flash').classList.contains('error')")
    text = exp.inner_text("#flash")
    assert text == "Repetitions must be at most 10.", text
    r = server.api("POST", "/api/sessions", json={"participant_id": "P43", "study": 1, "rig": "laser"})
    detail = r.json()["detail"]
    assert r.status_code == 422 and "body." not in detail and "Input should" not in detail, detail


def test_one_trial_numbering_on_both_pages(server, chromium):
    context = chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    try:
        s = start(server, "P44", 1, n_training=2)
        sid = s["session_id"]
        part = context.new_page()
        open_page(part, server, s)
        wait_respond(part, 0)
        part.keyboard.press("5")
        wait_respond(part, 1)  # the second training trial
        assert part.inner_text("#progress") == "Training 2 of 2"
        exp = context.new_page()
        login(exp, server)
        exp.wait_for_function("document.querySelector('#sessions td.live')?.textContent.includes('trial')")
        assert exp.inner_text("#sessions td.live") == "respond · training trial 2 of 2"
        exp.wait_for_function("document.getElementById('live-title').textContent.includes('training trial 2 of 2')")
        exp.wait_for_function("document.querySelectorAll('#answers tbody tr').length === 1")
        cells = exp.locator("#answers tbody tr td").all_inner_texts()
        assert cells[:2] == ["training", "1"]
        assert [r[0] for r in wait_answers(server, sid, 1)] == [0]
        csv = server.api("GET", "/api/export/trials.csv").text.splitlines()
        assert csv[1].split(",")[2:4] == ["training", "1"]
    finally:
        context.close()


#: The focused element's name: its id, else its text.
FOCUSED = "document.activeElement.id || document.activeElement.textContent"


def tab_to_a_button(page) -> str:
    page.locator("body").click(position={"x": 5, "y": 5})
    for _ in range(30):
        page.keyboard.press("Tab")
        if page.evaluate("document.activeElement.tagName") == "BUTTON":
            return page.evaluate(FOCUSED)
    raise AssertionError("no button took the focus")


def assert_focus_ring(page) -> None:
    page.evaluate("document.activeElement.setAttribute('data-focused', '1')")
    style = page.evaluate("(() => { const s = getComputedStyle(document.activeElement); return [s.outlineStyle, s.outlineWidth]; })()")
    assert style[0] not in ("none", "auto") and float(style[1].removesuffix("px")) >= 2, style
    assert contrast(page, "[data-focused]", "outlineColor") >= 3.0


def test_visible_focus_ring_and_legible_text(server, exp):
    login(exp, server)
    tab_to_a_button(exp)
    assert_focus_ring(exp)
    assert contrast(exp, ".muted") >= 4.5
    s = server.plan("P45", 1)
    part = exp.context.new_page()
    part.goto(server.base_url + s["participant_url"])
    part.keyboard.press("Tab")
    assert part.evaluate("document.activeElement.id") == "begin"
    assert_focus_ring(part)
    part.click("#begin")
    for selector in ("#orientation", "#message"):
        assert contrast(part, selector) >= 4.5, selector
    server.api("POST", f"/api/sessions/{s['session_id']}/start")
    wait_respond(part, 0)
    for selector in ("#progress", "#orientation"):
        assert contrast(part, selector) >= 4.5, selector


@pytest.mark.slow
def test_the_calibration_card_says_one_thing_at_a_time_and_shows_the_verdicts(server, exp):
    # Issue 38: "100 % · take 8/8" beside "No calibration yet" once a calibration ended,
    # and no quality verdicts on the page.
    add_participant(exp, server, "P42")
    exp.click("#calibrate")
    exp.wait_for_function("document.getElementById('calibrate').disabled")
    assert "No calibration yet" not in exp.inner_text("#cal-figure-message")
    exp.wait_for_function("!document.getElementById('calibrate').disabled", timeout=180_000)
    card = exp.inner_text("#calibration-card")
    assert "No calibration yet" not in card and "take" not in exp.inner_text("#cal-message"), card
    assert "saved" in exp.inner_text("#cal-message")
    exp.wait_for_function("!document.getElementById('cal-verdicts').hidden")
    verdicts = exp.inner_text("#cal-verdicts")
    assert verdicts.strip(), "no quality verdicts shown"
    assert exp.is_hidden("#cal-override-label"), "no override is offered for a calibration without errors"
    exp.wait_for_function("document.getElementById('cal-figure').naturalWidth > 0")


def hold_the_first_list_of_participants(page, server) -> list:
    """Log in with the page's first list of participants held back (as a busy server answers
    it late); returns ``[(route, reply)]`` once the page has asked for it."""
    held = []

    def hold(route):
        if route.request.method != "GET" or held:
            route.continue_()
            return
        held.append((route, route.fetch()))

    page.route("**/api/participants", hold)
    login(page, server)
    wait_for_held(page, held, "its list of participants")
    return held


def test_a_first_list_answered_late_leaves_the_focus_where_the_experimenter_put_it(server, exp):
    """A new database's page puts the focus on "add a participant", but not once the
    experimenter has moved it: a late first list (a busy server) does not take it away."""
    held = hold_the_first_list_of_participants(exp, server)
    name = tab_to_a_button(exp)
    route, reply = held[0]
    route.fulfill(response=reply)
    exp.wait_for_function("document.getElementById('participant').options.length > 0")
    exp.wait_for_timeout(300)
    focused = exp.evaluate(FOCUSED)
    assert focused == name, f"the focus went from {name!r} to {focused!r}"


def test_a_new_database_opens_on_add_a_participant(server, exp):
    login(exp, server)
    exp.wait_for_function("document.activeElement?.id === 'new-participant-id'")


def test_a_participant_added_before_the_first_list_arrives_stays_chosen(server, exp):
    """The page's first list of participants, answered late (a busy server), never shows over the
    list fetched after an add: the new participant stays chosen."""
    held = hold_the_first_list_of_participants(exp, server)
    with exp.expect_response(lambda r: r.request.method == "POST" and r.url.endswith("/api/participants")):
        exp.fill("#new-participant-id", "P42")
        exp.click("#new-participant button")
    exp.wait_for_timeout(500)  # a list asked after the add would have arrived by now
    route, reply = held[0]
    route.fulfill(response=reply)
    exp.wait_for_function("document.getElementById('participant').value === 'P42'")
    exp.wait_for_timeout(500)
    assert exp.evaluate("document.getElementById('participant').value") == "P42"
