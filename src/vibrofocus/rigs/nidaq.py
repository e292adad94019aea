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
any error.

Voltage ranges
--------------
Drives are actuator volts; the analog outputs put out ``drive / amplifier_gain`` and are
created with the range ``± limits.peak_v / amplifier_gain``, so the driver itself refuses
anything beyond the actuator limit.
"""

from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from ..layout import ArrayLayout
from .config import NidaqRigConfig
from .devices import DeviceError
from .hardware import HardwareRig

__all__ = ["NidaqRig", "NidaqTasks"]

log = logging.getLogger(__name__)


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
        Returns a new ``nidaqmx.Task``; default ``nidaqmx.Task``. Tests pass a factory of
        autospec fakes.
    """

    def __init__(self, config: NidaqRigConfig, task_factory: Callable[[], object] | None = None):
        self.config = config
        if task_factory is None:
            import nidaqmx
            import nidaqmx.system

            try:  # fail at setup, not at the first stimulus, when the driver is missing
                nidaqmx.system.System.local().driver_version
            except _daq_error_types() + (OSError,) as exc:
                raise DeviceError(
                    f"the NI-DAQmx driver is not available ({exc}); install NI-DAQmx, or use --rig simulated"
                ) from None
            task_factory = nidaqmx.Task
        self._task_factory = task_factory
        first = config.physical(config.channels.actuators[0])
        self.device = first.split("/")[0]
        #: Terminal the input task starts on.
        self.start_trigger = f"/{self.device}/ao/StartTrigger"
        # The output task now generating, so write_zeros (stop() from another thread
        # included) can halt it first: its channels are reserved until it stops.
        self._active_ao = None

    # ------------------------------------------------------------------ channels
    def _ao_task(self):
        cfg = self.config
        task = self._task_factory()
        peak = cfg.output_peak_v
        for i, ch in enumerate(cfg.channels.actuators):
            task.ao_channels.add_ao_voltage_chan(cfg.physical(ch), name_to_assign_to_channel=f"actuator{i + 1}",
                                                 min_val=-peak, max_val=peak)
        return task

    def _ai_task(self, channels: list[str], names: list[str], range_v: float):
        from nidaqmx.constants import TerminalConfiguration

        terminal = getattr(TerminalConfiguration, self.config.terminal_config.upper())
        task = self._task_factory()
        for ch, name in zip(channels, names):
            task.ai_channels.add_ai_voltage_chan(self.config.physical(ch), name_to_assign_to_channel=name,
                                                 terminal_config=terminal, min_val=-range_v, max_val=range_v)
        return task

    @staticmethod
    def _finite(task, fs: float, n: int) -> None:
        from nidaqmx.constants import AcquisitionType

        task.timing.cfg_samp_clk_timing(fs, sample_mode=AcquisitionType.FINITE, samps_per_chan=n)

    @staticmethod
    def _release(*tasks) -> None:
        for task in tasks:
            if task is None:
                continue
            try:
                task.stop()
            finally:
                task.close()

    def _timeout(self, n: int) -> float:
        return n / self.config.fs + 5.0

    def _wrap(self, exc: BaseException, what: str) -> DeviceError:
        return DeviceError(f"NI-DAQmx failed while {what}: {exc}")

    # ------------------------------------------------------------------ operations
    def play(self, volts: np.ndarray) -> None:
        """Play output volts, shape (n_actuators, n), V at the analog outputs."""
        n = volts.shape[1]
        ao = None
        try:
            ao = self._ao_task()
            self._finite(ao, self.config.fs, n)
            ao.write(volts, auto_start=False)
            self._active_ao = ao
            ao.start()
            ao.wait_until_done(timeout=self._timeout(n))
        except _daq_error_types() as exc:
            raise self._wrap(exc, "playing") from exc
        finally:
            self._active_ao = None
            self._release(ao)

    def play_and_record(self, volts: np.ndarray, n_record: int) -> np.ndarray:
        """Play output volts and record the vibrometer input, sample-synchronously.

        Parameters
        ----------
        volts : ndarray, shape (n_actuators, n)
            V at the analog outputs.
        n_record : int
            Input samples to take, >= n.

        Returns
        -------
        ndarray, shape (n_record,)
            Vibrometer input, V.
        """
        cfg = self.config
        n = volts.shape[1]
        ai = ao = None
        try:
            ai = self._ai_task([cfg.channels.vibrometer], ["vibrometer"], cfg.ai_range_v)
            self._finite(ai, cfg.fs, n_record)
            ai.triggers.start_trigger.cfg_dig_edge_start_trig(self.start_trigger)
            ai.start()  # armed: it waits for the output task's start trigger
            ao = self._ao_task()
            self._finite(ao, cfg.fs, n)
            ao.write(volts, auto_start=False)
            self._active_ao = ao
            ao.start()
            ao.wait_until_done(timeout=self._timeout(n))
            data = ai.read(number_of_samples_per_channel=n_record, timeout=self._timeout(n_record))
        except _daq_error_types() as exc:
            raise self._wrap(exc, "recording") from exc
        finally:
            self._active_ao = None
            self._release(ao, ai)
        out = np.asarray(data, dtype=float).reshape(-1)
        if out.shape != (n_record,):
            raise DeviceError(f"NI-DAQmx returned {out.size} samples, expected {n_record}")
        return out

    def read_inputs(self, channels: list[str], n: int, range_v: float = 10.0) -> np.ndarray:
        """Read analog inputs for ``n`` samples at the rig's rate; returns (n_channels, n) V."""
        ai = None
        try:
            ai = self._ai_task(channels, [f"input{i + 1}" for i in range(len(channels))], range_v)
            self._finite(ai, self.config.fs, n)
            ai.start()
            data = ai.read(number_of_samples_per_channel=n, timeout=self._timeout(n))
        except _daq_error_types() as exc:
            raise self._wrap(exc, "reading inputs") from exc
        finally:
            self._release(ai)
        return np.asarray(data, dtype=float).reshape(len(channels), n)

    def write_zeros(self) -> None:
        """Stop any output task that is generating, then set every actuator output to 0 V."""
        active = self._active_ao
        if active is not None:
            try:
                active.stop()
            except _daq_error_types() as exc:  # already stopped or finished: zeros follow anyway
                log.warning("stopping the running output task: %s", exc)
        ao = None
        try:
            ao = self._ao_task()
            ao.write(np.zeros(self.config.n_actuators), auto_start=True)
        except _daq_error_types() as exc:
            raise self._wrap(exc, "setting the outputs to zero") from exc
        finally:
            self._release(ao)


class NidaqRig(HardwareRig):
    """Actuators on NI-DAQmx analog outputs, the vibrometer (and strap sensors) on inputs.

    Parameters
    ----------
    config : NidaqRigConfig
    layout : ArrayLayout, optional
        Must have as many actuators as ``config.channels.actuators``.
    task_factory : callable, optional
        Passed to :class:`NidaqTasks` (tests only).

    Notes
    -----
    A single-spot vibrometer: ``max_points_per_recording = 1``.
    """

    kind = "nidaq"
    config_class = NidaqRigConfig

    def __init__(self, config: NidaqRigConfig, layout: ArrayLayout | None = None, *,
                 task_factory: Callable[[], object] | None = None):
        super().__init__(config, layout)
        self.strap_sensors = config.force_sensors.build() if config.force_sensors else None
        self.tasks = NidaqTasks(config, task_factory)

    def _play(self, drive: np.ndarray) -> None:
        self.tasks.play(drive / self.config.amplifier_gain)

    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        n_total = drive.shape[1] + n_tail
        lag = self.config.latency_samples
        out = np.pad(drive / self.config.amplifier_gain, ((0, 0), (0, n_tail)))
        volts = self.tasks.play_and_record(out, n_total + lag)[lag:]
        return self.vibrometer.to_displacement(volts, self.fs)[None, :]

    def _zero_outputs(self) -> None:
        self.tasks.write_zeros()

    def read_strap_forces(self) -> np.ndarray:
        """Mean force on each strap over ``force_sensors.averaging_s``, N, shape (n_straps,)."""
        fcfg = self.config.force_sensors
        if fcfg is None:
            raise DeviceError("this nidaq rig has no force_sensors configured")
        n = max(1, int(round(fcfg.averaging_s * self.fs)))
        volts = self.tasks.read_inputs(list(fcfg.channels), n)
        return self.strap_sensors.curve(volts.mean(axis=1))

    def describe(self) -> dict:
        """Settings to store beside a calibration (JSON-serialisable)."""
        out = super().describe()
        out.update(config=self.config.model_dump(mode="json"), vibrometer=self.vibrometer.describe())
        return out
