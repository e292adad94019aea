"""``serve-osc`` over real UDP on localhost with a real python-osc client: taps play on the
simulated rig, malformed messages are answered ``/error`` and play nothing, ``/stop`` ends
the server with every output at zero."""

from __future__ import annotations

import math
import socket
import threading

import numpy as np
import pytest

pytest.importorskip("pythonosc")
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.udp_client import SimpleUDPClient  # noqa: E402

from vibrofocus.realtime import OscTapServer, TapDesigner  # noqa: E402
from vibrofocus.rendering import TransferMatrix  # noqa: E402

from ._designer import simulated_designer  # noqa: E402

REPLY_S = 30.0


@pytest.fixture(scope="module")
def rig_and_designer():
    rig, designer = simulated_designer()
    designer.prepare_grid()
    return rig, designer


@pytest.fixture
def running(rig_and_designer):
    """A server in a thread, and a client aimed at it; the server is stopped afterwards."""
    rig, designer = rig_and_designer
    designer.set_method("inverse")
    server = OscTapServer(rig, designer, port=0)
    result = {}
    thread = threading.Thread(target=lambda: result.setdefault("who", server.serve()), daemon=True)
    thread.start()
    client = SimpleUDPClient(*server.address)
    yield server, client, rig, thread, result
    server.stop()
    thread.join(10)
    server.close()
    client.close() if hasattr(client, "close") else None


def _reply(client: SimpleUDPClient) -> OscMessage:
    data = client.receive(REPLY_S)
    assert data, "no reply from the server"
    return OscMessage(data)


def _ask(client: SimpleUDPClient, address: str, args) -> OscMessage:
    client.send_message(address, args)
    return _reply(client)


def test_tap_and_tap_xy_play_within_the_limit(running):
    server, client, rig, _, _ = running
    before = rig.n_played
    reply = _ask(client, "/tap", 5)
    assert reply.address == "/played" and reply.params[:1] == [5]
    assert rig.n_played == before + 1
    expected = rig.check(server.designer.drives_at(5))
    np.testing.assert_array_equal(rig.last_drive, expected)
    reply = _ask(client, "/tap_xy", [3.5, -4.0])
    assert reply.address == "/played" and reply.params[:2] == [3.5, -4.0]
    assert rig.n_played == before + 2
    assert np.abs(rig.last_drive).max() <= rig.limits.peak_v + 1e-12
    # Integers are millimetres too.
    assert _ask(client, "/tap_xy", [-10, 10]).address == "/played"
    assert [r.target for r in server.records[-3:]] == ["location 5", "x 3.5 mm, y -4 mm", "x -10 mm, y 10 mm"]


MALFORMED = [
    ("/tap", [], "takes 1 or 2 arguments"),
    ("/tap", "5", "integer location"),
    ("/tap", 5.0, "integer location"),
    ("/tap", True, "integer location"),
    ("/tap", [5, 6, 7], "takes 1 or 2 arguments"),
    ("/tap", [5, "loud"], "the level is a number"),
    ("/tap", [5, math.nan], "the level must be a finite number"),
    ("/tap", [5, math.inf], "the level must be a finite number"),
    ("/tap", [5, 41.0], "from -100 to 40"),
    ("/tap", [5, -1000], "from -100 to 40"),
    ("/tap", [5, 6.0], "drive refused"),
    ("/tap", 0, "unknown location"),
    ("/tap", 99, "unknown location"),
    ("/tap_xy", [math.nan, 0.0], "finite"),
    ("/tap_xy", [0.0, math.inf], "finite"),
    ("/tap_xy", [-math.inf, 0.0], "finite"),
    ("/tap_xy", [100.0, 0.0], "off the calibrated area"),
    ("/tap_xy", [0.0, -15.5], "off the calibrated area"),
    ("/tap_xy", [1.0], "takes 2 or 3 arguments"),
    ("/tap_xy", [1.0, 1.0, True], "the level is a number"),
    ("/tap_xy", [1.0, 1.0, 12.0], "drive refused"),
    ("/tap_xy", ["a", "b"], "two numbers"),
    ("/method", "no_such_method", "unknown method"),
    ("/method", 3, "method name"),
    ("/method", [], "takes 1 argument"),
    ("/tapp", 5, "unknown address"),
    ("/", [], "unknown address"),
    ("/stop", 1, "takes 0 arguments"),
]


def test_malformed_messages_are_answered_error_and_play_nothing(running):
    server, client, rig, thread, _ = running
    before = rig.n_played
    for address, args, needle in MALFORMED:
        reply = _ask(client, address, args)
        assert reply.address == "/error", (address, args, reply.address, reply.params)
        assert needle in reply.params[0], (address, args, reply.params)
        assert rig.n_played == before, (address, args)
        assert thread.is_alive()
    assert np.all(rig.outputs_v == 0)
    # Bytes that are no OSC packet, from a plain socket.
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        raw.settimeout(REPLY_S)
        for junk in (b"", b"\x00\x01garbage", b"/tap\x00\x00\x00\x00,i\x00\x00", b"#bundle\x00" + b"\xff" * 7):
            raw.sendto(junk, server.address)
            reply = OscMessage(raw.recv(65536))
            assert reply.address == "/error", junk
    finally:
        raw.close()
    assert rig.n_played == before and thread.is_alive()
    assert server.n_errors == len(MALFORMED) + 4
    # The server still serves: the next valid tap plays.
    assert _ask(client, "/tap", 1).address == "/played"
    assert rig.n_played == before + 1


def test_method_switch_then_tap(running):
    server, client, rig, _, _ = running
    reply = _ask(client, "/method", "funneling")
    assert reply.address == "/method" and reply.params == ["funneling"]
    assert _ask(client, "/tap", 2).address == "/played"
    assert server.records[-1].method == "funneling"
    assert np.abs(rig.last_drive).max() <= rig.limits.peak_v + 1e-12


def test_stop_ends_the_server_with_outputs_at_zero(running):
    server, client, rig, thread, result = running
    assert _ask(client, "/tap", 9).address == "/played"
    reply = _ask(client, "/stop", [])
    assert reply.address == "/stopped"
    thread.join(30)
    assert not thread.is_alive()
    assert result["who"].startswith("/stop from 127.0.0.1:")
    assert np.all(rig.outputs_v == 0)


def test_designer_interpolates_the_model_between_grid_points(rig_and_designer):
    rig, _ = rig_and_designer
    tm = TransferMatrix.from_model(rig, rig.layout, rig.fs)
    designer = TapDesigner(tm, rig, limit_v=rig.limits.peak_v)  # the default 2.5 mm grid
    rng = np.random.default_rng(29)
    band = (tm.freqs > 50) & (tm.freqs < 400)
    for _ in range(5):
        xy = rng.uniform(-14e-3, 14e-3, 2)
        true = rig.transfer(xy[None], tm.freqs)[:, 0]
        err = np.linalg.norm(designer.transfer_row(xy)[band] - true[band]) / np.linalg.norm(true[band])
        assert err < 0.05, (xy, err)
    drives = designer.drives_xy(np.array([2e-3, -3e-3]))
    assert drives.shape == (rig.layout.n_actuators, tm.n_samples)
    assert 0 < np.abs(drives).max() <= rig.limits.peak_v + 1e-12


def test_a_design_that_fails_unexpectedly_is_an_error_and_the_next_tap_plays(running, monkeypatch):
    server, client, rig, thread, _ = running
    before = rig.n_played

    def broken(xy):
        raise ZeroDivisionError("a bug in a design")

    monkeypatch.setattr(server.designer, "drives_xy", broken)
    reply = _ask(client, "/tap_xy", [1.0, 2.0])
    assert reply.address == "/error" and "ZeroDivisionError" in reply.params[0]
    assert rig.n_played == before and thread.is_alive()
    assert _ask(client, "/tap", 3).address == "/played"
    assert rig.n_played == before + 1


def test_the_rigs_safety_layer_refuses_what_is_over_its_limit(rig_and_designer):
    from vibrofocus.rigs import SafetyLimits
    from vibrofocus.rigs.simulated import SimulatedForearm

    _, designer = rig_and_designer
    designer.set_method("inverse")  # designs at 10 V peak
    strict = SimulatedForearm(seed=3, limits=SafetyLimits(peak_v=2.0))
    server = OscTapServer(strict, designer, port=0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    client = SimpleUDPClient(*server.address)
    try:
        for address, args in (("/tap", 5), ("/tap_xy", [0.0, 0.0])):
            reply = _ask(client, address, args)
            assert reply.address == "/error" and "peak" in reply.params[0], reply.params
        assert strict.n_played == 0 and np.all(strict.outputs_v == 0)
        assert _ask(client, "/stop", []).address == "/stopped"
    finally:
        server.stop()
        thread.join(10)
        server.close()


@pytest.mark.slow
def test_a_method_of_slow_designs_is_served_only_at_locations_made_ahead(running):
    server, client, rig, _, _ = running
    # Not made ahead: switching would design nine taps while messages wait. Refused, and
    # the server goes on with the method it had.
    reply = _ask(client, "/method", "minimax")
    assert reply.address == "/error" and "start serve-osc with --method minimax" in reply.params[0]
    assert _ask(client, "/tap", 2).address == "/played" and server.records[-1].method == "inverse"
    # Made ahead (as serve-osc --method minimax does at start-up): switching is free, taps at
    # locations play, a tap at a new point is refused (a design takes seconds).
    designer = server.designer
    designer.set_method("minimax")
    designer.set_method("inverse")
    assert designer.designed_ahead("minimax")
    assert _ask(client, "/method", "minimax").params == ["minimax"]
    played = _ask(client, "/tap", 5)
    assert played.address == "/played" and server.records[-1].method == "minimax"
    # The design made ahead, as played (the rig ramps the window's first and last samples).
    np.testing.assert_array_equal(rig.last_drive[:, 64:-64], designer.drives_at(5)[:, 64:-64])
    assert np.abs(rig.last_drive).max() <= rig.limits.peak_v + 1e-12
    n = len(server.records)
    reply = _ask(client, "/tap_xy", [0.0, 0.0])
    assert reply.address == "/error" and "takes seconds" in reply.params[0] and len(server.records) == n
