"""The audio rig against a real JACK server (dummy driver) through PortAudio.

The rig's outputs are wired back to its inputs by JACK's loopback ports (see conftest):
actuator 1's output reaches the "vibrometer" input, so the measured transfer function
from actuator 1 is the gain chain alone and the others are zero.
"""

from __future__ import annotations

import time
from unittest import mock

import numpy as np
import pytest

from vibrofocus.errors import SafetyError
from vibrofocus.rigs import DeviceError, Rig, make_rig
from vibrofocus.signals import ricker


pytestmark = pytest.mark.jack

# The test server of conftest.py (kept in step with JACK_RATE / JACK_PERIOD there).
JACK_RATE = 48_000
JACK_PERIOD = 4096

FS = 10_000.0
GAIN = 10.0
SENS = 1e-6  # m/V, a displacement decoder
VFS_OUT = 2.0
VFS_IN = 0.5
#: |H| of the loop: actuator V -> output V (/gain) -> input digital (/vfs_out) -> input V (*vfs_in) -> m (*sens)
EXPECTED_H = SENS * VFS_IN / (GAIN * VFS_OUT)


def jack_config(**channels) -> dict:
    chans = dict(actuators=[1, 2, 3, 4], vibrometer=1, loopback_output=5, loopback_input=5)
    chans.update(channels)
    chans = {k: v for k, v in chans.items() if v is not None}
    return {
        "kind": "audio", "fs": FS, "amplifier_gain": GAIN, "volts_full_scale": VFS_OUT,
        "input_volts_full_scale": VFS_IN, "max_latency_s": 0.2, "xrun_retries": 5,
        "device": {"name": "loopback", "hostapi": "JACK", "samplerate": float(JACK_RATE)},
        "channels": chans,
        "vibrometer": {"decoder": "displacement", "sensitivity": SENS, "highpass_hz": None},
    }


@pytest.fixture
def rig(jack_server):
    assert (jack_server.rate, jack_server.period) == (JACK_RATE, JACK_PERIOD)
    with make_rig("audio", config=jack_config()) as r:
        yield r


def pulse_drive(n_act: int = 4, channel: int = 0, amplitude: float = 5.0, n: int = 2000, t0: float = 0.05):
    drive = np.zeros((n_act, n))
    drive[channel] = amplitude * ricker(FS, duration=n / FS, t0=t0)
    return drive


class _IdealLoopRig(Rig):
    """Reference for the estimator, not a fake of the device: the loop's exact gain, no device."""

    kind = "ideal-loop"
    max_points_per_recording = 1

    def _play(self, drive):
        pass

    def _play_and_record(self, drive, points_xy, n_tail):
        return EXPECTED_H * np.pad(drive[:1], ((0, 0), (0, n_tail)))

    def _zero_outputs(self):
        pass


def test_calibration_through_loopback_is_flat_gain_chain_with_zero_phase(rig):
    from vibrofocus.calibration import calibrate

    # Real time on the dummy driver: one point, actuators 1 and 2 (2 goes elsewhere).
    settings = dict(participant_id="jack-loopback", method="h1", points=[0], actuators=[0, 1], sweep_s=1.0, repeats=2,
                    prompt=lambda label, xy: None)
    cal = calibrate(rig, **settings)
    assert rig.last_latency_samples == JACK_PERIOD  # JACK's loopback returns one period later
    band = (cal.freqs >= 10) & (cal.freqs <= 1000)
    h = cal.H[band, 0, :]
    # The same estimator on the exact loop gain without any device: what the rig adds
    # (resampling, scaling, latency) must vanish against it over the whole band.
    ref = calibrate(_IdealLoopRig(fs=FS), **settings).H[band, 0, 0]
    np.testing.assert_allclose(np.abs(h[:, 0] / ref), 1.0, atol=0.005)
    np.testing.assert_allclose(np.angle(h[:, 0] / ref), 0.0, atol=np.deg2rad(0.5))
    # Absolute: flat at the gain chain with zero phase where the sweep estimate is exact.
    flat = cal.freqs[band] >= 100
    np.testing.assert_allclose(np.abs(h[flat, 0]), EXPECTED_H, rtol=0.01)
    np.testing.assert_allclose(np.angle(h[flat, 0]), 0.0, atol=np.deg2rad(1.0))
    # Actuator 2 goes to another loopback port: nothing of it reaches the vibrometer input.
    assert h.shape[1] == 2
    assert np.abs(h[:, 1]).max() < 1e-3 * EXPECTED_H
    np.testing.assert_allclose(cal.coherence[band, 0, 0], 1.0, atol=1e-3)


def test_fixed_latency_from_config_aligns_and_zero_latency_does_not(jack_server):
    drive = pulse_drive()
    expected_peak = int(np.argmax(np.abs(drive[0])))
    lag_at_fs = JACK_PERIOD * FS / JACK_RATE  # 853.3 samples at 10 kHz
    with make_rig("audio", config={**jack_config(loopback_output=None, loopback_input=None),
                                   "latency_samples": JACK_PERIOD}) as aligned:
        rec = aligned.play_and_record(drive, tail_s=0.01)
    assert rec.shape == (1, drive.shape[1] + 100)
    assert int(np.argmax(np.abs(rec[0]))) == expected_peak
    np.testing.assert_allclose(rec[0, :2000], drive[0] * EXPECTED_H, atol=2e-3 * np.abs(drive).max() * EXPECTED_H)
    with make_rig("audio", config={**jack_config(loopback_output=None, loopback_input=None),
                                   "latency_samples": 0}) as unaligned:
        late = unaligned.play_and_record(drive, tail_s=0.01)
    assert abs(int(np.argmax(np.abs(late[0]))) - expected_peak - lag_at_fs) <= 1


def test_drive_reaches_output_scaled_by_gain_and_full_scale(rig):
    drive = pulse_drive(amplitude=8.0)
    safe = rig.check(drive)
    block = rig._to_device(safe, n_tail=0)
    assert block.dtype == np.float32 and block.shape[1] == 5
    assert len(block) == drive.shape[1] * JACK_RATE // int(FS)
    np.testing.assert_allclose(np.abs(block[:, 0]).max(), 8.0 / (GAIN * VFS_OUT), rtol=2e-3)
    np.testing.assert_array_equal(block[:, 4], block[:, 0])  # loopback carries the strongest drive
    assert not block[:, 1:4].any()


def test_resampling_overshoot_never_exceeds_the_limit(rig, caplog):
    # Full-scale steps at the limit: the 10 kHz -> 48 kHz interpolation overshoots
    # between the original samples (Gibbs); the device must still never see more.
    drive = np.zeros((4, 400))
    drive[0, 100:110] = 10.0
    drive[0, 110:120] = -10.0
    block = rig._to_device(rig.check(drive), n_tail=0)
    ceiling = rig.limits.peak_v / (GAIN * VFS_OUT)
    assert np.abs(block).max() <= ceiling * (1 + 1e-6)
    assert "clipped" in caplog.text


def test_missing_loopback_signal_is_a_clear_error(jack_server):
    # Output 5 carries the copy, but input 6 is wired to the unused output 6.
    with make_rig("audio", config=jack_config(loopback_input=6)) as r:
        with pytest.raises(DeviceError, match="loopback input 6 did not receive"):
            r.play_and_record(pulse_drive(), tail_s=0.0)


def test_no_way_to_align_refuses_before_opening_the_stream(jack_server):
    import sounddevice as sd

    with make_rig("audio", config=jack_config(loopback_output=None, loopback_input=None)) as r:
        with mock.patch.object(sd, "playrec", wraps=sd.playrec) as spy:
            with pytest.raises(DeviceError, match="cannot align recordings"):
                r.play_and_record(pulse_drive())
        spy.assert_not_called()


@pytest.mark.parametrize(
    "bad, match",
    [
        (lambda d: d * 3.0, "over the limit"),  # 15 V peak
        (lambda d: np.where(np.arange(d.shape[1]) == 7, np.nan, d), "NaN"),
        (lambda d: np.zeros((4, int(31 * FS))), "longer than the limit"),
        (lambda d: d[:3], "shape"),
    ],
    ids=["over-limit", "nan", "too-long", "wrong-channels"],
)
def test_unsafe_drives_never_reach_the_stream(rig, bad, match):
    import sounddevice as sd

    drive = bad(pulse_drive())
    with mock.patch.object(sd, "playrec", wraps=sd.playrec) as rec_spy, \
            mock.patch.object(sd, "play", wraps=sd.play) as play_spy:
        with pytest.raises(SafetyError, match=match):
            rig.play(drive)
        with pytest.raises(SafetyError, match=match):
            rig.play_and_record(drive)
    rec_spy.assert_not_called()
    play_spy.assert_not_called()


def test_stream_xrun_discards_the_recording(rig):
    import sounddevice as sd

    real_wait = sd.wait

    def wait_with_underflow(*args, **kwargs):
        real_wait(*args, **kwargs)
        return sd.CallbackFlags(4)  # paOutputUnderflow: PortAudio lost output samples

    with mock.patch.object(sd, "wait", wait_with_underflow), \
            mock.patch.object(sd, "playrec", wraps=sd.playrec) as spy:
        with pytest.raises(DeviceError, match="output underflow while recording"):
            rig.play_and_record(pulse_drive(), tail_s=0.0)
        assert spy.call_count == 1 + rig.config.xrun_retries  # taken again, then refused
        with pytest.raises(DeviceError, match="output underflow while playing"):
            rig.play(pulse_drive())  # a stimulus is never repeated
    assert not sd.get_stream().active


def test_one_xrun_is_retried_and_the_recording_kept(rig):
    import sounddevice as sd

    real_wait = sd.wait
    calls = []

    def wait_once_bad(*args, **kwargs):
        status = real_wait(*args, **kwargs)
        calls.append(status)
        return sd.CallbackFlags(2) if len(calls) == 1 else status  # paInputOverflow once

    drive = pulse_drive()
    with mock.patch.object(sd, "wait", wait_once_bad):
        rec = rig.play_and_record(drive, tail_s=0.0)
    assert len(calls) >= 2
    assert int(np.argmax(np.abs(rec[0]))) == int(np.argmax(np.abs(drive[0])))


def _loopback_input_now(seconds: float = 0.1) -> np.ndarray:
    import sounddevice as sd

    x = sd.rec(int(seconds * JACK_RATE), samplerate=JACK_RATE, device="loopback", mapping=[1, 2, 3, 4],
               blocking=True)
    return np.asarray(x)


def test_error_mid_play_stops_the_stream_and_outputs_go_silent(rig):
    import sounddevice as sd

    drive = np.zeros((4, int(2 * FS)))
    drive[:, :] = 2.0 * np.sin(2 * np.pi * 200 * np.arange(drive.shape[1]) / FS)  # 1.4 V RMS, 2 s
    started = {}

    def failing_wait(*args, **kwargs):
        time.sleep(0.2)
        started["active"] = sd.get_stream().active
        raise RuntimeError("operator pulled the cable")

    with mock.patch.object(sd, "wait", failing_wait):
        with pytest.raises(RuntimeError, match="cable"):
            rig.play(drive)
    assert started["active"]  # the error came while the drive was playing...
    assert not sd.get_stream().active  # ...and the rig stopped it at once
    assert not _loopback_input_now().any()  # every output is silent now


def test_stop_during_a_recording_discards_it(rig):
    import sounddevice as sd

    real_wait = sd.wait

    def stop_then_wait(*args, **kwargs):
        time.sleep(0.05)
        rig.stop()  # e.g. the experimenter's stop button, from another thread
        return real_wait(*args, **kwargs)

    with mock.patch.object(sd, "wait", stop_then_wait), \
            mock.patch.object(sd, "playrec", wraps=sd.playrec) as spy:
        with pytest.raises(DeviceError, match="stopped before it ended"):
            rig.play_and_record(pulse_drive(n=20_000), tail_s=0.0)
    assert spy.call_count == 1  # not retried
    assert not _loopback_input_now().any()


def test_device_selection_errors_are_specific(jack_server):
    with pytest.raises(DeviceError, match="no audio device named like 'nosuchcard'.*loopback"):
        make_rig("audio", config={**jack_config(), "device": {"name": "nosuchcard", "hostapi": "JACK"}})
    with pytest.raises(DeviceError, match="6 outputs .* output channels up to 7"):
        make_rig("audio", config=jack_config(loopback_output=7))
    with pytest.raises(DeviceError, match="host API matching 'ASIO'"):
        make_rig("audio", config={**jack_config(), "device": {"name": "loopback", "hostapi": "ASIO"}})


def test_device_selection_by_index(jack_server):
    import sounddevice as sd

    index = [d["index"] for d in sd.query_devices() if d["name"] == "loopback"][0]
    cfg = jack_config()
    cfg["device"] = {"name": index, "samplerate": float(JACK_RATE)}
    with make_rig("audio", config=cfg) as r:
        assert r.device_index == index
        assert r.describe()["device_fs"] == JACK_RATE


def test_the_cue_is_refused_on_the_interface_that_drives_the_actuators(rig):
    # A cue tone plays outside the safety layer, so it must never go to the rig's own
    # interface: naming that device (by index, or by name) is refused.
    from vibrofocus.errors import ValidationError
    from vibrofocus.studies import headphone_beep

    with pytest.raises(ValidationError, match="drives the actuators"):
        headphone_beep(rig.device_index, rig=rig)
    with pytest.raises(ValidationError, match="drives the actuators"):
        headphone_beep("loopback", rig=rig)
