"""Taps asked live over Open Sound Control: :class:`OscTapServer` (``vibrofocus serve-osc``).

One UDP socket, one thread: each datagram is parsed with python-osc, answered, and a
valid tap is played on the rig before the next datagram is read. The addresses:

``/tap <location>``
    A tap at a layout location (int, 1-based).
``/tap_xy <x_mm> <y_mm>``
    A tap at a point of the calibrated area, mm in the layout frame (int or float), with
    a method designed in milliseconds (not minimax, whose designs take seconds).
``/method <name>``
    Use another registered rendering method from now on; a method whose designs take
    seconds only if its location designs were made ahead (``serve-osc --method minimax``).
``/stop``
    All outputs to zero, and the server ends.

A played tap is answered ``/played`` with what was asked; every problem is answered
``/error <reason>`` to the sender, and nothing plays: a datagram that is no OSC packet,
an unknown address, a wrong type or number of arguments, NaN or Inf, a point off the
calibrated area, an unknown location or method, a drive the safety layer refuses.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ValidationError, VibrofocusError
from .designer import TapDesigner

__all__ = ["OscTapServer", "TapRecord", "ADDRESSES"]

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
        :attr:`records`.

    Attributes
    ----------
    records : list of TapRecord
        The taps played, in order.
    n_errors : int
        Messages answered with ``/error``.
    """

    def __init__(self, rig: Any, designer: TapDesigner, *, host: str = "127.0.0.1", port: int = 0,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.rig = rig
        self.designer = designer
        self.clock = clock
        self.records: list[TapRecord] = []
        self.n_errors = 0
        self.stopped_by: str | None = None
        self._stop = False
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise ValidationError(f"cannot listen on UDP {host}:{port}: {exc.strerror or exc} (another program may "
                                  "use the port: give another --port)") from None
        self._sock.settimeout(0.1)

    @property
    def address(self) -> tuple[str, int]:
        """``(host, port)`` the server listens on."""
        host, port = self._sock.getsockname()[:2]
        return host, port

    def stop(self) -> None:
        """End :meth:`serve` at its next turn (from any thread); outputs go to zero."""
        self._stop = True
        self.rig.stop()

    def close(self) -> None:
        """Close the socket (outputs at zero)."""
        self.rig.stop()
        self._sock.close()

    def serve(self) -> str:
        """Serve until ``/stop`` or :meth:`stop`; the rig is reserved meanwhile.

        Returns
        -------
        str
            Who stopped it (``"/stop from 127.0.0.1:50123"``, ``"stop()"``).

        Notes
        -----
        A KeyboardInterrupt (SIGINT, or SIGTERM under the CLI's handlers) ends it too:
        the outputs are set to zero and the interrupt goes on to the caller.
        """
        try:
            with self.rig.reserve("serve-osc"):
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
        finally:
            self.rig.stop()
        return self.stopped_by or "stop()"

    # -- one datagram -------------------------------------------------------------------
    def handle(self, data: bytes, sender: tuple, receipt_s: float) -> None:
        """Answer one datagram (and play what it asks).

        Parameters
        ----------
        data : bytes
            The datagram.
        sender : tuple
            Its source address; answers go there.
        receipt_s : float
            When it was read, s (:attr:`clock`).
        """
        from pythonosc.osc_packet import OscPacket, ParseError

        try:
            messages = [timed.message for timed in OscPacket(data).messages]
        except (ParseError, Exception):  # noqa: BLE001 - an undecodable datagram is refused, never fatal
            self._reply(sender, "/error", f"not an OSC packet ({len(data)} bytes); nothing played")
            return
        for message in messages:
            try:
                self._dispatch(message.address, list(message.params), sender, receipt_s)
            except _Refused as exc:
                self._reply(sender, "/error", str(exc))
            except VibrofocusError as exc:  # a refused design or drive: the safety layer's word
                self._reply(sender, "/error", f"{message.address}: {exc}")
            except Exception as exc:  # noqa: BLE001 - the server keeps serving whatever one message does
                # A play that failed has set the outputs to zero itself (Rig.play); stopping the
                # rig here would end the server's hold on it and refuse every later tap.
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
            self._play(self.designer.drives_at(location), receipt_s, f"location {location}", sender, [location])
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
            drives = self.designer.drives_xy(xy)
            self._play(drives, receipt_s, f"x {x:g} mm, y {y:g} mm", sender, [float(x), float(y)])
        elif address == "/method":
            (name,) = _arity(address, args, 1)
            if not isinstance(name, str):
                raise _Refused(f"/method takes one method name (a string), got {_type(name)}")
            try:
                self.designer.set_method(name, serving=True)
            except VibrofocusError as exc:
                raise _Refused(f"/method: {exc}") from None
            self._reply(sender, "/method", name)
        elif address == "/stop":
            _arity(address, args, 0)
            self.stopped_by = f"/stop from {_where(sender)}"
            self.stop()
            self._reply(sender, "/stopped")
        else:
            raise _Refused(f"unknown address {address[:80]!r}; known: {', '.join(ADDRESSES)}")

    def _play(self, drives: np.ndarray, receipt_s: float, target: str, sender: tuple, echo: list) -> None:
        self.rig.play(drives)
        self.records.append(TapRecord(receipt_s, self.clock(), target, self.designer.method))
        self._reply(sender, "/played", *echo)

    def _reply(self, sender: tuple, address: str, *args: Any) -> None:
        from pythonosc.osc_message_builder import OscMessageBuilder

        if address == "/error":
            self.n_errors += 1
            args = (_clean(args[0]),)
        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(arg)
        try:
            self._sock.sendto(builder.build().dgram, sender)
        except OSError:  # a sender that went away: nothing to tell
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
