"""Experimenter logins: a random id per login, revoked by logout, kept across restarts.

The login cookie holds a random id (256 bits), never the token. The server keeps only the
ids' SHA-256 and their expiry, in ``<database>.web-logins`` (owner-only, written
atomically), bound to the experimenter token: a server restarted with the same
``VIBROFOCUS_TOKEN`` keeps its experimenters logged in, one started with a new token
logs everybody out. Logout deletes the id, so a copied cookie stops working with it.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import secrets
import threading
import time
from pathlib import Path

from .._atomic import write_text
from .private import private_file

__all__ = ["LoginSessions", "LOGIN_TTL_S"]

log = logging.getLogger(__name__)

#: How long a login lasts, s.
LOGIN_TTL_S = 12 * 3600.0


def _digest(value: str) -> str:
    return hashlib.sha256(value.encode("utf-8", "surrogateescape")).hexdigest()


class LoginSessions:
    """The logins of one server.

    Parameters
    ----------
    path : Path
        Where the ids' hashes are kept.
    secret : bytes
        The server secret (binds the file to the token without storing it).
    token : str
        The experimenter token.
    ttl_s : float
        Lifetime of a login, s.
    """

    def __init__(self, path: Path, secret: bytes, token: str, ttl_s: float = LOGIN_TTL_S) -> None:
        self.path, self.ttl_s = Path(path), float(ttl_s)
        self._bound = hmac.new(secret, b"experimenter-logins:" + token.encode(), hashlib.sha256).hexdigest()
        self._lock = threading.Lock()
        self._ids: dict[str, float] = self._load()

    def new(self) -> str:
        """Start a login; returns the cookie value (a fresh random id)."""
        value = secrets.token_urlsafe(32)
        with self._lock:
            self._ids[_digest(value)] = time.time() + self.ttl_s
            self._save()
        return value

    def valid(self, value: str | None) -> bool:
        """True if ``value`` is an unexpired login id."""
        if not value:
            return False
        with self._lock:
            until = self._ids.get(_digest(value))
        return until is not None and until > time.time()

    def revoke(self, value: str | None) -> None:
        """End a login (logout)."""
        if not value:
            return
        with self._lock:
            if self._ids.pop(_digest(value), None) is not None:
                self._save()

    def _load(self) -> dict[str, float]:
        try:
            data = json.loads(self.path.read_text())
        except (OSError, ValueError):
            return {}
        if not isinstance(data, dict) or data.get("bound") != self._bound:
            return {}  # another token (or no file): nobody is logged in
        now = time.time()
        return {k: float(v) for k, v in dict(data.get("logins", {})).items() if isinstance(v, (int, float)) and v > now}

    def _save(self) -> None:
        now = time.time()
        self._ids = {k: v for k, v in self._ids.items() if v > now}
        private_file(self.path)  # 0600 before the first write; atomic writes keep the mode
        try:
            write_text(self.path, json.dumps({"bound": self._bound, "logins": self._ids}), what="login list")
        except Exception:  # noqa: BLE001 - the login still works in memory
            log.warning("the list of logins could not be saved; logins end when the server stops")
