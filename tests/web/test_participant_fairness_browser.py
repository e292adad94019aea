"""The participant page is fair and honest: reaction times from an onset the page saw,
no cell marked before the answer, refusals said as such, and no endless "Sending…"."""

from __future__ import annotations

import contextlib
import time

import pytest

from .test_participant_browser import OFFERS_TRIAL, open_page, pending, start, trial_events, wait_answers, wait_respond

pytestmark = pytest.mark.browser


def test_after_a_reload_the_trial_restarts_and_the_rt_is_timed_from_its_new_onset(server, page):
    s = start(server, "P31", 1)
    sid = s["session_id"]
    open_page(page, server, s)
    wait_respond(page, 0)
    page.keyboard.press("2")
    wait_respond(page, 1)  # trial 1's stimulus has played; the participant reloads
    page.reload()
    page.wait_for_function("document.body.dataset.state === 'respond'")
    page.wait_for_timeout(1500)  # the overlay waits; this time is not a reaction time
    page.click("#begin")
    # The trial comes again from "Get ready"; nothing answers before its new stimulus.
    page.wait_for_function("document.body.dataset.state !== 'respond'")
    wait_respond(page, 1)
    page.keyboard.press("6")
    rows = wait_answers(server, sid, 2)
    assert [(r[0], r[1]) for r in rows] == [(0, "2"), (1, "6")]
    assert rows[1][2] < 1.0, f"RT {rows[1][2]} s counts the time since the reload"
    # The page commits the answer; the engine then adds its onset (answer_onset), which
    # may land a moment after the answer: it may follow, nothing else may.
    kinds = trial_events(server, sid, 1)
    assert kinds[:6] == ["cue", "stimulus_onset", "trial_restarted", "cue", "stimulus_onset", "answer"], kinds
    assert kinds[6:] in ([], ["answer_onset"]), kinds


def cells_boxes(page) -> list[dict]:
    return [page.locator(f".cell[data-loc='{i}']").bounding_box() for i in range(1, 10)]


def overlap(a: dict, b: dict) -> bool:
    return not (a["x"] + a["width"] <= b["x"] or b["x"] + b["width"] <= a["x"]
                or a["y"] + a["height"] <= b["y"] or b["y"] + b["height"] <= a["y"])


@pytest.mark.parametrize("size", [(1280, 720), (1920, 1080), (1024, 768), (1366, 768)])
def test_the_begin_button_is_off_the_grid(server, chromium, size):
    s = server.plan("P32", 1)
    context = chromium.new_context(viewport={"width": size[0], "height": size[1]})
    try:
        page = context.new_page()
        page.goto(server.base_url + s["participant_url"])
        begin = page.locator("#begin").bounding_box()
        assert begin["y"] + begin["height"] <= size[1], "Begin is on the screen"
        boxes = cells_boxes(page)
        assert all(b["y"] >= 0 and b["y"] + b["height"] <= size[1] for b in boxes), "the grid fits the screen"
        assert not any(overlap(begin, b) for b in boxes), (begin, boxes)
    finally:
        context.close()


BORDER = "i => getComputedStyle(document.querySelector(`.cell[data-loc='${i}']`)).borderTopColor"


def test_no_cell_carries_a_hover_or_focus_mark_when_the_trial_starts(server, page):
    page.set_viewport_size({"width": 1280, "height": 720})
    s = start(server, "P33", 1)
    open_page(page, server, s)
    # The pointer rests on cell 5 and cell 5 has the focus before the stimulus.
    box = page.locator(".cell[data-loc='5']").bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.evaluate("document.querySelector(\".cell[data-loc='5']\").focus()")
    wait_respond(page, 0)
    plain = page.evaluate(BORDER, 1)
    assert page.evaluate(BORDER, 5) == plain, "the cell under the resting pointer is marked"
    assert not page.evaluate("document.activeElement.classList.contains('cell')"), "a cell keeps the focus"
    assert page.evaluate("getComputedStyle(document.querySelector(\".cell[data-loc='5']\")).outlineStyle") == "none"
    # Moving the pointer on purpose shows where it points.
    page.mouse.move(box["x"] + box["width"] / 2 + 30, box["y"] + box["height"] / 2 + 10, steps=5)
    assert page.evaluate(BORDER, 5) != plain
    # The cell clicked for an answer is not marked when the next trial starts.
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    wait_respond(page, 1)
    assert page.evaluate(BORDER, 5) == plain
    assert not page.evaluate("document.activeElement.classList.contains('cell')")


MESSAGES = """
window.vfMessages = [];
document.addEventListener('DOMContentLoaded', () => {
  const m = document.getElementById('message');
  new MutationObserver(() => window.vfMessages.push(m.textContent)).observe(m, {childList: true, characterData: true, subtree: true});
});
"""


@contextlib.contextmanager
def watched_context(chromium, script: str = ""):
    """A browser context whose pages record every message they show (``window.vfMessages``)."""
    context = chromium.new_context()
    context.set_default_timeout(15_000)
    context.add_init_script(script + MESSAGES)
    try:
        yield context
    finally:
        context.close()


def relay_states(page, screen: str, given: dict, drop=lambda news: False) -> None:
    """Pass the page's state polls through, noting in ``given[screen]`` the seq of the last state
    it was given; a state for which ``drop(news)`` holds is not given (its connection drops)."""
    def states(route):
        try:
            reply = route.fetch()
        except Exception:  # noqa: BLE001 - the page gave this request up (a new poll, or closed)
            return
        news = reply.json()
        if drop(news):
            route.abort()
        else:
            given[screen] = news.get("seq")
            route.fulfill(response=reply)

    page.route("**/state*", states)


def wait_both_offer(first, second, given: dict, trial_index: int, timeout_s: float = 15.0) -> None:
    """Wait until both screens were given the same state and offer ``trial_index``.

    A screen opened after the trial's onset has the trial presented again; the other screen
    answers only once it too holds that presentation.
    """
    deadline = time.monotonic() + timeout_s
    while not (given.get("first") is not None and given.get("first") == given.get("second")
               and first.evaluate(OFFERS_TRIAL, trial_index) and second.evaluate(OFFERS_TRIAL, trial_index)):
        assert time.monotonic() < deadline, (given, shown(first), shown(second))
        first.wait_for_timeout(50)


def shown(page) -> list[str]:
    """Every message the page has shown, in order."""
    return page.evaluate("window.vfMessages")


def test_a_refused_answer_is_not_called_taken(server, chromium):
    s = start(server, "P34", 1)
    sid = s["session_id"]
    with watched_context(chromium) as context:
        first, second = context.new_page(), context.new_page()
        try:
            freeze = {"on": False}
            given: dict[str, int] = {}
            relay_states(first, "first", given)
            # Once frozen, the second screen hears of nothing but trial 0's "respond" (its
            # connection drops whenever there is news), so it still offers trial 0.
            relay_states(second, "second", given, lambda news: freeze["on"] and (
                news.get("state"), news.get("trial_index")) != ("respond", 0))
            open_page(first, server, s)
            open_page(second, server, s)
            wait_both_offer(first, second, given, 0)
            freeze["on"] = True
            first.keyboard.press("3")
            assert [(r[0], r[1]) for r in wait_answers(server, sid, 1)] == [(0, "3")]
            second.keyboard.press("5")  # answers trial 0 differently: 409
            second.wait_for_function("document.getElementById('message').textContent.includes('not recorded')")
            assert "already answered" in second.inner_text("#message")
            assert not second.evaluate("document.body.classList.contains('answerable')"), "trial 0 offered again"
            freeze["on"] = False
            wait_respond(second, 1)
            assert not any("Answer taken" in m for m in shown(second)), shown(second)
            assert pending(second, sid) == []
            assert server.rows("SELECT trial_index, response FROM answers") == [(0, "3")]
        finally:
            first.unroute_all(behavior="ignoreErrors")
            second.unroute_all(behavior="ignoreErrors")


#: Every answer a page sends is recorded (``window.vfSentAnswers``: answer ids), and the
#: page's answer sends can be held: with ``window.vfHoldAnswers = "fail"`` they fail as a
#: lost connection does; with ``"lose-reply"`` the first reaches the server (and is
#: committed) but its reply never reaches the page, and the later ones get no reply at
#: all (each ends only when the page gives it up); with ``"until-retry"`` none gets a reply
#: until "Try again now" has been clicked. All happen inside the page, so which
#: tab sent what is known exactly, whatever the browser's and the test driver's timing.
SENT_ANSWERS = """
window.vfSentAnswers = [];
window.vfHoldAnswers = false;
window.vfRetryClicked = false;
document.addEventListener('click', (e) => { if (e.target.id === 'retry') window.vfRetryClicked = true; }, true);
const vfFetch = window.fetch.bind(window);
const vfNoReply = (options) => new Promise((_, reject) => {
  if (options.signal) options.signal.addEventListener('abort', () => reject(new DOMException('aborted', 'AbortError')));
});
window.fetch = (url, options = {}) => {
  if (String(url).endsWith('/answer')) {
    window.vfSentAnswers.push(JSON.parse(options.body).answer_id);
    if (window.vfHoldAnswers === 'fail') return Promise.reject(new TypeError('Failed to fetch (held by the test)'));
    if (window.vfHoldAnswers === 'lose-reply') {
      if (window.vfSentAnswers.length === 1) vfFetch(url, {...options, signal: undefined});
      return vfNoReply(options);
    }
    // 'until-retry': no reply until "Try again now" is clicked, so that the page's own
    // timed resends cannot take the answer (and hide the button) before the click.
    if (window.vfHoldAnswers === 'until-retry' && !window.vfRetryClicked) return vfNoReply(options);
  }
  return vfFetch(url, options);
};
"""


def test_two_tabs_each_report_only_their_own_answer(server, chromium):
    # Two tabs of one browser share localStorage, where unsent answers wait. The tab that
    # did not answer must not send the other's answer and then say "Answer taken".
    s = start(server, "P36", 1)
    sid = s["session_id"]
    stored = f"JSON.parse(localStorage.getItem('vibrofocus.pending.{sid}') || '[]')"
    with watched_context(chromium, SENT_ANSWERS) as context:
        first, second = context.new_page(), context.new_page()
        given: dict[str, int] = {}
        try:
            relay_states(first, "first", given)
            relay_states(second, "second", given)
            open_page(first, server, s)
            open_page(second, server, s)
            wait_both_offer(first, second, given, 0)
            first.evaluate("window.vfHoldAnswers = 'fail'")  # the first tab's sends fail for now
            first.keyboard.press("3")
            first.wait_for_function("window.vfSentAnswers.length >= 2")  # sent, failed, and tried again
            answer_id = first.evaluate(f"{stored}[0].answer_id")
            assert second.evaluate(f"{stored}.map(a => a.answer_id)") == [answer_id], "the answer is stored, shared"
            second.evaluate("window.dispatchEvent(new Event('online'))")  # wakes the second tab's sender
            second.wait_for_timeout(1000)
            assert second.evaluate("window.vfSentAnswers") == [], "the second tab sent the first tab's answer"
            assert server.rows("SELECT trial_index FROM answers") == []
            first.evaluate("window.vfHoldAnswers = false")
            first.wait_for_function(f"{stored}.length === 0")
            assert [(r[0], r[1], r[3]) for r in wait_answers(server, sid, 1)] == [(0, "3", answer_id)]
            wait_respond(second, 1)
            first.wait_for_function("window.vfMessages.some(m => m.includes('Answer taken'))")
            assert not any("Answer taken" in m for m in shown(second)), shown(second)
            assert second.evaluate("window.vfSentAnswers") == []
        finally:
            first.unroute_all(behavior="ignoreErrors")
            second.unroute_all(behavior="ignoreErrors")


def test_sending_times_out_and_can_be_retried_without_a_duplicate(server, chromium):
    s = start(server, "P35", 1)
    sid = s["session_id"]
    with watched_context(chromium, "window.vfSendTimeoutMs = 800;" + SENT_ANSWERS) as context:
        page = context.new_page()
        open_page(page, server, s)
        wait_respond(page, 0)
        # The answer reaches the server and is committed, but the reply never reaches the
        # page; the page's sends after it get no reply at all.
        page.evaluate("window.vfHoldAnswers = 'lose-reply'")
        page.keyboard.press("4")
        page.wait_for_selector("#retry", state="visible")
        assert "not replied yet" in page.inner_text("#message")
        rows = wait_answers(server, sid, 1)
        kept = pending(page, sid)
        assert [(a["trial_index"], a["response"], a["answer_id"]) for a in kept] == [(0, [4], rows[0][3])], \
            "the answer stays stored on the page until the server confirms it"
        page.evaluate("window.vfHoldAnswers = 'until-retry'")
        page.click("#retry")
        page.wait_for_function("document.getElementById('message').textContent.includes('Answer taken')")
        assert page.is_hidden("#retry")
        assert pending(page, sid) == []
        wait_respond(page, 1)
        assert server.rows("SELECT trial_index, response, answer_id FROM answers") == [(0, "4", rows[0][3])]
        sent = page.evaluate("window.vfSentAnswers")
        assert len(sent) >= 2 and set(sent) == {rows[0][3]}, sent  # the same answer id, sent again
