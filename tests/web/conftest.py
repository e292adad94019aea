"""Fixtures of the web tests: a real ``vibrofocus serve`` in a subprocess, a real chromium.

The server binds 127.0.0.1 on a free port with a temporary database and the ``fast``
pace, and is always stopped. Browser tests use Debian's chromium through Playwright's
Python API (never a downloaded browser) and are skipped when it is missing.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.conftest import CHROMIUM, CHROMIUM_ARGS  # noqa: F401 - the browser is shared with the docs test

from .other_user import other_user, shared_dir  # noqa: F401 - fixtures: a real second local user

TOKEN = "test-token-" + "x" * 20


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``vibrofocus serve`` in a subprocess; can be killed (SIGKILL) and started again."""

    def __init__(self, db: Path, port: int, log: Path, *, args: tuple[str, ...] = (), env: dict | None = None) -> None:
        self.args = tuple(args)
        self.env = dict(env or {})
        self.db = db
        self.port = port
        self.log = log
        self.proc: subprocess.Popen | None = None
        self.base_url = f"http://127.0.0.1:{port}"
        self.token = TOKEN

    def start(self) -> None:
        env = dict(os.environ, VIBROFOCUS_TOKEN=self.token, PYTHONUNBUFFERED="1", **self.env)
        with open(self.log, "ab") as fh:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "vibrofocus", "serve", "--db", str(self.db), "--port", str(self.port),
                 "--no-browser", "--pace", "fast", *self.args],
                stdout=fh, stderr=subprocess.STDOUT, env=env,
            )
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}:\n{self.log.read_text()}")
            try:
                if httpx.get(f"{self.base_url}/api/rigs", headers=self.headers, timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        raise RuntimeError(f"server did not start:\n{self.log.read_text()}")

    def kill(self) -> None:
        """SIGKILL: no shutdown handler runs, as in a crash."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)

    @property
    def headers(self) -> dict[str, str]:
        return {"X-Vibrofocus-Token": self.token}

    # ------------------------------------------------------------------ helpers
    def api(self, method: str, path: str, *, headers: dict | None = None, **kwargs) -> httpx.Response:
        """A request with the experimenter token (and ``headers`` on top)."""
        return httpx.request(method, self.base_url + path, headers={**self.headers, **(headers or {})}, timeout=30, **kwargs)

    def plan(self, participant: str, study: int, *, n_training: int = 2, repetitions: int = 1, seed: int = 7) -> dict:
        """Add a participant and plan a session; returns the session (with participant_url)."""
        assert self.api("POST", "/api/participants", json={"participant_id": participant}).status_code == 201
        r = self.api("POST", "/api/sessions", json={
            "participant_id": participant, "study": study, "seed": seed,
            "n_training": n_training, "repetitions": repetitions,
        })
        assert r.status_code == 201, r.text
        return r.json()

    def login_link(self) -> str:
        """The one-time login link this server printed last (from its log)."""
        lines = [ln for ln in self.log.read_text().splitlines() if ln.startswith("one-time login link")]
        assert lines, self.log.read_text()
        return lines[-1].rsplit(" ", 1)[1]

    def rows(self, sql: str, *args) -> list[tuple]:
        """Read the database directly (a second connection, as another program would)."""
        con = sqlite3.connect(self.db)
        try:
            return con.execute(sql, args).fetchall()
        finally:
            con.close()


def login(page, server: Server) -> None:
    """Log in on the experimenter page through its login form (the token in a POST)."""
    page.goto(server.base_url + "/")
    page.fill("#token", server.token)
    page.click("main.login button[type=submit]")
    # Not the card alone: the card is on the page before its script has run, and a click
    # on "Add" then submitted the form natively (the page reloaded to "/?", under load).
    page.wait_for_selector("body[data-ready='true'] #participant-card")


def wait_for_held(page, held: list, what: str) -> None:
    """Let ``page`` run until a route handler has put a request into ``held`` (15 s at most:
    a loaded machine asks later)."""
    for _ in range(300):
        if held:
            return
        page.wait_for_timeout(50)
    assert held, f"the page never asked for {what}"


@contextlib.contextmanager
def serving(folder: Path) -> Iterator[Server]:
    """A started :class:`Server` with its database and log in ``folder``, always stopped."""
    srv = Server(folder / "studies.sqlite", free_port(), folder / "server.log")
    srv.start()
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture
def server(tmp_path):
    with serving(tmp_path) as srv:
        yield srv


@pytest.fixture
def page(chromium):
    context = chromium.new_context(viewport={"width": 1280, "height": 800})
    pg = context.new_page()
    pg.set_default_timeout(15_000)
    try:
        yield pg
    finally:
        context.close()


#: ``(selector, property) => ratio``: the WCAG contrast ratio of an element's colour
#: ``property`` (``color`` or ``outlineColor``) against the background it is drawn on,
#: from computed styles. Opacity of the element and its ancestors is blended in; the
#: background is the nearest ancestor's non-transparent background colour (for an
#: outline, drawn outside the element, the search starts at the parent).
CONTRAST_JS = """
([selector, property]) => {
  const el = document.querySelector(selector);
  const parse = (c) => {
    const v = c.match(/rgba?\\(([^)]+)\\)/)[1].split(/[\\s,\\/]+/).filter(Boolean).map(Number);
    return [v[0], v[1], v[2], v.length > 3 ? v[3] : 1];
  };
  const fg = parse(getComputedStyle(el)[property]);
  let alpha = fg[3];
  for (let n = el; n; n = n.parentElement) alpha *= Number(getComputedStyle(n).opacity);
  let bg = [255, 255, 255, 1];
  for (let n = property === "outlineColor" ? el.parentElement : el; n; n = n.parentElement) {
    const b = parse(getComputedStyle(n).backgroundColor);
    if (b[3] > 0) { bg = b; break; }
  }
  const seen = fg.slice(0, 3).map((v, i) => v * alpha + bg[i] * (1 - alpha));
  const lum = (c) => c.map((v) => { v /= 255; return v <= 0.03928 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4; })
    .reduce((s, v, i) => s + v * [0.2126, 0.7152, 0.0722][i], 0);
  const [hi, lo] = [lum(seen), lum(bg.slice(0, 3))].sort((a, b) => b - a);
  return (hi + 0.05) / (lo + 0.05);
}
"""


def contrast(page, selector: str, prop: str = "color") -> float:
    """The WCAG contrast ratio of ``selector``'s ``prop`` on the page (see CONTRAST_JS)."""
    return page.evaluate(CONTRAST_JS, [selector, prop])


def calibrate(server: Server, participant: str, seed: int = 4) -> int:
    """Calibrate ``participant`` on the simulated forearm through the API; the calibration id."""
    job = server.api("POST", "/api/calibrations", json={"participant_id": participant, "seed": seed}).json()
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        j = server.api("GET", f"/api/calibrations/jobs/{job['job_id']}").json()
        if j["status"] != "running":
            assert j["status"] == "done", j
            return j["calibration_id"]
        time.sleep(0.3)
    raise AssertionError("the calibration did not finish")
