"""Screenshots of the experimenter and participant pages for the documentation.

Starts ``vibrofocus serve`` on a free localhost port with a temporary database, calibrates
a simulated participant, plans and starts a Study 2 session, answers a few trials in the
participant page, and writes docs/screenshots/experimenter.png and participant.png; then
pauses the session and opens its "Abort for good?" question for experimenter-abort.png
(1280x720) and experimenter-phone.png (the sessions card, 390 px wide).

Needs Debian's chromium (/usr/bin/chromium) and the playwright Python package::

    .venv/bin/python scripts/screenshots.py [--out docs/screenshots]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
from playwright.sync_api import sync_playwright

CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
TOKEN = "screenshots-" + "t" * 20
NAMES = ("experimenter.png", "participant.png", "experimenter-abort.png", "experimenter-phone.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "screenshots")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    base = f"http://127.0.0.1:{port}"
    headers = {"X-Vibrofocus-Token": TOKEN}
    with tempfile.TemporaryDirectory() as tmp:
        proc = subprocess.Popen(
            [sys.executable, "-m", "vibrofocus", "serve", "--db", f"{tmp}/studies.sqlite", "--port", str(port),
             "--no-browser", "--pace", "fast"],
            env=dict(os.environ, VIBROFOCUS_TOKEN=TOKEN),
        )
        try:
            _wait_up(base, headers)
            api = httpx.Client(base_url=base, headers=headers, timeout=60)
            api.post("/api/participants", json={"participant_id": "P07"}).raise_for_status()
            job = api.post("/api/calibrations", json={"participant_id": "P07", "seed": 7}).json()
            while (j := api.get(f"/api/calibrations/jobs/{job['job_id']}").json())["status"] == "running":
                time.sleep(0.3)
            if j["status"] != "done":
                raise SystemExit(f"calibration failed: {j['error']}")
            s = api.post("/api/sessions", json={
                "participant_id": "P07", "study": 2, "calibration_id": j["calibration_id"], "seed": 3,
            }).json()
            api.post(f"/api/sessions/{s['session_id']}/start").raise_for_status()
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
                ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
                ctx.set_default_timeout(60_000)
                part = ctx.new_page()
                part.set_viewport_size({"width": 1280, "height": 800})
                part.goto(base + s["participant_url"])
                part.click("#begin")
                answers = [("4", "5"), ("2",), ("5", "6"), ("8",)]
                for i, keys in enumerate(answers):
                    _wait_respond(part, i)
                    for k in keys:
                        part.keyboard.press(k)
                    part.keyboard.press("Enter")
                _wait_respond(part, len(answers))
                part.keyboard.press("2")
                part.keyboard.press("5")  # a selection in progress, before Enter
                part.mouse.move(5, 5)  # no hover highlight in the picture
                part.wait_for_timeout(400)  # let the CSS transitions finish
                part.screenshot(path=str(args.out / "participant.png"))

                exp = ctx.new_page()
                exp.goto(f"{base}/")  # the login form: the token goes in a POST, never in a URL
                exp.fill("#token", TOKEN)
                exp.click("main.login button[type=submit]")
                exp.wait_for_selector("#participant-card")
                exp.wait_for_function("document.querySelectorAll('#answers tbody tr').length >= 4")
                exp.locator("#cal-figure").evaluate("img => img.complete || new Promise(r => img.onload = r)")
                exp.select_option("#method", "inverse")
                exp.select_option("#location", "2")
                exp.click("#preview")
                exp.wait_for_function("!document.getElementById('preview-figure').hidden && document.getElementById('preview-figure').complete")
                exp.wait_for_function("(() => { const m = document.getElementById('cal-figure-message');"
                                      " return !m || m.hidden || !m.textContent.startsWith('Loading'); })()",
                                      timeout=60_000)
                exp.wait_for_timeout(300)
                exp.screenshot(path=str(args.out / "experimenter.png"), full_page=True)
                _abort_question(ctx, base, args.out)
                browser.close()
        finally:
            proc.terminate()
            try:
                proc.wait(60)  # a loaded machine takes a while to shut the server down
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(10)
    print(f"wrote {', '.join(NAMES)} in {args.out}")


def _abort_question(ctx, base: str, out: Path) -> None:
    """The sessions card with the question "Abort session N for good?" open, at 1280x720,
    and the same card on a 390 px phone."""
    exp = ctx.new_page()
    exp.set_viewport_size({"width": 1280, "height": 720})
    exp.goto(f"{base}/")
    exp.wait_for_selector("#participant-card")
    exp.click("#sessions button[data-action=pause]")
    exp.locator("#sessions td.status.paused").wait_for()
    exp.click("#sessions button[data-action=stop]")
    exp.locator("#sessions .confirm-stop").wait_for()
    exp.mouse.move(5, 5)
    exp.wait_for_timeout(300)
    exp.locator("#sessions-card").screenshot(path=str(out / "experimenter-abort.png"))
    exp.set_viewport_size({"width": 390, "height": 844})
    exp.wait_for_timeout(300)
    exp.locator("#sessions-card").screenshot(path=str(out / "experimenter-phone.png"))
    exp.keyboard.press("Escape")  # Keep it


def _wait_up(base: str, headers: dict[str, str]) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(base + "/api/rigs", headers=headers, timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            time.sleep(0.2)
    raise SystemExit("the server did not start")


def _wait_respond(page, i: int) -> None:
    page.wait_for_function(
        "i => document.body.dataset.state === 'respond' && document.body.dataset.trial === String(i)"
        " && document.body.classList.contains('answerable')", arg=i)


if __name__ == "__main__":
    main()
