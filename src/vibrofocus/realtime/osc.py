"""Taps asked live over Open Sound Control: :class:`OscTapServer` (``vibrofocus serve-osc``).

One UDP socket and two threads. A receiving thread reads every datagram as it comes,
walks its framing (:mod:`.osc_framing`), parses it with python-osc, refuses what is
malformed and queues each tap; the thread that called :meth:`OscTapServer.serve` (the
one that holds the rig) designs and plays the queued taps in order. So ``/stop`` is
never behind a tap: it empties the queue and stops the rig at once, in the middle of a
play. The addresses:

``/tap <location>``
    A tap at a layout location (int, 1-based).
``/tap_xy <x_mm> <y_mm>``
    A tap at a point of the calibrated area, mm in the layout frame (int or float), with
    a method designed in milliseconds (not minimax, whose designs take seconds).
``/method <name>``
    Use another registered rendering method for the taps queued after it; a method
    whose designs take seconds only if its location designs were made ahead
    (``serve-osc --method minimax``).
``/stop``
    All outputs to zero now (a play under way is cut), the taps still queued are
    dropped, and the server ends.

A played tap is answered ``/played`` with what was asked; every problem is answered
``/error <reason>`` to the sender, and nothing plays: a datagram that is no OSC packet
(framing included: a bundle element of a negative size, too deep a nesting, too many
elements), an unknown address, a wrong type or number of arguments, NaN or Inf, a point
off the calibrated area, an unknown location or method, a drive the safety layer
refuses; a tap that waited longer than ``max_wait_s`` behind others (``/error stale:
...``), a tap when ``max_queued`` already wait (``/error busy: ...``), and the taps that
a stop dropped (``/error stopped: ...``).
"""

from __future__ import annotations

import collections
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ValidationError, VibrofocusError
from .designer import TapDesigner
from .osc_framing import FramingError, parse_datagram

__all__ = ["OscTapServer", "TapRecord", "ADDRESSES", "MAX_WAIT_S", "MAX_QUEUED"]

#: The addresses the server answers, with their arguments.
ADDRESSES = {
    "/tap": "<location: int>",
    "/tap_xy": "<x_mm: float> <y_mm: float>",
    "/method": "<name: str>",
    "/stop": "(no arguments)",
}

#: Longest reason sent back in ``/error``, characters.
MAX_REASON_CHARS = 300
#: Largest datagram read, bytes.
MAX_DATAGRAM = 65536
#: A tap that waited longer than this behind others is dropped (``/error stale``), s.
MAX_WAIT_S = 0.5
#: Most taps and method changes waiting at once; more are refused (``/error busy``).
MAX_QUEUED = 256
#: How often the threads look whether the server was stopped (and let Ctrl-C in), s.
POLL_S = 0.05


class _Refused(Exception):
    """A message answered with ``/error``."""


@dataclass(frozen=True)
class TapRecord:
    """One played tap.

    Attributes
    ----------
    receipt_s : float
        When its datagram was read, s, on the server's clock.
    played_s : float
        When the rig's ``play`` returned, s, on the same clock.
    target : str
        What was asked (``"location 5"``, ``"x 3 mm, y -4 mm"``).
    method : str
        The method of its design.
    """

    receipt_s: float
    played_s: float
    target: str
    method: str


@dataclass(frozen=True)
class _Job:
    """A valid message waiting for the playing thread: a tap or a method change."""

    address: str
    value: Any  # the location, the point (m) or the method name
    target: str
    echo: list
    sender: tuple
    receipt_s: float


def _quiet_pythonosc() -> None:
    # python-osc logs what it cannot parse; a flood of hostile datagrams must not flood
    # stderr. Its own logger gets a handler that drops everything (the framing walk keeps
    # the datagrams it logs about through the root logger from reaching it).
    logger = logging.getLogger("pythonosc")
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())
    logger.propagate = False


class OscTapServer:
    """An OSC server that plays taps on a rig.

    Parameters
    ----------
    rig : Rig
        Where taps play (through its safety layer).
    designer : TapDesigner
        Where their drives come from.
    host : str
        Address to bind.
    port : int
        UDP port; 0 picks a free one (see :attr:`address`).
    clock : callable
        Seconds now (``time.perf_counter`` by default): receipt and play times of
        :attr:`records`, and how long a tap waited.
    max_wait_s : float
        A tap that waited longer than this between its receipt and its turn to play is
        dropped and answered ``/error stale: ...``, s.
    max_queued : int
        Most taps and method changes waiting at once; one more is answered
        ``/error busy: ...``.

    Attributes
    ----------
    records : list of TapRecord
        The taps played, in order.
    n_errors : int
        Messages answered with ``/error``.
    """

    def __init__(self, rig: Any, designer: TapDesigner, *, host: str = "127.0.0.1", port: int = 0,
                 clock: Callable[[], float] = time.perf_counter, max_wait_s: float = MAX_WAIT_S,
                 max_queued: int = MAX_QUEUED) -> None:
        from .._validation import check_positive

        self.rig = rig
        self.designer = designer
        self.clock = clock
        self.max_wait_s = check_positive(max_wait_s, "max_wait_s")
        if isinstance(max_queued, bool) or not isinstance(max_queued, int) or max_queued < 1:
            raise ValidationError(f"max_queued must be an integer >= 1, got {max_queued!r}")
        self.max_queued = max_queued
        self.records: list[TapRecord] = []
        self.n_errors = 0
        self.stopped_by: str | None = None
        self._stop = False
        # The queue, the stop and whether the playing thread holds a job, under one condition.
        self._cond = threading.Condition()
        self._queue: collections.deque[_Job] = collections.deque()
        self._busy = False
        self._player: int | None = None
        self._receiver: threading.Thread | None = None
        self._receiver_error: BaseException | None = None
        self._count_lock = threading.Lock()
        _quiet_pythonosc()
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise ValidationError(f"cannot listen on UDP {host}:{port}: {exc.strerror or exc} (another program may "
                                  "use the port: give another --port)") from None
        self._sock.settimeout(POLL_S)

    @property
    def address(self) -> tuple[str, int]:
        """``(host, port)`` the server listens on."""
        host, port = self._sock.getsockname()[:2]
        return host, port

    @property
    def n_waiting(self) -> int:
        """Taps and method changes received and not yet taken by the playing thread."""
        with self._cond:
            return len(self._queue)

    def stop(self) -> None:
        """Stop now, from any thread: outputs to zero, queued taps dropped, :meth:`serve` ends.

        A play under way is cut (the rig's own stop). When this returns, no tap of this
        server plays any more.
        """
        with self._cond:
            self._stop = True
            dropped = list(self._queue)
            self._queue.clear()
            self._cond.notify_all()
        self.rig.stop()
        for job in dropped:
            self._reply(job.sender, "/error", f"stopped: {job.address} {job.target} was not played")
        if threading.get_ident() == self._player:
            return
        # The playing thread may have taken its job just before: a play that began after
        # the rig's stop above would not see it. Stop again until that thread lets go.
        while True:
            with self._cond:
                if not self._busy:
                    return
                self._cond.wait(POLL_S / 5)
            self.rig.stop()

    def close(self) -> None:
        """Close the socket (outputs at zero)."""
        self.rig.stop()
        self._sock.close()

    def serve(self) -> str:
        """Serve until ``/stop`` or :meth:`stop`; the rig is reserved meanwhile.

        Taps play on the calling thread; a receiving thread reads the socket meanwhile.

        Returns
        -------
        str
            Who stopped it (``"/stop from 127.0.0.1:50123"``, ``"stop()"``).

        Notes
        -----
        A KeyboardInterrupt (SIGINT, or SIGTERM under the CLI's handlers) ends it too:
        the outputs are set to zero and the interrupt goes on to the caller.
        """
        self._player = threading.get_ident()
        try:
            with self.rig.reserve("serve-osc"):
                self._receiver = threading.Thread(target=self._receive, name="serve-osc receiver", daemon=True)
                self._receiver.start()
                while (job := self._next_job()) is not None:
                    try:
                        self._run(job)
                    finally:
                        with self._cond:
                            self._busy = False
                            self._cond.notify_all()
        finally:
            with self._cond:
                self._stop = True
                self._cond.notify_all()
            self.rig.stop()
            if self._receiver is not None:
                self._receiver.join()
        if self._receiver_error is not None:
            raise self._receiver_error
        return self.stopped_by or "stop()"

    # -- the receiving thread ---------------------------------------------------------
    def _receive(self) -> None:
        try:
            while not self._stop:
                try:
                    data, sender = self._sock.recvfrom(MAX_DATAGRAM)
                except (TimeoutError, socket.timeout):
                    continue
                except OSError:
                    if self._stop:
                        break
                    raise
                self.handle(data, sender, self.clock())
        except BaseException as exc:  # noqa: BLE001 - handed to serve(), which raises it
            self._receiver_error = exc
            self.stop()

    def handle(self, data: bytes, sender: tuple, receipt_s: float) -> None:
        """Answer one datagram: refuse what is wrong, queue the taps, act on ``/stop`` now.

        Parameters
        ----------
        data : bytes
            The datagram.
        sender : tuple
            Its source address; answers go there.
        receipt_s : float
            When it was read, s (:attr:`clock`).
        """
        try:
            messages = parse_datagram(data)
        except FramingError as exc:
            self._reply(sender, "/error", f"not an OSC packet ({len(data)} bytes: {exc}); nothing played")
            return
        except Exception:  # noqa: BLE001 - an undecodable datagram is refused, never fatal
            self._reply(sender, "/error", f"not an OSC packet ({len(data)} bytes); nothing played")
            return
        for message in messages:
            try:
                self._dispatch(message.address, list(message.params), sender, receipt_s)
            except _Refused as exc:
                self._reply(sender, "/error", str(exc))
            except Exception as exc:  # noqa: BLE001 - the server keeps serving whatever one message does
                self._reply(sender, "/error", f"{message.address}: unexpected {type(exc).__name__}: {exc}")
            if self._stop:
                return

    def _dispatch(self, address: str, args: list, sender: tuple, receipt_s: float) -> None:
        if address == "/tap":
            (location,) = _arity(address, args, 1)
            if isinstance(location, bool) or not isinstance(location, int):
                raise _Refused(f"/tap takes one integer location, got {_type(location)}")
            if not 1 <= location <= self.designer.layout.n_locations:
                raise _Refused(f"/tap: unknown location {location}; the locations are 1.."
                               f"{self.designer.layout.n_locations}")
            self._enqueue(_Job(address, location, f"location {location}", [location], sender, receipt_s))
        elif address == "/tap_xy":
            x, y = _arity(address, args, 2)
            for value in (x, y):
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise _Refused(f"/tap_xy takes two numbers (x_mm, y_mm), got {_type(value)}")
            if not (np.isfinite(x) and np.isfinite(y)):
                raise _Refused(f"/tap_xy: x and y must be finite numbers, got ({x}, {y})")
            xy = np.array([x, y], float) * 1e-3
            if not self.designer.area.contains(xy):
                raise _Refused(f"/tap_xy: ({x:g}, {y:g}) mm is off the calibrated area ({self.designer.area.describe()})")
            self._enqueue(_Job(address, xy, f"x {x:g} mm, y {y:g} mm", [float(x), float(y)], sender, receipt_s))
        elif address == "/method":
            (name,) = _arity(address, args, 1)
            if not isinstance(name, str):
                raise _Refused(f"/method takes one method name (a string), got {_type(name)}")
            # In the queue: the taps received before it keep the method they were asked with.
            self._enqueue(_Job(address, name, name, [name], sender, receipt_s))
        elif address == "/stop":
            _arity(address, args, 0)
            self.stopped_by = f"/stop from {_where(sender)}"
            self.stop()
            self._reply(sender, "/stopped")
        else:
            raise _Refused(f"unknown address {address[:80]!r}; known: {', '.join(ADDRESSES)}")

    def _enqueue(self, job: _Job) -> None:
        with self._cond:
            if self._stop:
                raise _Refused(f"stopped: {job.address} {job.target} was not played")
            if len(self._queue) >= self.max_queued:
                raise _Refused(f"busy: {len(self._queue)} messages wait already (at most {self.max_queued}); "
                               f"{job.address} {job.target} was not played")
            self._queue.append(job)
            self._cond.notify_all()

    # -- the playing thread -----------------------------------------------------------
    def _next_job(self) -> _Job | None:
        """The next job, or None once stopped; the job is held (``_busy``) until the caller lets go."""
        with self._cond:
            while not self._queue and not self._stop:
                self._cond.wait(POLL_S)
            if self._stop:
                return None
            self._busy = True
            return self._queue.popleft()

    def _run(self, job: _Job) -> None:
        try:
            if job.address == "/method":
                try:
                    self.designer.set_method(job.value, serving=True)
                except VibrofocusError as exc:
                    raise _Refused(f"/method: {exc}") from None
                self._reply(job.sender, "/method", *job.echo)
                return
            waited = self.clock() - job.receipt_s
            if waited > self.max_wait_s:
                raise _Refused(f"stale: {job.address} {job.target} waited {1e3 * waited:.0f} ms behind other taps, "
                               f"over the {1e3 * self.max_wait_s:g} ms bound; not played")
            drives = (self.designer.drives_at(job.value) if job.address == "/tap"
                      else self.designer.drives_xy(job.value))
            if self._stop:
                raise _Refused(f"stopped: {job.address} {job.target} was not played")
            self.rig.play(drives)
            self.records.append(TapRecord(job.receipt_s, self.clock(), job.target, self.designer.method))
            self._reply(job.sender, "/played", *job.echo)
        except _Refused as exc:
            self._reply(job.sender, "/error", str(exc))
        except VibrofocusError as exc:  # a refused design or drive: the safety layer's word
            self._reply(job.sender, "/error", f"{job.address}: {exc}")
        except Exception as exc:  # noqa: BLE001 - the server keeps serving whatever one tap does
            # A play that failed has set the outputs to zero itself (Rig.play); stopping the
            # rig here would end the server's hold on it and refuse every later tap.
            self._reply(job.sender, "/error", f"{job.address}: unexpected {type(exc).__name__}: {exc}")

    def _reply(self, sender: tuple, address: str, *args: Any) -> None:
        from pythonosc.osc_message_builder import OscMessageBuilder

        if address == "/error":
            with self._count_lock:
                self.n_errors += 1
            args = (_clean(args[0]),)
        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(arg)
        try:
            self._sock.sendto(builder.build().dgram, sender)
        except OSError:  # a sender that went away, or a socket closed meanwhile: nothing to tell
            pass


def _arity(address: str, args: list, n: int) -> list:
    if len(args) != n:
        raise _Refused(f"{address} takes {n} argument{'s' if n != 1 else ''} {ADDRESSES[address]}, got {len(args)}")
    return args


def _type(value: Any) -> str:
    return f"{type(value).__name__} {str(value)[:40]!r}"


def _where(sender: tuple) -> str:
    return f"{sender[0]}:{sender[1]}"


def _clean(text: Any) -> str:
    text = "".join(ch if ch.isprintable() else " " for ch in str(text))
    return text if len(text) <= MAX_REASON_CHARS else text[:MAX_REASON_CHARS - 3] + "..."
