"""The rig interface every backend implements (simulated, audio, NI-DAQmx).

In the way nidaqmx separates its public API from interchangeable interpreters, the
public methods here (``play``, ``play_and_record``, ``stop``) are final: they run the
safety layer and guarantee zero outputs afterwards, then hand a checked drive to the
backend's private ``_play`` / ``_play_and_record`` / ``_zero_outputs``.

They also keep one job at a time on the hardware: a play or recording from a thread
other than the one that holds :meth:`Rig.reserve` is refused with
:class:`~vibrofocus.rigs.DeviceBusyError`, and so is a play while another is running.
:meth:`Rig.stop` is the exception: it works from any thread, at any time.

Stops are counted, never flagged: :meth:`Rig.stop` increments a stop epoch, and every
play reads it when it is called. A stop at any moment after that, while the drive is
checked, admitted, resampled or handed to the device, ends the play; nothing a backend
does at its start can forget it (a flag that a backend cleared when it started would).
Backends ask :meth:`Rig._stop_requested` (or pass :meth:`Rig._stop_probe` to the thread
that feeds the device).
"""

from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from contextlib import contextmanager
from typing import Iterator

import numpy as np

from .._validation import as_array, check_positive
from ..defaults import FS_HZ
from ..errors import ValidationError
from ..layout import ArrayLayout
from .devices import DeviceBusyError, DeviceError, StoppedError
from .onset import DeviceOnset
from .safety import EnergyBudget, SafetyLimits, check_drive

__all__ = ["Rig"]

log = logging.getLogger(__name__)


class Rig(ABC):
    """A rig: actuators to play drives and (optionally) a sensor to record the skin.

    Parameters
    ----------
    layout : ArrayLayout, optional
        The array; default the reference setup.
    fs : float
        Sample rate of drives and recordings, Hz.
    limits : SafetyLimits, optional
        Limits at the actuator; default ``SafetyLimits()``.

    Notes
    -----
    ``max_points_per_recording`` is the number of skin points one recording can cover:
    1 for a single-spot vibrometer (the operator aims it between recordings), ``None``
    for a rig that can measure anywhere at once, such as the simulated forearm.
    """

    #: Short identifier used by ``--rig``.
    kind: str = "abstract"
    #: Points one recording can cover; None means any number.
    max_points_per_recording: int | None = 1
    #: Whether one job at a time holds the rig (hardware: True). A model, such as the
    #: simulated forearm, may serve several threads at once.
    one_job_at_a_time: bool = False

    def __init__(self, layout: ArrayLayout | None = None, fs: float = FS_HZ, limits: SafetyLimits | None = None):
        self.layout = layout if layout is not None else ArrayLayout.reference()
        self.fs = check_positive(fs, "fs")
        self._budget: EnergyBudget | None = None
        self.limits = limits if limits is not None else SafetyLimits()
        # Who holds the hardware: a job (reserve) or a single play; never two at once.
        self._use_lock = threading.Lock()
        self._job_owner: str | None = None
        # Set by stop() during a job: the job's further plays are refused until it ends.
        self._job_stopped = False
        self._job_thread: int | None = None
        self._playing = False
        # The stop epoch (module docstring): stop() increments it; a play ends if it
        # changed since the play was called. The entry epoch of the play running on
        # each thread is kept per thread for the backend.
        self._stop_epoch = 0
        self._epoch_lock = threading.Lock()
        self._entry = threading.local()

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        # The public methods hold the safety layer and the stop: a backend implements the
        # private ones (_play, _play_and_record, ...), never these.
        final = ("play", "play_and_record", "play_and_capture", "stop", "check", "reserve", "budget")
        overridden = [name for name in final if name in cls.__dict__]
        if overridden and cls.__module__ != __name__:
            raise TypeError(f"{cls.__name__} overrides {', '.join(overridden)} of Rig; these are final (they run "
                            "the safety layer and the emergency stop): implement _play, _play_and_record, "
                            "_play_and_capture and _zero_outputs instead")

    # ------------------------------------------------------------------ public, final
    def check(self, drive: np.ndarray) -> np.ndarray:
        """Run the safety layer on ``drive`` without playing it; return what would play.

        The check of one drive: the budget across consecutive plays is applied when the
        drive plays.
        """
        safe = check_drive(drive, self.fs, self.layout.n_actuators, self.limits)
        self._check_output_level(safe)
        return safe

    @property
    def limits(self) -> SafetyLimits:
        """The limits at the actuator (:class:`SafetyLimits`)."""
        return self._limits

    @limits.setter
    def limits(self, value: SafetyLimits) -> None:
        if not isinstance(value, SafetyLimits):
            raise ValidationError(f"limits must be SafetyLimits, got {type(value).__name__}")
        if getattr(self, "_limits_frozen", False):
            raise ValidationError(
                f"the limits of a {self.kind} rig come from its configuration and cannot be changed on the "
                "open rig (the energy budget's history would be lost); edit the configuration and open it again")
        self._limits = value
        self._budget = None

    @property
    def budget(self) -> EnergyBudget:
        """The RMS budget across this rig's consecutive plays."""
        if self._budget is None:
            self._budget = EnergyBudget(self.limits, self.layout.n_actuators, self.fs)
        return self._budget

    # ------------------------------------------------------------------ the stop epoch
    def _begin_play(self) -> int:
        """Read the stop epoch at the entry of a play and keep it for this thread's backend."""
        epoch = self._stop_epoch
        self._entry.epoch = epoch
        return epoch

    def _stop_requested(self) -> bool:
        """Whether :meth:`stop` was called since the play running on this thread was called."""
        epoch = getattr(self._entry, "epoch", None)
        return epoch is not None and self._stop_epoch != epoch

    def _stop_probe(self):
        """A callable for another thread (a device callback): True once this play is stopped."""
        epoch = getattr(self._entry, "epoch", self._stop_epoch)
        return lambda: self._stop_epoch != epoch

    def _raise_if_stopped(self, what: str) -> None:
        if self._stop_requested():
            raise StoppedError(what)

    def _admit(self, drive: np.ndarray, what: str) -> None:
        """Admit a checked drive to the energy budget now; a stop before or during admission ends it.

        Backends call it again before each retry of the same drive (every take counts).
        """
        self._raise_if_stopped(what)
        self.budget.admit(drive, self._clock())
        self._raise_if_stopped(what)

    @contextmanager
    def reserve(self, owner: str) -> Iterator["Rig"]:
        """Hold the rig for one job (a calibration, a session) on this thread.

        While it is held, plays and recordings from other threads, and a second
        ``reserve``, are refused with :class:`DeviceBusyError`. :meth:`stop` still works
        from any thread, and it ends the job: the job's further plays and recordings
        are refused (a stop between two takes of a calibration stops the calibration).

        Parameters
        ----------
        owner : str
            What holds it, as people read it ("calibration of P01"); shown to whoever
            is refused.
        """
        if not self.one_job_at_a_time:
            yield self
            return
        self._acquire(owner)
        self._job_owner, self._job_thread = owner, threading.get_ident()
        self._job_stopped = False
        try:
            yield self
        finally:
            self._job_owner = self._job_thread = None
            self._job_stopped = False
            self._use_lock.release()

    @property
    def busy_with(self) -> str | None:
        """What holds the rig now ("calibration of P01", "a play"), or None when it is free."""
        if self._job_owner is not None:
            return self._job_owner
        return "a play" if self._playing else None

    def _acquire(self, what: str) -> None:
        if not self._use_lock.acquire(blocking=False):
            raise DeviceBusyError(
                f"the {self.kind} rig is busy with {self.busy_with or 'another job'}; {what} was refused. "
                "Wait until it ends, or stop it first (one job uses a device at a time)"
            )

    @contextmanager
    def _exclusive(self, what: str) -> Iterator[None]:
        """Hold the hardware for one play: inside the caller's job, or alone."""
        if self._job_thread == threading.get_ident():
            if self._job_stopped:
                raise DeviceError(f"the {self.kind} rig was stopped (rig.stop()) during {self._job_owner}; "
                                  f"{what} was refused and the job ends here. Start it again when ready")
            yield  # this thread's own job holds the rig
            return
        if not self.one_job_at_a_time:
            yield
            return
        self._acquire(what)
        self._playing = True
        try:
            yield
        finally:
            self._playing = False
            self._use_lock.release()

    def _clock(self) -> float:
        """Now, s, on the clock the energy budget places plays on (monotonic)."""
        return time.monotonic()

    def _check_output_level(self, drive: np.ndarray) -> None:
        """A backend's own check of a checked drive (e.g. the voltage into its amplifier)."""

    def play(self, drive: np.ndarray) -> DeviceOnset:
        """Play a drive on the actuators (participant stimulation).

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages at the actuators, V.

        Returns
        -------
        DeviceOnset
            When the play started: host ``time.monotonic()``, s, and the first sample on
            the device's own clock where the rig has one (:mod:`vibrofocus.rigs.onset`).

        Raises
        ------
        SafetyError
            Before anything is played, if the drive breaks a limit.
        """
        self._begin_play()
        safe = self.check(drive)
        with self._exclusive("a play"):
            self._admit(safe, "play")
            handed = time.monotonic()
            onset = self._run_guarded(self._play, safe)
        # A backend without a device clock returns nothing: its onset is when it got the drive.
        return onset if isinstance(onset, DeviceOnset) else DeviceOnset(handed)

    def play_and_record(
        self, drive: np.ndarray, points_xy: np.ndarray | None = None, *, tail_s: float = 0.05
    ) -> np.ndarray:
        """Play a drive and record skin displacement, sample-synchronously.

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages at the actuators, V.
        points_xy : ndarray, shape (n_points, 2), optional
            Where to measure, m. A single-spot rig measures where its sensor is aimed and
            accepts at most one point (used as a label only); ``None`` means that spot.
        tail_s : float
            Recording continues this long after the drive ends, s, to catch the decay.

        Returns
        -------
        ndarray, shape (n_points, n_samples + round(tail_s * fs))
            Displacement, m.
        """
        self._begin_play()
        safe = self.check(drive)
        n_tail = int(round(check_positive(tail_s, "tail_s", allow_zero=True) * self.fs))
        if points_xy is not None:
            points_xy = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
            limit = self.max_points_per_recording
            if limit is not None and len(points_xy) > limit:
                raise ValidationError(
                    f"points_xy asks for {len(points_xy)} points, but the {self.kind} rig records "
                    f"{limit} point(s) per recording; record them one at a time"
                )
        with self._exclusive("a recording"):
            self._admit(safe, "recording")
            out = self._run_guarded(self._play_and_record, safe, points_xy, n_tail)
        return np.asarray(out, dtype=float)

    def play_and_capture(self, drive: np.ndarray, input_channel: int) -> tuple[np.ndarray, float]:
        """Play a drive and record one input of the interface as it comes, unaligned (a loopback).

        What ``vibrofocus latency`` measures with: the recording starts with the stream,
        so where a click appears in it is the interface's round trip.

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages at the actuators, V (through the safety layer, as for :meth:`play`).
        input_channel : int
            1-based input channel the loopback cable comes back on.

        Returns
        -------
        recording : ndarray, shape (n,)
            The input, in the interface's units (full scale 1 for an audio interface).
        fs : float
            Its sample rate, Hz (the device's own).

        Raises
        ------
        DeviceError
            On a rig that cannot record an input as it comes.
        """
        if isinstance(input_channel, bool) or not isinstance(input_channel, (int, np.integer)) or input_channel < 1:
            raise ValidationError(f"input_channel must be a channel number >= 1, got {input_channel!r}")
        self._begin_play()
        safe = self.check(drive)
        with self._exclusive("a loopback recording"):
            self._admit(safe, "recording")
            recording, fs = self._run_guarded(self._play_and_capture, safe, int(input_channel))
        return np.asarray(recording, dtype=float), float(fs)

    def stop(self) -> None:
        """Emergency stop: every output to zero now, from any thread.

        A play or recording running in another thread ends with a
        :class:`~vibrofocus.rigs.StoppedError`. The outputs reach 0 V within 100 ms plus the interface's
        own buffered output latency (:attr:`output_latency_s`). A job that holds the rig
        (:meth:`reserve`) ends: its further plays are refused. A play that was called
        before the stop and has not reached the device yet never plays.
        """
        with self._epoch_lock:
            self._stop_epoch += 1
        if self._job_owner is not None:
            self._job_stopped = True
        self._zero_now()

    @property
    def output_latency_s(self) -> float:
        """Buffered output latency of the interface, s: what :meth:`stop` cannot recall."""
        return 0.0

    def close(self) -> None:
        """Release the device (outputs left at zero)."""
        self.stop()

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> dict:
        """Settings to store beside a calibration or a session (JSON-serialisable)."""
        return {"kind": self.kind, "fs": self.fs, "limits": self.limits.to_dict(), "layout": self.layout.to_dict()}

    # ------------------------------------------------------------------ backend
    def _run_guarded(self, func, *args):
        # Outputs go to zero whatever happens, including KeyboardInterrupt mid-play.
        try:
            result = func(*args)
        except BaseException as exc:
            try:
                self._zero_now()
            except Exception as zero_exc:  # noqa: BLE001 - the first error must not be hidden
                log.critical("setting the outputs to zero failed: %s", zero_exc)
                exc.add_note(f"Setting the outputs to zero afterwards ALSO failed ({zero_exc}): "
                             "switch the amplifier off.")
            raise
        self._zero_now()
        return result

    def _zero_now(self) -> None:
        """Write zero to every output; interrupts wait until it is written, and a failure is tried once more.

        A second Ctrl-C while the zero is being written would otherwise leave the last
        voltage held on a device whose outputs keep their value (NI analog outputs).
        """
        from .._interrupts import critical_section

        with critical_section():
            try:
                self._zero_outputs()
            except BaseException as first:  # noqa: BLE001 - one more try, then the first error
                log.error("setting the outputs to zero failed (%s); trying once more", first)
                try:
                    self._zero_outputs()
                except BaseException:  # noqa: BLE001
                    raise first from None

    @abstractmethod
    def _play(self, drive: np.ndarray) -> DeviceOnset | None:
        """Play a drive that has passed the safety layer; return its onset if the device has a clock."""

    @abstractmethod
    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        """Play a checked drive and return displacement, shape (n_points, n_samples + n_tail), m."""

    def _play_and_capture(self, drive: np.ndarray, input_channel: int) -> tuple[np.ndarray, float]:
        """Play a checked drive, return ``(recording of input_channel, its rate)``; not every rig can."""
        raise DeviceError(f"the {self.kind} rig cannot record a loopback input as it comes (vibrofocus latency "
                          "supports the simulated, audio and nidaq rigs)")

    @abstractmethod
    def _zero_outputs(self) -> None:
        """Set every output to zero volts now."""
