"""The NI-DAQmx rig.

No NI driver can run here, so the adapter is checked against a FAKE task layer
(``fake_nidaqmx``) that models NI's task states: reserved channels, error -50103,
outputs that hold their last value, a coerced sample clock. Its methods have the real
``nidaqmx`` signatures (checked below). Tests against a real device or NI's simulated
device are marked ``nidaq_hardware`` and run only when ``VIBROFOCUS_NIDAQ_DEVICE`` names
one (e.g. a simulated PCIe-6361 made in NI MAX).
"""

from __future__ import annotations

import inspect
import os
import threading
import time

import nidaqmx
import numpy as np
import pytest
from nidaqmx.constants import AcquisitionType, TerminalConfiguration
from nidaqmx.errors import DaqError
from nidaqmx.task import Timing
from nidaqmx.task.channels import AOChannel
from nidaqmx.task.collections import AIChannelCollection, AOChannelCollection
from nidaqmx.task.triggering import StartTrigger

from vibrofocus.errors import SafetyError, ValidationError
from vibrofocus.rigs import DeviceBusyError, DeviceError, check_straps, parse_rig_config
from vibrofocus.rigs.nidaq import NidaqRig

from .ctrl_c import ctrl_c_after
from .fake_nidaqmx import RESERVED, FakeDevice, FakeTask, _AIChannels, _AOChannels, _StartTrigger, _Timing

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


@pytest.fixture
def device():
    return FakeDevice()


def make(device, **extra) -> NidaqRig:
    rig = NidaqRig(parse_rig_config(nidaq_config(**extra)), task_factory=device.factory, system=device.system())
    device.forget_setup()  # the setup's idle-output probe (closed): tests count their own tasks
    return rig


@pytest.fixture
def rig(device):
    r = make(device)
    yield r
    r.close()


def drive(n=1000, amplitude=5.0):
    t = np.arange(n) / FS
    d = np.zeros((4, n))
    d[1] = amplitude * np.sin(2 * np.pi * 100 * t)
    return d


def square(seconds: float, volts: float) -> np.ndarray:
    """A 100 Hz square wave of +-volts on every actuator: a drive that is never near 0 V while it plays."""
    n = int(seconds * FS)
    return np.tile(volts * np.sign(np.sin(2 * np.pi * 100 * (np.arange(n) + 0.5) / FS)), (4, 1))


def ao_tasks(device):
    return [t for t in device.tasks if t.ao_channels.channels]


@pytest.mark.parametrize("fake, real", [(FakeTask, nidaqmx.Task), (_AOChannels, AOChannelCollection),
                                        (_AIChannels, AIChannelCollection), (_Timing, Timing),
                                        (_StartTrigger, StartTrigger)])
def test_fake_matches_the_real_api(fake, real):
    for name, member in vars(fake).items():
        if name.startswith("_") or not callable(member):
            continue
        assert hasattr(real, name), f"nidaqmx has no {real.__name__}.{name}"
        fake_params = list(inspect.signature(member).parameters)
        real_params = list(inspect.signature(getattr(real, name)).parameters)
        assert fake_params == real_params[:len(fake_params)], name
    assert hasattr(AOChannel, "ao_idle_output_behavior")


def test_output_channels_have_the_range_of_the_amplifier_cap(rig, device):
    rig.play(drive())
    play_task = ao_tasks(device)[0]
    assert [c.name for c in play_task.ao_channels.channels] == ["Dev1/ao0", "Dev1/ao1", "Dev1/ao2", "Dev1/ao3"]
    for c in play_task.ao_channels.channels:  # amplifier_input_max_v, 1 V by default
        assert (c.min_val, c.max_val) == (-1.0, 1.0)


def test_writes_are_scaled_by_the_amplifier_gain_and_outputs_end_at_zero(rig, device):
    d = drive()
    rig.play(d)
    play_task, zero_task = ao_tasks(device)
    np.testing.assert_allclose(play_task.written[0], rig.check(d) / GAIN, rtol=1e-12)
    assert play_task.timing.samps_per_chan == d.shape[1]
    np.testing.assert_array_equal(zero_task.written[0][:, -1], np.zeros(4))
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    assert all(t.state == "closed" for t in device.tasks)
    assert device.reserved == {}


def test_input_is_armed_on_the_output_start_trigger_before_the_output_starts(rig, device):
    n, tail = 1000, 200
    expected_volts = np.random.default_rng(7).standard_normal(n + tail)
    device.reads = [expected_volts.tolist()]
    rec = rig.play_and_record(drive(n), tail_s=tail / FS)
    ai = next(t for t in device.tasks if t.ai_channels.channels)
    ao = ao_tasks(device)[0]
    (chan,) = ai.ai_channels.channels
    assert (chan.name, chan.terminal_config, chan.min_val, chan.max_val) == (
        "Dev1/ai0", TerminalConfiguration.DIFF, -10.0, 10.0)
    assert ai.triggers.start_trigger.source == "/Dev1/ao/StartTrigger"
    assert ai.timing.samps_per_chan == ao.timing.samps_per_chan == n + tail
    ev = device.events
    assert ev.index((ai.number, "start")) < ev.index((ao.number, "write")) < ev.index((ao.number, "start"))
    assert not ao.written[0][:, n:].any()  # the output plays the tail as zeros
    np.testing.assert_allclose(rec, expected_volts[None] * 1e-6, rtol=1e-12)
    assert rig.last_clipped.tolist() == [False]


def test_a_clipped_vibrometer_input_is_reported(rig, device):
    volts = np.zeros(1100)
    volts[500] = 10.0  # the end of the +-10 V input range
    device.reads = [volts.tolist()]
    rig.play_and_record(drive(), tail_s=0.01)
    assert rig.last_clipped.tolist() == [True]


def test_known_input_delay_is_removed(device):
    n, lag = 500, 3
    volts = np.zeros(n + lag)
    volts[lag + 100] = 1.0
    device.reads = [volts.tolist()]
    with make(device, latency_samples=lag) as r:
        rec = r.play_and_record(drive(n), tail_s=0)
    assert rec.shape == (1, n)
    assert int(np.argmax(rec[0])) == 100


@pytest.mark.parametrize("method", ["write", "start", "is_task_done"])
def test_driver_error_mid_play_leaves_zeros_and_says_so(rig, device, method):
    device.fail[method] = DaqError("fake driver failure", -200000)
    with pytest.raises(DeviceError, match="NI-DAQmx failed while playing: .*fake driver failure"):
        rig.play(drive())
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    assert all(t.state == "closed" for t in device.tasks) and device.reserved == {}


def test_stop_from_another_thread_brings_the_outputs_to_zero(device):
    """The fix of -50103: abort + unreserve the playing task before the zero write."""
    device.idle_zero = False  # the outputs hold their last value by themselves
    rig = make(device)
    d = square(2.0, 3.0)  # +-0.3 V at the outputs while it plays
    seen = {}

    def stopper():
        time.sleep(0.2)
        rig.stop()
        seen["after"] = device.output_vector()

    thread = threading.Thread(target=stopper)
    thread.start()
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match="stopped"):
        rig.play(d)
    elapsed = time.monotonic() - t0
    thread.join()
    assert elapsed < 1.5  # the 2 s play ended at the stop, not at its end
    np.testing.assert_array_equal(seen["after"], 0.0)  # 0 V when stop() returns (how fast: the JACK test)
    np.testing.assert_array_equal(device.output_vector(), 0.0)
    assert all(t.state == "closed" for t in device.tasks) and device.reserved == {}
    rig.close()


def test_the_fake_refuses_a_zero_write_while_a_stopped_task_holds_its_channels(device):
    """What the old stop did: stop() the committed task, then a second task writes zeros."""
    play, zero = device.factory(), device.factory()
    for task in (play, zero):
        for i in range(4):
            task.ao_channels.add_ao_voltage_chan(f"Dev1/ao{i}", min_val=-1.0, max_val=1.0)
    play.timing.cfg_samp_clk_timing(FS, sample_mode=AcquisitionType.FINITE, samps_per_chan=10_000)
    play.write(np.full((4, 10_000), 0.5), auto_start=False)
    play.start()
    play.stop()
    with pytest.raises(DaqError) as err:
        zero.write(np.zeros(4), auto_start=True)
    assert err.value.error_code == RESERVED
    assert device.output_vector().max() == 0.5  # the coil keeps its voltage


def test_ctrl_c_interrupts_a_long_play_and_leaves_zeros(rig, device):
    d = square(5.0, 2.0)
    t0 = time.monotonic()
    with ctrl_c_after(0.2), pytest.raises(KeyboardInterrupt):
        rig.play(d)
    assert time.monotonic() - t0 < 3.0  # the 5 s play did not run to its end
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_a_failing_abort_still_closes_every_task_and_the_first_error_is_kept(rig, device):
    device.fail["read"] = DaqError("read failed", -200279)
    device.fail["control TASK_ABORT"] = DaqError("abort failed", -200000)
    with pytest.raises(DeviceError, match="read failed"):
        rig.play_and_record(drive())
    assert all(t.state == "closed" for t in device.tasks)
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_an_error_while_zeroing_does_not_hide_the_first_one(rig, device):
    device.fail["read"] = DaqError("read failed", -200279)
    original = device.factory

    def factory():
        task = original()
        if len(device.tasks) >= 3:  # every zero task after the failed recording (the retry too)
            task.device.fail["add_ao_voltage_chan"] = DaqError("device gone", -201003)
        return task

    rig._daq._task_factory = factory
    with pytest.raises(DeviceError, match="read failed") as err:
        rig.play_and_record(drive())
    assert any("ALSO failed" in note and "device gone" in note for note in err.value.__notes__)
    rig._daq._task_factory = original  # the device is back: the fixture's close zeroes it


def test_a_zero_write_that_fails_once_is_tried_again(rig, device):
    device.idle_zero = False
    original = device.factory
    failed = []

    def factory():
        task = original()
        if len(device.tasks) == 2 and not failed:  # the zero task after the play, once
            failed.append(task)
            device.fail["add_ao_voltage_chan"] = DaqError("glitch", -200000)
        elif failed:
            device.fail.pop("add_ao_voltage_chan", None)
        return task

    rig._daq._task_factory = factory
    rig.play(square(0.1, 3.0))
    assert failed, "the first zero write did not fail: the test did not test the retry"
    zero_tasks = device.tasks[1:]
    assert len(zero_tasks) == 2  # the failed zero write (its channel refused), and the one tried again
    assert zero_tasks[-1].written and not np.any(zero_tasks[-1].written[-1])
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_channel_creation_failure_closes_the_task(device):
    cfg = nidaq_config()
    with make(device) as r:
        device.fail["add_ao_voltage_chan"] = DaqError("no such channel", -200170)
        with pytest.raises(DeviceError):
            r.play(drive())
    assert all(t.state == "closed" for t in device.tasks)


def test_a_rate_the_timebase_cannot_make_is_refused(device):
    device.timebase_hz = 80e6 / 3  # 26.67 MHz: no integer divisor gives 10 kHz
    with make(device) as r, pytest.raises(DeviceError, match="sample clock at .* not the 10000 Hz"):
        r.play(drive())
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_a_mistaken_gain_cannot_put_more_than_the_cap_into_the_amplifier(device):
    # amplifier_gain = 1 by mistake: the actuator limit of 10 V would need 10 V into the amplifier.
    with pytest.raises(ValidationError, match="amplifier_input_max_v = 1 V"):
        parse_rig_config(nidaq_config(amplifier_gain=1.0))
    # with the limit lowered to fit the cap, no sample beyond 1 V leaves the DAQ
    with make(device, amplifier_gain=1.0, limits={"peak_v": 1.0}) as r:
        with pytest.raises(SafetyError):
            r.play(drive(amplitude=5.0))
        r.play(drive(amplitude=1.0))
    assert max(np.abs(w).max() for t in device.tasks for w in t.written) <= 1.0


@pytest.mark.parametrize("change, words", [
    (dict(device="Dev2", channels={"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "ai0"}),
     "NI device 'Dev2' not found"),
    (dict(channels={"actuators": ["ao0", "ao1", "ao2", "ao7"], "vibrometer": "ai0"}), "no analog output Dev1/ao7"),
    (dict(), "outside the output rates"),  # on a device whose outputs run at most 5 kHz
])
def test_setup_is_checked_before_the_first_play(device, change, words):
    device.ao_max_rate = 5_000.0 if not change else device.ao_max_rate
    cfg = nidaq_config(**change)
    with pytest.raises(DeviceError, match=words):
        NidaqRig(parse_rig_config(cfg), task_factory=device.factory, system=device.system())
    assert device.tasks == []


def test_channels_on_two_devices_are_refused():
    cfg = nidaq_config(channels={"actuators": ["Dev1/ao0", "Dev2/ao0", "Dev1/ao1", "Dev1/ao2"],
                                 "vibrometer": "ai0"})
    with pytest.raises(ValidationError, match="2 devices .*sample-synchronous"):
        parse_rig_config(cfg)


def test_one_device_one_rig(rig, device):
    with pytest.raises(DeviceBusyError, match="nidaq:Dev1 is in use by"):
        make(device)
    rig.close()
    make(device).close()  # free again once the first rig is closed


@pytest.mark.parametrize(
    "bad, match",
    [
        (drive(amplitude=10.5), "over the limit of 10 V"),
        (np.where(np.arange(1000) == 5, np.inf, drive()), "NaN/Inf"),
        (np.zeros((4, int(31 * FS))), "longer than the limit"),
    ],
    ids=["over-limit", "inf", "too-long"],
)
def test_unsafe_drives_never_reach_a_task(rig, device, bad, match):
    with pytest.raises(SafetyError, match=match):
        rig.play(bad)
    with pytest.raises(SafetyError, match=match):
        rig.play_and_record(bad)
    assert device.tasks == []  # no task was even created


def test_strap_forces_read_through_the_curve(device):
    curve = {"volts": [0.0, 1.0, 2.0], "newtons": [0.0, 1.0, 3.0]}
    # averaging_s = 0.01 s at 10 kHz: 100 samples per strap
    device.reads = [np.vstack([np.full(100, 1.0), np.full(100, 1.5)]).tolist()]
    with make(device, force_sensors={"channels": ["ai1", "ai2"], "names": ["proximal", "distal"],
                                     "curve": curve, "averaging_s": 0.01}) as r:
        reading = check_straps(r)
    np.testing.assert_allclose(reading.forces_n, [1.0, 2.0])
    assert reading.verdicts == ("ok", "too tight")
    assert not reading.ok
    ai = next(t for t in device.tasks if t.ai_channels.channels)
    assert [c.name for c in ai.ai_channels.channels] == ["Dev1/ai1", "Dev1/ai2"]
    # reading the straps plays nothing (only the closing zero write touches the outputs)
    assert all(not t.written or not np.any(t.written[0]) for t in ao_tasks(device))


def test_layout_mismatch_is_refused(device):
    from vibrofocus import ArrayLayout

    ref = ArrayLayout.reference()
    two = ArrayLayout(ref.actuators_xy[:2], ref.locations_xy)
    with pytest.raises(ValidationError, match="4 actuator channel.*2 actuators"):
        NidaqRig(parse_rig_config(nidaq_config()), layout=two, task_factory=device.factory)


def test_missing_driver_is_a_clear_error():
    from vibrofocus.rigs import make_rig

    with pytest.raises(DeviceError, match="NI-DAQmx driver is not available"):
        make_rig("nidaq", config=nidaq_config())


@pytest.mark.nidaq_hardware
@pytest.mark.skipif(not os.environ.get("VIBROFOCUS_NIDAQ_DEVICE"),
                    reason="set VIBROFOCUS_NIDAQ_DEVICE to a real or NI-simulated device (e.g. Dev1)")
def test_real_device_plays_records_and_stops_from_another_thread():
    from vibrofocus.rigs import make_rig

    dev = os.environ["VIBROFOCUS_NIDAQ_DEVICE"]
    cfg = nidaq_config(device=dev, force_sensors=None)
    cfg["channels"] = {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "ai0"}
    with make_rig("nidaq", config=cfg) as rig:
        rec = rig.play_and_record(drive(), tail_s=0.01)
        assert rec.shape == (1, 1100)
        assert np.isfinite(rec).all()
        long = square(2.0, 1.0)
        timer = threading.Timer(0.2, rig.stop)
        timer.start()
        with pytest.raises(DeviceError, match="stopped"):
            rig.play(long)
        timer.join()


def test_a_stop_between_two_takes_ends_the_job(rig, device):
    # A calibration holds the rig; the experimenter's stop comes while nothing plays.
    with rig.reserve("the calibration of P01"):
        rig.play_and_record(drive(), tail_s=0.0)
        n_tasks = len(device.tasks)
        rig.stop()  # as from another thread, between two takes
        with pytest.raises(DeviceError, match="stopped .* during the calibration of P01"):
            rig.play_and_record(drive(), tail_s=0.0)
        assert all(not t.written or not np.any(t.written[0]) for t in device.tasks[n_tasks:])  # only zeros
    rig.play(drive())  # a new job may start


def test_fake_properties_exist_on_the_real_api():
    from nidaqmx.task import OutStream

    from .fake_nidaqmx import _OutStream

    pairs = [(StartTrigger, _StartTrigger, ("timestamp_enable", "timestamp_timescale", "timestamp_val")),
             (OutStream, _OutStream, ("total_samp_per_chan_generated",))]
    for real, fake, names in pairs:
        for name in names:
            assert isinstance(getattr(real, name), property), name
            assert isinstance(getattr(fake, name), property), name


def test_onset_is_the_start_trigger_timestamp_where_the_device_gives_one():
    from nidaqmx.constants import Timescale

    device = FakeDevice(timestamps=True, product_type="cDAQ-9185 (FAKE)")
    with make(device) as rig:
        first, second = rig.play(drive()), rig.play(drive())
    plays = [t for t in ao_tasks(device) if t.triggers.start_trigger.stamp is not None]
    assert len(plays) == 2
    for onset, task in zip((first, second), plays):
        trigger = task.triggers.start_trigger
        assert (trigger.timestamp_enable, trigger.timestamp_timescale) == (True, Timescale.USE_IO_DEVICE)
        assert onset.clock == "nidaq_start_trigger"
        assert onset.device_s == trigger.stamp.timestamp()  # read back, to the microsecond it holds
    assert second.device_s > first.device_s and second.host_s > first.host_s
    assert rig._daq.start_timestamp_supported is True


def test_a_device_without_start_timestamps_counts_its_sample_clock_and_is_asked_once(device):
    lengths = [1000, 250, 4000]
    with make(device) as rig:
        onsets = [rig.play(drive(n)) for n in lengths]
        assert rig._daq.samples_generated == sum(lengths)  # read back from each task, not assumed
    assert [o.clock for o in onsets] == ["nidaq_samples"] * 3
    # Each onset is the samples the earlier plays generated over the rate.
    assert [o.device_s for o in onsets] == [0.0, 1000 / FS, 1250 / FS]
    assert onsets[2].host_s > onsets[1].host_s > onsets[0].host_s
    assert rig._daq.start_timestamp_supported is False
    assert all(t.triggers.start_trigger.stamp is None for t in device.tasks)


def test_latency_through_a_loopback_is_its_delay_in_samples():
    from vibrofocus.realtime import measure_latency

    delay = 3
    device = FakeDevice(loopback={"Dev1/ai5": "Dev1/ao1"}, loopback_delay=delay)
    with make(device) as rig:
        report = measure_latency(rig, count=3, spacing_s=0.0, loopback=6, channel=2, amplitude_v=1.0)
    # The input starts on the output's start trigger: the only delay is the wire's.
    np.testing.assert_allclose(report.latencies_s, delay / FS, atol=1e-9)
    assert report.input_fs == FS
    ai = [t for t in device.tasks if t.ai_channels.channels]
    assert [c.name for t in ai for c in t.ai_channels.channels] == ["Dev1/ai5"] * 3
    assert all(t.triggers.start_trigger.source == "/Dev1/ao/StartTrigger" for t in ai)
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_latency_on_an_input_the_device_lacks_names_it(device):
    from vibrofocus.realtime import measure_latency

    with make(device) as rig, pytest.raises(DeviceError, match="Dev1/ai8 does not exist"):
        measure_latency(rig, count=2, spacing_s=0.0, loopback=9, channel=1)
    np.testing.assert_array_equal(device.output_vector(), 0.0)


def test_a_compactdaq_chassis_with_output_and_input_modules_plays_and_records():
    """The paper's own rig is a cDAQ-9174: AO and AI on separate modules, triggers on the chassis."""
    device = FakeDevice("cDAQ1", modules={"cDAQ1Mod1": ("ao", 4), "cDAQ1Mod2": ("ai", 4)},
                        product_type="cDAQ-9174 (FAKE)", loopback={"cDAQ1Mod2/ai0": "cDAQ1Mod1/ao1"})
    cfg = nidaq_config(device="cDAQ1Mod1", force_sensors=None)
    cfg["channels"] = {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "cDAQ1Mod2/ai0"}
    rig = NidaqRig(parse_rig_config(cfg), task_factory=device.factory, system=device.system())
    try:
        assert any("inputs on cDAQ1Mod2" in line and "chassis cDAQ1" in line for line in rig.setup_report)
        d = drive()
        rec = rig.play_and_record(d, tail_s=0.0)
        ai = [t for t in device.tasks if t.ai_channels.channels][-1]
        assert ai.triggers.start_trigger.source == "/cDAQ1/ao/StartTrigger"
        # The loopback reads actuator 2's output through the chassis trigger: the drive itself, scaled.
        expected = rig.check(d)[1] / GAIN * 1e-6  # volts at the output -> m through the decoder's 1e-6 m/V
        np.testing.assert_allclose(rec[0], expected, atol=1e-12)
    finally:
        rig.close()


def test_modules_of_two_chassis_are_refused():
    cfg = nidaq_config(device="cDAQ1Mod1", force_sensors=None)
    cfg["channels"] = {"actuators": ["ao0", "ao1", "ao2", "ao3"], "vibrometer": "cDAQ2Mod2/ai0"}
    with pytest.raises(ValidationError, match="modules of one CompactDAQ chassis"):
        parse_rig_config(cfg)


@pytest.mark.parametrize("idle_zero, words", [(True, "go to 0 V by themselves"), (False, "HOLD their last value"),
                                              ("refused", "HOLD their last value")])
def test_the_setup_report_says_whether_outputs_idle_at_zero_and_a_refused_zero_idle_still_plays(idle_zero, words):
    device = FakeDevice(idle_zero=idle_zero)
    rig = make(device)
    try:
        assert any(words in line for line in rig.setup_report)
        rig.play(drive())
        np.testing.assert_array_equal(device.output_vector(), 0.0)
    finally:
        rig.close()


def test_the_fake_refuses_a_one_sample_finite_output_task_as_daqmx_does(device):
    task = device.factory()
    task.ao_channels.add_ao_voltage_chan("Dev1/ao0", min_val=-1.0, max_val=1.0)
    with pytest.raises(DaqError):
        task.timing.cfg_samp_clk_timing(FS, sample_mode=AcquisitionType.FINITE, samps_per_chan=1)
