"""The ``nidaq`` rig: NI-DAQmx analog outputs for the actuators, analog inputs for sensors.

All calls into the NI-DAQmx driver live in :class:`NidaqTasks`, a thin adapter, so the
rest of the rig is plain numpy and the adapter can be checked against an autospec of the
``nidaqmx.Task`` API where no NI hardware (or driver) exists.

Synchronisation
---------------
The vibrometer input task is configured with the same sample rate and a finite length,
armed first, and starts on the output task's start trigger (``/Dev1/ao/StartTrigger``):
both sample clocks derive from the device's timebase, so input sample ``k`` is taken with
output sample ``k``. The output task plays the drive followed by the recording tail in
zeros, so the outputs end at zero; NI analog outputs hold their last value, which is why
:meth:`NidaqTasks.write_zeros` also writes an explicit zero after every play and after
any error, and why the output channels ask for ``ao_idle_output_behavior = ZERO_VOLTS``
where the device supports it.

One task per play
-----------------
Unlike the audio rig, which keeps one stream running, this rig starts a finite task per
play: a streaming task whose program falls behind stops with its outputs holding their
last value (a regenerating one replays its buffer), which is unsafe without a hardware
watchdog (docs/hardware.md, "One running stream, and taps per second").

Stopping
--------
A play waits for its task by polling ``is_task_done`` every few milliseconds, so Ctrl-C
and a stop from another thread end it at once. The emergency stop
(:meth:`NidaqTasks.write_zeros`) aborts the running output task and unreserves its
channels (``TaskMode.TASK_ABORT``, then ``TASK_UNRESERVE``): a stopped task that was
written before it started stays committed and keeps its channels reserved, so a zero
written through a second task would fail with error -50103 while the outputs hold their
last value.

Onsets
------
Where the device timestamps its start trigger (``StartTrigger.timestamp_enable``; devices
synchronised over TSN, such as the cDAQ-9185/9189), every play asks for it on the I/O
device's timescale and reads it back after the task has run
(:data:`~vibrofocus.rigs.onset.NIDAQ_CLOCK`). A device that does not support it (most PCI
and USB devices) refuses the property once; from then on its onsets are on the sample
clock's count instead (:data:`~vibrofocus.rigs.onset.NIDAQ_SAMPLES_CLOCK`): the samples the
rig's completed output tasks generated before the play, read back from each task
(``OutStream.total_samp_per_chan_generated``), over the rate.

Voltage ranges
--------------
Drives are actuator volts; the analog outputs put out ``drive / amplifier_gain`` and are
created with the range ``± amplifier_input_max_v`` (1 V by default), so the driver itself
refuses anything beyond the independent cap on the voltage into the amplifier.
"""

from __future__ import annotations

import logging
import threading
import time
from contextlib import contextmanager
from datetime import timezone
from typing import Callable, Iterator

import numpy as np

from ..layout import ArrayLayout
from .config import NidaqRigConfig
from ..errors import SafetyError
from .devices import DeviceError, StoppedError
from .hardware import HardwareRig
from .onset import NIDAQ_CLOCK, NIDAQ_SAMPLES_CLOCK, DeviceOnset

__all__ = ["NidaqRig", "NidaqTasks"]

log = logging.getLogger(__name__)

#: How often a play looks whether its task is done (and whether it was stopped), s.
POLL_S = 0.005
#: DAQmx error of a property the device does not support.
_UNSUPPORTED_PROPERTY = -200452
#: DAQmx error of a property value the device does not support (a device with the idle
#: output property may still refuse ZERO_VOLTS).
_UNSUPPORTED_VALUE = -200077
#: A loopback capture (``vibrofocus latency``) records this long after the click, s.
CAPTURE_TAIL_S = 0.05


def _daq_error_types() -> tuple[type[BaseException], ...]:
    try:
        from nidaqmx.errors import DaqError, DaqNotFoundError, DaqNotSupportedError
    except ImportError:  # pragma: no cover - nidaqmx is a dependency
        return ()
    return (DaqError, DaqNotFoundError, DaqNotSupportedError)


class NidaqTasks:
    """Thin adapter over ``nidaqmx``: the only code of vibrofocus that calls the driver.

    Parameters
    ----------
    config : NidaqRigConfig
    task_factory : callable, optional
        Returns a new ``nidaqmx.Task``; default ``nidaqmx.Task``. Tests pass the factory
        of a FAKE task layer.
    system : object, optional
        ``nidaqmx.system.System.local()`` or a fake of it, for :meth:`check_setup`.
    """

    def __init__(self, config: NidaqRigConfig, task_factory: Callable[[], object] | None = None,
                 system: object | None = None):
        self.config = config
        if task_factory is None:
            import nidaqmx
            import nidaqmx.system

            try:  # fail at setup, not at the first stimulus, when the driver is missing
                system = nidaqmx.system.System.local()
                system.driver_version
            except _daq_error_types() + (OSError,) as exc:
                raise DeviceError(
                    f"the NI-DAQmx driver is not available ({exc}); install NI-DAQmx, or use --rig simulated"
                ) from None
            task_factory = nidaqmx.Task
        self._task_factory = task_factory
        self._system = system
        first = config.physical(config.channels.actuators[0])
        #: The device of the outputs (a module, on a CompactDAQ chassis).
        self.device = first.split("/")[0]
        #: The device that times the tasks and routes their triggers: the chassis of cDAQ modules.
        self.timing_device = config.timing_device
        #: Terminal the input task starts on (on a chassis: its backplane's AO start trigger).
        self.start_trigger = f"/{self.timing_device}/ao/StartTrigger"
        # The output task now generating, so an emergency stop from another thread can
        # abort it and free its channels; the lock keeps that from racing its closing.
        self._active_ao = None
        self._active_lock = threading.Lock()
        # Whether the operation running now was stopped: set per operation from the rig's
        # stop epoch (rigs.base), never a flag that an operation clears when it starts.
        self._stopped: Callable[[], bool] = lambda: False
        #: Whether the outputs go to 0 V by themselves when a task stops (device-dependent).
        self.idle_zero_supported: bool | None = None
        #: Whether the device timestamps the output task's start trigger (device-dependent).
        self.start_timestamp_supported: bool | None = None
        #: Samples the completed output tasks generated, per channel (the sample clock's count).
        self.samples_generated = 0

    # ------------------------------------------------------------------ setup checks
    def check_setup(self) -> list[str]:
        """Check the device, channels, rates, output range and timing before any play.

        Returns
        -------
        list of str
            What was found, one line each, for ``vibrofocus devices --check``.

        Raises
        ------
        DeviceError
            Naming the first thing that does not fit, in words a lab can act on.
        """
        cfg = self.config
        if self._system is None:
            return ["NI-DAQmx: no system to query; setup not checked"]
        found = []
        names = [d.name for d in self._system.devices]
        inputs = [cfg.channels.vibrometer] + (list(cfg.force_sensors.channels) if cfg.force_sensors else [])
        ao_device, ai_device = self.device, cfg.physical(inputs[0]).split("/")[0]
        for device in dict.fromkeys((ao_device, ai_device)):
            if device not in names:
                raise DeviceError(f"NI device {device!r} not found; NI MAX lists: {', '.join(names) or 'none'}")
        dev, ai_dev = self._system.devices[ao_device], self._system.devices[ai_device]
        found.append(f"device {ao_device}: {dev.product_type}" + (
            f"; inputs on {ai_device}: {ai_dev.product_type} (chassis {self.timing_device})"
            if ai_device != ao_device else ""))
        ao = {c.name for c in dev.ao_physical_chans}
        ai = {c.name for c in ai_dev.ai_physical_chans}
        missing = [cfg.physical(c) for c in cfg.channels.actuators if cfg.physical(c) not in ao]
        if missing:
            raise DeviceError(f"{ao_device} has no analog output {', '.join(missing)}; its outputs are "
                              f"{', '.join(sorted(ao)) or 'none'}")
        missing = [cfg.physical(c) for c in inputs if cfg.physical(c) not in ai]
        if missing:
            raise DeviceError(f"{ai_device} has no analog input {', '.join(missing)}; its inputs are "
                              f"{', '.join(sorted(ai)) or 'none'}")
        found.append(f"channels: outputs {', '.join(cfg.physical(c) for c in cfg.channels.actuators)}, "
                     f"vibrometer {cfg.physical(cfg.channels.vibrometer)}")
        if not dev.ao_samp_clk_supported:
            raise DeviceError(f"{self.device} has no hardware-timed analog output; it cannot play drives")
        if not dev.ao_min_rate <= cfg.fs <= dev.ao_max_rate:
            raise DeviceError(f"fs = {cfg.fs:g} Hz is outside the output rates of {self.device} "
                              f"({dev.ao_min_rate:g}-{dev.ao_max_rate:g} Hz)")
        if cfg.fs > ai_dev.ai_max_single_chan_rate:
            raise DeviceError(f"fs = {cfg.fs:g} Hz is above the input rate of {ai_device} "
                              f"({ai_dev.ai_max_single_chan_rate:g} Hz)")
        found.append(f"rate: {cfg.fs:g} Hz (outputs {dev.ao_min_rate:g}-{dev.ao_max_rate:g} Hz, "
                     f"input up to {ai_dev.ai_max_single_chan_rate:g} Hz)")
        rngs = list(dev.ao_voltage_rngs)
        cap = cfg.amplifier_input_max_v
        pairs = [(rngs[i], rngs[i + 1]) for i in range(0, len(rngs) - 1, 2)]
        if not any(lo <= -cap and cap <= hi for lo, hi in pairs):
            raise DeviceError(f"no output range of {self.device} covers +-{cap:g} V (ranges {pairs})")
        found.append(f"output range: +-{cap:g} V into the amplifier (device ranges {pairs})")
        probe = self._ao_task()  # asks for 0 V idle outputs; writes nothing
        probe.close()
        found.append("outputs go to 0 V by themselves when a task stops" if self.idle_zero_supported else
                     "outputs HOLD their last value when a task stops (the device cannot idle at 0 V): an explicit "
                     "zero is written after every play and at every stop")
        return found

    # ------------------------------------------------------------------ channels
    def _ao_task(self):
        cfg = self.config
        task = self._task_factory()
        try:
            cap = cfg.amplifier_input_max_v
            for i, ch in enumerate(cfg.channels.actuators):
                chan = task.ao_channels.add_ao_voltage_chan(
                    cfg.physical(ch), name_to_assign_to_channel=f"actuator{i + 1}", min_val=-cap, max_val=cap)
                self._idle_at_zero(chan)
        except BaseException:
            task.close()  # a task whose channels failed would otherwise leak
            raise
        return task

    def _idle_at_zero(self, chan) -> None:
        if self.idle_zero_supported is False:
            return
        from nidaqmx.constants import AOIdleOutputBehavior

        try:
            chan.ao_idle_output_behavior = AOIdleOutputBehavior.ZERO_VOLTS
            self.idle_zero_supported = True
        except _daq_error_types() as exc:
            if getattr(exc, "error_code", None) not in (_UNSUPPORTED_PROPERTY, _UNSUPPORTED_VALUE):
                raise
            self.idle_zero_supported = False  # the explicit zero write still follows every play

    def _ai_task(self, channels: list[str], names: list[str], range_v: float):
        from nidaqmx.constants import TerminalConfiguration

        terminal = getattr(TerminalConfiguration, self.config.terminal_config.upper())
        task = self._task_factory()
        try:
            for ch, name in zip(channels, names):
                task.ai_channels.add_ai_voltage_chan(self.config.physical(ch), name_to_assign_to_channel=name,
                                                     terminal_config=terminal, min_val=-range_v, max_val=range_v)
        except BaseException:
            task.close()
            raise
        return task

    def _finite(self, task, n: int) -> None:
        from nidaqmx.constants import AcquisitionType

        fs = self.config.fs
        task.timing.cfg_samp_clk_timing(fs, sample_mode=AcquisitionType.FINITE, samps_per_chan=n)
        actual = float(task.timing.samp_clk_rate)  # the driver may coerce the rate
        if abs(actual - fs) > 1e-6 * fs:
            raise DeviceError(f"NI-DAQmx runs the sample clock at {actual:g} Hz, not the {fs:g} Hz asked; "
                              "choose an fs the device's timebase divides exactly")

    @staticmethod
    def _release(tasks) -> BaseException | None:
        """Abort and close every task, even when one of them fails; return the first failure."""
        from nidaqmx.constants import TaskMode

        first = None
        for task in tasks:
            try:
                task.control(TaskMode.TASK_ABORT)
            except _daq_error_types() as exc:
                first = first or exc
            finally:
                try:
                    task.close()
                except _daq_error_types() as exc:
                    first = first or exc
        return first

    @contextmanager
    def _tasks(self, what: str, *, stops: str | None = None) -> Iterator[list]:
        """Tasks made in the block are closed after it; driver errors become DeviceError.

        ``stops`` names what ``stop()`` ends here ("play", "recording"): a driver error
        after a stop (the task was aborted under it) is that :class:`StoppedError`. A
        failure while closing never hides the error that ended the block.
        """
        tasks: list = []
        try:
            yield tasks
        except _daq_error_types() as exc:
            self._close_after_error(tasks)
            if stops is not None and self._stopped():
                raise StoppedError(stops) from exc
            raise self._wrap(exc, what) from exc
        except BaseException:
            self._close_after_error(tasks)
            raise
        self._set_active(None)
        failure = self._release(tasks)
        if failure is not None:
            raise self._wrap(failure, f"closing the tasks after {what}")

    def _close_after_error(self, tasks: list) -> None:
        self._set_active(None)
        failure = self._release(tasks)
        if failure is not None:
            log.error("closing NI-DAQmx tasks after an error also failed: %s", failure)

    def _timeout(self, n: int) -> float:
        return n / self.config.fs + 5.0

    def _wrap(self, exc: BaseException, what: str) -> DeviceError:
        return DeviceError(f"NI-DAQmx failed while {what}: {exc}")

    def _set_active(self, task) -> None:
        with self._active_lock:
            self._active_ao = task

    def _stamp_start(self, ao) -> bool:
        """Ask the output task to timestamp its start trigger; False where the device cannot."""
        if self.start_timestamp_supported is False:
            return False
        from nidaqmx.constants import Timescale

        trigger = ao.triggers.start_trigger
        try:
            trigger.timestamp_enable = True
            trigger.timestamp_timescale = Timescale.USE_IO_DEVICE
        except _daq_error_types() as exc:
            if getattr(exc, "error_code", None) != _UNSUPPORTED_PROPERTY:
                raise
            self.start_timestamp_supported = False  # asked once: the host time serves from now on
            return False
        self.start_timestamp_supported = True
        return True

    @staticmethod
    def _start_time_s(ao) -> float:
        """The output task's start trigger timestamp, s since the Unix epoch."""
        stamp = ao.triggers.start_trigger.timestamp_val
        if stamp.tzinfo is None:  # the I/O device's timescale is UTC
            stamp = stamp.replace(tzinfo=timezone.utc)
        return float(stamp.timestamp())

    def _register(self, ao, stops: str, *, start: bool = False) -> None:
        """Make ``ao`` the task a stop aborts (and start it), unless this operation was stopped.

        Under the lock that :meth:`write_zeros` aborts through: a stop before this is
        seen here; one after it finds the task registered (so it is aborted and unreserved,
        and its zero write is not refused with -50103).
        """
        with self._active_lock:
            if self._stopped():
                raise StoppedError(stops)
            self._active_ao = ao
            if start:
                ao.start()

    def _run_output(self, ao, n: int, stops: str) -> DeviceOnset:
        """Start the written output task and wait for it, polling, so a stop or Ctrl-C ends it at once.

        ``stops`` names what a stop ends ("play", "recording"), for its :class:`StoppedError`.
        Returns the onset: ``time.monotonic()`` at the start, and the start trigger's
        timestamp where the device gives one, else the sample clock's count before it.
        """
        stamped = self._stamp_start(ao)
        host = time.monotonic()
        self._register(ao, stops, start=True)
        deadline = time.monotonic() + self._timeout(n)
        while True:
            if self._stopped():
                raise StoppedError(stops)
            if ao.is_task_done():
                break
            if time.monotonic() > deadline:
                raise DeviceError(f"NI-DAQmx did not finish a {n / self.config.fs:.3f} s play in time")
            time.sleep(POLL_S)
        if stamped:
            return DeviceOnset(host, self._start_time_s(ao), NIDAQ_CLOCK)
        before = self.samples_generated
        self.samples_generated += int(ao.out_stream.total_samp_per_chan_generated)
        return DeviceOnset(host, before / self.config.fs, NIDAQ_SAMPLES_CLOCK)

    def _checked_volts(self, volts: np.ndarray) -> np.ndarray:
        """The last check before the driver: finite, the right channels, within the amplifier cap.

        The rig's safety layer has run before this; the adapter still refuses anything
        that would put more than ``amplifier_input_max_v`` into the amplifier, so no caller
        of the adapter can hold a voltage on a coil past the cap.
        """
        arr = np.asarray(volts, dtype=float)
        cap = self.config.amplifier_input_max_v
        if arr.ndim != 2 or arr.shape[0] != self.config.n_actuators or arr.shape[1] < 2:
            raise SafetyError(f"NI output refused: shape must be ({self.config.n_actuators}, n >= 2), got {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.abs(arr).max() > cap * (1 + 1e-9):
            raise SafetyError(f"NI output refused: samples must be finite and within +-{cap:g} V "
                              "(amplifier_input_max_v)")
        return arr

    # ------------------------------------------------------------------ operations
    def play(self, volts: np.ndarray, *, stopped: Callable[[], bool]) -> DeviceOnset:
        """Play output volts, shape (n_actuators, n), V at the analog outputs; return the onset.

        ``stopped`` tells whether the play was stopped since it was called (the rig's
        stop epoch, :meth:`Rig._stop_probe`).
        """
        volts = self._checked_volts(volts)
        n = volts.shape[1]
        self._stopped = stopped
        with self._tasks("playing", stops="play") as tasks:
            ao = self._ao_task()
            tasks.append(ao)
            self._register(ao, "play")  # before the write: a stop now aborts and unreserves it
            self._finite(ao, n)
            ao.write(volts, auto_start=False)
            onset = self._run_output(ao, n, "play")
        return onset

    def play_and_record(self, volts: np.ndarray, n_record: int, *, stopped: Callable[[], bool],
                        channel: str | None = None, name: str = "vibrometer") -> np.ndarray:
        """Play output volts and record one analog input, sample-synchronously.

        Parameters
        ----------
        volts : ndarray, shape (n_actuators, n)
            V at the analog outputs.
        n_record : int
            Input samples to take, >= n.
        channel : str, optional
            The input (``ai3`` or ``Dev1/ai3``); default the vibrometer's.
        name : str
            The name the task gives the input channel.
        stopped : callable
            Whether the recording was stopped since it was called (as for :meth:`play`).

        Returns
        -------
        ndarray, shape (n_record,)
            The input, V.
        """
        cfg = self.config
        volts = self._checked_volts(volts)
        n = volts.shape[1]
        self._stopped = stopped
        with self._tasks("recording", stops="recording") as tasks:
            ai = self._ai_task([cfg.channels.vibrometer if channel is None else channel], [name], cfg.ai_range_v)
            tasks.append(ai)
            self._finite(ai, n_record)
            ai.triggers.start_trigger.cfg_dig_edge_start_trig(self.start_trigger)
            ai.start()  # armed: it waits for the output task's start trigger
            ao = self._ao_task()
            tasks.insert(0, ao)  # the output is aborted first
            self._register(ao, "recording")
            self._finite(ao, n)
            ao.write(volts, auto_start=False)
            self._run_output(ao, n, "recording")
            data = ai.read(number_of_samples_per_channel=n_record, timeout=self._timeout(n_record))
        out = np.asarray(data, dtype=float).reshape(-1)
        if out.shape != (n_record,):
            raise DeviceError(f"NI-DAQmx returned {out.size} samples, expected {n_record}")
        return out

    def read_inputs(self, channels: list[str], n: int, range_v: float = 10.0) -> np.ndarray:
        """Read analog inputs for ``n`` samples at the rig's rate; returns (n_channels, n) V."""
        with self._tasks("reading inputs") as tasks:
            ai = self._ai_task(channels, [f"input{i + 1}" for i in range(len(channels))], range_v)
            tasks.append(ai)
            self._finite(ai, n)
            ai.start()
            data = ai.read(number_of_samples_per_channel=n, timeout=self._timeout(n))
        return np.asarray(data, dtype=float).reshape(len(channels), n)

    def write_zeros(self) -> None:
        """Emergency stop, from any thread: abort and unreserve the running output task, then write 0 V."""
        from nidaqmx.constants import TaskMode

        with self._active_lock:
            active = self._active_ao
            if active is not None:
                for mode in (TaskMode.TASK_ABORT, TaskMode.TASK_UNRESERVE):
                    try:
                        active.control(mode)
                    except _daq_error_types() as exc:  # already done and closing: zeros follow anyway
                        log.warning("%s of the running output task failed: %s", mode.name, exc)
        with self._tasks("setting the outputs to zero") as tasks:
            ao = self._ao_task()
            tasks.append(ao)
            ao.write(np.zeros(self.config.n_actuators), auto_start=True)


class NidaqRig(HardwareRig):
    """Actuators on NI-DAQmx analog outputs, the vibrometer (and strap sensors) on inputs.

    Parameters
    ----------
    config : NidaqRigConfig
    layout : ArrayLayout, optional
        Must have as many actuators as ``config.channels.actuators``.
    task_factory : callable, optional
        Passed to :class:`NidaqTasks` (tests only).
    system : object, optional
        Passed to :class:`NidaqTasks` (tests only).

    Notes
    -----
    A single-spot vibrometer: ``max_points_per_recording = 1``.
    """

    kind = "nidaq"
    config_class = NidaqRigConfig

    def __init__(self, config: NidaqRigConfig, layout: ArrayLayout | None = None, *,
                 task_factory: Callable[[], object] | None = None, system: object | None = None):
        super().__init__(config, layout)
        self.strap_sensors = config.force_sensors.build() if config.force_sensors else None
        # Private: every drive reaches the adapter through Rig.play and its safety layer.
        self._daq = NidaqTasks(config, task_factory, system)
        self._lock_device(f"nidaq:{self._daq.timing_device}")
        try:  # the same checks as `vibrofocus devices --check`, before the first play
            self.setup_report = self._daq.check_setup()
        except BaseException:
            self.device_lock.release()
            raise
        self.last_clipped: np.ndarray | None = None
        self.last_dropout_mask: np.ndarray | None = None

    def _play(self, drive: np.ndarray) -> DeviceOnset:
        return self._daq.play(drive / self.config.amplifier_gain, stopped=self._stop_probe())

    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        n_total = drive.shape[1] + n_tail
        lag = self.config.latency_samples
        out = np.pad(drive / self.config.amplifier_gain, ((0, 0), (0, n_tail)))
        volts = self._daq.play_and_record(out, n_total + lag, stopped=self._stop_probe())[lag:]
        # A converter at the end of its range clipped the vibrometer signal: H would be wrong.
        self.last_clipped = np.array([bool(np.any(np.abs(volts) >= 0.999 * self.config.ai_range_v))])
        self.last_dropout_mask = np.zeros((1, volts.size), dtype=bool)
        return self.vibrometer.to_displacement(volts, self.fs)[None, :]

    def _play_and_capture(self, drive: np.ndarray, input_channel: int) -> tuple[np.ndarray, float]:
        # The input started by the output task's start trigger, on the same timebase: where
        # the click appears in it is the round trip from the converters, not a buffer's.
        n_record = drive.shape[1] + int(round(CAPTURE_TAIL_S * self.fs))
        out = np.pad(drive / self.config.amplifier_gain, ((0, 0), (0, n_record - drive.shape[1])))
        volts = self._daq.play_and_record(out, n_record, channel=f"ai{input_channel - 1}", name="loopback",
                                          stopped=self._stop_probe())
        return volts, self.fs

    def _zero_outputs(self) -> None:
        self._daq.write_zeros()

    def read_strap_forces(self) -> np.ndarray:
        """Mean force on each strap over ``force_sensors.averaging_s``, N, shape (n_straps,)."""
        fcfg = self.config.force_sensors
        if fcfg is None:
            raise DeviceError("this nidaq rig has no force_sensors configured")
        n = max(1, int(round(fcfg.averaging_s * self.fs)))
        with self._exclusive("a strap reading"):
            volts = self._daq.read_inputs(list(fcfg.channels), n)
        return self.strap_sensors.curve(volts.mean(axis=1))

    def describe(self) -> dict:
        """Settings to store beside a calibration (JSON-serialisable)."""
        out = super().describe()
        out.update(config=self.config.model_dump(mode="json"), vibrometer=self.vibrometer.describe())
        return out
