"""Throttling of wrong secrets per client: logins, experimenter tokens, participant keys.

Every secret here is long and random, so guessing one is hopeless unless the guesses are
many and fast. A client (an IP address) that gives :attr:`Throttle.limit` wrong secrets of
one kind within :attr:`Throttle.window_s` seconds is refused (429) for that kind, right
secret or not, until its oldest failure leaves the window. A request that carries no
secret at all is not a failure.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable

__all__ = ["Throttle", "THROTTLED_MESSAGE"]

#: What a throttled client reads.
THROTTLED_MESSAGE = "Too many wrong logins or links from this computer. Wait a minute, then try again."


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
