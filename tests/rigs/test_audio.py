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

from .ctrl_c import ctrl_c_after


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


@pytest.mark.slow
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


def test_a_tap_at_the_limit_is_scaled_under_it_after_resampling_not_clipped(rig, caplog):
    """A Ricker tap whose samples sit at the limit peaks a little over it between them at 48 kHz."""
    import logging

    import scipy.signal

    drive = np.zeros((4, 400))
    drive[0] = ricker(FS, sigma=0.25e-3, duration=400 / FS, t0=0.02)  # a sharp tap: content up to about 2 kHz
    drive[0] *= 10.0 / np.abs(drive[0]).max()
    safe = rig.check(drive)
    plain = scipy.signal.resample_poly(safe[0] / (GAIN * VFS_OUT), 24, 5)
    ceiling = rig.limits.peak_v / (GAIN * VFS_OUT)
    assert np.abs(plain).max() > ceiling  # the case under test: the resampled drive does overshoot
    with caplog.at_level(logging.WARNING):
        block = rig._to_device(safe, n_tail=0)
    assert np.abs(block).max() <= ceiling * (1 + 1e-6)
    # One gain for the whole drive (its shape kept), not a clip: proportional to the plain resampling.
    np.testing.assert_allclose(block[:, 0], plain * ceiling / np.abs(plain).max(), rtol=1e-5, atol=1e-7)
    assert "over the limit" not in caplog.text  # no warning on every tap


def test_a_drive_that_overshoots_a_lot_when_resampled_is_refused(rig):
    # Full-scale steps at the limit: the 10 kHz -> 48 kHz interpolation rings well past it (Gibbs).
    from vibrofocus.errors import SafetyError

    drive = np.zeros((4, 400))
    drive[0, 100:110] = 10.0
    drive[0, 110:120] = -10.0
    with pytest.raises(SafetyError, match="peaks .* over the limit between its samples"):
        rig._to_device(rig.check(drive), n_tail=0)


def test_missing_loopback_signal_is_a_clear_error(jack_server):
    # Output 5 carries the copy, but input 6 is wired to the unused output 6.
    with make_rig("audio", config=jack_config(loopback_input=6)) as r:
        with pytest.raises(DeviceError, match="loopback input 6 did not receive"):
            r.play_and_record(pulse_drive(), tail_s=0.0)


def test_no_way_to_align_refuses_before_anything_reaches_the_stream(jack_server):
    with make_rig("audio", config=jack_config(loopback_output=None, loopback_input=None)) as r:
        with mock.patch.object(r, "_run_stream", wraps=r._run_stream) as spy:
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
    drive = bad(pulse_drive())
    with mock.patch.object(rig._stream, "schedule", wraps=rig._stream.schedule) as spy:
        with pytest.raises(SafetyError, match=match):
            rig.play(drive)
        with pytest.raises(SafetyError, match=match):
            rig.play_and_record(drive)
    spy.assert_not_called()


def _with_status(rig, flags_for_call):
    """Wrap the rig's stream runner so the n-th stream reports ``flags_for_call(n)`` besides its own.

    JACK's dummy driver cannot be made to lose samples on demand; this injects the flag
    PortAudio would raise, to test what the rig does with it.
    """
    import sounddevice as sd

    real = rig._run_stream
    calls = []

    def run(block, record, what):
        recorded, status, onset = real(block, record, what)
        calls.append(status)
        status |= sd.CallbackFlags(flags_for_call(len(calls)))
        return recorded, status, onset

    return mock.patch.object(rig, "_run_stream", run), calls


@pytest.mark.slow
def test_stream_xrun_discards_the_recording(rig):
    patch, calls = _with_status(rig, lambda n: 4)  # paOutputUnderflow: PortAudio lost output samples
    with patch:
        with pytest.raises(DeviceError, match="output underflow while recording"):
            rig.play_and_record(pulse_drive(), tail_s=0.0)
        assert len(calls) == 1 + rig.config.xrun_retries  # taken again, then refused
        with pytest.raises(DeviceError, match="output underflow while playing"):
            rig.play(pulse_drive())  # a stimulus is never repeated
    assert len(calls) == 2 + rig.config.xrun_retries


def test_one_xrun_is_retried_and_the_recording_kept(rig):
    patch, calls = _with_status(rig, lambda n: 2 if n == 1 else 0)  # paInputOverflow once
    drive = pulse_drive()
    with patch:
        rec = rig.play_and_record(drive, tail_s=0.0)
    assert len(calls) == 2
    assert int(np.argmax(np.abs(drive[0]))) == int(np.argmax(np.abs(rec[0])))


def test_a_study_on_jack_presents_a_trial_whose_stimulus_lost_samples_again(rig, tmp_path):
    # Issue 56, part C, on a real JACK server: the second stimulus reports an output underflow
    # (injected: the dummy driver loses none on demand); its trial is played again and the run ends
    # with each answer stored once.
    from vibrofocus.studies import StudyEngine, StudyStore
    from vibrofocus.studies.engine import Response

    class Keypad:
        def respond(self, presentation):
            return Response(presentation.trial.target, 0.3)

        def wait_resume(self):
            return True

    patch, calls = _with_status(rig, lambda n: 4 if n == 2 else 0)  # paOutputUnderflow on the second play
    with StudyStore(tmp_path / "s.db") as store, patch:
        store.add_participant("p1")
        sid = store.create_session("p1", 1, seed=5, config={"repetitions": 1, "n_training": 0,
                                                            "methods": ["inverse"], "locations": [4, 6]})
        summary = StudyEngine(store, sid, rig, renderer=lambda method, target: pulse_drive(n=500)).run(Keypad())
        assert (summary.status, summary.n_answered, len(calls)) == ("completed", 2, 3)
        (xrun,) = store.events(sid, kind="xrun")
        assert xrun.payload["trial_index"] == 1 and xrun.payload["represented"] is True
        assert "output underflow while playing" in xrun.payload["message"]
        assert xrun.payload["onset_device_s"] is not None  # where the lost stimulus began, on the DAC clock
        assert [(a.trial_index, a.response) for a in store.answers(sid)] == [
            (t.trial_index, (t.target,)) for t in store.planned_trials(sid)]


class _LoopbackRecorder:
    """A second JACK client recording the loopback capture ports (what the actuators get)."""

    def __init__(self, channels=(1, 2, 3, 4)):
        import sounddevice as sd

        self.chunks = []
        cols = [c - 1 for c in channels]

        def callback(indata, frames, time_info, status):
            self.chunks.append((time_info.inputBufferAdcTime, indata[:, cols].copy()))

        self.stream = sd.InputStream(samplerate=JACK_RATE, device="loopback", channels=max(channels),
                                     dtype="float32", callback=callback)

    def __enter__(self):
        self.stream.start()
        return self

    def __exit__(self, *exc):
        self.stream.stop()
        self.stream.close()

    def now(self) -> float:
        return self.stream.time

    def signal(self) -> tuple[np.ndarray, np.ndarray]:
        """(times (n,), samples (n, channels)) of everything recorded."""
        times = np.concatenate([t + np.arange(len(x)) / JACK_RATE for t, x in self.chunks])
        return times, np.concatenate([x for _, x in self.chunks])


def _loopback_input_now(seconds: float = 0.1) -> np.ndarray:
    with _LoopbackRecorder() as rec:
        time.sleep(seconds + 2 * JACK_PERIOD / JACK_RATE)
    return rec.signal()[1]


def _long_sine(seconds=2.0, peak=2.0):
    n = int(seconds * FS)
    return np.tile(peak * np.sin(2 * np.pi * 200 * np.arange(n) / FS), (4, 1))  # 1.4 V RMS


def test_ctrl_c_mid_play_silences_the_outputs(rig):
    t0 = time.monotonic()
    with ctrl_c_after(0.3), pytest.raises(KeyboardInterrupt):
        rig.play(_long_sine())
    assert time.monotonic() - t0 < 1.5  # the 2 s play did not run to its end
    assert not _loopback_input_now().any()  # every output is silent now


def test_stop_from_another_thread_reaches_zero_within_100_ms_plus_the_buffered_latency(rig):
    import threading

    stopped = {}

    def stop_later():
        time.sleep(0.5)
        stopped["t"] = recorder.now()
        rig.stop()

    with _LoopbackRecorder() as recorder:
        thread = threading.Thread(target=stop_later)
        thread.start()
        with pytest.raises(DeviceError, match="play was stopped before it ended"):
            rig.play(_long_sine(seconds=3.0))
        thread.join()
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    times, x = recorder.signal()
    loud = np.flatnonzero(np.abs(x).max(axis=1) > 1e-4)
    assert loud.size, "the drive never reached the outputs"
    time_to_zero = times[loud[-1]] - stopped["t"]
    # The loopback itself delays what it records by one period.
    allowed = 0.100 + rig.output_latency_s + JACK_PERIOD / JACK_RATE
    print(f"time to zero {1e3 * time_to_zero:.0f} ms (allowed {1e3 * allowed:.0f} ms; output latency "
          f"{1e3 * rig.output_latency_s:.0f} ms)")
    assert time_to_zero < allowed


def test_the_whole_drive_plays_including_its_fade_out(rig):
    # A drive that is loud up to its last samples: the stream must not end before they play.
    drive = np.zeros((4, 3000))
    drive[0] = 3.0 * np.sin(2 * np.pi * 200 * np.arange(3000) / FS)
    with _LoopbackRecorder(channels=(1,)) as recorder:
        rig.play(drive)
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    x = recorder.signal()[1][:, 0]
    played = rig.check(drive)[0] / (GAIN * VFS_OUT)  # digital level of what was asked
    expected_energy = np.sum(played**2) * JACK_RATE / FS
    np.testing.assert_allclose(np.sum(x.astype(float) ** 2), expected_energy, rtol=0.02)


def test_every_play_returns_its_onset_on_the_portaudio_dac_clock(rig):
    # Through JACK, PortAudio's stream clock is JACK's frame time since the stream opened:
    # one stream for the rig's life, so the onsets of its plays are on one clock.
    onsets = [rig.play(pulse_drive()) for _ in range(2)]
    for onset in onsets:
        assert onset.clock == "portaudio_dac"
        assert np.isfinite(onset.device_s) and onset.device_s >= 0.0
        # How far ahead of its callback the first sample reaches the converter, by PortAudio's
        # JACK host: the playback latency of the port it feeds, read at every JACK cycle (two
        # periods: JACK2 runs asynchronously by default), plus where the callback's piece lies in
        # the cycle (PortAudio hands a 4096-frame cycle on in 1024-frame pieces, and a play may
        # start in any of them). The stream's latency, as PortAudio reports it at opening, is one
        # period; the rig states the most it measured, a piece's length past the largest lead.
        period = JACK_PERIOD / JACK_RATE
        assert period <= onset.latency_s < 3 * period
        assert onset.latency_s <= rig.output_latency_s < 4 * period
        assert onset.output_host_s == onset.host_s + onset.latency_s
    assert onsets[1].host_s > onsets[0].host_s
    # Back to back on one clock: the second begins after the first's 0.2 s, within a period or two.
    gap = onsets[1].device_s - onsets[0].device_s - 2000 / FS
    assert 0.0 <= gap <= 3 * JACK_PERIOD / JACK_RATE
    assert not onsets[0].xrun and not onsets[1].xrun


def test_a_second_job_on_the_device_is_refused(rig, jack_server):
    import threading

    from vibrofocus.rigs import DeviceBusyError

    with pytest.raises(DeviceBusyError, match="audio:loopback is in use by"):
        make_rig("audio", config=jack_config())  # a second rig on the same interface
    holding, release = threading.Event(), threading.Event()

    def job():
        with rig.reserve("calibration of P01"):
            holding.set()
            release.wait(5)

    thread = threading.Thread(target=job)
    thread.start()
    holding.wait(5)
    try:
        with pytest.raises(DeviceBusyError, match="busy with calibration of P01"):
            rig.play(pulse_drive())
        with pytest.raises(DeviceBusyError, match="busy with calibration of P01"):
            rig.play_and_record(pulse_drive())
    finally:
        release.set()
        thread.join()
    rig.play(pulse_drive())  # free again


def test_a_clipped_vibrometer_input_is_reported(rig):
    rig.play_and_record(pulse_drive(), tail_s=0.0)
    assert rig.last_clipped.tolist() == [False]
    # 10 V at the actuator -> 0.5 digital out -> looped back at 0.5 of the input's full scale; a
    # config whose input full scale equals the output's reads it at the same level.
    cfg = jack_config()
    cfg["volts_full_scale"] = 0.5
    cfg["amplifier_gain"] = 20.0
    rig.close()
    with make_rig("audio", config=cfg) as loud:
        drive = np.zeros((4, 2000))
        drive[0, 500:1500] = 10.0 * np.sin(2 * np.pi * 50 * np.arange(1000) / FS)  # 10 V peak: 1.0 digital
        loud.play_and_record(drive, tail_s=0.0)
        assert loud.last_clipped.tolist() == [True]


def test_stop_during_a_recording_discards_it(rig):
    import threading

    timer = threading.Timer(0.3, rig.stop)
    with mock.patch.object(rig, "_run_stream", wraps=rig._run_stream) as spy:
        timer.start()
        with pytest.raises(DeviceError, match="recording was stopped before it ended"):
            rig.play_and_record(pulse_drive(n=20_000), tail_s=0.0)
    timer.join()
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

    with pytest.raises(ValidationError, match="may be the audio interface that drives the actuators"):
        headphone_beep(rig.device_index, rig=rig)
    with pytest.raises(ValidationError, match="may be the audio interface that drives the actuators"):
        headphone_beep("loopback", rig=rig)


@pytest.mark.parametrize("rig_name, cue_name, same", [
    ("Focusrite USB ASIO", "Speakers (Focusrite USB Audio)", True),  # ASIO vs MME names of one interface
    ("Focusrite USB ASIO", "Headphones (Realtek High Definition Audio)", False),
    ("Scarlett 2i2 USB: Audio (hw:1,0)", "Scarlett 2i2 USB: Audio (hw:1,0)", True),
    ("Scarlett 2i2 USB: Audio (hw:1,0)", "HDA Intel PCH: ALC3246 Analog (hw:0,0)", False),
    ("MOTU UltraLite-mk5", "default", True),  # routes to the system mix: may reach the interface
    ("MOTU UltraLite-mk5", "pulse", True),
])
def test_interface_identity_across_host_apis(rig_name, cue_name, same):
    from vibrofocus.rigs.audio import same_audio_interface

    assert same_audio_interface(rig_name, cue_name) is same


@pytest.mark.slow
def test_devices_check_opens_the_rig_and_plays_nothing(jack_server, tmp_path):
    import json
    import subprocess
    import sys

    good = tmp_path / "lab.json"
    good.write_text(json.dumps(jack_config()))
    r = subprocess.run([sys.executable, "-m", "vibrofocus", "devices", "--check", str(good), "--json"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    found = json.loads(r.stdout)["found"]
    assert found[0].endswith("loopback (JACK Audio Connection Kit)") and "resampled 24/5" in found[1]
    assert any("at most 1 V into it" in line for line in found)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(jack_config(loopback_output=7)))
    r = subprocess.run([sys.executable, "-m", "vibrofocus", "devices", "--check", str(bad)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("error:") == 1 and "output channels up to 7" in r.stderr


def _stop_from_another_thread(rig) -> None:
    import threading

    stopper = threading.Thread(target=rig.stop)
    stopper.start()
    stopper.join()


@pytest.mark.parametrize("window", ["admission", "conversion"])
def test_a_stop_while_the_play_is_prepared_plays_nothing(rig, window):
    """A stop before the stream starts (the budget, the resampling) is never forgotten."""
    from vibrofocus.rigs import StoppedError

    if window == "admission":
        real = rig.budget.admit
        rig.budget.admit = lambda drive, start_s: (_stop_from_another_thread(rig), real(drive, start_s))
    else:
        real = rig._to_device
        rig._to_device = lambda drive, n_tail: (_stop_from_another_thread(rig), real(drive, n_tail))[1]
    with _LoopbackRecorder() as recorder:
        with pytest.raises(StoppedError):
            rig.play(_long_sine(seconds=5.0))
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    x = recorder.signal()[1]
    assert np.abs(x).max() < 1e-4, "the drive reached the outputs after the stop"


@pytest.mark.slow
@pytest.mark.parametrize("delay_ms", [0, 5, 15, 50])
def test_a_stop_early_in_a_play_reaches_zero_within_one_period_plus_latency(rig, delay_ms):
    """The done-when of the second hardware pass: stops 0-50 ms into a 5 s play, measured by a second client."""
    import threading

    from vibrofocus.rigs import StoppedError

    stopped = {}

    def stop_later():
        time.sleep(delay_ms / 1e3)
        stopped["t"] = recorder.now()
        rig.stop()

    # The clock starts when the play is under way (its conversion for the device begins):
    # a stop before play() is called is an old stop, which does not end a new play.
    real = rig._to_device
    thread = threading.Thread(target=stop_later)

    def to_device(drive, n_tail):
        thread.start()
        return real(drive, n_tail)

    rig._to_device = to_device
    with _LoopbackRecorder() as recorder:
        t0 = time.monotonic()
        with pytest.raises(StoppedError):
            rig.play(_long_sine(seconds=5.0))
        elapsed = time.monotonic() - t0
        thread.join()
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    times, x = recorder.signal()
    loud = np.flatnonzero(np.abs(x).max(axis=1) > 1e-4)
    # One period plus the stream's output latency, plus the loopback's own period.
    allowed = JACK_PERIOD / JACK_RATE + rig.output_latency_s + JACK_PERIOD / JACK_RATE
    last = times[loud[-1]] - stopped["t"] if loud.size else 0.0
    print(f"stop {delay_ms} ms in: last output {1e3 * last:.0f} ms after the stop (allowed {1e3 * allowed:.0f} ms), "
          f"play returned after {elapsed:.2f} s")
    assert elapsed < 1.0
    assert last < allowed


def test_every_take_of_a_recording_counts_against_the_energy_budget(rig):
    """Retries after an xrun play the drive again: each is admitted (no 1 s window over the limit)."""
    admitted = []
    real = rig.budget.admit

    def admit(drive, start_s):
        admitted.append(float(np.sqrt(np.mean(drive**2))))
        return real(drive, start_s)

    rig.budget.admit = admit
    patch, calls = _with_status(rig, lambda n: 2 if n < 3 else 0)  # two xruns, then a good take
    with patch:
        rig.play_and_record(pulse_drive(), tail_s=0.0)
    assert len(calls) == 3
    assert len(admitted) == 3


def test_devices_check_tone_plays_one_percent_of_full_scale(jack_server, tmp_path):
    """The volts_full_scale measurement: a 100 Hz sine at 1 % of digital full scale, measured by a second client."""
    import json
    import subprocess
    import sys

    cfg = tmp_path / "lab.json"
    cfg.write_text(json.dumps(jack_config()))
    # A tone the stream reports samples lost for is discarded and the command says "retry"
    # (refusing is tested in test_stream_xrun_discards_the_recording); the JACK dummy driver
    # beside a loaded test run can lose a period, so a lost take is taken again, as a user
    # would, with a fresh recorder. Every check below is on the one take that succeeded.
    for _take in range(3):
        with _LoopbackRecorder(channels=(1, 2)) as recorder:
            r = subprocess.run([sys.executable, "-m", "vibrofocus", "devices", "--check", str(cfg), "--tone",
                                "--tone-s", "1", "--json"], capture_output=True, text=True, timeout=60)
            time.sleep(3 * JACK_PERIOD / JACK_RATE)
        if r.returncode == 0 or "samples were lost" not in r.stderr:
            break
    assert r.returncode == 0, r.stderr
    tone = json.loads(r.stdout)["tone"]
    assert tone["output_channel"] == 1 and tone["frequency_hz"] == 100.0
    np.testing.assert_allclose(tone["expected_rms_v"], 0.01 * VFS_OUT / np.sqrt(2), rtol=1e-9)
    assert 0 < tone["stream_output_latency_s"] < 1.0
    x = recorder.signal()[1].astype(float)
    np.testing.assert_allclose(np.abs(x[:, 0]).max(), 0.01, rtol=0.02)  # digital peak on output 1
    assert np.abs(x[:, 1]).max() < 1e-6  # nothing on the other actuators
    loud = x[np.abs(x[:, 0]) > 0.005, 0]
    assert 0.9 < len(loud) / JACK_RATE / 0.5 < 1.6  # about half the samples of 1 s of sine are above half its peak


def test_volts_full_scale_is_required_and_the_error_says_how_to_measure_it():
    from vibrofocus.errors import ValidationError
    from vibrofocus.rigs import parse_rig_config

    cfg = jack_config()
    del cfg["volts_full_scale"]
    with pytest.raises(ValidationError, match=r"volts_full_scale: required.*devices --check FILE --tone"):
        parse_rig_config(cfg)


@pytest.mark.parametrize("rig_name, default_name, same_index, risk", [
    ("MOTU Pro Audio", "Out 1-2 (MOTU Pro Audio)", False, "same"),
    ("Focusrite USB ASIO", "Speakers (Focusrite USB Audio)", False, "same"),
    ("MOTU Pro Audio", "default", False, "routing"),
    ("MOTU Pro Audio", "pulse", False, "routing"),
    ("MOTU Pro Audio", "Headphones (Realtek High Definition Audio)", False, None),
    ("loopback", "loopback", True, "same"),
])
def test_the_page_beeps_default_output_is_checked_against_the_actuator_interface(rig_name, default_name,
                                                                                  same_index, risk):
    from vibrofocus.rigs.audio import default_output_risk

    assert default_output_risk(rig_name, default_name, same_index=same_index) == risk


def test_the_cue_plays_at_the_devices_own_rate(jack_server):
    """A JACK server runs at one rate (48 kHz here): a cue fixed at 44.1 kHz could not open on it."""
    from vibrofocus.rigs.cue import CUE_PEAK, CueTone

    cue = CueTone("loopback")  # no rig: only the rate is under test here
    assert cue.fs == JACK_RATE
    with _LoopbackRecorder(channels=(1,)) as recorder:
        cue()
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    x = recorder.signal()[1][:, 0].astype(float)
    np.testing.assert_allclose(np.abs(x).max(), CUE_PEAK, rtol=0.02)


_DYING_SERVER_SCRIPT = """
import json, os, signal, sys, threading, time
import numpy as np
from vibrofocus.rigs import DeviceError, make_rig
config = json.loads(sys.argv[1])
n = int(3.0 * config["fs"])
drive = np.tile(2.0 * np.sin(2 * np.pi * 200 * np.arange(n) / config["fs"]), (4, 1))
with make_rig("audio", config=config) as rig:
    # SIGTERM: the server goes away mid-play but leaves JACK's server registry clean (a
    # SIGKILLed server's entry stays, and JACK refuses new servers once the registry is full).
    threading.Timer(0.5, os.kill, args=(int(sys.argv[2]), signal.SIGTERM)).start()
    t0 = time.monotonic()
    try:
        rig.play(drive)
        outcome = "played to its end"
    except DeviceError as exc:
        outcome = "DeviceError: " + str(exc)
    print(json.dumps({"outcome": outcome, "elapsed_s": time.monotonic() - t0}), flush=True)
"""


@pytest.mark.slow
def test_a_jack_server_that_dies_mid_play_gives_a_device_error_not_a_hang(jack_server, tmp_path):
    """The server stops 0.5 s into a 3 s play: the play ends with DeviceError within its deadline.

    In a process of its own (with a JACK server of its own): PortAudio cannot be shut down
    cleanly in a process whose JACK server died.
    """
    import json
    import os
    import subprocess
    import sys

    from .conftest import end_private_jackd, start_private_jackd

    name = f"vibrofocus-dying-{os.getpid()}"
    proc = start_private_jackd(name)
    try:
        env = {**os.environ, "JACK_DEFAULT_SERVER": name, "JACK_NO_START_SERVER": "1"}
        run = subprocess.run([sys.executable, "-c", _DYING_SERVER_SCRIPT, json.dumps(jack_config()), str(proc.pid)],
                             capture_output=True, text=True, timeout=60, env=env)
    finally:
        end_private_jackd(proc, name)
    assert run.returncode == 0, run.stderr[-1500:]  # it exits by itself: PortAudio is not terminated at exit
    result = json.loads(run.stdout.strip().splitlines()[-1])
    print(f"the play ended {result['elapsed_s']:.1f} s after it began: {result['outcome'][:120]}")
    assert result["outcome"].startswith("DeviceError")
    assert result["elapsed_s"] < 0.5 + 2.0 + 1.5  # the server's end, no callback for STALL_S, slack


@pytest.mark.parametrize("device_name, hostapi", [("default", "JACK Audio Connection Kit"),
                                                  ("pipewire", "ALSA"), ("Speakers (MOTU)", "MME"),
                                                  ("sysdefault:CARD=MOTU", "ALSA")])
def test_a_routed_device_without_loopback_plays_stimuli_but_refuses_recordings(jack_server, device_name, hostapi):
    """The loopback rule is a recording's: it keys on the device too, and it does not lock out play-only rigs."""
    with make_rig("audio", config={**jack_config(loopback_output=None, loopback_input=None),
                                   "latency_samples": JACK_PERIOD}) as rig:
        rig.device_name, rig.hostapi_name = device_name, hostapi  # as PortAudio would name such a device
        rig.play(pulse_drive())
        with pytest.raises(DeviceError, match="does not keep one round-trip latency"):
            rig.play_and_record(pulse_drive())


def test_a_callback_error_is_named_in_the_devices_error(rig):
    """The stream ends early when its callback raises: the error says why, with the exception chained."""
    bad_block = np.zeros((4800, 2), np.float32)  # two columns for five output channels: the callback fails
    with pytest.raises(DeviceError, match="the audio callback failed while playing: ValueError") as err:
        rig._run_stream(bad_block, record=False, what="playing")
    assert isinstance(err.value.__cause__, ValueError)


def test_jacks_system_ports_keep_one_round_trip_and_record_without_a_loopback(jack_server):
    """JACK is steady whatever its device is called: only system-mix devices need the loopback."""
    with make_rig("audio", config={**jack_config(loopback_output=None, loopback_input=None),
                                   "latency_samples": JACK_PERIOD}) as rig:
        rig.device_name = "system"  # as PortAudio names JACK's hardware ports
        assert not rig.unsteady_latency
        assert rig.play_and_record(pulse_drive(), tail_s=0.0).shape == (1, 2000)


def test_the_stream_opens_once_and_plays_run_in_it(rig):
    """No stream is opened per play: every play and recording is scheduled into the running one."""
    import sounddevice as sd

    with mock.patch.object(sd, "Stream", wraps=sd.Stream) as opened, \
            mock.patch.object(sd, "OutputStream", wraps=sd.OutputStream) as opened_out:
        for _ in range(3):
            rig.play(pulse_drive(n=500))
        rig.play_and_record(pulse_drive(), tail_s=0.0)
    opened.assert_not_called()
    opened_out.assert_not_called()
    assert rig._stream.stream.active


def test_the_budget_places_back_to_back_plays_at_their_output_times(rig):
    """Each play is admitted at its first frame's time at the outputs (the stream's frame axis)."""
    admitted = []
    real = rig.budget.admit

    def admit(drive, start_s):
        admitted.append(start_s)
        return real(drive, start_s)

    rig.budget.admit = admit
    onsets = [rig.play(pulse_drive(n=1000)) for _ in range(3)]
    period = JACK_PERIOD / JACK_RATE
    for start_s, onset in zip(admitted, onsets):
        # Placed at its onset's time at the outputs (the old rig: where it was admitted, 0.3-1 s
        # before), or earlier where it reached the callback late (then the budget ends it as
        # much later: delay_last); the host's time of a callback jitters by milliseconds.
        assert -0.01 <= onset.output_host_s - start_s <= 2 * period + 0.01
    # Each starts at a callback's buffer boundary (JACK's DAC times jitter by a few ms around the
    # frames). PortAudio's JACK host hands a cycle on in pieces (1024 frames of 4096 here), so a
    # play may start at any piece of a cycle, not only at the cycle's start.
    frames = rig._stream.last[2]
    assert JACK_PERIOD % frames == 0, frames
    buffers = [(o.device_s - onsets[0].device_s) * JACK_RATE / frames for o in onsets]
    assert buffers == sorted(buffers)
    np.testing.assert_allclose(buffers, np.round(buffers), atol=0.005 * JACK_RATE / frames)


def test_a_stop_between_buffers_leaves_the_next_buffer_silent(rig):
    """rig.stop() returns once the callback has written a buffer of silence after it."""
    import threading

    with _LoopbackRecorder(channels=(1,)) as recorder:
        thread = threading.Thread(target=lambda: (time.sleep(0.4), rig.stop()))
        thread.start()
        from vibrofocus.rigs import StoppedError

        with pytest.raises(StoppedError):
            rig.play(_long_sine(seconds=3.0))
        stopped_at = recorder.now()
        thread.join()
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    times, x = recorder.signal()
    loud = np.flatnonzero(np.abs(x[:, 0]) > 1e-4)
    # Written before the stop returned, plus the loopback's own period: nothing later.
    assert loud.size and times[loud[-1]] <= stopped_at + 2 * JACK_PERIOD / JACK_RATE


def test_an_xrun_in_a_play_is_flagged_on_its_onset(rig):
    """A lost buffer during a play: XrunError, carrying the play's onset with xrun set."""
    import sounddevice as sd

    from vibrofocus.rigs import XrunError

    stream = rig._stream
    real = stream._callback

    def losing(indata, outdata, frames, time_info, status):
        # The dummy driver cannot lose samples on demand: the flag PortAudio would raise
        # (paOutputUnderflow) in the buffers after the play's first.
        playing = stream.job is not None and stream.job.pos > 0
        return real(indata, outdata, frames, time_info, sd.CallbackFlags(4) if playing else status)

    with mock.patch.object(stream, "_callback", losing):
        with pytest.raises(XrunError, match="output underflow while playing") as err:
            rig.play(pulse_drive(n=20_000))
    assert err.value.onset is not None and err.value.onset.xrun
    assert err.value.onset.clock == "portaudio_dac"
    assert not rig.play(pulse_drive()).xrun  # the next play, with no loss, is not flagged


def test_closing_waits_out_the_latency_round_of_its_abort_before_unregistering(jack_server):
    """The rig's close lets the server's latency round after its abort pass before unregistering its ports.

    Aborting the stream disconnects its ports; at the next cycle the server has every client
    recompute its port latencies in libjack's notification thread, which walks the
    client's port list unguarded against a port being unregistered (jackaudio/jack2#216).
    An observer client sees the server's events in the order and at the time it sends
    them: the rig's first port goes at least two periods after its last disconnection.
    """
    import threading

    import jack

    events: list[tuple] = []
    lock = threading.Lock()
    observer = jack.Client("close-observer", no_start_server=True)

    @observer.set_port_connect_callback
    def connected(a, b, connect):
        with lock:
            events.append(("connect", connect, a.name, b.name, time.monotonic()))

    @observer.set_port_registration_callback(only_available=False)
    def registered(port, register):
        with lock:
            events.append(("register", register, port.name if port is not None else None, time.monotonic()))

    observer.activate()
    try:
        rig = make_rig("audio", config=jack_config())
        try:
            rig.play(pulse_drive())
            own = set(rig._own_ports.values())
            time.sleep(4 * JACK_PERIOD / JACK_RATE)  # the rounds of the opening are over
            with lock:
                events.clear()
        finally:
            rig.close()
        time.sleep(2 * JACK_PERIOD / JACK_RATE)
    finally:
        observer.deactivate()
        observer.close()
    with lock:
        seen = list(events)
    disconnected = [e[-1] for e in seen if e[0] == "connect" and not e[1] and (e[2] in own or e[3] in own)]
    unregistered = [e[-1] for e in seen if e[0] == "register" and not e[1]]
    assert disconnected and unregistered, seen
    assert min(unregistered) - max(disconnected) >= 2 * JACK_PERIOD / JACK_RATE, seen
