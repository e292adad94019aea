"""``/stop`` is never behind a queued tap, and a tap that waited too long is dropped.

The rig here is the simulated forearm with a hook in its play: a play blocks until the
rig is stopped (or the test lets it go), so which play ran, which was cut and which never
began is known exactly, with no sleep race.
"""

from __future__ import annotations

import socket
import threading
import time

import pytest

pytest.importorskip("pythonosc")
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder  # noqa: E402
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.osc_message_builder import OscMessageBuilder  # noqa: E402

from vibrofocus.realtime import OscTapServer, TapDesigner  # noqa: E402
from vibrofocus.rendering import TransferMatrix  # noqa: E402
from vibrofocus.rigs.simulated import SimulatedForearm  # noqa: E402

#: A bound on every wait of the test for the server (a hang fails the test, never a race).
WAIT_S = 30.0


class HeldRig(SimulatedForearm):
    """A simulated rig whose first ``hold`` plays last until it is stopped or let go."""

    def __init__(self, hold: int = 1, **kwargs):
        super().__init__(**kwargs)
        self.hold = hold
        self.started = threading.Event()  # a held play has begun
        self.cut = threading.Event()  # stop() came
        self.let_go = threading.Event()  # the test ends a held play
        self.events: list[str] = []

    def _play(self, drive):
        n = len([e for e in self.events if e == "begin"])
        self.events.append("begin")
        if n < self.hold:
            self.started.set()
            # Held until a stop or the test's word; never longer than WAIT_S (then the test fails).
            deadline = time.monotonic() + WAIT_S
            while not (self.cut.is_set() or self.let_go.is_set()) and time.monotonic() < deadline:
                self.cut.wait(0.005)
            self.events.append("cut" if self.cut.is_set() else "let go" if self.let_go.is_set() else "ran out")
        else:
            self.events.append("played")
        return super()._play(drive)

    def _zero_outputs(self):
        # Rig.stop() is final: a stop is seen here, as the stop epoch moving (Rig.stop
        # moves it before it zeroes), unlike the zero write after every play.
        if self._stop_epoch != getattr(self, "_epoch_seen", 0):
            self._epoch_seen = self._stop_epoch
            self.cut.set()
            self.events.append("stop")
        super()._zero_outputs()


@pytest.fixture(scope="module")
def designer():
    arm = SimulatedForearm(seed=3)
    tm = TransferMatrix.from_model(arm, arm.layout, arm.fs)
    d = TapDesigner(tm, arm, method="inverse", limit_v=arm.limits.peak_v, grid_pitch_m=5e-3)
    d.prepare_grid()
    return d


def _message(address, *args):
    builder = OscMessageBuilder(address=address)
    for arg in args:
        builder.add_arg(arg)
    return builder.build()


def _wait(condition, what):
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"the server never got to: {what}"
        time.sleep(0.005)


def _serve(rig, designer, **kwargs):
    designer.set_method("inverse")
    server = OscTapServer(rig, designer, port=0, **kwargs)
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("who", server.serve()), daemon=True)
    thread.start()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(WAIT_S)
    client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return server, thread, result, client


class Replies:
    """Every reply to one client, read as it comes (a burst of a thousand must not overflow the socket)."""

    def __init__(self, client: socket.socket):
        self.client, self.messages, self.done = client, [], threading.Event()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        try:
            while True:
                message = OscMessage(self.client.recv(65536))
                self.messages.append(message)
                if message.address == "/stopped":
                    return
        except OSError:
            return
        finally:
            self.done.set()


@pytest.mark.parametrize("how", ["30 datagrams", "one bundle of 1000"])
def test_stop_cuts_the_play_under_way_and_drops_every_queued_tap(designer, how):
    rig = HeldRig(seed=3)
    server, thread, result, client = _serve(rig, designer)
    replies = Replies(client)
    try:
        if how == "30 datagrams":
            for i in range(30):
                client.sendto(_message("/tap", 1 + i % 9).dgram, server.address)
            n_taps = 30
        else:
            bundle = OscBundleBuilder(IMMEDIATELY)
            for i in range(1000):
                bundle.add_content(_message("/tap", 1 + i % 9))
            client.sendto(bundle.build().dgram, server.address)
            n_taps = 1000
        assert rig.started.wait(WAIT_S)
        n_queued = min(n_taps - 1, server.max_queued)
        _wait(lambda: server.n_waiting == n_queued, "every tap received")
        client.sendto(_message("/stop").dgram, server.address)
        thread.join(WAIT_S)
        assert not thread.is_alive()
        assert replies.done.wait(WAIT_S)
    finally:
        server.stop()
        server.close()
        client.close()
    # The first tap was cut by the stop; no other play began, before or after it.
    assert [e for e in rig.events if e != "stop"] == ["begin", "cut"], rig.events
    assert rig.events.index("stop") < rig.events.index("cut")
    assert (rig.outputs_v == 0).all()
    assert result["who"].startswith("/stop from 127.0.0.1:")
    # Every other tap was answered /error: dropped by the stop, or refused while the queue was full.
    assert server.n_errors == n_taps - 1
    errors = [r.params[0] for r in replies.messages if r.address == "/error"]
    assert sum(e.startswith("stopped: /tap location") for e in errors) == n_queued, errors[:3]
    assert sum(e.startswith("busy: ") for e in errors) == n_taps - 1 - n_queued
    assert replies.messages[-1].address == "/stopped"


def test_a_tap_that_waited_too_long_is_dropped_as_stale_and_a_fresh_one_plays(designer):
    now = [0.0]
    rig = HeldRig(seed=3)
    server, thread, result, client = _serve(rig, designer, clock=lambda: now[0], max_wait_s=0.5)
    try:
        for location in (1, 2, 3):
            client.sendto(_message("/tap", location).dgram, server.address)
        rig.started.wait(WAIT_S)
        _wait(lambda: server.n_waiting == 2, "taps 2 and 3 queued")
        now[0] = 0.501  # taps 2 and 3 have now waited past the bound
        rig.let_go.set()
        replies = [OscMessage(client.recv(65536)) for _ in range(3)]
        assert replies[0].address == "/played" and replies[0].params[:1] == [1]
        for reply, location in zip(replies[1:], (2, 3)):
            assert reply.address == "/error"
            assert reply.params[0].startswith(f"stale: /tap location {location} waited 501 ms"), reply.params
        client.sendto(_message("/tap", 4).dgram, server.address)  # received at 0.501: fresh
        reply = OscMessage(client.recv(65536))
        assert reply.address == "/played" and reply.params[:1] == [4]
        assert [r.target for r in server.records] == ["location 1", "location 4"]
        assert rig.events.count("begin") == 2
    finally:
        server.stop()
        thread.join(WAIT_S)
        server.close()
        client.close()


def test_a_method_change_applies_to_the_taps_queued_after_it_only(designer):
    rig = HeldRig(seed=3)
    server, thread, _, client = _serve(rig, designer)
    try:
        client.sendto(_message("/tap", 1).dgram, server.address)
        rig.started.wait(WAIT_S)
        for message in (_message("/tap", 2), _message("/method", "funneling"), _message("/tap", 3)):
            client.sendto(message.dgram, server.address)
        _wait(lambda: server.n_waiting == 3, "three messages queued")
        rig.let_go.set()
        addresses = [OscMessage(client.recv(65536)).address for _ in range(4)]
        assert addresses == ["/played", "/played", "/method", "/played"]
        assert [(r.target, r.method) for r in server.records] == [
            ("location 1", "inverse"), ("location 2", "inverse"), ("location 3", "funneling")]
    finally:
        server.stop()
        thread.join(WAIT_S)
        server.close()
        client.close()
