"""The guard in front of every route: host, origin, size and access checks, security headers.

It is a plain ASGI middleware, so that it acts before FastAPI reads or parses anything:

1. **Host allow-list.** A request must name this server by an allowed host name
   (``127.0.0.1``, ``localhost``, ``::1`` and the ``--host`` it was started with). A web
   page whose own domain was made to point at 127.0.0.1 (DNS rebinding) sends its own
   name and is refused.
2. **Origin check.** Every request that can change something (any method other than
   GET, HEAD and OPTIONS) must come from a page of this server: its ``Origin`` (or, when
   a browser sends none, its ``Referer``) must be this server's own address, port
   included. Browsers treat every port of 127.0.0.1 as the same *site*, so the
   ``SameSite=Strict`` cookie alone would still reach this server from a page served by
   any other local program; the origin check is what stops such a page.
   Experimenter requests authenticated by the login cookie are also refused when the
   browser says (``Sec-Fetch-Site``) that another origin made them, reads included.
3. **Authentication before the body.** Experimenter routes need the token (header) or
   the login cookie, participant routes the session's key, checked from the headers
   alone; a request that fails is answered before a byte of its body is read.
   Wrong secrets are counted per client and kind (:mod:`.throttle`): a client that gives
   too many has its further wrong ones answered 429 for a while. The right secret always
   gets in, and wrong secrets in requests another site's page made are not counted, so
   neither a local process nor a web page can lock the experimenter or a participant out.
4. **Size limit and deadline.** A body longer than :data:`MAX_BODY_BYTES` is refused (413)
   while it is read, so a huge upload costs no memory; a body that has not arrived whole
   within ``body_timeout_s`` (:data:`BODY_TIMEOUT_S`) is refused (408), so a client that
   declares a body and never sends it cannot hold a connection for ever.
5. **Headers on every answer.** ``Content-Security-Policy`` (``frame-ancestors 'none'``:
   no other page can frame these pages; forms post only to this server),
   ``X-Frame-Options: DENY``, ``X-Content-Type-Options: nosniff``,
   ``Referrer-Policy: same-origin`` and ``Cache-Control: no-store`` on the API.

Comparisons of secrets use :func:`hmac.compare_digest` on bytes (see :func:`same_secret`),
which also accepts text that is not ASCII instead of raising.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Callable, Iterable
from typing import Any
from urllib.parse import parse_qs, urlsplit

from .throttle import THROTTLED_MESSAGE, counts_as_guess

__all__ = [
    "MAX_BODY_BYTES",
    "BODY_TIMEOUT_S",
    "LOCAL_HOSTS",
    "SecurityMiddleware",
    "same_secret",
    "host_name",
]

#: Longest request body accepted, bytes (an answer is about 150 bytes).
MAX_BODY_BYTES = 64 * 1024
#: Longest wait for a whole request body once the head is in, s.
BODY_TIMEOUT_S = 10.0
#: What a client whose body did not come in time reads.
BODY_TIMEOUT_MESSAGE = "The request's body did not arrive in time, so it was dropped. Try again."
#: Host names that always reach this server.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")

_SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})

# No page here shows text a visitor wrote as HTML (the scripts build text nodes), so the
# policy is about framing and forms; a script-src would also forbid the browser tests'
# page probes (Playwright evaluates them as strings).
_PAGE_CSP = "frame-ancestors 'none'; object-src 'none'; base-uri 'none'; form-action 'self'"
# Analysis reports are written by `vibrofocus analyze`: they may style and embed images
# inline, but run no script and, like every page here, cannot be framed.
_REPORT_CSP = (
    "default-src 'self'; script-src 'none'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
    "object-src 'none'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)

Scope = dict[str, Any]
Receive = Callable[[], Awaitable[dict[str, Any]]]
Send = Callable[[dict[str, Any]], Awaitable[None]]


def same_secret(given: str | bytes | None, expected: str | bytes) -> bool:
    """Constant-time equality of two secrets; False for a missing one.

    Text is compared as UTF-8 bytes, so a secret with characters outside ASCII is simply
    wrong, never an error.
    """
    if given is None:
        return False

    def raw(x: str | bytes) -> bytes:
        return x if isinstance(x, bytes) else x.encode("utf-8", "surrogateescape")

    import hmac

    return hmac.compare_digest(raw(given), raw(expected))


def host_name(host_header: str) -> str:
    """The host name of a ``Host`` header value, lower case, without port or brackets."""
    value = host_header.strip().lower()
    if value.startswith("["):  # [::1]:8000
        return value[1:].split("]", 1)[0]
    if value.count(":") == 1:
        return value.split(":", 1)[0]
    return value


def _origin_of(url: str) -> str | None:
    """``scheme://host[:port]`` of a URL, lower case; None if it has none."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return None
    if not parts.scheme or not parts.netloc:
        return None
    return f"{parts.scheme}://{parts.netloc}".lower()


class SecurityMiddleware:
    """ASGI middleware applying the checks of this module.

    Parameters
    ----------
    app : ASGI application
        The FastAPI app it guards.
    web : WebState
        Gives the token and participant-key checks (``token_ok``, ``cookie_ok``,
        ``key_ok``).
    allowed_hosts : iterable of str
        Host names accepted in the ``Host`` header (lower case, no port).
    max_body_bytes : int
        Largest request body accepted.
    body_timeout_s : float
        Longest wait for a whole request body, s.
    """

    def __init__(self, app: Any, web: Any, *, allowed_hosts: Iterable[str], max_body_bytes: int = MAX_BODY_BYTES,
                 body_timeout_s: float = BODY_TIMEOUT_S) -> None:
        self.app = app
        self.web = web
        self.allowed_hosts = frozenset(h.strip("[]").lower() for h in allowed_hosts)
        self.max_body_bytes = int(max_body_bytes)
        self.body_timeout_s = float(body_timeout_s)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", ())}
        path: str = scope.get("path", "")
        method: str = scope.get("method", "GET").upper()

        host = headers.get("host", "")
        if host_name(host) not in self.allowed_hosts:
            shown = " or ".join(sorted(self.allowed_hosts))
            await _refuse(send, 400, f"This server answers only when opened at {shown}. Open the address that 'vibrofocus serve' printed.")
            return
        own_origin = f"http://{host}".lower()

        if method not in _SAFE_METHODS:
            origin = headers.get("origin")
            if origin is None and "referer" in headers:
                origin = _origin_of(headers["referer"]) or "null"
            if origin is not None and origin.lower() != own_origin:
                await _refuse(send, 403, "This request came from a page that is not part of this study server, so it was refused.")
                return

        client = (scope.get("client") or ("unknown",))[0]
        query = scope.get("query_string", b"").decode("latin-1")
        denied = self._access(path, headers, client, query)
        if denied is not None:
            status, message, *retry = denied
            await _refuse(send, status, message, retry_after=retry[0] if retry else None)
            return

        if method not in _SAFE_METHODS:
            declared = headers.get("content-length")
            if declared is not None and (not declared.isdigit() or int(declared) > self.max_body_bytes):
                await _refuse(send, 413, "This request is too large for the study server.")
                return
            try:
                body, ok = await asyncio.wait_for(self._read_body(receive), self.body_timeout_s)
            except asyncio.TimeoutError:
                await _refuse(send, 408, BODY_TIMEOUT_MESSAGE)
                return
            if not ok:
                await _refuse(send, 413, "This request is too large for the study server.")
                return
            if body and body[-1]["type"] == "http.disconnect":
                return  # the client left (or was closed to make room) before its body came
            receive = _replay(body, receive)

        await self.app(scope, receive, _with_headers(send, path))

    # ------------------------------------------------------------------ checks
    def _access(self, path: str, headers: dict[str, str], client: str = "unknown", query: str = "") -> tuple | None:
        """``(status, message[, retry_after_s])`` if the request may not reach its route, else None."""
        web = self.web
        if path.startswith(("/api/participant/", "/participant/")):
            parts = path.split("/")
            sid = parts[3] if path.startswith("/api/") else parts[2]
            # ASCII digits only: str.isdigit() also takes '²' and '١' (which int() reads as 1).
            if not (sid.isascii() and sid.isdigit()) or len(sid) > 15:
                return 404, "There is no such session."
            if path.startswith("/api/"):
                key = headers.get("x-participant-key")
            else:
                key = (parse_qs(query).get("key") or [None])[0]
            return self._secret(client, "key", key, lambda: web.key_ok(int(sid), key), 403, web.KEY_MESSAGE, headers)
        if path.startswith(("/api/", "/reports/")):
            token = headers.get("x-vibrofocus-token")
            if token is not None:
                return self._secret(client, "token", token, lambda: web.token_ok(token), 401, web.TOKEN_MESSAGE, headers)
            if web.cookie_ok(headers.get("cookie")):
                site = headers.get("sec-fetch-site")
                if site is not None and site not in ("same-origin", "none"):
                    return 403, "This request came from a page that is not part of this study server, so it was refused."
                return None
            return 401, web.TOKEN_MESSAGE
        return None

    def _secret(self, client: str, kind: str, given: str | None, ok: Callable[[], bool], status: int, message: str,
                headers: dict[str, str]) -> tuple | None:
        """Check a secret under the client's throttle (see :mod:`.throttle`).

        The right secret always passes; a wrong one (not a missing one) counts unless
        another site's page sent it; over the limit, a wrong one gets 429.
        """
        if ok():
            return None
        wait = self.web.throttle.retry_after(client, kind)
        if wait is not None:
            return 429, THROTTLED_MESSAGE, wait
        if given and counts_as_guess(headers.get("sec-fetch-site")):
            self.web.throttle.failed(client, kind)
        return status, message

    async def _read_body(self, receive: Receive) -> tuple[list[dict[str, Any]], bool]:
        """Read the whole body, at most ``max_body_bytes``; ``(messages, within limit)``."""
        messages: list[dict[str, Any]] = []
        size = 0
        while True:
            message = await receive()
            messages.append(message)
            if message["type"] != "http.request":
                return messages, True
            size += len(message.get("body", b""))
            if size > self.max_body_bytes:
                return messages, False
            if not message.get("more_body", False):
                return messages, True


def _replay(messages: list[dict[str, Any]], receive: Receive) -> Receive:
    """A ``receive`` that gives the messages already read, then the client's own."""
    queue = list(messages)

    async def again() -> dict[str, Any]:
        if queue:
            return queue.pop(0)
        return await receive()

    return again


def _with_headers(send: Send, path: str) -> Send:
    """Wrap ``send`` to add the security headers to the response start."""
    csp = _REPORT_CSP if path.startswith("/reports/") else _PAGE_CSP
    extra = [
        (b"content-security-policy", csp.encode()),
        (b"x-frame-options", b"DENY"),
        (b"x-content-type-options", b"nosniff"),
        (b"referrer-policy", b"same-origin"),
    ]
    if path.startswith("/api/") or path == "/" or path.startswith("/login"):
        extra.append((b"cache-control", b"no-store"))

    async def wrapped(message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            names = {k.lower() for k, _ in message.get("headers", [])}
            message = dict(message)
            message["headers"] = list(message.get("headers", [])) + [(k, v) for k, v in extra if k not in names]
        await send(message)

    return wrapped


async def _refuse(send: Send, status: int, detail: str, *, retry_after: int | None = None) -> None:
    """Answer ``{"detail": ...}`` with ``status`` (and the security headers)."""
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
               (b"connection", b"close")]
    if retry_after is not None:
        headers.append((b"retry-after", str(int(retry_after)).encode()))
    await _with_headers(send, "/api/")({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
