"""Onsets on the device clock: the record, the simulated rig's sample clock, a rig without one."""

import math

import numpy as np
import pytest

from vibrofocus import SimulatedForearm
from vibrofocus.errors import SafetyError, ValidationError
from vibrofocus.rigs import CLOCKS, DeviceOnset
from vibrofocus.rigs.onset import SIMULATED_CLOCK

FS = 10_000.0


def _drive(n: int) -> np.ndarray:
    drive = np.zeros((4, n))
    drive[1, n // 4:n // 2] = 2.0
    return drive


@pytest.fixture
def rig():
    return SimulatedForearm(seed=3, noise_m=0.0, dropout_rate=0.0, fs=FS)


def test_the_simulated_clock_advances_by_exactly_the_samples_each_play_put_out(rig):
    lengths = [400, 1234, 77, 4096]
    onsets = [rig.play(_drive(n)) for n in lengths]
    assert [o.clock for o in onsets] == [SIMULATED_CLOCK] * len(lengths)
    assert [o.latency_s for o in onsets] == [0.0] * len(lengths)  # no output buffer
    assert onsets[0].device_s == 0.0
    # Each onset is the samples played before it over the rate: the running sum of the lengths.
    expected = np.concatenate([[0], np.cumsum(lengths[:-1])]) / FS
    assert [o.device_s for o in onsets] == list(expected)
    for before, after, n in zip(onsets, onsets[1:], lengths):
        assert round((after.device_s - before.device_s) * FS) == n
        assert after.host_s >= before.host_s
    assert rig.samples_played == sum(lengths)


def test_recordings_and_loopback_captures_move_the_clock_by_everything_they_put_out(rig):
    rig.play_and_record(_drive(500), tail_s=0.01)  # 500 samples of drive, 100 of tail
    assert rig.play(_drive(300)).device_s == 600 / FS
    recording, _ = rig.play_and_capture(_drive(200), 1)
    assert rig.play(_drive(10)).device_s == (900 + recording.size) / FS


def test_a_refused_drive_leaves_the_clock_where_it_was(rig):
    rig.play(_drive(100))
    bad = _drive(100)
    bad[0, 3] = np.nan
    with pytest.raises(SafetyError):
        rig.play(bad)
    assert rig.play(_drive(100)).device_s == 100 / FS


class _NoClock(SimulatedForearm):
    """A lab's own backend whose _play returns nothing (no device clock)."""

    def _play(self, drive):
        super()._play(drive)


def test_a_backend_without_a_device_clock_gives_the_host_time_only():
    onset = _NoClock(seed=1, noise_m=0.0, dropout_rate=0.0).play(_drive(100))
    assert (onset.device_s, onset.clock, onset.latency_s) == (None, None, None)
    assert onset.output_host_s == onset.host_s
    assert math.isfinite(onset.host_s)


@pytest.mark.parametrize("kwargs, words", [
    ({"host_s": float("nan")}, "host time must be a finite number of seconds"),
    ({"host_s": 1.0, "device_s": 2.0}, "come together"),
    ({"host_s": 1.0, "clock": SIMULATED_CLOCK}, "come together"),
    ({"host_s": 1.0, "device_s": float("inf"), "clock": SIMULATED_CLOCK}, "device time must be a finite number"),
    ({"host_s": 1.0, "device_s": 2.0, "clock": "wall"}, "unknown device clock 'wall'"),
    ({"host_s": 1.0, "latency_s": -0.01}, "latency must be None or 0-2 s"),
    ({"host_s": 1.0, "latency_s": float("nan")}, "latency must be None or 0-2 s"),
    ({"host_s": 1.0, "latency_s": True}, "latency must be None or 0-2 s"),
])
def test_an_onset_is_checked(kwargs, words):
    with pytest.raises(ValidationError, match=words):
        DeviceOnset(**kwargs)


def test_a_labs_own_clock_is_registered_once_and_then_stored(tmp_path, monkeypatch):
    from vibrofocus.rigs import register_clock
    from vibrofocus.rigs import onset as onset_module

    monkeypatch.setattr(onset_module, "CLOCKS", dict(CLOCKS))  # the registry is process-wide
    with pytest.raises(ValidationError, match="unknown device clock 'lab_fpga'"):
        DeviceOnset(1.0, 2.0, "lab_fpga")
    register_clock("lab_fpga", "our FPGA's sample counter / rate")
    assert DeviceOnset(1.0, 2.0, "lab_fpga").clock == "lab_fpga"
    register_clock("lab_fpga", "our FPGA's sample counter / rate")  # the same again: no change
    for name, meaning, words in (("Lab FPGA", "x", "lower-case"), ("lab_fpga", "another", "already named"),
                                 ("portaudio_dac", "mine", "already named"), ("lab2", " ", "say what clock")):
        with pytest.raises(ValidationError, match=words):
            register_clock(name, meaning)


def test_every_clock_is_described():
    assert set(CLOCKS) == {"simulated_samples", "portaudio_dac", "nidaq_start_trigger", "nidaq_samples"}
    assert all(isinstance(text, str) and text for text in CLOCKS.values())
