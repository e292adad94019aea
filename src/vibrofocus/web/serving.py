"""How ``vibrofocus serve`` runs the app: connection limits, timeouts and a log that cannot flood.

uvicorn accepts every TCP connection and keeps a silent one open for ever; enough of them
use up the process's file descriptors, and then nobody gets a page while every refused
accept writes a line to the log. Here each connection is held to:

- a **header timeout**: a connection that has not sent a whole request head within
  ``header_timeout_s`` (a silent socket, or one that sends a header a byte at a time)
  is closed;
- a **keep-alive timeout**: a connection idle between requests is closed after
  ``keep_alive_s`` (uvicorn's own);
- a **body deadline**: a request whose body has not arrived whole within
  ``body_timeout_s`` gets ``408`` and its connection is closed (checked by
  :class:`~vibrofocus.web.security.SecurityMiddleware`, which reads every body);
- a **cap** on open connections (below the file-descriptor limit): a connection beyond
  it closes the longest-idle connection (one with no request in progress for more than
  ``head_grace_s``), or else the one that has waited longest for a request body that
  does not come (a client that declared a body and sends nothing holds a connection
  without doing anything), or else the longest-idle one still inside its grace. The
  grace matters under a flood of stalled bodies: a connection that has just opened has
  not had the time to send its head, and without the grace the flood's newer
  connections closed it as "idle" before its request (an emergency stop, a
  participant's answer) was read. So neither idle sockets nor stalled bodies can lock
  out a participant or the experimenter; when every connection is busy with real work,
  the new one gets ``503`` with a sentence saying why, and is closed;
- **reserved slots for the emergency stop**: beyond the cap, :data:`RESERVED_SLOTS` more
  connections are accepted that answer only ``POST /api/emergency-stop`` (everything else
  on them gets the ``503``), so the stop button works whatever the load.
  ``vibrofocus stop`` reaches the same stop without TCP at all (:mod:`.emergency`).

Log records pass through :class:`FloodFilter`: a message repeated faster than a few times
a minute is counted, not written, and the count is written once the burst is over.
"""

from __future__ import annotations

import errno
import socket

import json
import logging
import sys
import time
from dataclasses import dataclass
from typing import Any

__all__ = ["ServerLimits", "FloodFilter", "guarded_protocol", "effective_cap", "run", "RESERVED_SLOTS", "HEAD_GRACE_S"]

log = logging.getLogger(__name__)

#: File descriptors kept free for the database, calibrations, reports and the listener.
FD_RESERVE = 128

#: Connections beyond the cap kept for ``POST /api/emergency-stop`` only.
RESERVED_SLOTS = 8
#: Default time a connection has, after opening or after its last response, to start a
#: request before it counts as idle, s (a client on a network with a round trip under a
#: second sends its request head well within it).
HEAD_GRACE_S = 0.5
#: The one request a reserved connection may carry.
EMERGENCY_STOP = ("POST", "/api/emergency-stop")

#: What a connection beyond the cap reads.
FULL_MESSAGE = (
    "The study server has too many open connections right now. Try again in a few seconds; "
    "if this persists, tell the experimenter."
)


@dataclass(frozen=True)
class ServerLimits:
    """Connection limits of ``vibrofocus serve``.

    Attributes
    ----------
    max_connections : int
        Most connections open at once (lowered to fit the file-descriptor limit).
    header_timeout_s : float
        Longest wait for a whole request head on a connection, s.
    keep_alive_s : float
        Longest idle time between two requests on one connection, s.
    body_timeout_s : float
        Longest wait for the whole body of a request once its head is in, s (then 408).
    head_grace_s : float
        Time a connection has, after opening or after its last response, to start a
        request before the cap may close it as idle, s (:data:`HEAD_GRACE_S`).
    """

    max_connections: int = 1000
    header_timeout_s: float = 10.0
    keep_alive_s: float = 5.0
    body_timeout_s: float = 10.0
    head_grace_s: float = HEAD_GRACE_S

    def __post_init__(self) -> None:
        if self.max_connections < 4:
            raise ValueError(f"max_connections must be at least 4, got {self.max_connections}")
        if not all(t > 0 for t in (self.header_timeout_s, self.keep_alive_s, self.body_timeout_s, self.head_grace_s)):
            raise ValueError("header_timeout_s, keep_alive_s, body_timeout_s and head_grace_s must be positive")


def effective_cap(limits: ServerLimits) -> int:
    """The connection cap after leaving :data:`FD_RESERVE` descriptors free.

    Parameters
    ----------
    limits : ServerLimits
        The limits asked for.

    Returns
    -------
    int
        ``limits.max_connections``, lowered to fit the process's file-descriptor limit.
    """
    try:
        import resource
    except ImportError:  # Windows: no descriptor limit of this kind
        return limits.max_connections
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY:
        return limits.max_connections
    return max(4, min(limits.max_connections, soft - FD_RESERVE))


def guarded_protocol(limits: ServerLimits, cap: int | None = None) -> type:
    """uvicorn's h11 protocol with the header timeout and the connection cap of ``limits``.

    Parameters
    ----------
    limits : ServerLimits
        The limits.
    cap : int, optional
        Connection cap; default :func:`effective_cap`.

    Returns
    -------
    type
        An ``asyncio.Protocol`` class for ``uvicorn.Config(http=...)``.
    """
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    cap = effective_cap(limits) if cap is None else int(cap)
    full_body = json.dumps({"detail": FULL_MESSAGE}).encode()
    full_response = (
        b"HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: 5\r\n"
        b"connection: close\r\ncontent-length: " + str(len(full_body)).encode() + b"\r\n\r\n" + full_body
    )

    class GuardedH11Protocol(H11Protocol):
        """One connection, under the limits (see the module's docstring)."""

        _idle_since: float = 0.0
        _head_timer: Any = None
        _reserved: bool = False

        def connection_made(self, transport: Any) -> None:  # noqa: D102 - asyncio's
            super().connection_made(transport)
            self._idle_since = time.monotonic()
            if len(self.connections) > cap and not self._evict():
                if not self._reserve():
                    self.connections.discard(self)
                    transport.write(full_response)
                    transport.close()
                    return
            self._arm_head_timer()

        def data_received(self, data: bytes) -> None:  # noqa: D102 - asyncio's
            super().data_received(data)
            if self._busy():
                self._disarm_head_timer()
            elif self._head_timer is None and not self.transport.is_closing():
                self._arm_head_timer()  # the start of a request head after a keep-alive wait

        def on_response_complete(self) -> None:  # noqa: D102 - uvicorn's
            self._idle_since = time.monotonic()
            self._disarm_head_timer()
            super().on_response_complete()

        def connection_lost(self, exc: Exception | None) -> None:  # noqa: D102 - asyncio's
            self._disarm_head_timer()
            super().connection_lost(exc)

        # -------------------------------------------------------------- helpers
        def _busy(self) -> bool:
            """A request is in progress (its head is read, its response not finished)."""
            return self.cycle is not None and not self.cycle.response_complete

        def _stalled(self) -> bool:
            """Busy only waiting for the client's request body (the route has not begun)."""
            return self._busy() and self.conn.their_state is h11.SEND_BODY

        def _others(self) -> list[GuardedH11Protocol]:
            return [c for c in self.connections if c is not self and isinstance(c, GuardedH11Protocol)]

        def _evict(self) -> bool:
            """Make room: close the longest-idle other connection past its grace
            (``limits.head_grace_s``), else the longest-stalled body, else the longest-idle
            one still in its grace.

            False if every other connection is busy with a request it has whole.
            """
            others = self._others()
            idle_before = time.monotonic() - limits.head_grace_s
            for pick in (lambda c: not c._busy() and c._idle_since < idle_before,
                         GuardedH11Protocol._stalled,
                         lambda c: not c._busy()):
                chosen = [c for c in others if pick(c)]
                if chosen:
                    min(chosen, key=lambda c: c._idle_since)._close()
                    return True
            return False

        def _reserve(self) -> bool:
            """Take one of the slots kept for the emergency stop; False if none is left.

            A reserved connection that has not sent its request head yet gives way to a
            newer one, so silent sockets cannot hold the reserve either.
            """
            reserved = [c for c in self._others() if c._reserved]
            if len(reserved) >= RESERVED_SLOTS:
                waiting = [c for c in reserved if c.cycle is None]
                if not waiting:
                    return False
                min(waiting, key=lambda c: c._idle_since)._close()
            self._reserved = True
            self.app = _only_emergency_stop(self.app)
            return True

        def _arm_head_timer(self) -> None:
            self._head_timer = self.loop.call_later(limits.header_timeout_s, self._head_timeout)

        def _disarm_head_timer(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None

        def _head_timeout(self) -> None:
            self._head_timer = None
            if not self._busy():
                self._close()

        def _close(self) -> None:
            self._disarm_head_timer()
            self.connections.discard(self)
            if not self.transport.is_closing():
                try:
                    self.conn.send(h11.ConnectionClosed())
                except h11.LocalProtocolError:
                    pass  # mid-request head: nothing to tell the peer
                self.transport.close()

    def _only_emergency_stop(app: Any) -> Any:
        """An ASGI app passing only the emergency stop to ``app``; the rest gets the 503."""

        async def reserved(scope: dict, receive: Any, send: Any) -> None:
            if (scope.get("method", "").upper(), scope.get("path")) == EMERGENCY_STOP:
                await app(scope, receive, send)
                return
            await send({"type": "http.response.start", "status": 503, "headers": [
                (b"content-type", b"application/json"), (b"retry-after", b"5"), (b"connection", b"close"),
                (b"content-length", str(len(full_body)).encode())]})
            await send({"type": "http.response.body", "body": full_body})

        return reserved

    return GuardedH11Protocol


class FloodFilter(logging.Filter):
    """Let through at most ``burst`` records of one message per ``window_s`` seconds.

    The rest are counted; the first record of that message after the window says how
    many were left out. A total of ``total`` records per window bounds the log whatever
    the messages.

    Parameters
    ----------
    burst : int
        Records of one message (logger and format string) per window.
    total : int
        Records of all messages per window.
    window_s : float
        The window, s.
    clock : callable
        Time source, s (``time.monotonic``).
    """

    def __init__(self, burst: int = 5, total: int = 100, window_s: float = 60.0, clock: Any = time.monotonic) -> None:
        super().__init__()
        self.burst, self.total, self.window_s, self.clock = int(burst), int(total), float(window_s), clock
        self._start = clock()
        self._counts: dict[tuple[str, str], int] = {}
        self._dropped: dict[tuple[str, str], int] = {}
        self._passed = 0

    def filter(self, record: logging.LogRecord) -> bool:  # noqa: D102 - logging's
        now = self.clock()
        if now - self._start >= self.window_s:
            self._start, self._counts, self._passed = now, {}, 0
        what = (record.name, str(record.msg))
        n = self._counts[what] = self._counts.get(what, 0) + 1
        if n > self.burst or self._passed >= self.total:
            self._dropped[what] = self._dropped.get(what, 0) + 1
            return False
        self._passed += 1
        left_out = self._dropped.pop(what, 0)
        if left_out:
            record.msg = f"{record.msg} [{left_out} more like this were left out of the log]"
        return True


def _logging(level: int = logging.WARNING) -> None:
    """One stderr handler on the root logger, through a :class:`FloodFilter`."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.addFilter(FloodFilter())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access", "asyncio"):
        logging.getLogger(name).handlers[:] = []
        logging.getLogger(name).propagate = True


def listen(host: str, port: int) -> socket.socket:
    """Bind and listen on ``host:port`` now, so a busy port is one clear error before anything starts.

    Parameters
    ----------
    host : str
        Address to bind.
    port : int
        TCP port (0: any free port).

    Returns
    -------
    socket.socket
        The listening socket, for :func:`run`.

    Raises
    ------
    ValidationError
        The address is in use or cannot be bound.
    """
    from ..errors import ValidationError

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(2048)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise ValidationError(f"--port {port}: {host}:{port} is already in use (another vibrofocus serve?); "
                                  "choose another --port or stop the other server") from None
        raise ValidationError(f"--host {host} --port {port}: cannot listen there ({exc.strerror})") from None
    return sock


def run(app: Any, *, host: str, port: int, limits: ServerLimits = ServerLimits(),
        sock: socket.socket | None = None, trusted_proxy: str | None = None) -> None:
    """Serve ``app`` with uvicorn under ``limits`` until interrupted.

    Parameters
    ----------
    app : ASGI application
        The app of :func:`vibrofocus.web.create_app`.
    host : str
        Address to bind.
    port : int
        TCP port.
    limits : ServerLimits
        Connection limits.
    sock : socket.socket, optional
        A socket already listening (:func:`listen`); default: uvicorn binds ``host:port``.
    trusted_proxy : str, optional
        Address (or comma-separated addresses) of a reverse proxy whose
        ``X-Forwarded-For`` names the real client. Default None: forwarding headers are
        ignored, so the client is always the TCP peer (a local process cannot pose as
        another address to dodge or aim the throttle of wrong secrets).
    """
    import uvicorn

    _logging()
    cap = effective_cap(limits)
    if cap < limits.max_connections:
        log.warning("at most %d connections (the file-descriptor limit leaves no room for %d)", cap, limits.max_connections)
    config = uvicorn.Config(
        app, host=host, port=port, log_config=None, log_level="warning", access_log=False,
        http=guarded_protocol(limits, cap), timeout_keep_alive=limits.keep_alive_s,
        # uvicorn trusts X-Forwarded-For from 127.0.0.1 by default: any local process could
        # then choose the client address the throttle counts.
        proxy_headers=trusted_proxy is not None,
        forwarded_allow_ips=trusted_proxy if trusted_proxy is not None else "",
    )
    uvicorn.Server(config).run(sockets=None if sock is None else [sock])
