"""Throttling of wrong secrets per client and kind: login links, experimenter tokens, participant keys.

A client (an IP address) that gives :attr:`Throttle.limit` wrong secrets of one kind
(``login-link``, ``token``, ``key``) within :attr:`Throttle.window_s` seconds has its
further wrong secrets of that kind answered 429 (with ``Retry-After``) until its oldest
failure leaves the window. A request that carries no secret is not a failure.

Two rules keep the throttle from locking anybody out:

- **The right secret always gets in.** Every secret here is random (a participant key
  128 bits, the token and login links 192 bits): at a million guesses a second, finding
  one takes longer than the age of the universe, throttled or not. What refusing the
  right secret would add is a lockout anybody could trigger: every client on the lab
  computer is 127.0.0.1, so ten wrong tokens a minute from any local process (or any web
  page, below) would keep the experimenter and the participants out. Nor would the
  throttle stop a local guesser if it did refuse: the whole of 127.0.0.0/8 reaches the
  server, so a local process can give each guess its own address.
- **Requests another site made are not counted** (:func:`counts_as_guess`). A browser
  says in ``Sec-Fetch-Site`` who made a request; one made by a page of another site
  (``cross-site``) or of another port of this computer (``same-site``) is a web page's
  doing (an ``<img>`` pointing at ``/login/junk``), not a guess by someone who could use
  the answer: it cannot read the reply. Its wrong secret is refused but not counted.

So the throttle is a brake on floods of wrong secrets (each answered cheaply and not
logged), not what keeps the secrets safe; their length does that.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable

__all__ = ["Throttle", "THROTTLED_MESSAGE", "counts_as_guess"]

#: What a throttled client reads.
THROTTLED_MESSAGE = "Too many wrong logins or links from this computer. Wait a minute, then try again."

#: ``Sec-Fetch-Site`` values of requests made by a page that is not this server's.
_OTHER_SITES = frozenset({"cross-site", "same-site"})


def counts_as_guess(sec_fetch_site: str | None) -> bool:
    """Whether a wrong secret in a request counts against its client.

    Parameters
    ----------
    sec_fetch_site : str or None
        The request's ``Sec-Fetch-Site`` header (None when absent: a program, or an old
        browser).

    Returns
    -------
    bool
        False for a request a page of another site or port made (the browser says
        ``cross-site`` or ``same-site``); True otherwise.
    """
    return (sec_fetch_site or "").strip().lower() not in _OTHER_SITES


class Throttle:
    """Failed attempts per (client, kind) in a sliding window.

    Parameters
    ----------
    limit : int
        Failures allowed in the window; the next attempt is refused.
    window_s : float
        The window, s.
    clock : callable
        Time source, s.
    """

    def __init__(self, limit: int = 10, window_s: float = 60.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.limit, self.window_s, self.clock = int(limit), float(window_s), clock
        self._failures: dict[tuple[str, str], deque[float]] = {}
        self._lock = threading.Lock()

    def retry_after(self, client: str, kind: str) -> int | None:
        """Seconds until ``client`` may try a secret of ``kind`` again; None if it may now."""
        with self._lock:
            times = self._recent(client, kind)
            if len(times) < self.limit:
                return None
            return max(1, math.ceil(times[0] + self.window_s - self.clock()))

    def failed(self, client: str, kind: str) -> None:
        """Count a wrong secret of ``kind`` from ``client``."""
        with self._lock:
            self._recent(client, kind).append(self.clock())
            if len(self._failures) > 10_000:  # many clients: forget those with nothing recent
                for k in [k for k, v in self._failures.items() if not v or v[-1] < self.clock() - self.window_s]:
                    del self._failures[k]

    def _recent(self, client: str, kind: str) -> deque[float]:
        times = self._failures.setdefault((client, kind), deque())
        horizon = self.clock() - self.window_s
        while times and times[0] <= horizon:
            times.popleft()
        return times
