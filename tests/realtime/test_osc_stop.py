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
from vibrofocus.realtime.osc_framing import MAX_ELEMENTS  # noqa: E402
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


@pytest.mark.parametrize("how", ["30 datagrams", "1000 in bundles of 16"])
def test_stop_cuts_the_play_under_way_and_drops_every_queued_tap(designer, how):
    rig = HeldRig(seed=3)
    # No tap goes stale while the test waits for them all to be read (a loaded machine is slow).
    server, thread, result, client = _serve(rig, designer, max_wait_s=WAIT_S)
    replies = Replies(client)
    try:
        if how == "30 datagrams":
            for i in range(30):
                client.sendto(_message("/tap", 1 + i % 9).dgram, server.address)
            n_taps = 30
        else:
            n_taps = 1000
            for first in range(0, n_taps, MAX_ELEMENTS):
                bundle = OscBundleBuilder(IMMEDIATELY)
                for i in range(first, min(first + MAX_ELEMENTS, n_taps)):
                    bundle.add_content(_message("/tap", 1 + i % 9))
                client.sendto(bundle.build().dgram, server.address)
        assert rig.started.wait(WAIT_S)
        n_queued = min(n_taps - 1, server.max_queued)
        # Every datagram handled (a /stop would act ahead of those still unread).
        _wait(lambda: server.n_waiting == n_queued and server.n_errors == n_taps - 1 - n_queued,
              "every tap received")
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


def _collect(client, until, bound_s=WAIT_S):
    """Replies to ``client`` until ``until(replies)`` holds; fails after ``bound_s`` (a reply never sent)."""
    replies = []
    deadline = time.monotonic() + bound_s
    while not until(replies):
        left = deadline - time.monotonic()
        assert left > 0, f"no more replies after {[(r.address, r.params[:1]) for r in replies][-5:]}"
        client.settimeout(left)
        try:
            replies.append(OscMessage(client.recv(65536)))
        except socket.timeout:
            continue
    return replies


def test_every_message_of_a_bundle_is_answered_those_after_its_stop_too(designer):
    rig = HeldRig(seed=3)
    server, thread, result, client = _serve(rig, designer)
    try:
        bundle = OscBundleBuilder(IMMEDIATELY)
        for message in (_message("/tap", 1), _message("/stop"), _message("/tap", 7), _message("/method", "funneling")):
            bundle.add_content(message)
        client.sendto(bundle.build().dgram, server.address)
        replies = _collect(client, lambda r: len(r) == 4)
        thread.join(WAIT_S)
        assert not thread.is_alive()
    finally:
        server.stop()
        server.close()
        client.close()
    answers = [(r.address, r.params[0] if r.params else None) for r in replies]
    expected = [("/error", "stopped: /tap location 7 was not played"),
                ("/error", "stopped: /method funneling was not played"), ("/stopped", None)]
    for answer in expected:
        assert answer in answers, answers
        answers.remove(answer)
    # Tap 1, queued before the stop, was dropped from the queue or cut in its play: an /error either way.
    assert [a for a, _ in answers] == ["/error"], answers
    assert "begin" not in rig.events[rig.events.index("stop"):] and (rig.outputs_v == 0).all()


@pytest.mark.parametrize("per_datagram", [1, MAX_ELEMENTS])
def test_a_stop_behind_datagrams_waiting_in_the_socket_acts_before_any_of_them(designer, per_datagram):
    """The datagrams are in the server's socket before it serves, the /stop last: it acts first."""
    rig = HeldRig(seed=3)
    designer.set_method("inverse")
    server = OscTapServer(rig, designer, port=0, max_wait_s=WAIT_S)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    n_datagrams = 40
    for k in range(n_datagrams):
        bundle = OscBundleBuilder(IMMEDIATELY)
        for i in range(per_datagram):
            bundle.add_content(_message("/tap", 1 + (k + i) % 9))
        client.sendto(bundle.build().dgram if per_datagram > 1 else _message("/tap", 1 + k % 9).dgram,
                      server.address)
    client.sendto(_message("/stop").dgram, server.address)
    n_taps = n_datagrams * per_datagram
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("who", server.serve()), daemon=True)
    thread.start()
    try:
        replies = _collect(client, lambda r: len(r) == n_taps + 1)
        thread.join(WAIT_S)
        assert not thread.is_alive()
    finally:
        server.stop()
        server.close()
        client.close()
    # No tap began: the stop came first, and every tap was answered as dropped by it.
    assert "begin" not in rig.events and rig.n_played == 0, rig.events
    assert replies[0].address == "/stopped"
    errors = [r.params[0] for r in replies[1:]]
    assert len(errors) == n_taps and all(e.startswith("stopped: /tap location") for e in errors), errors[:3]
    assert server.n_errors == n_taps and result["who"].startswith("/stop from 127.0.0.1:")


_FLOOD = """
import socket, sys, time
data = open(sys.argv[1], "rb").read()
port, until = int(sys.argv[2]), time.monotonic() + float(sys.argv[3])
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 16)  # its answers: dropped once full, never read
s.setblocking(False)
while time.monotonic() < until:
    try:
        s.sendto(data, ("127.0.0.1", port))
    except OSError:
        time.sleep(0.001)
"""


def test_a_stop_during_a_local_flood_of_big_bundles_acts_and_no_tap_plays_after_it(designer, tmp_path):
    """The issue's flood, bounded: 2.5 s of 2000-message /tap bundles from another process, /stop 0.5 s in."""
    import subprocess
    import sys

    rig = SimulatedForearm(seed=3)
    server, thread, result, client = _serve(rig, designer)
    bundle = OscBundleBuilder(IMMEDIATELY)
    for _ in range(2000):
        bundle.add_content(_message("/tap", 5))
    (tmp_path / "bundle.osc").write_bytes(bundle.build().dgram)
    (tmp_path / "flood.py").write_text(_FLOOD, encoding="utf-8")
    flood = subprocess.Popen([sys.executable, str(tmp_path / "flood.py"), str(tmp_path / "bundle.osc"),
                              str(server.address[1]), "2.5"])
    try:
        time.sleep(0.5)
        sent = time.monotonic()
        client.sendto(_message("/stop").dgram, server.address)
        replies = _collect(client, lambda r: bool(r) and r[-1].address == "/stopped", bound_s=5.0)
        stopped_after_s = time.monotonic() - sent
        thread.join(WAIT_S)
        assert not thread.is_alive()
    finally:
        flood.wait(30)
        server.stop()
        server.close()
        client.close()
    assert replies[-1].address == "/stopped"
    # The old server took 0.3-5 s here, playing the flood's taps meanwhile (tens after the stop).
    assert stopped_after_s < 1.0, stopped_after_s
    assert [r for r in server.records if r.onset_host_s > sent] == []


def test_a_tap_that_waited_in_the_socket_past_the_bound_is_stale_and_a_fresh_one_plays(designer):
    """The wait counts from the datagram's arrival in the kernel (Linux), not from its read."""
    import sys

    if not sys.platform.startswith("linux"):
        pytest.skip("the kernel's arrival stamp is read on Linux only")
    rig = SimulatedForearm(seed=3)
    designer.set_method("inverse")
    server = OscTapServer(rig, designer, port=0, max_wait_s=0.2)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.sendto(_message("/tap", 2).dgram, server.address)
    time.sleep(0.4)  # in the socket's buffer, unread: the server does not serve yet
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    try:
        (stale,) = _collect(client, lambda r: len(r) == 1)
        client.sendto(_message("/tap", 3).dgram, server.address)
        (fresh,) = _collect(client, lambda r: len(r) == 1)
    finally:
        server.stop()
        thread.join(WAIT_S)
        server.close()
        client.close()
    assert stale.address == "/error" and stale.params[0].startswith("stale: this datagram waited over the 200 ms")
    assert fresh.address == "/played" and fresh.params[:1] == [3]
    assert [r.target for r in server.records] == ["location 3"]
