"""Other programs on the audio rig's JACK ports, against a real JACK server (dummy driver).

The other program is a real second JACK client in a process of its own (a sine at half
of digital full scale, as a media player would send), connected to the rig's playback
ports before or during a play. What reaches the actuators is measured as in
test_audio.py: by a recording client on JACK's loopback ports.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from vibrofocus.rigs import DeviceError, SharedOutputError, make_rig
from vibrofocus.errors import SafetyError

from .test_audio import FS, GAIN, JACK_PERIOD, JACK_RATE, VFS_OUT, _LoopbackRecorder, _long_sine, jack_config

pytestmark = pytest.mark.jack

#: The other program's level, fraction of digital full scale: with the rig's drive at its
#: 10 V limit (half of full scale here), JACK's sum reaches full scale, 20 V at the actuator.
OTHER_LEVEL = 0.5
OTHER_NAME = "media-player"

# A second JACK client in its own process: a 230 Hz sine at OTHER_LEVEL on one output port,
# connected where stdin says ("connect PORT"), until stdin closes.
_OTHER_PROGRAM = """
import sys
import numpy as np
import jack

client = jack.Client(sys.argv[1], use_exact_name=True, no_start_server=True)
out = client.outports.register("out_1")
level, rate, phase = float(sys.argv[2]), client.samplerate, [0]


@client.set_process_callback
def process(frames):
    n = np.arange(phase[0], phase[0] + frames)
    out.get_array()[:] = level * np.sin(2 * np.pi * 230.0 * n / rate)
    phase[0] += frames


client.activate()
print("ready", flush=True)
for line in sys.stdin:
    command, _, port = line.strip().partition(" ")
    if command == "connect":
        client.connect(out, port)
        print("connected", flush=True)
client.deactivate()
client.close()
"""


class _OtherProgram:
    """The other program: a JACK client of its own process, connected on request."""

    def __init__(self, name: str = OTHER_NAME, level: float = OTHER_LEVEL):
        self.name = name
        self.proc = subprocess.Popen([sys.executable, "-c", _OTHER_PROGRAM, name, str(level)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "ready"

    def connect(self, port: str) -> None:
        self.proc.stdin.write(f"connect {port}\n")
        self.proc.stdin.flush()
        assert self.proc.stdout.readline().strip() == "connected"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _connections(port: str) -> list[str]:
    import jack

    client = jack.Client("test-lister", no_start_server=True)
    try:
        return [p.name for p in client.get_all_connections(port)]
    finally:
        client.close()


def _tap_at_the_limit(seconds: float = 0.1) -> np.ndarray:
    # The drive: 0.1 s at the rig's 10 V peak limit on actuator 1 (half of full scale here).
    n = int(seconds * FS)
    drive = np.zeros((4, n))
    drive[0] = 10.0 * np.sin(2 * np.pi * 200 * np.arange(n) / FS)
    return drive


@pytest.mark.parametrize("job", ["play", "play_and_record"])
def test_another_client_on_an_actuator_port_is_refused_before_the_play_starts(jack_server, job):
    """The issue's reproduction: the old rig played, and JACK's sum reached 20 V at the actuator (limit 10 V)."""
    with make_rig("audio", config=jack_config()) as rig, _OtherProgram() as other, \
            _LoopbackRecorder(channels=(1,)) as recorder:
        other.connect("loopback:playback_1")
        time.sleep(2 * JACK_PERIOD / JACK_RATE)
        with pytest.raises(SharedOutputError, match=rf"JACK client '{OTHER_NAME}' \({OTHER_NAME}:out_1 into "
                           r"loopback:playback_1, output 1, actuator 1\).*refused before it started and the rig "
                           "disconnected it") as refused:
            getattr(rig, job)(_tap_at_the_limit())
        assert isinstance(refused.value, SafetyError) and isinstance(refused.value, DeviceError)
        # The other program no longer reaches actuator 1; the rig's running stream does.
        assert _connections("loopback:playback_1") == [rig._own_ports[1]]
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
        refused_at = len(recorder.signal()[1])
        # With the other program cut off, the next play goes through, alone on the output.
        rig.play(_tap_at_the_limit())
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    x = recorder.signal()[1][:, 0].astype(float)
    volts_at_actuator = np.abs(x).max() * VFS_OUT * GAIN
    print(f"{job}: the most at actuator 1 was {volts_at_actuator:.2f} V (limit 10 V)")
    # Before the refusal: the other program alone (10 V); never the sum (20 V on the old rig).
    np.testing.assert_allclose(np.abs(x[:refused_at]).max(), OTHER_LEVEL, rtol=2e-3)
    assert volts_at_actuator <= 10.0 * (1 + 2e-3)
    # The rig's own play afterwards reaches its limit, the other program's sine is gone.
    np.testing.assert_allclose(np.abs(x[refused_at:]).max(), 10.0 / (VFS_OUT * GAIN), rtol=2e-3)
    assert np.abs(x[-JACK_PERIOD:]).max() < 1e-6


def test_a_client_that_connects_mid_play_stops_it_at_zero(jack_server):
    """A second client connects to actuator 2's port 0.5 s into a 3 s play: both are silent soon after."""
    connected = {}
    with make_rig("audio", config=jack_config()) as rig, _OtherProgram() as other, \
            _LoopbackRecorder() as recorder:

        def connect_later():
            time.sleep(0.5)
            connected["t"] = recorder.now()
            other.connect("loopback:playback_2")

        thread = threading.Thread(target=connect_later)
        t0 = time.monotonic()
        thread.start()
        with pytest.raises(SharedOutputError, match=rf"'{OTHER_NAME}' \({OTHER_NAME}:out_1 into loopback:playback_2, "
                           r"output 2, actuator 2\) connected while the rig was playing.*stopped and the rig's "
                           "outputs are at zero and the rig disconnected it"):
            rig.play(_long_sine(seconds=3.0))
        elapsed = time.monotonic() - t0
        thread.join()
        assert _connections("loopback:playback_2") == [rig._own_ports[2]]
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    times, x = recorder.signal()
    loud = np.flatnonzero(np.abs(x).max(axis=1) > 1e-4)
    last = times[loud[-1]] - connected["t"]
    # The rig looks every POLL_S; then its stream's buffered output and one period of the
    # loopback itself; the other program connects within a few ms of being asked.
    from vibrofocus.rigs.audio import POLL_S

    allowed = POLL_S + rig.output_latency_s + 2 * JACK_PERIOD / JACK_RATE + 0.05
    # What reached actuator 2 before the rig saw the connection: the sum, for up to a poll
    # and a period (what software cannot recall: docs/hardware.md).
    summed = np.abs(x[:, 1]).max()
    print(f"the play ended {elapsed:.2f} s after it began; last output {1e3 * last:.0f} ms after the other client "
          f"was asked to connect (allowed {1e3 * allowed:.0f} ms); actuator 2 peaked at {summed * VFS_OUT * GAIN:.1f} V")
    assert elapsed < 2.5  # the 3 s play did not run to its end
    assert last < allowed


def test_a_client_on_a_port_the_rig_does_not_use_is_left_alone(jack_server):
    """Output 6 is neither an actuator nor the loopback: the rig plays and leaves that connection."""
    with make_rig("audio", config=jack_config()) as rig, _OtherProgram() as other:
        other.connect("loopback:playback_6")
        rig.play(_tap_at_the_limit())
        rig.play_and_record(_tap_at_the_limit(), tail_s=0.0)
        assert _connections("loopback:playback_6") == [f"{OTHER_NAME}:out_1"]


def test_the_loopback_output_is_watched_too(jack_server):
    with make_rig("audio", config=jack_config()) as rig, _OtherProgram() as other:
        other.connect("loopback:playback_5")
        with pytest.raises(SharedOutputError, match=r"output 5, the loopback output"):
            rig.play_and_record(_tap_at_the_limit(), tail_s=0.0)


@pytest.mark.slow
def test_devices_check_names_another_client_on_the_outputs(jack_server, tmp_path):
    import json

    cfg = tmp_path / "lab.json"
    cfg.write_text(json.dumps(jack_config()))
    command = [sys.executable, "-m", "vibrofocus", "devices", "--check", str(cfg), "--json"]
    r = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    found = json.loads(r.stdout)["found"]
    assert any(line.startswith("other programs on the outputs: checked (JACK connections)") for line in found)
    with _OtherProgram() as other:
        other.connect("loopback:playback_3")
        r = subprocess.run(command, capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stderr.count("error:") == 1, r.stderr
        assert f"JACK client '{OTHER_NAME}' ({OTHER_NAME}:out_1 into loopback:playback_3, output 3, actuator 3)" in r.stderr
        assert "the rig would refuse to play and disconnect it" in r.stderr
        assert _connections("loopback:playback_3") == [f"{OTHER_NAME}:out_1"]  # --check disconnects nothing


@pytest.mark.parametrize("hostapi, device, mixes", [
    ("MME", "Speakers (Focusrite USB Audio)", True),
    ("Windows WASAPI", "Out 1-2 (MOTU Pro Audio)", True),
    ("ASIO", "Focusrite USB ASIO", False),
    ("Core Audio", "MOTU UltraLite-mk5", True),
    ("ALSA", "Scarlett 2i2 USB: Audio (hw:1,0)", False),
    ("ALSA", "pipewire", True),
])
def test_devices_check_says_where_other_programs_cannot_be_seen(hostapi, device, mixes):
    from vibrofocus.rigs.audio import other_programs_report

    line = other_programs_report(hostapi, device)
    assert line.startswith(f"other programs on the outputs: NOT checked: {hostapi} gives no way to see")
    assert ("mixes other programs' sound into the outputs" in line) is mixes
    assert "limiter or mute on the amplifier's input" in line
    assert "NOT" not in other_programs_report("JACK Audio Connection Kit", "system")


def test_the_guard_refuses_when_it_cannot_tell_the_streams_own_ports(jack_server):
    """Ports registered by two clients while the stream opened: which feed is the rig's own is unknown."""
    import jack

    from vibrofocus.rigs.jack_guard import JackOutputGuard

    guard = JackOutputGuard("loopback", [1, 3])
    clients = []
    try:
        before = guard.output_ports()
        clients.append(jack.Client("stream-a", no_start_server=True))
        for n in (4, 5, 6):
            clients[0].outports.register(f"out_{n}")
        assert guard.own_ports(before, 3) == {1: "stream-a:out_4", 3: "stream-a:out_6"}
        clients.append(jack.Client("stream-b", no_start_server=True))
        for n in (0, 1, 2):
            clients[1].outports.register(f"out_{n}")
        with pytest.raises(DeviceError, match="could not tell its own stream's JACK ports.*nothing was played"):
            guard.own_ports(before, 3)
    finally:
        for client in clients:
            client.close()
        guard.close()
    with pytest.raises(DeviceError, match="the rig is closed"):
        guard.feeds()


def test_a_connection_the_rig_could_not_remove_says_to_switch_the_amplifier_off():
    from vibrofocus.rigs.jack_guard import ForeignFeed, shared_output_message

    feeds = [ForeignFeed("firefox:output_FL", "system:playback_1", 1),
             ForeignFeed("ardour:master/out_1", "system:playback_2", 2)]
    message = shared_output_message(feeds, {1: "actuator 1", 2: "actuator 2"}, when="during",
                                     failed=["firefox:output_FL -> system:playback_1: refused"])
    assert message.startswith("another program feeds the rig's outputs: JACK clients 'ardour', 'firefox' "
                              "(firefox:output_FL into system:playback_1, output 1, actuator 1; ardour:master/out_1 "
                              "into system:playback_2, output 2, actuator 2) connected while the rig was playing")
    assert message.endswith("but the rig could NOT disconnect it (firefox:output_FL -> system:playback_1: refused): "
                            "switch the amplifier off, then close that program")
    assert "\n" not in message
