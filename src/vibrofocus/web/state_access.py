"""The web app's secrets: the participant keys, the experimenter token, its cookie and login codes.

One part of :class:`~vibrofocus.web.state.WebState`, split along its jobs.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
import time

from fastapi import HTTPException, Request

from .security import same_secret

__all__ = ["AccessState", "login_cookie", "TOKEN_HEADER", "TOKEN_COOKIE", "KEY_HEADER", "LOGIN_CODE_TTL_S"]

TOKEN_HEADER = "X-Vibrofocus-Token"
TOKEN_COOKIE = "vf_token"
KEY_HEADER = "X-Participant-Key"
#: How long a one-time login link printed by ``vibrofocus serve`` stays valid, s.
LOGIN_CODE_TTL_S = 15 * 60.0


class AccessState:
    """Who may do what: the secrets part of :class:`~vibrofocus.web.state.WebState` (its
    ``secret``, ``token``, ``lock``, ``login_codes`` and ``logins``)."""

    TOKEN_MESSAGE = (
        "You are not logged in as the experimenter. Open the login link that 'vibrofocus serve' "
        "printed, or log in with the experimenter token."
    )
    KEY_MESSAGE = "This participant link does not belong to this session. Ask the experimenter for the right link."

    def participant_key(self, session_id: int) -> str:
        """The participant key of a session (URL-safe, 22 characters)."""
        mac = hmac.new(self.secret, f"participant-session:{int(session_id)}".encode(), hashlib.sha256).digest()
        return base64.urlsafe_b64encode(mac[:16]).decode().rstrip("=")

    def key_ok(self, session_id: int, key: str | None) -> bool:
        """True if ``key`` is the participant key of ``session_id`` (constant time)."""
        return same_secret(key, self.participant_key(session_id))

    def check_key(self, session_id: int, key: str | None) -> None:
        """Raise 403 unless ``key`` is the participant key of ``session_id``."""
        if not self.key_ok(session_id, key):
            raise HTTPException(403, detail=self.KEY_MESSAGE)

    def token_ok(self, given: str | None) -> bool:
        """True if ``given`` is the experimenter token (constant time)."""
        return same_secret(given, self.token)

    def cookie_ok(self, cookie_header: str | None) -> bool:
        """True if a ``Cookie`` header carries a current experimenter login."""
        return self.logins.valid(login_cookie(cookie_header))

    def check_token(self, request: Request) -> None:
        """Raise 401 unless the request carries the experimenter token or login cookie."""
        if not (self.token_ok(request.headers.get(TOKEN_HEADER)) or self.cookie_ok(request.headers.get("cookie"))):
            raise HTTPException(401, detail=self.TOKEN_MESSAGE)

    def new_login_code(self, ttl_s: float = LOGIN_CODE_TTL_S) -> str:
        """A one-time login code, valid for ``ttl_s`` seconds (see ``GET /login/{code}``)."""
        code = secrets.token_urlsafe(24)
        with self.lock:
            now = time.monotonic()
            for old in [c for c, until in self.login_codes.items() if until < now]:
                del self.login_codes[old]
            self.login_codes[code] = now + ttl_s
        return code

    def use_login_code(self, code: str) -> bool:
        """Spend a login code: True once for a valid, unexpired code, False otherwise."""
        with self.lock:
            match = next((c for c in self.login_codes if same_secret(code, c)), None)
            if match is None:
                return False
            until = self.login_codes.pop(match)
        return until >= time.monotonic()


def login_cookie(cookie_header: str | None) -> str | None:
    """The login cookie's value in a ``Cookie`` header, if any."""
    for part in (cookie_header or "").split(";"):
        name, _, value = part.strip().partition("=")
        if name == TOKEN_COOKIE:
            return value
    return None
