"""The experimenter page at the sizes it is used at (1024x768, 1280x720, a 390 px phone):
the "abort for good?" question on a line of its own with both answers on screen, one word
for an aborted session, a paused session said as paused, the Seed field's whole
placeholder, and a database of simulated participants opening on "add a participant".

Geometry is compared through bounding boxes, never pixels. One served app for the module.
"""

from __future__ import annotations

import math

import pytest

from .conftest import login, serving
from .test_participant_browser import open_page, start, wait_respond

pytestmark = pytest.mark.browser

SIZES = {"1024x768": (1024, 768), "1280x720": (1280, 720), "phone": (390, 844)}

#: ``selector => [lines, words]``: how many lines an element's text takes (distinct tops of
#: its text's line boxes) and how many words it has.
LINES_JS = """
(selector) => {
  const e = document.querySelector(selector);
  const r = document.createRange();
  r.selectNodeContents(e);
  const tops = new Set([...r.getClientRects()].map((b) => Math.round(b.top)));
  return [tops.size, e.textContent.trim().split(/\\s+/).length];
}
"""

#: ``selector => [text width, room]`` of an input's placeholder, px: the width its font
#: gives the text, and the content box left beside a number field's spin buttons (16 px).
PLACEHOLDER_JS = """
(selector) => {
  const e = document.querySelector(selector);
  const s = getComputedStyle(e);
  const ctx = document.createElement("canvas").getContext("2d");
  ctx.font = s.font;
  const room = e.clientWidth - parseFloat(s.paddingLeft) - parseFloat(s.paddingRight) - (e.type === "number" ? 16 : 0);
  return [ctx.measureText(e.placeholder).width, room];
}
"""


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    with serving(tmp_path_factory.mktemp("layout")) as srv:
        yield srv


@pytest.fixture
def context(chromium, request):
    width, height = SIZES[getattr(request, "param", "1280x720")]
    ctx = chromium.new_context(viewport={"width": width, "height": height})
    ctx.set_default_timeout(15_000)
    ctx.add_init_script("window.vfFlashMs = 60000;")  # the flash stays until it is read
    try:
        yield ctx
    finally:
        ctx.close()


def inside(inner: dict, outer: dict) -> bool:
    return (inner["x"] >= outer["x"] - 0.5 and inner["y"] >= outer["y"] - 0.5
            and inner["x"] + inner["width"] <= outer["x"] + outer["width"] + 0.5
            and inner["y"] + inner["height"] <= outer["y"] + outer["height"] + 0.5)


@pytest.mark.parametrize("context", list(SIZES), indirect=True)
def test_the_abort_question_fits_with_both_answers_on_screen(served, context):
    exp = context.new_page()
    width, height = exp.viewport_size["width"], exp.viewport_size["height"]
    participant = f"L{width}"
    s = served.plan(participant, 1, n_training=1, repetitions=1)
    assert served.api("POST", f"/api/sessions/{s['session_id']}/start").status_code == 200
    login(exp, served)
    exp.select_option("#participant", participant)
    exp.locator("#sessions td.status.running").wait_for()
    assert exp.evaluate("document.documentElement.scrollWidth") <= width, "the page is wider than the screen"
    text_width, room = exp.evaluate(PLACEHOLDER_JS, "#rig-seed")
    assert text_width <= room, f"the Seed placeholder needs {text_width:.0f} px, the field has {room:.0f}"

    exp.click("#sessions button[data-action=stop]")
    question = exp.locator("#sessions .confirm-stop")
    question.wait_for()
    assert "Abort session" in question.inner_text() and "for good" in question.inner_text()
    lines, words = exp.evaluate(LINES_JS, "#sessions .confirm-stop")
    assert lines <= math.ceil(words / 5), f"{words} words on {lines} lines: wrapped into a narrow column"
    card = exp.locator("#sessions-card").bounding_box()
    screen = {"x": 0, "y": 0, "width": width, "height": 1e9}  # below the fold is fine; off the side is not
    boxes = {a: exp.locator(f"#sessions button[data-action={a}]").bounding_box() for a in ("stop-cancel", "stop-confirm")}
    for action, box in boxes.items():
        assert inside(box, card) and inside(box, screen), (action, box, card)
        assert exp.evaluate(f"(b => b.scrollWidth <= b.clientWidth)(document.querySelector('#sessions button[data-action={action}]'))")
    q = question.bounding_box()
    assert inside(q, card) and inside(q, screen), (q, card)
    assert exp.inner_text("#sessions button[data-action=stop-cancel]") == "Keep it"
    assert exp.evaluate("document.activeElement.dataset.action") == "stop-cancel", "the safe answer has the focus"
    exp.click("#sessions button[data-action=stop-cancel]")
    question.wait_for(state="detached")
    assert served.rows("SELECT status FROM sessions WHERE session_id = ?", s["session_id"]) == [("running",)]


def test_pause_and_abort_are_said_in_the_words_of_the_status_column(served, context):
    s = start(served, "P61", 1, n_training=1, repetitions=1)
    sid = s["session_id"]
    part = context.new_page()
    open_page(part, served, s)
    wait_respond(part, 0)
    part.keyboard.press("5")
    wait_respond(part, 1)
    exp = context.new_page()
    login(exp, served)
    exp.select_option("#participant", "P61")
    exp.wait_for_function("document.querySelector('#sessions td.live')?.textContent.startsWith('respond')")
    exp.click("#sessions button[data-action=pause]")
    exp.locator("#sessions td.status.paused").wait_for()
    assert exp.inner_text("#flash").startswith(f"Session {sid} paused"), exp.inner_text("#flash")
    exp.wait_for_function("document.querySelector('#sessions td.live').textContent.startsWith('paused')")
    assert exp.inner_text("#sessions td.live") == "paused at main trial 1 of 27"
    # The title comes from its own request, issued after the table's: it follows within a
    # poll, and must not stay on the state before the pause.
    exp.wait_for_function("document.getElementById('live-title').textContent.includes('paused')")
    assert "respond" not in exp.inner_text("#live-title")

    exp.click("#sessions button[data-action=stop]")
    exp.click("#sessions button[data-action=stop-confirm]")
    exp.locator("#sessions td.status.aborted").wait_for()
    assert exp.inner_text("#flash").startswith(f"Session {sid} aborted"), exp.inner_text("#flash")
    assert exp.inner_text("#sessions td.status").startswith("aborted")
    assert served.rows("SELECT status FROM sessions WHERE session_id = ?", sid) == [("aborted",)]


def test_only_simulated_participants_opens_on_add_a_participant(server, context):
    # As after simulate-study: the models' participants, no person. (Their sessions need
    # a calibration, which takes long here; the page showed the first one's latest session.)
    assert server.api("POST", "/api/participants", json={"participant_id": "sim-001", "simulated": True}).status_code == 201
    exp = context.new_page()
    login(exp, server)
    exp.wait_for_function("document.querySelectorAll('#participant option').length === 2")
    assert exp.input_value("#participant") == ""
    assert exp.evaluate("document.activeElement.id") == "new-participant-id"
    assert exp.locator("#sessions tbody tr").count() == 0
    # A person added next is the one the page opens on, whatever the models' order.
    assert server.api("POST", "/api/participants", json={"participant_id": "P62"}).status_code == 201
    exp.reload()
    exp.wait_for_function("document.getElementById('participant').value === 'P62'")
