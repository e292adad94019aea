"""``serve-osc`` on the audio rig against a real JACK server (dummy driver), a second JACK
client recording what the actuator outputs get: ``/stop`` after 30 queued taps, or after one
bundle of 1000 taps, brings them to zero within 100 ms plus the interface's latency, and the
datagram with a negative bundle element size is answered ``/error`` while the next tap plays."""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time

import numpy as np
import pytest

pytest.importorskip("pythonosc")
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder  # noqa: E402
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.osc_message_builder import OscMessageBuilder  # noqa: E402

from tests.rigs.conftest import jack_server  # noqa: E402,F401 - the fixture
from tests.rigs.test_audio import FS, JACK_PERIOD, JACK_RATE, _LoopbackRecorder, jack_config  # noqa: E402
from vibrofocus.realtime import OscTapServer, TapDesigner  # noqa: E402
from vibrofocus.realtime.osc_framing import MAX_ELEMENTS  # noqa: E402
from vibrofocus.rendering import TransferMatrix  # noqa: E402
from vibrofocus.rigs import make_rig  # noqa: E402
from vibrofocus.rigs.simulated import SimulatedForearm  # noqa: E402


WAIT_S = 30.0
TAP5 = b"/tap\x00\x00\x00\x00,i\x00\x00" + struct.pack(">i", 5)
#: 36 bytes: a bundle whose one element's size is -4.
NEGATIVE = b"#bundle\x00" + b"\x00" * 7 + b"\x01" + struct.pack(">i", -4) + TAP5
LOUD = 1e-4  # digital level above the dummy driver's silence


def _message(address, *args):
    builder = OscMessageBuilder(address=address)
    for arg in args:
        builder.add_arg(arg)
    return builder.build()


@pytest.fixture
def served(jack_server):  # noqa: F811
    rig = make_rig("audio", config=jack_config())
    arm = SimulatedForearm(seed=3, fs=FS)
    designer = TapDesigner(TransferMatrix.from_model(arm, rig.layout, rig.fs), None, method="inverse",
                           limit_v=rig.limits.peak_v)
    with _serving(rig, designer) as (server, thread, result, client):
        yield rig, server, thread, result, client


@contextlib.contextmanager
def _serving(rig, designer):
    """A server on ``rig`` in a thread, and a client socket; everything closed at the end, the rig too."""
    server = OscTapServer(rig, designer, port=0)
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("who", server.serve()), daemon=True)
    thread.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(WAIT_S)
    try:
        yield server, thread, result, client
    finally:
        server.stop()
        thread.join(WAIT_S)
        server.close()
        client.close()
        rig.close()


@pytest.mark.parametrize("how", ["30 datagrams", "1000 in bundles of 16"])
def test_stop_after_queued_taps_reaches_zero_within_100_ms_plus_latency(served, how):
    rig, server, thread, result, client = served
    with _LoopbackRecorder() as recorder:
        if how == "30 datagrams":
            for i in range(30):
                client.sendto(_message("/tap", 1 + i % 9).dgram, server.address)
        else:
            for first in range(0, 1000, MAX_ELEMENTS):  # a datagram holds at most MAX_ELEMENTS messages
                bundle = OscBundleBuilder(IMMEDIATELY)
                for i in range(first, min(first + MAX_ELEMENTS, 1000)):
                    bundle.add_content(_message("/tap", 1 + i % 9))
                client.sendto(bundle.build().dgram, server.address)
        # The first tap reaches the outputs.
        deadline = time.monotonic() + WAIT_S
        while not any(np.abs(x).max() > LOUD for _, x in list(recorder.chunks)):
            assert time.monotonic() < deadline, "the first tap never reached the outputs"
            time.sleep(0.01)
        stopped_at = recorder.now()
        client.sendto(_message("/stop").dgram, server.address)
        thread.join(WAIT_S)
        assert not thread.is_alive()
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    times, x = recorder.signal()
    loud = np.flatnonzero(np.abs(x).max(axis=1) > LOUD)
    time_to_zero = times[loud[-1]] - stopped_at
    # The loopback itself delays what it records by one period.
    allowed = 0.100 + rig.output_latency_s + JACK_PERIOD / JACK_RATE
    print(f"{how}: time to zero {1e3 * time_to_zero:.0f} ms (allowed {1e3 * allowed:.0f} ms)")
    assert time_to_zero < allowed
    assert result["who"].startswith("/stop from 127.0.0.1:")
    assert server.records == []  # the one tap that began was cut: none played to its end


def test_the_negative_size_datagram_is_an_error_and_the_next_tap_plays(served):
    rig, server, thread, _, client = served
    client.sendto(NEGATIVE, server.address)
    reply = OscMessage(client.recv(65536))
    assert reply.address == "/error" and "not positive" in reply.params[0]
    with _LoopbackRecorder() as recorder:
        client.sendto(TAP5, server.address)
        reply = OscMessage(client.recv(65536))
        time.sleep(3 * JACK_PERIOD / JACK_RATE)
    assert reply.address == "/played" and reply.params[:1] == [5]
    assert np.abs(recorder.signal()[1]).max() > LOUD
    assert thread.is_alive()


@pytest.mark.slow
def test_taps_sent_faster_than_a_stream_opens_all_play(jack_server):  # noqa: F811
    """20 taps of 80 ms sent at 3 per second: every one played, none stale (the old rig opened a
    stream per tap, 0.3-0.5 s, and padded it by the latency and 4096 frames: they fell behind)."""
    from pythonosc.osc_message import OscMessage as Reply

    rig = make_rig("audio", config=jack_config())
    arm = SimulatedForearm(seed=3, fs=FS)
    designer = TapDesigner(TransferMatrix.from_model(arm, rig.layout, rig.fs, n_samples=800), None, method="inverse",
                           limit_v=rig.limits.peak_v)
    with _serving(rig, designer) as (server, _, _, client):
        for location in range(1, 10):
            designer.drives_at(location)  # designed ahead, as serve-osc does
        t0 = time.monotonic()
        for i in range(20):
            time.sleep(max(0.0, t0 + i / 3.0 - time.monotonic()))
            client.sendto(_message("/tap", 1 + i % 9).dgram, server.address)
        replies = [Reply(client.recv(65536)) for _ in range(20)]
    errors = [r.params[0] for r in replies if r.address != "/played"]
    waits = [1e3 * (r.played_s - r.receipt_s) for r in server.records]
    print(f"{len(server.records)} of 20 played; receipt to play() returned: median {np.median(waits):.0f} ms")
    # A lost period on a loaded machine is answered /error (XrunError); nothing else may be.
    assert all("samples were lost" in e for e in errors), errors
    assert len(server.records) >= 18
