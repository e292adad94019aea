"""Taps asked live over Open Sound Control: :class:`OscTapServer` (``vibrofocus serve-osc``).

One UDP socket and two threads. A receiving thread reads every datagram as it comes,
walks its framing (:mod:`.osc_framing`), parses it with python-osc, refuses what is
malformed and queues each tap; the thread that called :meth:`OscTapServer.serve` (the
one that holds the rig) designs and plays the queued taps in order. So ``/stop`` is
never behind a tap: it empties the queue and stops the rig at once, in the middle of a
play. Nor is it behind other datagrams: before it handles each datagram, the receiving
thread reads every datagram waiting in the socket (at most :data:`MAX_BACKLOG` ahead;
past that, one is answered ``/error busy`` unread), and acts on a ``/stop`` among them
first. A datagram holds at most :data:`~.osc_framing.MAX_ELEMENTS` messages and bundles,
so that none holds the receiving thread for long. The addresses:

``/tap <location> [<level_db>]``
    A tap at a layout location (int, 1-based).
``/tap_xy <x_mm> <y_mm> [<level_db>]``
    A tap at a point of the calibrated area, mm in the layout frame (int or float), with
    a method designed in milliseconds (not minimax, whose designs take seconds).
``/method <name>``
    Use another registered rendering method for the taps queued after it; a method
    whose designs take seconds only if its location designs were made ahead
    (``serve-osc --method minimax``).
``/stop``
    All outputs to zero now (a play under way is cut), the taps still queued are
    dropped, and the server ends; the taps in datagrams already read, the stop's own
    included, are answered ``/error stopped: ...``.

The optional level is in dB re the design (0: the design as made, scaled to the drive
limit; -6: half its amplitude); the safety layer still checks the scaled drive, so a
level that would break a limit is answered ``/error`` and plays nothing.

A played tap is answered ``/played`` with what was asked (the location, or x and y)
followed by five fixed fields: the tap's id (1, 2, ... on this server, or after the
last tap of its log), its onset on the host's clock (``time.monotonic()``, s), its onset
on the device's clock (s; NaN where the rig has none), that clock's name (``""`` where
none) and the level played (dB re the design). Every problem is answered
``/error <reason>`` to the sender, and nothing plays: a datagram that is no OSC packet
(framing included: a bundle element of a negative size, too deep a nesting, too many
elements), an unknown address, a wrong type or number of arguments, NaN or Inf, a level
out of range, a point off the calibrated area, an unknown location or method, a drive
the safety layer refuses; a tap that waited longer than ``max_wait_s`` since its datagram
was read, behind other taps or other datagrams (``/error stale: ...``), a tap when
``max_queued`` already wait or a datagram read when :data:`MAX_BACKLOG` already wait
(``/error busy: ...``), and the taps that a stop dropped (``/error stopped: ...``).

Each played tap goes to the server's tap log (:class:`~vibrofocus.realtime.taplog.TapLog`,
committed before ``/played`` is sent) and marker sink (an LSL outlet) when it has them.
"""

from __future__ import annotations

import collections
import logging
import platform
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._docs import fill_doc
from ..errors import ValidationError, VibrofocusError
from .designer import TapDesigner
from .osc_framing import MAX_ELEMENTS, FramingError, TooManyElements, parse_datagram

__all__ = ["OscTapServer", "TapRecord", "ADDRESSES", "MAX_WAIT_S", "MAX_QUEUED", "MAX_BACKLOG", "LEVEL_DB_RANGE",
           "PLAYED_FIELDS"]

#: The addresses the server answers, with their arguments.
ADDRESSES = {
    "/tap": "<location: int> [<level_db: float>]",
    "/tap_xy": "<x_mm: float> <y_mm: float> [<level_db: float>]",
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
#: Most datagrams read from the socket and not yet handled; one read past them is answered
#: ``/error busy`` without being parsed (unless it holds a ``/stop``, which acts at once).
MAX_BACKLOG = 512
#: Most datagrams read from the socket in one go between two handled datagrams.
READ_AHEAD = 1024
_BUSY_TEXT = (f"busy: {MAX_BACKLOG} datagrams read wait already to be handled (a flood of datagrams?); nothing in "
              "this one played")
#: Levels a tap may ask, dB re the design: outside them a level is a mistake (a linear
#: gain, a level in dB SPL), refused before the safety layer sees it.
LEVEL_DB_RANGE = (-100.0, 40.0)
#: The fixed fields ``/played`` carries after what was asked.
PLAYED_FIELDS = ("tap_id", "onset_host_s", "onset_device_s", "onset_clock", "level_db")
#: How often the threads look whether the server was stopped (and let Ctrl-C in), s.
POLL_S = 0.05
#: The receive buffer asked for, bytes (the system caps it: net.core.rmem_max on Linux).
RCVBUF_BYTES = 4 << 20

# The kernel's arrival time of each datagram (SO_TIMESTAMP: a struct timeval of two C
# longs on the wall clock), so that a tap's wait counts its time in the socket's buffer.
# Python names no constant for it; Linux's is 29 (parisc's excepted). Elsewhere the wait
# is counted from the read.
_SO_TIMESTAMP: int | None = (getattr(socket, "SO_TIMESTAMP", 29) if sys.platform.startswith("linux")
                             and not platform.machine().startswith("parisc") else None)
_TIMEVAL = struct.Struct("@ll")


class _Double(float):
    """A number sent as an OSC double (``d``), not python-osc's default 32-bit float."""


class _Refused(Exception):
    """A message answered with ``/error``."""


@dataclass(frozen=True)
class TapRecord:
    """One played tap.

    Attributes
    ----------
    receipt_s : float
        When its datagram arrived (or was read: see the server's ``clock``), s, on the server's clock.
    played_s : float
        When the rig's ``play`` returned, s, on the same clock.
    target : str
        What was asked (``"location 5"``, ``"x 3 mm, y -4 mm"``).
    method : str
        The method of its design.
    tap_id : int
        The tap's number: 1, 2, ... on this server (after the last tap of its log).
    address : str
        ``"/tap"`` or ``"/tap_xy"``.
    location : int or None
        The layout location of a ``/tap``.
    x_mm, y_mm : float or None
        The point of a ``/tap_xy``, mm.
    level_db : float
        The level played, dB re the design.
    onset_host_s : float
        The onset on the host's clock (``time.monotonic()``), s: the rig's
        :class:`~vibrofocus.rigs.DeviceOnset`.
    onset_device_s : float or None
        The onset on the device's clock, s (None where the rig has none).
    onset_clock : str or None
        That clock's name (:data:`vibrofocus.rigs.CLOCKS`).
    sender : str
        Who asked (``"127.0.0.1:50123"``).
    drive_peak_v : float
        Peak of the played drive, V.
    """

    receipt_s: float
    played_s: float
    target: str
    method: str
    tap_id: int = 0
    address: str = "/tap"
    location: int | None = None
    x_mm: float | None = None
    y_mm: float | None = None
    level_db: float = 0.0
    onset_host_s: float = float("nan")
    onset_device_s: float | None = None
    onset_clock: str | None = None
    sender: str = ""
    drive_peak_v: float = float("nan")

    def played_args(self) -> list:
        """The fixed fields of ``/played`` (:data:`PLAYED_FIELDS`), as OSC sends them: a
        missing device onset is NaN, a missing clock ``""``; the onsets are doubles (OSC type
        ``d``: a 32-bit float would keep only milliseconds of an hour-old clock)."""
        device = float("nan") if self.onset_device_s is None else float(self.onset_device_s)
        return [int(self.tap_id), _Double(self.onset_host_s), _Double(device), self.onset_clock or "",
                float(self.level_db)]

    def marker(self) -> dict[str, Any]:
        """The tap as a stimulus-onset marker (the fields of the study engine's, where they apply)."""
        return {"event": "stimulus_onset", "source": "serve-osc", "tap_id": self.tap_id, "method": self.method,
                "target": self.location, "x_mm": self.x_mm, "y_mm": self.y_mm, "level_db": self.level_db,
                "played": True, "onset_device_s": self.onset_device_s, "onset_clock": self.onset_clock,
                "response": None}


@dataclass(frozen=True)
class _Job:
    """A valid message waiting for the playing thread: a tap or a method change."""

    address: str
    value: Any  # the location, the point (m) or the method name
    target: str
    echo: list
    sender: tuple
    receipt_s: float
    level_db: float = 0.0


def _quiet_pythonosc() -> None:
    # python-osc logs what it cannot parse; a flood of hostile datagrams must not flood
    # stderr. Its own logger gets a handler that drops everything (the framing walk keeps
    # the datagrams it logs about through the root logger from reaching it).
    logger = logging.getLogger("pythonosc")
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())
    logger.propagate = False


@fill_doc
class OscTapServer:
    """An OSC server that plays taps on a rig.

    Parameters
    ----------
    %(rig)s
    designer : TapDesigner
        Where their drives come from.
    host : str
        Address to bind.
    port : int
        UDP port; 0 picks a free one (see :attr:`address`).
    clock : callable
        Seconds now (``time.perf_counter`` by default): receipt and play times of
        :attr:`records`, and how long a tap waited. With ``time.perf_counter`` or
        ``time.monotonic``, on Linux, a datagram's receipt is when the kernel received
        it (its time in the socket's buffer counts); otherwise when it was read.
    max_wait_s : float
        A tap that waited longer than this between its receipt and its turn to be queued
        or played (behind other datagrams, or other taps) is dropped and answered
        ``/error stale: ...``, s.
    max_queued : int
        Most taps and method changes waiting at once; one more is answered
        ``/error busy: ...``.
    tap_log : TapLog, optional
        Where every played tap is kept (:class:`~vibrofocus.realtime.taplog.TapLog`,
        ``serve-osc --log``): each tap is committed there before its ``/played`` is sent,
        and tap ids go on from the log's last one. A tap that cannot be kept is answered
        ``/error`` and stops the server (outputs at zero): no tap plays unrecorded after it.
    marker_sink : callable, optional
        ``marker_sink(marker, host_time_s)``, given every played tap's
        :meth:`TapRecord.marker` and its onset on the host's clock
        (:meth:`vibrofocus.io.lsl.MarkerOutlet.push`, ``serve-osc --lsl``). A failing sink
        is logged once and stops nothing.

    Attributes
    ----------
    records : list of TapRecord
        The taps played, in order.
    n_errors : int
        Messages answered with ``/error``.
    log_error : Exception or None
        Why the tap log could not keep a tap (the server stopped then).
    """

    def __init__(self, rig: Any, designer: TapDesigner, *, host: str = "127.0.0.1", port: int = 0,
                 clock: Callable[[], float] = time.perf_counter, max_wait_s: float = MAX_WAIT_S,
                 max_queued: int = MAX_QUEUED, tap_log: Any = None,
                 marker_sink: Callable[[dict, float], Any] | None = None) -> None:
        from .._validation import check_positive

        self.rig = rig
        self.designer = designer
        self.clock = clock
        self.max_wait_s = check_positive(max_wait_s, "max_wait_s")
        if isinstance(max_queued, bool) or not isinstance(max_queued, int) or max_queued < 1:
            raise ValidationError(f"max_queued must be an integer >= 1, got {max_queued!r}")
        self.max_queued = max_queued
        self.records: list[TapRecord] = []
        self.tap_log = tap_log
        self.marker_sink = marker_sink
        self._marker_failed = False
        self.log_error: Exception | None = None
        self._last_tap_id = int(tap_log.last_tap_id) if tap_log is not None else 0
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
        self._fixed: dict[str, bytes] = {}  # prepared /error datagrams (_reply_fixed)
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
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        except OSError:  # the system's own size then
            pass
        self._stamped = False
        # A clock of the caller's own (a test's) may not run in seconds of real time: the
        # kernel's stamp, which does, is used only with the real clocks.
        if (_SO_TIMESTAMP is not None and hasattr(self._sock, "recvmsg")
                and clock in (time.perf_counter, time.monotonic)):
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMP, 1)
                self._stamped = True
            except OSError:
                pass

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
        # Datagrams read and not yet handled, oldest first: (data, sender, receipt_s).
        backlog: collections.deque[tuple[bytes, tuple, float]] = collections.deque()
        try:
            while not self._stop:
                if not backlog:
                    try:
                        data, sender, receipt_s = self._recv()
                    except (TimeoutError, socket.timeout):
                        continue
                    except OSError:
                        if self._stop:
                            break
                        raise
                    self._take(data, sender, receipt_s, backlog)
                # The kernel's buffer is first in, first out: read what waits there before
                # handling anything, so that a /stop behind a flood acts now.
                self._read_ahead(backlog)
                if backlog and not self._stop:
                    data, sender, receipt_s = backlog.popleft()
                    if self.clock() - receipt_s > self.max_wait_s:
                        self._reply_fixed(sender, self._stale_text)  # behind: answered unparsed
                    else:
                        self.handle(data, sender, receipt_s)
            # Stopped: what was read, and what waits in the socket now, is answered
            # (every tap in it: /error stopped), once.
            self._read_ahead(backlog)
            while backlog:
                self.handle(*backlog.popleft())
        except BaseException as exc:  # noqa: BLE001 - handed to serve(), which raises it
            self._receiver_error = exc
            self.stop()

    def _read_ahead(self, backlog: collections.deque) -> None:
        """Read the datagrams waiting in the socket (at most :data:`READ_AHEAD`), without waiting."""
        try:
            self._sock.settimeout(0.0)
        except OSError:  # closed meanwhile (close() after a stop)
            return
        try:
            for _ in range(READ_AHEAD):
                try:
                    data, sender, receipt_s = self._recv()
                except (BlockingIOError, InterruptedError):
                    return
                except OSError:
                    if self._stop:
                        return
                    raise
                self._take(data, sender, receipt_s, backlog)
        finally:
            try:
                self._sock.settimeout(POLL_S)
            except OSError:
                pass

    def _recv(self) -> tuple[bytes, tuple, float]:
        """One datagram, its sender and when it arrived on :attr:`clock` (the kernel's
        time stamp where there is one: the time it waited in the socket's buffer counts)."""
        if not self._stamped:
            data, sender = self._sock.recvfrom(MAX_DATAGRAM)
            return data, sender, self.clock()
        data, ancillary, _flags, sender = self._sock.recvmsg(MAX_DATAGRAM, 64)
        now, wall = self.clock(), time.time()
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMP and len(payload) == _TIMEVAL.size:
                sec, usec = _TIMEVAL.unpack(payload)
                # Clamped (a wall clock stepped meanwhile): never after its read, at most a minute before.
                return data, sender, now - min(max(wall - (sec + 1e-6 * usec), 0.0), 60.0)
        return data, sender, now

    def _take(self, data: bytes, sender: tuple, receipt_s: float, backlog: collections.deque) -> None:
        """A datagram just read: a ``/stop`` in it acts now; the rest waits its turn in ``backlog``."""
        if b"/stop" in data:
            try:
                messages = parse_datagram(data)
            except Exception:  # noqa: BLE001 - refused in its turn, like any bad datagram
                messages = []
            if any(m.address == "/stop" and not m.params for m in messages):
                self._handle_messages(messages, sender, receipt_s)
                return
        if self._stop:
            self.handle(data, sender, receipt_s)  # after a stop: its taps answered /error stopped, now
            return
        # Behind a flood, each datagram costs one read and one prepared answer, no parse:
        # the receiving thread catches up as fast as it can, and a /stop is not lost long.
        if self.clock() - receipt_s > self.max_wait_s:
            self._reply_fixed(sender, self._stale_text)
        elif len(backlog) >= MAX_BACKLOG:
            self._reply_fixed(sender, _BUSY_TEXT)
        else:
            backlog.append((data, sender, receipt_s))

    def handle(self, data: bytes, sender: tuple, receipt_s: float) -> None:
        """Answer one datagram: refuse what is wrong, queue the taps, act on ``/stop`` now.

        Parameters
        ----------
        data : bytes
            The datagram.
        sender : tuple
            Its source address; answers go there.
        receipt_s : float
            When it arrived, s (:attr:`clock`).
        """
        try:
            messages = parse_datagram(data)
        except TooManyElements as exc:
            self._reply(sender, "/error", f"refused: {exc} ({len(data)} bytes; send at most {MAX_ELEMENTS} "
                                          "messages a datagram); nothing in it played")
            return
        except FramingError as exc:
            self._reply(sender, "/error", f"not an OSC packet ({len(data)} bytes: {exc}); nothing played")
            return
        except Exception:  # noqa: BLE001 - an undecodable datagram is refused, never fatal
            self._reply(sender, "/error", f"not an OSC packet ({len(data)} bytes); nothing played")
            return
        self._handle_messages(messages, sender, receipt_s)

    def _handle_messages(self, messages: list, sender: tuple, receipt_s: float) -> None:
        # Every message is answered, those after a /stop too (a tap: /error stopped).
        for message in messages:
            try:
                self._dispatch(message.address, list(message.params), sender, receipt_s)
            except _Refused as exc:
                self._reply(sender, "/error", str(exc))
            except Exception as exc:  # noqa: BLE001 - the server keeps serving whatever one message does
                self._reply(sender, "/error", f"{message.address}: unexpected {type(exc).__name__}: {exc}")

    def _dispatch(self, address: str, args: list, sender: tuple, receipt_s: float) -> None:
        if address == "/tap":
            args, level_db = _level(address, args, 1)
            (location,) = args
            if isinstance(location, bool) or not isinstance(location, int):
                raise _Refused(f"/tap takes one integer location, got {_type(location)}")
            if not 1 <= location <= self.designer.layout.n_locations:
                raise _Refused(f"/tap: unknown location {location}; the locations are 1.."
                               f"{self.designer.layout.n_locations}")
            self._enqueue(_Job(address, location, f"location {location}", [location], sender, receipt_s, level_db))
        elif address == "/tap_xy":
            args, level_db = _level(address, args, 2)
            x, y = args
            for value in (x, y):
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise _Refused(f"/tap_xy takes two numbers (x_mm, y_mm), got {_type(value)}")
            if not (np.isfinite(x) and np.isfinite(y)):
                raise _Refused(f"/tap_xy: x and y must be finite numbers, got ({x}, {y})")
            xy = np.array([x, y], float) * 1e-3
            if not self.designer.area.contains(xy):
                raise _Refused(f"/tap_xy: ({x:g}, {y:g}) mm is off the calibrated area ({self.designer.area.describe()})")
            self._enqueue(_Job(address, xy, f"x {x:g} mm, y {y:g} mm", [float(x), float(y)], sender, receipt_s,
                               level_db))
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
        waited = self.clock() - job.receipt_s
        with self._cond:
            if self._stop:
                raise _Refused(f"stopped: {job.address} {job.target} was not played")
            if waited > self.max_wait_s:
                # Read long before its turn in the receiving thread: the server is behind.
                raise _Refused(f"stale: {job.address} {job.target} waited {1e3 * waited:.0f} ms behind other "
                               f"datagrams, over the {1e3 * self.max_wait_s:g} ms bound; not played")
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
            if job.level_db != 0.0:
                # The level scales the design; the rig's safety layer checks what results.
                drives = drives * 10.0 ** (job.level_db / 20.0)
            if self._stop:
                raise _Refused(f"stopped: {job.address} {job.target} was not played")
            onset = self.rig.play(drives)
            played_s = self.clock()
            record = self._record(job, onset, played_s, float(np.max(np.abs(drives))))
            self.records.append(record)
            self._keep(job, record)
            self._reply(job.sender, "/played", *job.echo, *record.played_args())
        except _Refused as exc:
            self._reply(job.sender, "/error", str(exc))
        except VibrofocusError as exc:  # a refused design or drive: the safety layer's word
            self._reply(job.sender, "/error", f"{job.address} {job.target}: {exc}")
        except Exception as exc:  # noqa: BLE001 - the server keeps serving whatever one tap does
            # A play that failed has set the outputs to zero itself (Rig.play); stopping the
            # rig here would end the server's hold on it and refuse every later tap.
            self._reply(job.sender, "/error", f"{job.address} {job.target}: unexpected {type(exc).__name__}: {exc}")

    def _record(self, job: _Job, onset: Any, played_s: float, peak_v: float) -> TapRecord:
        self._last_tap_id += 1
        host_s = getattr(onset, "host_s", None)
        device_s, clock = getattr(onset, "device_s", None), getattr(onset, "clock", None)
        point = job.address == "/tap_xy"
        return TapRecord(
            job.receipt_s, played_s, job.target, self.designer.method, tap_id=self._last_tap_id,
            address=job.address, location=int(job.value) if job.address == "/tap" else None,
            x_mm=float(job.echo[0]) if point else None, y_mm=float(job.echo[1]) if point else None,
            level_db=float(job.level_db), onset_host_s=float(host_s) if host_s is not None else time.monotonic(),
            onset_device_s=None if device_s is None else float(device_s), onset_clock=clock,
            sender=_where(job.sender), drive_peak_v=peak_v)

    def _keep(self, job: _Job, record: TapRecord) -> None:
        """The tap to the log (or the server stops) and to the marker sink, before ``/played``."""
        if self.tap_log is not None:
            try:
                self.tap_log.append(record)
            except Exception as exc:  # noqa: BLE001 - answered, and no tap plays unrecorded after it
                self.log_error = exc
                self.stopped_by = f"the tap log ({type(exc).__name__}: {exc})"
                self.stop()
                raise _Refused(f"{job.address} {job.target}: played as tap {record.tap_id} but not recorded in "
                               f"the tap log ({exc}); the server stops") from None
        if self.marker_sink is not None:
            try:
                self.marker_sink(record.marker(), record.onset_host_s)
            except Exception as exc:  # noqa: BLE001 - a marker stream never stops the taps
                if not self._marker_failed:
                    self._marker_failed = True
                    logging.getLogger(__name__).warning("a tap's marker could not be sent (%s: %s); taps go on",
                                                        type(exc).__name__, exc)

    @property
    def _stale_text(self) -> str:
        return (f"stale: this datagram waited over the {1e3 * self.max_wait_s:g} ms bound before the server could "
                "read it (a flood of datagrams?); nothing in it played")

    def _reply_fixed(self, sender: tuple, text: str) -> None:
        """``/error text``, built once per text."""
        with self._count_lock:
            self.n_errors += 1
            dgram = self._fixed.get(text)
            if dgram is None:
                from pythonosc.osc_message_builder import OscMessageBuilder

                builder = OscMessageBuilder(address="/error")
                builder.add_arg(_clean(text))
                dgram = self._fixed[text] = builder.build().dgram
        try:
            self._sock.sendto(dgram, sender)
        except OSError:
            pass

    def _reply(self, sender: tuple, address: str, *args: Any) -> None:
        from pythonosc.osc_message_builder import OscMessageBuilder

        if address == "/error":
            with self._count_lock:
                self.n_errors += 1
            args = (_clean(args[0]),)
        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(float(arg), "d") if isinstance(arg, _Double) else builder.add_arg(arg)
        try:
            self._sock.sendto(builder.build().dgram, sender)
        except OSError:  # a sender that went away, or a socket closed meanwhile: nothing to tell
            pass


def _level(address: str, args: list, n: int) -> tuple[list, float]:
    """The ``n`` arguments of a tap and its optional level (dB re the design; 0 without one)."""
    if len(args) not in (n, n + 1):
        raise _Refused(f"{address} takes {n} or {n + 1} arguments {ADDRESSES[address]}, got {len(args)}")
    if len(args) == n:
        return args, 0.0
    level = args[n]
    if isinstance(level, bool) or not isinstance(level, (int, float)):
        raise _Refused(f"{address}: the level is a number of dB re the design, got {_type(level)}")
    lo, hi = LEVEL_DB_RANGE
    if not (np.isfinite(level) and lo <= level <= hi):
        raise _Refused(f"{address}: the level must be a finite number of dB re the design from {lo:g} to {hi:g}, "
                       f"got {level}")
    return args[:n], float(level)


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
