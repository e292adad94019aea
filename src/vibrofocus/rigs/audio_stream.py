"""The audio rig's one running stream: plays scheduled into its callback at a frame index.

:class:`RunningStream` opens one full-duplex PortAudio stream when the rig opens and
keeps it running, writing silence, until the rig closes. A play or recording is a
:class:`Job` handed to the stream's callback with the frame index it starts at (the
frames the callback has handed out since the stream started); the callback writes its
block from that frame on, records the inputs beside it where asked, and writes silence
again from the first buffer after a stop. Nothing is opened per play, so a play's
onset is the next buffer boundary after it is scheduled (docs/performance.md, "Taps at
the outputs").

Every call into PortAudio that may wait on the audio server (opening, starting, aborting
and closing the stream) has a deadline (:data:`OPEN_DEADLINE_S`, :data:`CLOSE_DEADLINE_S`),
and a running stream whose callback stops coming for :data:`STALL_S` counts as a server
that stopped answering. PortAudio cannot leave a hung or restarted server within the
process that used it (a call into it blocks for good, or fails with "Insufficient memory"
until the process restarts), so after either the audio server is *lost* for this process
(:func:`server_lost`): every later play is refused at once with a message that says to
restart vibrofocus after the audio server, and PortAudio is not terminated at the
process's exit, where it would block or abort (docs/hardware.md, "A hung or restarted
audio server").
"""

from __future__ import annotations

import atexit
import logging
import math
import threading
import time
import weakref
from typing import Callable

import numpy as np

from .devices import DeviceError

__all__ = ["RunningStream", "Job", "server_lost", "raise_if_lost", "mark_lost", "call_with_deadline", "OPEN_DEADLINE_S", "CLOSE_DEADLINE_S",
           "STALL_S"]

log = logging.getLogger(__name__)

#: Longest a stream may take to open and start, s.
OPEN_DEADLINE_S = 5.0
#: Longest a stream may take to abort and close, s.
CLOSE_DEADLINE_S = 5.0
#: A running stream whose callback has not come for this long: the server stopped answering, s.
STALL_S = 2.0
#: How long each of the budget axis's two windows of callbacks lasts, s: the axis is the
#: earliest of the last two windows' estimates (a callback runs late, never early), which
#: follows a drift between the device's and the host's clocks within two windows.
ANCHOR_WINDOW_S = 1.0
#: How long a new stream's callbacks run before its first play is placed, s: a few cycles,
#: so that the budget's axis has seen a callback that came on time.
AXIS_SETTLE_S = 0.2

# Why the audio server is lost for this process (None while it answers): process-wide,
# as PortAudio's state is.
_lost: str | None = None
_lost_lock = threading.Lock()
# Every stream not yet closed, for the check at the process's exit.
_OPEN: "weakref.WeakSet[RunningStream]" = weakref.WeakSet()
_exit_check_registered = False


def _check_at_exit() -> None:
    # Runs before sounddevice's own exit handler (registered after it): a stream whose
    # callback stopped coming means a server that hung or went away, where terminating
    # PortAudio would block or abort.
    for stream in list(_OPEN):
        if stream.stalled():
            mark_lost("the audio server stopped answering before the process exited")
            return


def _register_exit_check() -> None:
    global _exit_check_registered
    if not _exit_check_registered:
        atexit.register(_check_at_exit)
        _exit_check_registered = True


def server_lost() -> str | None:
    """Why the audio server can no longer be used from this process, or None while it answers."""
    return _lost


def _lost_message() -> str:
    return (f"{_lost}. PortAudio cannot reconnect to a hung or restarted audio server within the process that used "
            "it: the outputs are silent; restart the audio server (JACK) if it is not running, then restart "
            "vibrofocus")


def mark_lost(reason: str) -> None:
    """Record that the audio server is lost for this process (the first reason is kept).

    From then on PortAudio is not terminated at the process's exit: on a server that hangs
    it would block for good, on one that went away it aborts on an assertion.

    Parameters
    ----------
    reason : str
        What happened, as people read it (the first words of every later refusal).
    """
    global _lost
    with _lost_lock:
        if _lost is not None:
            return
        _lost = reason
    log.error("%s", reason)
    try:
        import sounddevice as sd
    except OSError:
        return
    # sounddevice registers Pa_Terminate at import; it has no public way to skip it.
    handler = getattr(sd, "_exit_handler", None)
    if handler is not None:
        atexit.unregister(handler)


def raise_if_lost() -> None:
    """Raise :class:`DeviceError` saying what to do when the audio server is lost for this process."""
    if _lost is not None:
        raise DeviceError(_lost_message())


def call_with_deadline(func: Callable[[], object], seconds: float, what: str) -> object:
    """Run ``func()`` in a daemon thread; give up on it after ``seconds``.

    A call that does not return in time leaves the audio server lost for this process
    (:func:`mark_lost`) and raises :class:`DeviceError`; the thread is abandoned, so
    Ctrl-C and the process's exit still work.

    Parameters
    ----------
    func : callable
        The PortAudio call.
    seconds : float
        Its deadline, s.
    what : str
        What it does, as people read it ("open the stream").
    """
    raise_if_lost()
    result: dict = {}

    def run() -> None:
        try:
            result["value"] = func()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            result["error"] = exc

    thread = threading.Thread(target=run, name=f"vibrofocus-audio-{what.replace(' ', '-')}", daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        mark_lost(f"the audio server did not answer within {seconds:g} s when the rig tried to {what} (is it "
                  "stopped or hung?)")
        raise DeviceError(_lost_message())
    if "error" in result:
        raise result["error"]
    return result.get("value")


class Job:
    """One play or recording for the running stream's callback.

    Parameters
    ----------
    block : ndarray, shape (n_frames, n_out)
        Digital samples for the stream's output columns, float32.
    start_frame : int
        The stream frame its first sample goes out at (later if it reaches the callback
        after that frame: then :attr:`actual_start` says when).
    stopped : callable
        True once the play was stopped (the rig's stop epoch).
    in_cols : list of int, optional
        The stream's input columns to record beside it (0-based); None: play only.
    """

    def __init__(self, block: np.ndarray, start_frame: int, stopped: Callable[[], bool],
                 in_cols: list[int] | None = None):
        self.block = block
        self.total = len(block)
        self.start_frame = int(start_frame)
        self.stopped = stopped
        self.in_cols = in_cols
        self.recorded = np.zeros((self.total, len(in_cols)), np.float32) if in_cols is not None else None
        self.pos = 0
        self.actual_start: int | None = None
        #: (host time.monotonic(), outputBufferDacTime, dac - currentTime) of the first sample.
        self.onset: tuple[float, float, float] | None = None
        self.status = None
        self.error: BaseException | None = None
        self.done = threading.Event()
        self.halted = threading.Event()


def buffer_lead_s(current: float, dac: float) -> float:
    """How far ahead of its callback a buffer reaches the outputs, s: ``dac - current``,
    or 0 (at the outputs now) where the host API gives no such times or they lie 2 s or
    more apart."""
    lead = dac - current
    return lead if math.isfinite(lead) and 0.0 <= lead < 2.0 else 0.0


class FrameAxis:
    """When a stream's frame 0 was at its outputs, in host time: the energy budget's time axis.

    Each callback gives an estimate: its host time, plus how far ahead of it its buffer
    reaches the converter, less its first frame's time on the stream. A callback can only
    run late (a loaded machine delays it by milliseconds), never early, so the axis is the
    earliest estimate of the last two windows of :data:`ANCHOR_WINDOW_S`; it follows a drift
    between the device's and the host's clocks within two windows. A lost buffer (the device
    or its server fell behind) leaves the frame count behind the host's clock for good: the
    axis starts over at that callback's estimate, never earlier than it was.

    Parameters
    ----------
    fs : float
        The stream's rate, Hz.
    """

    def __init__(self, fs: float):
        self.fs = float(fs)
        #: Host time of frame 0 at the outputs (None before the first callback), s.
        self.anchor_s: float | None = None
        # The earliest estimate in the window before and in the current one, and when the
        # current one began.
        self._mins = [math.inf, math.inf]
        self._window_s = 0.0

    def update(self, now: float, first: int, current: float, dac: float, lost: bool = False) -> None:
        """Take one callback's times.

        Parameters
        ----------
        now : float
            Host time (``time.monotonic()``) in the callback, s.
        first : int
            The stream frame its buffer begins at.
        current, dac : float
            Its ``currentTime`` and ``outputBufferDacTime``, s on the stream's clock (NaN or
            anything outside 0-2 s apart: the buffer is taken to be at the outputs now).
        lost : bool
            Whether it reported lost samples.
        """
        estimate = now + buffer_lead_s(current, dac) - first / self.fs
        if self.anchor_s is None or lost:
            start = estimate if self.anchor_s is None else max(self.anchor_s, estimate)
            self._mins, self._window_s = [start, start], now
        elif now - self._window_s >= ANCHOR_WINDOW_S:
            self._mins, self._window_s = [self._mins[1], estimate], now
        else:
            self._mins[1] = min(self._mins[1], estimate)
        self.anchor_s = min(self._mins)


class RunningStream:
    """A full-duplex PortAudio stream that runs from the rig's opening to its closing.

    Parameters
    ----------
    sd : module
        sounddevice.
    device : int
        The PortAudio device.
    fs : float
        The device's rate, Hz.
    n_in, n_out : int
        Input and output channels the stream opens.
    out_cols : list of int
        The output columns (0-based) a job's block columns go to.
    latency : str or float
        PortAudio's suggested latency.

    Raises
    ------
    DeviceError
        The stream did not open or start (or not within :data:`OPEN_DEADLINE_S`).
    """

    def __init__(self, sd, device: int, fs: float, n_in: int, n_out: int, out_cols: list[int], latency):
        self._sd = sd
        self.fs = float(fs)
        self.out_cols = list(out_cols)
        self.frame = 0
        self.callbacks = 0
        #: Callbacks that reported lost samples since the stream opened.
        self.xruns = 0
        self.job: Job | None = None
        # The job whose last buffer the next callback's flags tell of.
        self.trailing: Job | None = None
        self.opened_s = time.monotonic()
        # (host time, first frame, frames, currentTime, outputBufferDacTime) of the last callback.
        self.last: tuple[float, int, int, float, float] | None = None
        # The budget's time axis: when frame 0 was at the outputs, in host time.
        self.axis = FrameAxis(self.fs)
        #: The latest a buffer handed over in a callback finished playing, after that
        #: callback, s (its ``outputBufferDacTime - currentTime`` plus its own length): what a
        #: stop cannot recall. PortAudio's figure for a JACK stream is one period; JACK2 plays
        #: two to three periods behind (measured), so this is the one to state.
        self.largest_ahead_s = 0.0
        self._first_callback_s: float | None = None

        def make():
            return sd.Stream(samplerate=self.fs, device=device, channels=(n_in, n_out), dtype="float32",
                             latency=latency, callback=lambda *args: self._callback(*args))

        try:
            self.stream = call_with_deadline(make, OPEN_DEADLINE_S, "open its stream")
        except sd.PortAudioError as exc:
            raise DeviceError(f"the audio interface could not open a stream: {exc}") from None
        _OPEN.add(self)
        _register_exit_check()  # after sounddevice's import: it runs before sounddevice's handler
        latency_s = self.stream.latency
        self.output_latency_s = float(latency_s[1] if isinstance(latency_s, tuple) else latency_s)

    def start(self) -> None:
        """Start the stream (silence until a job comes), within :data:`OPEN_DEADLINE_S`."""
        try:
            call_with_deadline(self.stream.start, OPEN_DEADLINE_S, "start its stream")
        except self._sd.PortAudioError as exc:
            raise DeviceError(f"the audio interface could not start a stream: {exc}") from None
        self.opened_s = time.monotonic()
        self._settle_axis()

    def _settle_axis(self) -> None:
        # The first callbacks of a stream on a loaded machine may all come late: wait until they
        # have run AXIS_SETTLE_S. Callbacks that do not come are the stall check's to report.
        deadline = self.opened_s + STALL_S
        while time.monotonic() < deadline:
            first, last = self._first_callback_s, self.last
            if first is not None and last is not None and last[0] - first >= AXIS_SETTLE_S:
                return
            time.sleep(0.005)

    # ------------------------------------------------------------------ the callback
    def _callback(self, indata, outdata, frames, time_info, status) -> None:
        now = time.monotonic()
        first = self.frame
        self.frame = first + frames
        current, dac = float(time_info.currentTime), float(time_info.outputBufferDacTime)
        self.last = (now, first, frames, current, dac)
        if self._first_callback_s is None:
            self._first_callback_s = now
        self.axis.update(now, first, current, dac, lost=bool(status))
        self.largest_ahead_s = max(self.largest_ahead_s, buffer_lead_s(current, dac) + frames / self.fs)
        self.callbacks += 1
        if status:
            self.xruns += 1
        trailing = self.trailing
        if trailing is not None:  # what was lost in the last job's last buffer is told now
            trailing.status |= status
            self.trailing = None
        outdata.fill(0)
        job = self.job
        if job is None:
            return
        try:
            if job.stopped() or job.halted.is_set():
                self.job = None
                job.done.set()
                return
            offset = 0
            if job.actual_start is None:
                offset = max(0, job.start_frame - first)
                if offset >= frames:
                    return  # its frame is in a later buffer
                job.actual_start = first + offset
                job.onset = (now, dac + offset / self.fs, dac - current + offset / self.fs)
                # This callback's flags tell of the buffer before it, not of the job.
                job.status = type(status)()
            else:
                job.status |= status
            n = min(frames - offset, job.total - job.pos)
            outdata[offset:offset + n, self.out_cols] = job.block[job.pos:job.pos + n]
            if job.recorded is not None:
                job.recorded[job.pos:job.pos + n] = indata[offset:offset + n, job.in_cols]
            job.pos += n
            if job.pos >= job.total:
                self.job = None
                self.trailing = job
                job.done.set()
        except BaseException as exc:  # noqa: BLE001 - the stream runs on; the job reports it
            outdata.fill(0)
            job.error = exc
            self.job = None
            job.done.set()

    # ------------------------------------------------------------------ the play's side
    @property
    def anchor_s(self) -> float | None:
        """Host time of frame 0 at the outputs (None before the first callback), s."""
        return self.axis.anchor_s

    @property
    def period_s(self) -> float:
        """The length of the last buffer, s (a guess before the first)."""
        return (self.last[2] if self.last is not None else 1024) / self.fs

    def plan(self, margin_s: float) -> tuple[int, float]:
        """The first buffer boundary whose callback comes after ``margin_s`` from now.

        Returns
        -------
        frame : int
            The stream frame a job scheduled now would start at.
        at_s : float
            When that frame is at the outputs, on the budget's time axis
            (``time.monotonic()`` of frame 0 at the outputs, plus frames / fs).
        """
        last, anchor = self.last, self.anchor_s
        if last is None or anchor is None:
            return self.frame, time.monotonic()
        host, first, frames, _, _ = last
        period = frames / self.fs
        ahead = max(1, math.ceil((time.monotonic() + margin_s - host) / period))
        frame = first + ahead * frames
        return frame, anchor + frame / self.fs

    def time_of(self, frame: int) -> float:
        """A frame's time at the outputs on the budget's axis, s."""
        return (self.anchor_s if self.anchor_s is not None else self.opened_s) + frame / self.fs

    def schedule(self, job: Job) -> None:
        """Hand a job to the callback."""
        if self.job is not None:
            raise DeviceError("the audio stream is already playing a job; one play at a time")
        self.job = job

    def retire(self, job: Job, wait: bool = True) -> None:
        """Take a job off the callback (silence from its next buffer); wait for that buffer.

        The callback after a job's last buffer also tells whether that buffer was lost
        (its status flags): after the wait, :attr:`Job.status` holds it.
        """
        job.halted.set()
        if self.job is job:
            self.job = None
        if wait:
            self.wait_callback()

    def wait_callback(self) -> bool:
        """Wait for the next callback (within two buffers and 50 ms); whether it came."""
        seen = self.callbacks
        deadline = time.monotonic() + 2 * self.period_s + 0.05
        while self.callbacks == seen:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
        return True

    def stalled(self) -> bool:
        """Whether the callback has not come for :data:`STALL_S`."""
        last = self.last[0] if self.last is not None else self.opened_s
        return time.monotonic() - last > STALL_S

    def alive(self) -> bool:
        """Whether the stream still runs and its callback still comes."""
        try:
            active = bool(self.stream.active)
        except Exception:  # noqa: BLE001 - a stream PortAudio no longer knows
            return False
        return active and not self.stalled()

    def close(self, settle_s: float = 0.0) -> None:
        """Abort and close the stream within :data:`CLOSE_DEADLINE_S` (nothing once the server is lost).

        Parameters
        ----------
        settle_s : float
            Time to wait between aborting the stream and closing it, s. On JACK, aborting
            disconnects the stream's ports, and the server answers a changed graph a cycle
            or two later by having every client recompute its ports' latencies in libjack's
            notification thread; closing unregisters the ports, and libjack (1.9.21 and
            later alike) removes a port from the list that thread walks without a lock
            (jackaudio/jack2#216), which can crash the process. Waiting out that round
            keeps the rig's own abort from racing its close.
        """
        self.job = None
        _OPEN.discard(self)
        if self.stalled():
            mark_lost("the audio server stopped answering (the rig's stream got no callback for "
                      f"{STALL_S:g} s) before the rig closed")
        if _lost is not None:
            return  # a call into PortAudio would block or fail; the stream goes with the process

        def end():
            try:
                if self.stream.active:
                    self.stream.abort()
                    time.sleep(settle_s)
            finally:
                self.stream.close()

        try:
            call_with_deadline(end, CLOSE_DEADLINE_S, "close its stream")
        except DeviceError as exc:
            log.error("%s", exc)
        except Exception as exc:  # noqa: BLE001 - closing goes on
            # At the process's exit sounddevice may have terminated PortAudio first, which
            # closed the stream already.
            (log.debug if "not initialized" in str(exc).lower() else log.warning)(
                "closing the audio stream: %s", exc)
