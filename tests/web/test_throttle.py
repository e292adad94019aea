"""The throttle of wrong secrets, unit by unit (issue 38, item 11)."""

from __future__ import annotations

import asyncio
import threading

from vibrofocus.web.security import SecurityMiddleware
from vibrofocus.web.throttle import Throttle, counts_as_guess


def test_requests_another_site_made_do_not_count():
    assert not counts_as_guess("cross-site")
    assert not counts_as_guess("same-site")  # another port of this computer
    assert not counts_as_guess(" Cross-Site ")
    assert counts_as_guess("same-origin")
    assert counts_as_guess("none")  # typed or opened from outside the browser
    assert counts_as_guess(None)  # a program


class _Web:
    """The parts of WebState the middleware uses, with a real Throttle."""

    TOKEN_MESSAGE = "not logged in"
    KEY_MESSAGE = "wrong key"

    def __init__(self) -> None:
        self.now = [0.0]
        self.throttle = Throttle(limit=3, window_s=60.0, clock=lambda: self.now[0])
        self.lock = threading.Lock()

    def token_ok(self, token):
        return token == "right-token"

    def key_ok(self, sid, key):
        return key == "right-key"

    def cookie_ok(self, cookie):
        return False


async def _status(mw, path, headers):
    sent = []

    async def receive():
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": "GET", "path": path, "query_string": b"", "client": ("127.0.0.1", 5),
             "headers": [(k.lower().encode(), v.encode()) for k, v in {"host": "127.0.0.1:8000", **headers}.items()]}
    await mw(scope, receive, send)
    return sent[0]["status"]


def test_the_right_secret_passes_the_throttle_and_other_sites_never_count():
    web = _Web()

    async def app(scope, receive, send):
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    mw = SecurityMiddleware(app, web, allowed_hosts=["127.0.0.1"])

    def status(path, **headers):
        return asyncio.run(_status(mw, path, headers))

    for _ in range(10):  # a web page's images: refused, never counted
        assert status("/api/participant/1/state", **{"x-participant-key": "junk", "sec-fetch-site": "cross-site"}) == 403
    assert web.throttle.retry_after("127.0.0.1", "key") is None
    codes = [status("/api/participant/1/state", **{"x-participant-key": "junk"}) for _ in range(5)]
    assert codes == [403, 403, 403, 429, 429]
    assert status("/api/participant/1/state", **{"x-participant-key": "right-key"}) == 200
    assert status("/api/rigs", **{"x-vibrofocus-token": "wrong"}) == 401  # another kind: its own count
    assert status("/api/rigs", **{"x-vibrofocus-token": "right-token"}) == 200
    web.now[0] = 61.0
    assert status("/api/participant/1/state", **{"x-participant-key": "junk"}) == 403  # the window has passed
