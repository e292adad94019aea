"""The NI-DAQmx rig.

No NI driver can run here, so the adapter is checked against FAKE tasks: autospecs of
the real ``nidaqmx.Task`` API (and of its channel, timing and trigger collections), which
refuse calls or arguments the real API does not have. Tests against a real device or
NI's simulated device are marked ``nidaq_hardware`` and run only when
``VIBROFOCUS_NIDAQ_DEVICE`` names one (e.g. a simulated PCIe-6361 made in NI MAX).
"""

from __future__ import annotations

import os
from unittest import mock
from unittest.mock import create_autospec

import nidaqmx
import numpy as np
import pytest
from nidaqmx.constants import AcquisitionType, TerminalConfiguration
from nidaqmx.errors import DaqError
from nidaqmx.task import Timing
from nidaqmx.task.collections import AIChannelCollection, AOChannelCollection
from nidaqmx.task.triggering import StartTrigger, Triggers

from vibrofocus.errors import SafetyError, ValidationError
from vibrofocus.rigs import DeviceError, check_straps, parse_rig_config
from vibrofocus.rigs.nidaq import NidaqRig

FS = 10_000.0
GAIN = 10.0


def nidaq_config(**extra) -> dict:
    cfg = {
        "kind": "nidaq", "fs": FS, "amplifier_gain": GAIN, "device": "Dev1", "terminal_config": "diff",
        "channels": {"actuators": ["ao0", "ao1", "ao2", "Dev1/ao3"], "vibrometer": "ai0"},
        "vibrometer": {"decoder": "displacement", "sensitivity": 1e-6, "highpass_hz": None},
        "force_sensors": {"channels": ["ai1", "ai2"], "names": ["proximal", "distal"]},
    }
    cfg.update(extra)
    return cfg


class FakeTaskFactory:
    """Makes FAKE ``nidaqmx.Task`` objects (autospecs) and records every one it made, in order.

    ``reads`` gives what successive ``read`` calls return (the recorded input); ``fail_on``
    makes a named method of the first task raise a ``DaqError`` as the driver would.
    """

    def __init__(self, reads=None, fail_on: str | None = None):
        self.tasks: list[mock.NonCallableMagicMock] = []
        self.reads = list(reads or [])
        self.fail_on = fail_on
        self.events: list[tuple[int, str]] = []  # (task number, method) in call order

    def __call__(self):
        task = create_autospec(nidaqmx.Task, instance=True)
        # Properties are not specced by create_autospec; spec them by hand.
        task.ao_channels = create_autospec(AOChannelCollection, instance=True)
        task.ai_channels = create_autospec(AIChannelCollection, instance=True)
        task.timing = create_autospec(Timing, instance=True)
        task.triggers = create_autospec(Triggers, instance=True)
        task.triggers.start_trigger = create_autospec(StartTrigger, instance=True)
        number = len(self.tasks)
        for name in ("start", "write", "read", "stop", "close", "wait_until_done"):
            getattr(task, name).side_effect = self._side_effect(number, name)
        self.tasks.append(task)
        return task

    def _side_effect(self, number, name):
        def effect(*args, **kwargs):
            self.events.append((number, name))
            if name == self.fail_on and number == 0:
                raise DaqError("fake driver failure", -200000)
            if name == "read":
                return self.reads.pop(0)
            return None

        return effect

    def ao_tasks(self):
        return [t for t in self.tasks if t.ao_channels.add_ao_voltage_chan.called]

    def ai_tasks(self):
        return [t for t in self.tasks if t.ai_channels.add_ai_voltage_chan.called]


def make(factory, **extra) -> NidaqRig:
    return NidaqRig(parse_rig_config(nidaq_config(**extra)), task_factory=factory)


def drive(n=1000, amplitude=5.0):
    t = np.arange(n) / FS
    d = np.zeros((4, n))
    d[1] = amplitude * np.sin(2 * np.pi * 100 * t)
    return d


def test_output_channels_have_the_range_the_limit_allows():
    fake = FakeTaskFactory()
    make(fake).play(drive())
    play_task = fake.ao_tasks()[0]
    calls = play_task.ao_channels.add_ao_voltage_chan.call_args_list
    assert [c.args[0] for c in calls] == ["Dev1/ao0", "Dev1/ao1", "Dev1/ao2", "Dev1/ao3"]
    assert [c.kwargs["name_to_assign_to_channel"] for c in calls] == [f"actuator{i}" for i in (1, 2, 3, 4)]
    for c in calls:  # 10 V at the actuator through a gain of 10: +-1 V at the outputs
        assert (c.kwargs["min_val"], c.kwargs["max_val"]) == (-1.0, 1.0)


def test_writes_are_scaled_by_the_amplifier_gain_and_outputs_end_at_zero():
    fake = FakeTaskFactory()
    rig = make(fake)
    d = drive()
    rig.play(d)
    play_task, zero_task = fake.ao_tasks()
    written = play_task.write.call_args.args[0]
    np.testing.assert_allclose(written, rig.check(d) / GAIN, rtol=1e-12)
    assert play_task.write.call_args.kwargs["auto_start"] is False
    play_task.timing.cfg_samp_clk_timing.assert_called_once_with(
        FS, sample_mode=AcquisitionType.FINITE, samps_per_chan=d.shape[1])
    # After the play: an explicit on-demand zero on every output, and every task closed.
    np.testing.assert_array_equal(zero_task.write.call_args.args[0], np.zeros(4))
    assert zero_task.write.call_args.kwargs["auto_start"] is True
    for task in fake.tasks:
        task.close.assert_called_once()


def test_input_is_armed_on_the_output_start_trigger_before_the_output_starts():
    n, tail = 1000, 200
    expected_volts = np.random.default_rng(7).standard_normal(n + tail)
    fake = FakeTaskFactory(reads=[expected_volts.tolist()])
    rig = make(fake)
    rec = rig.play_and_record(drive(n), tail_s=tail / FS)
    ai = fake.ai_tasks()[0]
    ao = fake.ao_tasks()[0]
    ai.ai_channels.add_ai_voltage_chan.assert_called_once_with(
        "Dev1/ai0", name_to_assign_to_channel="vibrometer", terminal_config=TerminalConfiguration.DIFF,
        min_val=-10.0, max_val=10.0)
    ai.triggers.start_trigger.cfg_dig_edge_start_trig.assert_called_once_with("/Dev1/ao/StartTrigger")
    # Same rate and clock for both; the input takes the drive plus its tail.
    ai.timing.cfg_samp_clk_timing.assert_called_once_with(FS, sample_mode=AcquisitionType.FINITE,
                                                          samps_per_chan=n + tail)
    ao.timing.cfg_samp_clk_timing.assert_called_once_with(FS, sample_mode=AcquisitionType.FINITE,
                                                          samps_per_chan=n + tail)
    ai_no, ao_no = fake.tasks.index(ai), fake.tasks.index(ao)
    events = fake.events
    assert events.index((ai_no, "start")) < events.index((ao_no, "write")) < events.index((ao_no, "start"))
    # The output plays the tail as zeros, so it ends at 0 V.
    assert not ao.write.call_args.args[0][:, n:].any()
    np.testing.assert_allclose(rec, expected_volts[None] * 1e-6, rtol=1e-12)


def test_known_input_delay_is_removed():
    n, lag = 500, 3
    volts = np.zeros(n + lag)
    volts[lag + 100] = 1.0
    fake = FakeTaskFactory(reads=[volts.tolist()])
    rec = make(fake, latency_samples=lag).play_and_record(drive(n), tail_s=0)
    assert rec.shape == (1, n)
    assert int(np.argmax(rec[0])) == 100
    fake.ai_tasks()[0].timing.cfg_samp_clk_timing.assert_called_once_with(
        FS, sample_mode=AcquisitionType.FINITE, samps_per_chan=n + lag)


@pytest.mark.parametrize("method", ["write", "start", "wait_until_done"])
def test_driver_error_mid_play_leaves_zeros_and_says_so(method):
    fake = FakeTaskFactory(fail_on=method)
    with pytest.raises(DeviceError, match="NI-DAQmx failed while playing: .*fake driver failure"):
        make(fake).play(drive())
    play_task, zero_task = fake.tasks
    np.testing.assert_array_equal(zero_task.write.call_args.args[0], np.zeros(4))
    for task in fake.tasks:
        task.stop.assert_called_once()
        task.close.assert_called_once()


def test_stop_from_another_thread_halts_the_running_task_before_writing_zeros():
    fake = FakeTaskFactory()
    rig = make(fake)
    original = fake._side_effect

    def side_effect(number, name):
        effect = original(number, name)
        if number == 0 and name == "wait_until_done":
            def stop_now(*a, **k):
                effect(*a, **k)
                rig.stop()  # the experimenter's stop button while the drive plays
            return stop_now
        return effect

    fake._side_effect = side_effect
    rig.play(drive())
    play_task = fake.tasks[0]
    first_zero_task = 1
    assert fake.events.index((0, "stop")) < fake.events.index((first_zero_task, "write"))
    np.testing.assert_array_equal(fake.tasks[first_zero_task].write.call_args.args[0], np.zeros(4))
    play_task.close.assert_called_once()


def test_interrupt_mid_recording_leaves_zeros():
    fake = FakeTaskFactory(reads=[])  # read() pops from an empty list: IndexError mid-recording
    rig = make(fake)
    with pytest.raises(IndexError):
        rig.play_and_record(drive())
    zero_task = fake.ao_tasks()[-1]
    np.testing.assert_array_equal(zero_task.write.call_args.args[0], np.zeros(4))


@pytest.mark.parametrize(
    "bad, match",
    [
        (drive(amplitude=10.5), "over the limit of 10 V"),
        (np.where(np.arange(1000) == 5, np.inf, drive()), "NaN/Inf"),
        (np.zeros((4, int(31 * FS))), "longer than the limit"),
    ],
    ids=["over-limit", "inf", "too-long"],
)
def test_unsafe_drives_never_reach_a_task(bad, match):
    fake = FakeTaskFactory()
    rig = make(fake)
    with pytest.raises(SafetyError, match=match):
        rig.play(bad)
    with pytest.raises(SafetyError, match=match):
        rig.play_and_record(bad)
    assert fake.tasks == []  # no task was even created


def test_strap_forces_read_through_the_curve():
    curve = {"volts": [0.0, 1.0, 2.0], "newtons": [0.0, 1.0, 3.0]}
    # averaging_s = 0.01 s at 10 kHz: 100 samples per strap
    volts = np.vstack([np.full(100, 1.0), np.full(100, 1.5)])
    fake = FakeTaskFactory(reads=[volts.tolist()])
    rig = make(fake, force_sensors={"channels": ["ai1", "ai2"], "names": ["proximal", "distal"],
                                    "curve": curve, "averaging_s": 0.01})
    reading = check_straps(rig)
    np.testing.assert_allclose(reading.forces_n, [1.0, 2.0])
    assert reading.verdicts == ("ok", "too tight")
    assert not reading.ok
    ai = fake.ai_tasks()[0]
    assert [c.args[0] for c in ai.ai_channels.add_ai_voltage_chan.call_args_list] == ["Dev1/ai1", "Dev1/ai2"]
    assert not fake.ao_tasks()  # reading the straps never touches the outputs


def test_layout_mismatch_is_refused():
    from vibrofocus import ArrayLayout

    ref = ArrayLayout.reference()
    two = ArrayLayout(ref.actuators_xy[:2], ref.locations_xy)
    with pytest.raises(ValidationError, match="4 actuator channel.*2 actuators"):
        NidaqRig(parse_rig_config(nidaq_config()), layout=two, task_factory=FakeTaskFactory())


def test_missing_driver_is_a_clear_error():
    from vibrofocus.rigs import make_rig

    with pytest.raises(DeviceError, match="NI-DAQmx driver is not available"):
        make_rig("nidaq", config=nidaq_config())


@pytest.mark.nidaq_hardware
@pytest.mark.skipif(not os.environ.get("VIBROFOCUS_NIDAQ_DEVICE"),
                    reason="set VIBROFOCUS_NIDAQ_DEVICE to a real or NI-simulated device (e.g. Dev1)")
def test_real_device_plays_and_records():
    from vibrofocus.rigs import make_rig

    dev = os.environ["VIBROFOCUS_NIDAQ_DEVICE"]
    cfg = nidaq_config(device=dev, force_sensors=None)
    cfg["channels"] = {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "ai0"}
    with make_rig("nidaq", config=cfg) as rig:
        rec = rig.play_and_record(drive(), tail_s=0.01)
        assert rec.shape == (1, 1100)
        assert np.isfinite(rec).all()
