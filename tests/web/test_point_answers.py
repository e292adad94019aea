"""Point answers over HTTP against the real server: a point on the picture is stored in mm
beside its nearest location; a point off the picture, a location, or both, get 422 and
change nothing. And in a real chromium: a click on the picture, and the keyboard's cursor,
answer, at 1024 x 768 and on a 390 px phone."""

from __future__ import annotations

import csv
import io
import time

import httpx
import pytest

from .test_api import snapshot, wait_state
from .test_participant_browser import wait_answers, wait_respond


def plan_point(server, participant: str, *, n_training: int = 1, repetitions: int = 1) -> dict:
    assert server.api("POST", "/api/participants", json={"participant_id": participant}).status_code == 201
    r = server.api("POST", "/api/sessions", json={"participant_id": participant, "study": 1, "seed": 7, "point": True,
                                                  "n_training": n_training, "repetitions": repetitions})
    assert r.status_code == 201, r.text
    s = r.json()
    assert server.api("POST", f"/api/sessions/{s['session_id']}/start").status_code == 200
    return s


def post(server, sid, key, **fields):
    body = {"session_id": sid, "trial_index": 0, "rt_s": 0.8, "answer_id": "point-0001", **fields}
    return httpx.post(f"{server.base_url}/api/participant/{sid}/answer", json=body,
                      headers={"X-Participant-Key": key}, timeout=10)


def test_a_point_answer_over_http_and_its_refusals(server):
    s = plan_point(server, "P01")
    sid, key = s["session_id"], s["participant_url"].split("key=")[1]
    wait_state(server, sid, key, "respond")
    before = snapshot(server.db)
    cases = [
        (dict(point_mm=[40.0, 0.0]), "outside the picture's area"),  # the picture ends at x = 32.5 mm
        (dict(point_mm=[0.0, -32.6]), "outside the picture's area"),
        (dict(point_mm=[0.0]), "at least 2"),
        (dict(point_mm=["1", 2.0]), "point"),
        (dict(response=[5]), "takes a point answer"),
        (dict(response=[5], point_mm=[0.0, 0.0]), "not both"),
        (dict(), "not neither"),
    ]
    for fields, words in cases:
        r = post(server, sid, key, **fields)
        assert r.status_code == 422, (fields, r.text)
        assert words.lower() in r.json()["detail"].lower(), (fields, r.json())
    assert snapshot(server.db) == before, "a refused point changed the database"
    r = post(server, sid, key, point_mm=[-9.0, 7.5])
    assert r.status_code == 200, r.text
    assert r.json()["response"] == [1] and r.json()["point_mm"] == [-9.0, 7.5]
    assert server.rows("SELECT response, response_x_mm, response_y_mm FROM answers") == [("1", -9.0, 7.5)]
    # The web app's export carries the point and the block's level and allowed answers (the fit reads them).
    rows = list(csv.DictReader(io.StringIO(server.api("GET", "/api/export/trials.csv").text)))
    assert [(r["response"], r["response_x_mm"], r["response_y_mm"], r["level_db"], r["allowed"]) for r in rows] == [
        ("1", "-9.0", "7.5", "0.0", "1 2 3 4 5 6 7 8 9")]
    # The session goes on: the trial loop commits the same answer, point and all (nothing new).
    deadline, seq = time.monotonic() + 20, -1
    while time.monotonic() < deadline:
        st = httpx.get(f"{server.base_url}/api/participant/{sid}/state?after={seq}&wait=1&ready=1",
                       headers={"X-Participant-Key": key}).json()
        seq = st["seq"]
        if st["state"] == "respond" and st["trial_index"] == 1:
            break
    assert st["trial_index"] == 1 and st["point"], st
    assert server.proc.poll() is None, "the server stopped"
    assert server.rows("SELECT response, response_x_mm, response_y_mm FROM answers") == [("1", -9.0, 7.5)]
    # The page of a point session draws the picture, not the 3 x 3 buttons.
    html = httpx.get(server.base_url + s["participant_url"]).text
    assert '<svg id="arm"' in html and 'class="cell"' not in html
    assert html.count('class="location"') == 9 and html.count('class="actuator"') == 4


def test_a_point_answer_needs_study_1(server):
    assert server.api("POST", "/api/participants", json={"participant_id": "P02"}).status_code == 201
    r = server.api("POST", "/api/sessions", json={"participant_id": "P02", "study": 2, "point": True})
    assert r.status_code == 422 and "study 1" in r.json()["detail"]


def _point_on_screen(page, x_mm: float, y_mm: float) -> tuple[float, float]:
    """Where on the screen the layout point (x, y) mm is drawn (the SVG's y points down)."""
    return tuple(page.evaluate("""([x, y]) => {
        const svg = document.getElementById('arm');
        const p = svg.createSVGPoint(); p.x = x; p.y = -y;
        const s = p.matrixTransform(svg.getScreenCTM());
        return [s.x, s.y];
    }""", [x_mm, y_mm]))


@pytest.mark.browser
@pytest.mark.parametrize("viewport", [(1024, 768), (390, 844)], ids=["desktop", "phone"])
def test_the_picture_takes_a_click_and_the_keyboard(server, chromium, viewport):
    width, height = viewport
    phone = width < 500
    s = plan_point(server, "P03", n_training=1, repetitions=1)
    sid = s["session_id"]
    context = chromium.new_context(viewport={"width": width, "height": height}, has_touch=phone, is_mobile=phone)
    context.set_default_timeout(15_000)
    try:
        page = context.new_page()
        page.goto(server.base_url + s["participant_url"])
        assert "arrow keys" in page.inner_text("#overlay-text")
        page.click("#begin")
        wait_respond(page, 0)
        # The picture scales to the screen and lies wholly on it.
        box = page.locator("#arm").bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= width and box["y"] + box["height"] <= height, box
        assert box["width"] > 0.5 * min(width, height * 0.62), box
        # 1) A click (a tap on the phone) 4 mm right of location 7 (-10, -10) mm.
        x, y = _point_on_screen(page, -6.0, -10.0)
        if phone:
            page.touchscreen.tap(x, y)
        else:
            page.mouse.click(x, y)
        rows = wait_answers(server, sid, 1)
        (pt,) = server.rows("SELECT response, response_x_mm, response_y_mm FROM answers WHERE trial_index = 0")
        # A pixel is 65 mm / picture width: the point is within 1 px of where it was clicked.
        mm_per_px = 65.0 / box["width"]
        assert pt[0] == "7" and abs(pt[1] + 6.0) <= mm_per_px + 0.01 and abs(pt[2] + 10.0) <= mm_per_px + 0.01, (pt, rows)
        # 2) The keyboard: the first arrow shows the cursor at the picture's centre (0, 0); three
        # steps right (1 mm each), one big step up (Shift: 5 mm), one step down; Enter answers.
        wait_respond(page, 1)
        for key in ("ArrowRight", "ArrowRight", "ArrowRight", "Shift+ArrowUp", "ArrowDown"):
            page.keyboard.press(key)
        assert page.is_visible("#cursor")
        page.keyboard.press("Enter")
        wait_answers(server, sid, 2)
        (pt,) = server.rows("SELECT response, response_x_mm, response_y_mm FROM answers WHERE trial_index = 1")
        # The first arrow moves from the centre too: 3 mm right, 4 mm up (toward the wrist): location 5's.
        assert pt == ("5", 3.0, 4.0), pt
    finally:
        context.close()
