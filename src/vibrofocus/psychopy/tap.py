"""A vibrofocus tap as a PsychoPy experiment uses a sound: :class:`TapStimulus`.

Set where and how loud, then ``win.callOnFlip(tap.play)``: the tap is asked on the frame
the screen shows, without holding that frame, and its onsets are collected afterwards
(:meth:`TapStimulus.result`) and stored in the experiment's data file
(:meth:`TapStimulus.store`, ``thisExp.addData``). Two ways to play:

- through a running ``vibrofocus serve-osc`` (:meth:`TapStimulus.osc`): the rig stays in
  its own process, and taps from the experiment are logged there too (``--log``);
- in-process (:meth:`TapStimulus.in_process`): the experiment opens the rig itself (the
  simulated arm, or a hardware rig with its calibration); each play runs on a thread of
  its own, so a hardware play never holds the screen.

Nothing here imports PsychoPy: a Coder script uses this class directly, and the Builder
component (:mod:`vibrofocus.psychopy.builder`) writes code that does.
"""

from __future__ import annotations

import math
import numbers
import os
import re
import socket
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._validation import check_positive, shorten
from ..errors import ValidationError

__all__ = ["TapStimulus", "TapResult", "DATA_FIELDS"]

#: The fields :meth:`TapStimulus.store` adds to the data file, as ``<name>.<field>``.
DATA_FIELDS = ("tap_id", "level_db", "method", "location", "x_mm", "y_mm", "asked_host_s", "onset_host_s",
               "onset_device_s", "onset_clock", "error")


def _say(line: str) -> None:
    """A line on stderr, flushed (the default ``report`` of :meth:`TapStimulus.in_process`)."""
    print(line, file=sys.stderr, flush=True)


@dataclass(frozen=True)
class TapResult:
    """What became of one :meth:`TapStimulus.play`.

    Attributes
    ----------
    tap_id : int or None
        The tap's id (``serve-osc``'s, which its ``--log`` keeps; counted from 1 in-process);
        None if it did not play.
    level_db : float
        The level asked, dB re the design.
    method : str
        The rendering method.
    location : int or None
        The layout location (None for a tap at a point).
    x_mm, y_mm : float or None
        The point, mm (None for a location).
    asked_host_s : float
        When :meth:`TapStimulus.play` ran, ``time.monotonic()``, s.
    onset_host_s : float or None
        The first sample handed to the device, on the same clock, s.
    onset_device_s : float or None
        The first sample on the device's own clock, s (None without one).
    onset_clock : str or None
        That clock's name.
    error : str or None
        Why the tap did not play (the server's ``/error`` reason, or the safety layer's).
    """

    tap_id: int | None
    level_db: float
    method: str
    location: int | None
    x_mm: float | None
    y_mm: float | None
    asked_host_s: float
    onset_host_s: float | None = None
    onset_device_s: float | None = None
    onset_clock: str | None = None
    error: str | None = None

    @property
    def played(self) -> bool:
        """Whether the tap played."""
        return self.error is None


@dataclass(eq=False)
class _Asked:
    level_db: float
    method: str
    location: int | None
    xy_mm: tuple[float, float] | None
    asked_host_s: float
    result: TapResult | None = None
    done: threading.Event | None = None
    given_up: bool = False  # its wait timed out: a late answer is discarded, never given to another tap


class TapStimulus:
    """A tap to present in a PsychoPy experiment (or any Python script).

    Build one with :meth:`osc` or :meth:`in_process`, then :meth:`set` the location (or
    point) and level, call :meth:`play` (``win.callOnFlip(tap.play)`` to start it with the
    next screen refresh), and :meth:`result` / :meth:`store` once the frame is shown.

    Parameters
    ----------
    backend : object
        What plays: made by :meth:`osc` or :meth:`in_process`.
    name : str
        The prefix of the data file's columns (``tap.onset_host_s``, ...).
    method : str
        The rendering method of the first tap.
    timeout_s : float
        How long :meth:`result` waits for a tap's answer, s.

    Attributes
    ----------
    status : int
        ``0`` (not started) until :meth:`play`, then ``1`` (started), as PsychoPy's
        ``NOT_STARTED`` and ``STARTED``.
    """

    def __init__(self, backend: Any, *, name: str = "tap", method: str = "inverse", timeout_s: float = 5.0) -> None:
        self._backend = backend
        self.name = _name(name)
        self.timeout_s = check_positive(timeout_s, "timeout_s")
        self.method = _method(method)
        backend.set_method(self.method, self.timeout_s)  # at once: a server that is not there is said now
        self.location: int | None = 1
        self.xy_mm: tuple[float, float] | None = None
        self.level_db = 0.0
        self.status = 0
        self._pending: deque[_Asked] = deque()

    # -- making one ----------------------------------------------------------------------
    @classmethod
    def osc(cls, host: str = "127.0.0.1", port: int = 9000, **kwargs: Any) -> "TapStimulus":
        """Taps played by a running ``vibrofocus serve-osc --port PORT``.

        Parameters
        ----------
        host : str
            The server's address.
        port : int
            Its UDP port.
        **kwargs
            ``name``, ``method``, ``timeout_s`` of :class:`TapStimulus`.

        Returns
        -------
        TapStimulus
        """
        return cls(_OscBackend(host, port), **kwargs)

    @classmethod
    def in_process(cls, rig: Any = "simulated", *, calibration: str | os.PathLike | None = None,
                   rig_config: Any = None, seed: int | None = None, anywhere: bool = True,
                   grid_pitch_m: float | None = None, report: Callable[[str], Any] | None = _say,
                   **kwargs: Any) -> "TapStimulus":
        """Taps played on a rig this process opens (and closes with :meth:`close`).

        Parameters
        ----------
        rig : str or Rig
            ``"simulated"``, ``"audio"``, ``"nidaq"`` (opened with ``rig_config``) or an
            open :class:`~vibrofocus.rigs.Rig`.
        calibration : path-like, optional
            The calibration the taps are designed from (required for hardware rigs; on the
            simulated rig, default: the simulated arm's own transfer).
        rig_config : path-like or dict, optional
            The hardware settings of an audio or nidaq rig.
        seed : int, optional
            The simulated arm's participant seed.
        anywhere : bool
            Evaluate the skin model for taps at points (``x_mm``, ``y_mm``) now, as
            ``serve-osc`` does at start (seconds), so that no such tap waits for it.
        grid_pitch_m : float, optional
            Pitch of that evaluation grid, m (default
            :data:`vibrofocus.realtime.GRID_PITCH_M`).
        report : callable or None
            Called with a line of text as the start goes (what it prepares, then the grid's
            progress at most every 10 s with the time left, then the time it took); default:
            the line on stderr (PsychoPy's Runner shows it). None: nothing is said.
        **kwargs
            ``name``, ``method``, ``timeout_s`` of :class:`TapStimulus`.

        Returns
        -------
        TapStimulus
        """
        backend = _RigBackend(rig, calibration, rig_config, seed, kwargs.get("method", "inverse"), anywhere,
                              grid_pitch_m, report=report)
        return cls(backend, **kwargs)

    # -- the next tap --------------------------------------------------------------------
    def set(self, *, location: int | None = None, x_mm: float | None = None, y_mm: float | None = None,
            level_db: float | None = None, method: str | None = None) -> "TapStimulus":
        """Set the next tap: a location, or a point (``x_mm`` and ``y_mm``); its level; its method.

        Parameters
        ----------
        location : int, optional
            A layout location (1-based).
        x_mm, y_mm : float, optional
            A point of the calibrated area, mm (both, instead of a location).
        level_db : float, optional
            dB re the calibrated design (0: the design as made; -6: half its amplitude).
        method : str, optional
            A registered rendering method; switched now (a server or rig makes its
            location designs when it switches).

        Returns
        -------
        TapStimulus
            Itself.

        Raises
        ------
        ValidationError
            Bad settings, or a method the server or rig refuses (nothing changes).
        """
        if location is not None and (x_mm is not None or y_mm is not None):
            raise ValidationError("give a location or a point (x_mm, y_mm), not both")
        if (x_mm is None) != (y_mm is None):
            raise ValidationError("a point needs both x_mm and y_mm")
        if location is not None:
            # numbers.Integral/Real take numpy's scalars too: PsychoPy's conditions files give np.int64.
            if (isinstance(location, (bool, np.bool_)) or not isinstance(location, numbers.Real)
                    or not math.isfinite(location) or int(location) != location):
                raise ValidationError(f"location must be an integer, got {shorten(location)}")
            self.location, self.xy_mm = int(location), None
        if x_mm is not None:
            self.xy_mm, self.location = (_finite(x_mm, "x_mm"), _finite(y_mm, "y_mm")), None
        if level_db is not None:
            self.level_db = _finite(level_db, "level_db")
        if method is not None:
            # Switched now, at a routine's start, and confirmed: a method the server or the
            # rig refuses raises here, rather than a tap recorded under a method it was not.
            self._backend.set_method(_method(method), self.timeout_s)
            self.method = method
        return self

    def play(self) -> None:
        """Ask the tap now and return at once (``win.callOnFlip(tap.play)``); see :meth:`result`."""
        asked = _Asked(self.level_db, self.method, self.location, self.xy_mm, time.monotonic())
        self._pending.append(asked)
        self.status = 1
        self._backend.play(asked)

    def result(self, timeout_s: float | None = None) -> TapResult:
        """The oldest played tap's outcome, waiting for it if needed.

        Parameters
        ----------
        timeout_s : float, optional
            Longest wait, s (default :attr:`timeout_s`).

        Returns
        -------
        TapResult
            A tap that got no answer in time has ``error`` ``"no answer in ... s"``.
        """
        if not self._pending:
            raise ValidationError("no tap was played: call play() first")
        asked = self._pending.popleft()
        self._backend.wait(asked, self.timeout_s if timeout_s is None else check_positive(timeout_s, "timeout_s"))
        return asked.result

    def store(self, exp: Any, result: TapResult | None = None) -> TapResult:
        """Add a tap's outcome to the experiment's data file: ``<name>.tap_id``, ``<name>.onset_host_s``, ...

        Parameters
        ----------
        exp : object with ``addData(name, value)``
            PsychoPy's ``thisExp`` (``data.ExperimentHandler``), or a loop.
        result : TapResult, optional
            Default: :meth:`result` of the oldest played tap.

        Returns
        -------
        TapResult
        """
        result = self.result() if result is None else result
        values = asdict(result)
        for field in DATA_FIELDS:
            # An empty cell, not "None", for what a tap has not (PsychoPy writes str(value)).
            exp.addData(f"{self.name}.{field}", "" if values[field] is None else values[field])
        return result

    def close(self) -> None:
        """Close the socket, or the rig opened in-process (outputs at zero)."""
        self._backend.close()

    def __enter__(self) -> "TapStimulus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _name(name: Any) -> str:
    if not isinstance(name, str) or not name.isidentifier():
        raise ValidationError(f"name must be a Python identifier (a PsychoPy component name), got {shorten(name)}")
    return name


def _method(name: Any) -> str:
    if not isinstance(name, str) or not name:
        raise ValidationError(f"method must be a rendering method's name, got {shorten(name)}")
    return name


def _finite(value: Any, what: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValidationError(f"{what} must be a finite number, got {shorten(value)}")
    return float(value)


def _result(asked: _Asked, **fields: Any) -> TapResult:
    xy = asked.xy_mm or (None, None)
    return TapResult(tap_id=fields.pop("tap_id", None), level_db=asked.level_db, method=asked.method,
                     location=asked.location, x_mm=xy[0], y_mm=xy[1], asked_host_s=asked.asked_host_s, **fields)


class _MethodAsked:
    """A ``/method`` waiting for its answer."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.reply: Any = None
        self.given_up = False


#: Most requests given up whose late answers are still recognised (and discarded).
_GIVEN_UP_KEPT = 256


def _f32(value: float) -> float:
    """``value`` as OSC sends it (a 32-bit float): the server echoes that."""
    return struct.unpack(">f", struct.pack(">f", value))[0]


class _OscBackend:
    """Asks a ``serve-osc`` over a UDP socket connected to it (the kernel drops datagrams
    from anyone else), and pairs each answer with its request by what the answer echoes:
    the location or point and the level of a ``/played`` (with tap ids that increase),
    the target named in an ``/error``, the name of a ``/method``. The server answers one
    client's taps in the order asked, so an answer goes to the oldest request it fits;
    an answer to a request already given up (timed out) is discarded."""

    def __init__(self, host: str, port: int) -> None:
        try:
            from pythonosc.osc_message_builder import OscMessageBuilder  # noqa: F401
        except ImportError:
            raise ValidationError("playing through serve-osc needs python-osc: pip install 'vibrofocus[osc]'") from None
        if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
            raise ValidationError(f"port must be an integer from 1 to 65535, got {shorten(port)}")
        if not isinstance(host, str) or not host:
            raise ValidationError(f"host must be an address, got {shorten(host)}")
        self._server = (host, port)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            # Connected: answers come only from the server's address and port.
            self._sock.connect(self._server)
        except OSError as exc:
            self._sock.close()
            raise ValidationError(f"cannot reach {self._where()}: {exc.strerror or exc}") from None
        self._method = ""
        # Requests not answered yet, oldest first; those given up stay (marked) until their answer.
        self._waiting: deque[_Asked | _MethodAsked] = deque()
        self._last_tap_id = 0
        self._lock = threading.Lock()

    def _where(self) -> str:
        return f"serve-osc at {self._server[0]}:{self._server[1]}"

    def _send(self, address: str, *args: Any) -> None:
        from pythonosc.osc_message_builder import OscMessageBuilder

        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(arg)
        self._sock.send(builder.build().dgram)

    def set_method(self, name: str, timeout_s: float) -> None:
        """Switch the server's method now and wait for its answer (not on a flip: a server
        makes a new method's nine location designs when it switches)."""
        if name == self._method:
            return
        asked = _MethodAsked(name)
        with self._lock:
            self._send("/method", name)
            self._waiting.append(asked)
        error = self._pump(asked, timeout_s)
        if asked.reply is None:
            with self._lock:
                self._give_up(asked)
            raise ValidationError(f"no answer from {self._where()} in {timeout_s:g} s (is it running, on that "
                                  f"port?{' ' + error if error else ''})")
        if asked.reply.address != "/method":
            # The server keeps its method: a tap recorded under this name would be false.
            reason = asked.reply.params[0] if asked.reply.params else asked.reply.address
            raise ValidationError(f"{self._where()} refused method {name!r}: {reason}")
        self._method = name

    def play(self, asked: _Asked) -> None:
        with self._lock:
            if asked.location is not None:
                self._send("/tap", asked.location, float(asked.level_db))
            else:
                self._send("/tap_xy", float(asked.xy_mm[0]), float(asked.xy_mm[1]), float(asked.level_db))
            self._waiting.append(asked)

    def wait(self, asked: _Asked, timeout_s: float) -> None:
        error = self._pump(asked, timeout_s)
        if asked.result is None:
            asked.result = _result(asked, error=error or f"no answer from {self._where()} in {timeout_s:g} s")
            with self._lock:
                self._give_up(asked)

    def _pump(self, until: Any, timeout_s: float) -> str | None:
        """Read answers, each to the request it echoes, until ``until`` has its own; a
        socket error (no server: ICMP port unreachable) is returned."""
        from pythonosc.osc_message import OscMessage

        deadline = time.monotonic() + timeout_s
        while (until.result if isinstance(until, _Asked) else until.reply) is None:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._sock.settimeout(left)
            try:
                data = self._sock.recv(65536)
            except (TimeoutError, socket.timeout):
                continue
            except OSError as exc:
                return f"{self._where()}: {exc}"
            try:
                message = OscMessage(data)
            except Exception:  # noqa: BLE001 - not an answer of serve-osc
                continue
            with self._lock:
                owner = self._owner(message)
                if owner is None or owner.given_up:
                    continue  # an answer to nothing asked, or to a request given up: discarded
            if isinstance(owner, _MethodAsked):
                owner.reply = message
            else:
                owner.result = self._answer(owner, message)
        return None

    def _owner(self, message: Any) -> _Asked | _MethodAsked | None:
        """The request ``message`` answers (taken off the waiting list), or None (under the lock)."""
        params = list(message.params)
        if message.address == "/method":
            fits = lambda w: isinstance(w, _MethodAsked) and params == [w.name]  # noqa: E731
        elif message.address == "/played":
            if len(params) < 6 or isinstance(params[-5], bool) or not isinstance(params[-5], int):
                return None
            tap_id, level, echo = params[-5], params[-1], params[:-5]
            if tap_id <= self._last_tap_id:
                return None  # tap ids increase: an old or a repeated answer
            fits = lambda w: isinstance(w, _Asked) and _echo(w) == echo and _f32(w.level_db) == level  # noqa: E731
        elif message.address == "/error" and params and isinstance(params[0], str):
            fits = _error_fits(params[0])
        else:
            return None
        owner = next((w for w in self._waiting if fits(w)), None)
        if owner is None:
            return None
        if message.address == "/played":
            self._last_tap_id = params[-5]
            # Answers come in the order asked: those asked before this tap and given up
            # were answered already (or their answer was lost): forget them.
            while self._waiting and self._waiting[0] is not owner and self._waiting[0].given_up:
                self._waiting.popleft()
        self._waiting.remove(owner)
        return owner

    def _give_up(self, asked: Any) -> None:
        """``asked`` timed out: kept, marked, so that its late answer is recognised and discarded."""
        asked.given_up = True
        given_up = [w for w in self._waiting if w.given_up]
        for old in given_up[:max(0, len(given_up) - _GIVEN_UP_KEPT)]:
            self._waiting.remove(old)

    @staticmethod
    def _answer(asked: _Asked, message: Any) -> TapResult:
        params = list(message.params)
        if message.address == "/played" and len(params) >= 5:
            tap_id, host_s, device_s, clock, _level = params[-5:]
            device = None if not isinstance(device_s, float) or math.isnan(device_s) else float(device_s)
            return _result(asked, tap_id=int(tap_id), onset_host_s=float(host_s), onset_device_s=device,
                           onset_clock=clock or None)
        reason = params[0] if message.address == "/error" and params else f"unexpected answer {message.address}"
        return _result(asked, error=str(reason))

    def close(self) -> None:
        self._sock.close()


def _echo(asked: _Asked) -> list:
    """What ``/played`` echoes of a tap: its location, or its point as 32-bit floats."""
    if asked.location is not None:
        return [asked.location]
    return [_f32(asked.xy_mm[0]), _f32(asked.xy_mm[1])]


_LOCATION = re.compile(r"(?:/tap location|unknown location) (-?\d+)\b")
_POINT = re.compile(r"/tap_xy(?: x (\S+) mm, y (\S+) mm|: \((\S+), (\S+)\) mm)")
_METHOD = re.compile(r"/method\b(?: (\S+) was not played)?")


def _error_fits(reason: str):
    """Which waiting request an ``/error`` answers: the tap or method its reason names
    (the server's reasons name the target: ``stopped: /tap location 5 ...``), else the
    oldest tap (a reason that names none, as a refused datagram's)."""
    if (found := _LOCATION.search(reason)) is not None:
        location = int(found.group(1))
        return lambda w: isinstance(w, _Asked) and w.location == location
    if (found := _POINT.search(reason)) is not None:
        x, y = (found.group(1), found.group(2)) if found.group(1) is not None else (found.group(3), found.group(4))
        return lambda w: (isinstance(w, _Asked) and w.xy_mm is not None
                          and (f"{_f32(w.xy_mm[0]):g}", f"{_f32(w.xy_mm[1]):g}") == (x, y))
    if (found := _METHOD.search(reason)) is not None:
        name = found.group(1)
        return lambda w: isinstance(w, _MethodAsked) and name in (None, w.name)
    return lambda w: isinstance(w, _Asked)


class _Stages:
    """The lines of a start that takes tens of seconds: each stage, the grid's rows at most
    every 10 s with the time left, and the time it took."""

    EVERY_S = 10.0

    def __init__(self, report: Callable[[str], Any] | None) -> None:
        self.report, self.start, self.last = report, time.monotonic(), None

    def __call__(self, line: str) -> None:
        if self.report is not None:
            self.report(f"vibrofocus: {line}")

    def rows(self, done: int, total: int) -> None:
        now = time.monotonic()
        if done < total and self.last is not None and now - self.last < self.EVERY_S:
            return
        self.last = now
        spent = now - self.start
        left = f", about {spent * (total - done) / done:.0f} s left" if 0 < done < total else ""
        self(f"grid {done}/{total} rows ({spent:.0f} s{left})")

    def done(self) -> None:
        self(f"ready in {time.monotonic() - self.start:.0f} s")


class _RigBackend:
    """Plays on a rig of this process, each play on a worker thread (in the order asked)."""

    def __init__(self, rig: Any, calibration: Any, rig_config: Any, seed: int | None, method: str,
                 anywhere: bool = True, grid_pitch_m: float | None = None,
                 report: Callable[[str], Any] | None = None) -> None:
        from ..realtime import GRID_PITCH_M, TapDesigner
        from ..rendering import TransferMatrix
        from ..rigs import make_rig

        say = _Stages(report)
        if isinstance(rig, str):
            say(f"opening the {rig} rig and designing its taps ...")
            self._rig, self._owned = make_rig(rig, config=rig_config, seed=seed), True
        else:
            self._rig, self._owned = rig, False
        try:
            if calibration is not None:
                from ..calibration import load_calibration

                cal = load_calibration(calibration)
                if abs(cal.fs - self._rig.fs) > 1e-9 * self._rig.fs:
                    raise ValidationError(f"calibration {calibration} is at {cal.fs:g} Hz but the rig runs at "
                                          f"{self._rig.fs:g} Hz")
                tm, model = TransferMatrix.from_calibration(cal), cal.fit
            elif getattr(self._rig, "kind", "") == "simulated" or hasattr(self._rig, "transfer"):
                tm, model = TransferMatrix.from_model(self._rig, self._rig.layout, self._rig.fs), self._rig
            else:
                raise ValidationError("a hardware rig needs the calibration its taps are designed from")
            self.designer = TapDesigner(tm, model, method=method, limit_v=self._rig.limits.peak_v,
                                        grid_pitch_m=grid_pitch_m or GRID_PITCH_M)
            if anywhere and model is not None:
                say("evaluating the skin model on the grid for taps at points (tens of seconds; "
                    "anywhere=False skips it) ...")
                self.designer.prepare_grid(say.rows)
            say.done()
        except BaseException:
            if self._owned:
                self._rig.close()
            raise
        self._tap_id = 0
        self._lock = threading.Lock()  # one play at a time, in the order asked

    def set_method(self, name: str, timeout_s: float) -> None:
        from ..errors import VibrofocusError

        if name == self.designer.method:
            return
        with self._lock:  # after the plays under way
            try:
                self.designer.set_method(name)
            except VibrofocusError as exc:
                raise ValidationError(f"method {name!r}: {exc}") from None

    def play(self, asked: _Asked) -> None:
        asked.done = threading.Event()
        threading.Thread(target=self._play, args=(asked,), name="vibrofocus tap", daemon=True).start()

    def _play(self, asked: _Asked) -> None:
        import numpy as np

        from ..errors import VibrofocusError

        try:
            with self._lock:
                try:
                    drives = (self.designer.drives_at(asked.location) if asked.location is not None
                              else self.designer.drives_xy(np.asarray(asked.xy_mm, float) * 1e-3))
                    if asked.level_db != 0.0:
                        drives = drives * 10.0 ** (asked.level_db / 20.0)
                    onset = self._rig.play(drives)  # the safety layer decides
                except VibrofocusError as exc:
                    asked.result = _result(asked, error=str(exc))
                    return
                self._tap_id += 1
                asked.result = _result(asked, tap_id=self._tap_id, onset_host_s=float(onset.host_s),
                                       onset_device_s=onset.device_s, onset_clock=onset.clock)
        except Exception as exc:  # noqa: BLE001 - told through the result, never lost in a thread
            asked.result = _result(asked, error=f"{type(exc).__name__}: {exc}")
        finally:
            asked.done.set()

    def wait(self, asked: _Asked, timeout_s: float) -> None:
        if not asked.done.wait(timeout_s):
            asked.result = _result(asked, error=f"no answer from the rig in {timeout_s:g} s")

    def close(self) -> None:
        self._rig.stop()
        if self._owned:
            self._rig.close()
