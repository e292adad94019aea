"""A FAKE NI-DAQmx task layer, for tests only: no NI driver can run here.

It models what matters for safety, after NI's task state model (NI-DAQmx Help, "Task
State Model"): a task written before it starts is committed and reserves its channels
until it is aborted and unreserved or closed; ``stop`` returns it to that committed
state; a write to channels another task reserved fails with error -50103; analog outputs
hold their last value when a task stops or aborts, unless the channel's idle output
behaviour is zero volts on a device that supports it; the sample clock is coerced to a
divisor of the timebase. Finite tasks take real time (``n / rate``), so a stop from
another thread meets a task that is really running. A device made with ``timestamps=True``
timestamps a task's start trigger when asked (on the others the property is unsupported,
error -200452), and ``loopback`` wires an output to an input: an input task started on
the output's start trigger reads what that output played, ``loopback_delay`` samples
late.

Every method here exists on the real ``nidaqmx`` classes with the same parameter names
(checked by ``test_fake_matches_the_real_api``).
"""

from __future__ import annotations

import threading
import time
from datetime import datetime, timezone
from types import SimpleNamespace

import numpy as np
from nidaqmx.constants import AOIdleOutputBehavior, TaskMode
from nidaqmx.errors import DaqError

RESERVED = -50103
UNSUPPORTED = -200452
#: A property value the device does not support (e.g. ZERO_VOLTS idle on some devices), and
#: the code a finite output task of fewer than 2 samples gets here (NI documents a minimum
#: buffer of 2 samples for finite generation; the exact code of that refusal is assumed).
INVALID_VALUE = -200077
OUT_OF_RANGE = -200561
INVALID_TASK = -200088


class FakeDevice:
    """One NI device: its outputs (V), who reserved which channel, and what it supports.

    Default: a USB-6343 (4 analog outputs, 32 inputs; 8 modelled). With ``modules`` it is
    a CompactDAQ chassis (``name`` = "cDAQ1") holding an output and an input module
    (``{"cDAQ1Mod1": ("ao", 4), "cDAQ1Mod2": ("ai", 4)}``): channels live on the modules,
    the start trigger on the chassis (``/cDAQ1/ao/StartTrigger``). ``idle_zero="refused"``
    models a device that has the idle-output property but refuses ZERO_VOLTS (-200077).
    """

    def __init__(self, name="Dev1", *, n_ao=4, n_ai=8, idle_zero=True, timebase_hz=100e6,
                 ao_max_rate=2e6, ai_max_rate=2e6, ao_ranges=(-10.0, 10.0, -5.0, 5.0, -1.0, 1.0),
                 product_type="USB-6343 (FAKE)", timestamps=False, loopback=None, loopback_delay=0,
                 modules=None):
        self.name = name
        self.product_type = product_type
        self.modules = dict(modules or {})
        if self.modules:
            self.ao_names = [f"{m}/ao{i}" for m, (kind, n) in self.modules.items() if kind == "ao" for i in range(n)]
            self.ai_names = [f"{m}/ai{i}" for m, (kind, n) in self.modules.items() if kind == "ai" for i in range(n)]
        else:
            self.ao_names = [f"{name}/ao{i}" for i in range(n_ao)]
            self.ai_names = [f"{name}/ai{i}" for i in range(n_ai)]
        self.outputs = {ch: 0.0 for ch in self.ao_names}
        self.reserved: dict[str, FakeTask] = {}
        self.idle_zero = idle_zero
        self.timebase_hz = timebase_hz
        self.ao_max_rate = ao_max_rate
        self.ai_max_rate = ai_max_rate
        self.ao_ranges = list(ao_ranges)
        self.lock = threading.RLock()
        self.reads: list = []  # what successive reads return; zeros when empty
        self.fail: dict[str, DaqError] = {}  # method name -> error raised once by the next task calling it
        self.tasks: list[FakeTask] = []
        self.events: list[tuple[int, str]] = []
        self.timestamps = timestamps
        self.loopback: dict[str, str] = dict(loopback or {})  # "Dev1/ai3" -> "Dev1/ao1"
        self.loopback_delay = loopback_delay
        self.last_output: FakeTask | None = None  # the output task that started last

    def factory(self):
        task = FakeTask(self)
        self.tasks.append(task)
        return task

    def forget_setup(self) -> None:
        """Forget the tasks made so far (a rig's setup probe), so a test counts only its own; they must be closed."""
        assert all(t.state == "closed" for t in self.tasks), "a setup task was left open"
        self.tasks.clear()
        self.events.clear()

    def output_vector(self) -> np.ndarray:
        return np.array([self.outputs[ch] for ch in self.ao_names])

    # what nidaqmx.system.System.local() offers, for check_setup
    def system(self):
        def device(name, product, ao, ai):
            return SimpleNamespace(
                name=name, product_type=product,
                ao_physical_chans=[SimpleNamespace(name=n) for n in ao],
                ai_physical_chans=[SimpleNamespace(name=n) for n in ai],
                ao_samp_clk_supported=bool(ao), ao_min_rate=0.1, ao_max_rate=self.ao_max_rate,
                ai_max_single_chan_rate=self.ai_max_rate, ao_voltage_rngs=self.ao_ranges if ao else [])

        devices = [device(self.name, self.product_type, [] if self.modules else self.ao_names,
                          [] if self.modules else self.ai_names)]
        for module in self.modules:
            devices.append(device(module, f"NI 9xxx module of {self.name} (FAKE)",
                                  [n for n in self.ao_names if n.startswith(module + "/")],
                                  [n for n in self.ai_names if n.startswith(module + "/")]))

        class Devices(list):
            def __getitem__(self, key):
                if isinstance(key, str):
                    return next(d for d in self if d.name == key)
                return list.__getitem__(self, key)

        return SimpleNamespace(devices=Devices(devices), driver_version="FAKE")


class FakeAOChannel:
    def __init__(self, task, name, min_val, max_val):
        self._task, self.name, self.min_val, self.max_val = task, name, min_val, max_val
        self._idle = AOIdleOutputBehavior.MAINTAIN_EXISTING_VALUE

    @property
    def ao_idle_output_behavior(self):
        return self._idle

    @ao_idle_output_behavior.setter
    def ao_idle_output_behavior(self, value):
        if self._task.device.idle_zero == "refused":
            raise DaqError("Requested value is not a supported value for this property (FAKE)", INVALID_VALUE)
        if not self._task.device.idle_zero:
            raise DaqError("Specified property is not supported by the device (FAKE)", UNSUPPORTED)
        self._idle = value


class _AOChannels:
    def __init__(self, task):
        self._task, self.channels = task, []

    def add_ao_voltage_chan(self, physical_channel, name_to_assign_to_channel="", min_val=-10.0, max_val=10.0,
                            units=None, custom_scale_name=""):
        self._task._call("add_ao_voltage_chan")
        if physical_channel not in self._task.device.ao_names:
            raise DaqError(f"Physical channel {physical_channel} does not exist (FAKE)", -200170)
        chan = FakeAOChannel(self._task, physical_channel, min_val, max_val)
        self.channels.append(chan)
        return chan


class _AIChannels:
    def __init__(self, task):
        self._task, self.channels = task, []

    def add_ai_voltage_chan(self, physical_channel, name_to_assign_to_channel="", terminal_config=None,
                            min_val=-5.0, max_val=5.0, units=None, custom_scale_name=""):
        self._task._call("add_ai_voltage_chan")
        if physical_channel not in self._task.device.ai_names:
            raise DaqError(f"Physical channel {physical_channel} does not exist (FAKE)", -200170)
        self.channels.append(SimpleNamespace(name=physical_channel, min_val=min_val, max_val=max_val,
                                             terminal_config=terminal_config))


class _Timing:
    def __init__(self, task):
        self._task = task
        self.samp_clk_rate = None
        self.samps_per_chan = None

    def cfg_samp_clk_timing(self, rate, source="", active_edge=None, sample_mode=None, samps_per_chan=1000):
        if self._task.ao_channels.channels and samps_per_chan < 2:
            raise DaqError("Finite generation needs at least 2 samples per channel (FAKE)", INVALID_VALUE)
        divisor = max(1, round(self._task.device.timebase_hz / rate))
        self.samp_clk_rate = self._task.device.timebase_hz / divisor  # coerced, as the driver does
        self.samps_per_chan = samps_per_chan


class _StartTrigger:
    def __init__(self, task):
        self._task = task
        self.source = None
        self._stamp_enabled = False
        self._timescale = None
        self.stamp: datetime | None = None  # set when the task starts with timestamps enabled

    def cfg_dig_edge_start_trig(self, trigger_source, trigger_edge=None):
        self.source = trigger_source

    def _supported(self):
        if not self._task.device.timestamps:
            raise DaqError("Specified property is not supported by the device (FAKE)", UNSUPPORTED)

    def _setting(attr):  # noqa: N805 - builds a property in the class body
        # A start trigger property the device may not support (error -200452 there).
        def get(self):
            self._supported()
            return getattr(self, attr)

        def set_(self, val):
            self._supported()
            setattr(self, attr, val)

        return property(get, set_)

    timestamp_enable = _setting("_stamp_enabled")
    timestamp_timescale = _setting("_timescale")
    del _setting

    @property
    def timestamp_val(self):
        self._supported()
        if self.stamp is None:
            raise DaqError("The start trigger has no timestamp: the task did not start with it enabled (FAKE)",
                           -209830)
        return self.stamp


class _OutStream:
    def __init__(self, task):
        self._task = task

    @property
    def total_samp_per_chan_generated(self):
        # The samples the sample clock has put out since the task started.
        task = self._task
        if task.t0 is None or task.data is None:
            return 0
        if task.state == "done":
            return task.data.shape[1]
        return min(task.data.shape[1], int((time.monotonic() - task.t0) * task.timing.samp_clk_rate))


class FakeTask:
    """One FAKE ``nidaqmx.Task`` with the states of NI's task state model."""

    def __init__(self, device: FakeDevice):
        self.device = device
        self.number = len(device.tasks)
        self.ao_channels = _AOChannels(self)
        self.ai_channels = _AIChannels(self)
        self.timing = _Timing(self)
        self.triggers = SimpleNamespace(start_trigger=_StartTrigger(self))
        self.out_stream = _OutStream(self)
        self.state = "verified"
        self.data: np.ndarray | None = None
        self.t0: float | None = None
        self.written: list[np.ndarray] = []

    # -- helpers
    def _call(self, name):
        self.device.events.append((self.number, name))
        if self.state == "closed":
            raise DaqError("Task specified is invalid or does not exist (FAKE)", INVALID_TASK)
        err = self.device.fail.pop(name, None)
        if err is not None:
            raise err

    def _channels(self):
        return [c.name for c in self.ao_channels.channels]

    def _reserve(self):
        dev = self.device
        taken = [ch for ch in self._channels() if dev.reserved.get(ch, self) is not self]
        if taken:
            raise DaqError(f"The specified resource is reserved: {', '.join(taken)} (FAKE)", RESERVED)
        for ch in self._channels():
            dev.reserved[ch] = self

    def _unreserve(self):
        for ch, task in list(self.device.reserved.items()):
            if task is self:
                del self.device.reserved[ch]

    def _sample_now(self) -> np.ndarray:
        n = self.data.shape[1]
        k = min(n - 1, int((time.monotonic() - self.t0) * self.timing.samp_clk_rate))
        return self.data[:, k]

    def _halt(self, values: np.ndarray) -> None:
        # Outputs hold `values`, or go to 0 V where the idle behaviour says so.
        for chan, v in zip(self.ao_channels.channels, values):
            idle_zero = chan.ao_idle_output_behavior == AOIdleOutputBehavior.ZERO_VOLTS
            self.device.outputs[chan.name] = 0.0 if idle_zero else float(v)

    def _finish_if_done(self) -> bool:
        if self.state != "running" or self.data is None:
            return self.state != "running"
        n = self.data.shape[1]
        if time.monotonic() - self.t0 >= n / self.timing.samp_clk_rate:
            self._halt(self.data[:, -1])
            self.state = "done"
            return True
        return False

    # -- the nidaqmx.Task API used by vibrofocus
    def write(self, data, auto_start=True, timeout=10.0):
        with self.device.lock:
            self._call("write")
            arr = np.atleast_2d(np.asarray(data, dtype=float))
            if arr.shape[0] != len(self._channels()):
                arr = arr.T
            for chan, row in zip(self.ao_channels.channels, arr):
                if np.any(row > chan.max_val + 1e-12) or np.any(row < chan.min_val - 1e-12):
                    raise DaqError("Attempted writing analog data that is too large or too small (FAKE)",
                                   OUT_OF_RANGE)
            self._reserve()
            self.written.append(arr.copy())
            if auto_start and self.timing.samp_clk_rate is None:
                # on demand: the value goes out now; the implicit transitions are undone
                for chan, v in zip(self.ao_channels.channels, arr[:, -1]):
                    self.device.outputs[chan.name] = float(v)
                self._unreserve()
                return arr.shape[1]
            self.data = arr
            self.state = "committed"  # written before it starts: committed, channels reserved
            return arr.shape[1]

    def start(self):
        with self.device.lock:
            self._call("start")
            self._reserve()
            self.state = "running"
            self.t0 = time.monotonic()
            trigger = self.triggers.start_trigger
            if trigger._stamp_enabled:
                trigger.stamp = datetime.now(timezone.utc)
            if self.ao_channels.channels:
                self.device.last_output = self

    def is_task_done(self):
        with self.device.lock:
            self._call("is_task_done")
            return self._finish_if_done()

    def wait_until_done(self, timeout=10.0):
        while not self.is_task_done():
            time.sleep(0.001)

    def read(self, number_of_samples_per_channel=-1, timeout=10.0):
        self._call("read")
        if self.device.reads:
            return self.device.reads.pop(0)
        n = number_of_samples_per_channel
        wired = [self.device.loopback.get(c.name) for c in self.ai_channels.channels]
        source = self.device.last_output
        out = np.zeros(n)
        on_output_start = self.triggers.start_trigger.source == f"/{self.device.name}/ao/StartTrigger"
        if len(wired) == 1 and wired[0] and source is not None and on_output_start:
            played = np.concatenate([np.zeros(self.device.loopback_delay), source.data[source._channels().index(wired[0])]])
            out[:min(n, played.size)] = played[:n]
        return out.tolist()

    def stop(self):
        with self.device.lock:
            self._call("stop")
            if self.state == "running" and self.data is not None and not self._finish_if_done():
                self._halt(self._sample_now())
            if self.state in ("running", "done"):
                self.state = "committed"  # back to the state before start: still reserved

    def control(self, action):
        with self.device.lock:
            self._call(f"control {TaskMode(action).name}")
            if action == TaskMode.TASK_ABORT:
                if self.state == "running" and self.data is not None and not self._finish_if_done():
                    self._halt(self._sample_now())
                self.state = "aborted"  # channels stay reserved until unreserved or closed
            elif action == TaskMode.TASK_UNRESERVE:
                self._unreserve()
                self.state = "verified"

    def close(self):
        with self.device.lock:
            self.device.events.append((self.number, "close"))
            if self.state == "closed":
                return
            if self.state == "running" and self.data is not None and not self._finish_if_done():
                self._halt(self._sample_now())
            self._unreserve()
            self.state = "closed"
