"""``/tap`` and ``/tap_xy`` with a level, and what ``/played`` carries: over real UDP with a
python-osc client, on the simulated rig (its device clock counts played samples)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

pytest.importorskip("pythonosc")
from pythonosc.osc_message import OscMessage  # noqa: E402
from pythonosc.udp_client import SimpleUDPClient  # noqa: E402

from vibrofocus.realtime import PLAYED_FIELDS, OscTapServer, TapLog, read_tap_log  # noqa: E402
from vibrofocus.rigs import make_rig  # noqa: E402

from ._designer import simulated_designer  # noqa: E402

REPLY_S = 30.0


@pytest.fixture(scope="module")
def designer():
    _, designer = simulated_designer()
    designer.prepare_grid()
    return designer


@pytest.fixture
def serve(designer):
    """Start a server on a fresh simulated rig (with the given log); stop it afterwards."""
    started = []

    def start(**kwargs):
        rig = make_rig("simulated", seed=3)
        server = OscTapServer(rig, designer, port=0, **kwargs)
        thread = threading.Thread(target=server.serve, daemon=True)
        thread.start()
        started.append((server, thread))
        return server, SimpleUDPClient(*server.address), rig

    yield start
    for server, thread in started:
        server.stop()
        thread.join(10)
        server.close()


def _ask(client, address, args) -> OscMessage:
    client.send_message(address, args)
    data = client.receive(REPLY_S)
    assert data, "no reply"
    return OscMessage(data)


def test_level_scales_the_played_drive_by_its_decibels(serve):
    server, client, rig = serve()
    design = rig.check(server.designer.drives_at(5))  # 0 dB: the design as made (at the limit)
    peaks = {}
    for level in (0, -6.0, -12.0, -20.5):
        reply = _ask(client, "/tap", [5, level] if level else 5)
        assert reply.address == "/played", reply.params
        assert reply.params[-1] == pytest.approx(level)
        np.testing.assert_allclose(rig.last_drive, design * 10 ** (level / 20), rtol=1e-12, atol=0)
        peaks[level] = np.abs(rig.last_drive).max()
    # +6 dB doubles the amplitude: -6 dB to 0 dB, and -12 dB to -6 dB.
    assert peaks[0] / peaks[-6.0] == pytest.approx(10 ** (6 / 20), rel=1e-12)
    assert peaks[-6.0] / peaks[-12.0] == pytest.approx(1.9953, rel=1e-4)
    assert peaks[0] / peaks[-20.5] == pytest.approx(10 ** (20.5 / 20), rel=1e-12)
    # A tap anywhere too; integers are decibels as well.
    reply = _ask(client, "/tap_xy", [2.0, -3.0, -6])
    assert reply.address == "/played" and reply.params[:2] == [2.0, -3.0] and reply.params[-1] == -6.0
    full = rig.check(server.designer.drives_xy(np.array([2e-3, -3e-3])))
    np.testing.assert_allclose(rig.last_drive, full * 10 ** (-6 / 20), rtol=1e-9, atol=1e-12)
    assert [r.level_db for r in server.records] == [0.0, -6.0, -12.0, -20.5, -6.0]


def test_a_level_over_the_limit_is_refused_by_the_safety_layer_and_plays_nothing(serve):
    server, client, rig = serve()
    # The designs are scaled to the rig's peak limit: anything above 0 dB breaks it.
    for args in ([5, 0.5], [5, 6.0], ["/tap_xy", 0.0, 0.0, 3.0]):
        address = "/tap"
        if args[0] == "/tap_xy":
            address, args = args[0], args[1:]
        reply = _ask(client, address, args)
        assert reply.address == "/error" and "drive refused" in reply.params[0] and "peak" in reply.params[0]
    assert rig.n_played == 0 and np.all(rig.outputs_v == 0) and server.records == []
    assert _ask(client, "/tap", [5, -0.5]).address == "/played"  # just under it plays
    assert rig.n_played == 1


def test_played_carries_the_tap_id_and_the_onset_on_the_host_and_device_clocks(serve):
    server, client, rig = serve()
    n_samples = server.designer.tm.n_samples
    replies, sent, answered = [], [], []
    for k, (address, args) in enumerate([("/tap", 1), ("/tap", [9, -3.0]), ("/tap_xy", [0.0, 0.0]),
                                         ("/tap", [4, -10])]):
        sent.append(time.monotonic())
        replies.append(_ask(client, address, args))
        answered.append(time.monotonic())
    assert [r.address for r in replies] == ["/played"] * 4
    tails = [dict(zip(PLAYED_FIELDS, r.params[-len(PLAYED_FIELDS):])) for r in replies]
    assert [t["tap_id"] for t in tails] == [1, 2, 3, 4]
    assert [r.params[:-len(PLAYED_FIELDS)] for r in replies] == [[1], [9], [0.0, 0.0], [4]]
    # The simulated device clock: samples played before each tap, over the rate.
    assert [t["onset_device_s"] for t in tails] == [k * n_samples / rig.fs for k in range(4)]
    assert {t["onset_clock"] for t in tails} == {"simulated_samples"}
    # Host onsets (time.monotonic, sent as doubles: every digit) fall between the ask and the answer.
    for t, a, b, record in zip(tails, sent, answered, server.records):
        assert a <= t["onset_host_s"] <= b
        assert t["onset_host_s"] == record.onset_host_s and t["onset_device_s"] == record.onset_device_s


def test_the_log_keeps_every_acknowledged_tap_and_tap_ids_go_on(serve, tmp_path):
    path = tmp_path / "taps.db"
    with TapLog(path) as log:
        server, client, rig = serve(tap_log=log)
        played = [_ask(client, "/tap", [loc, -float(loc)]) for loc in (1, 2, 3)]
        assert _ask(client, "/tap", 77).address == "/error"  # refused: not logged
        played.append(_ask(client, "/tap_xy", [1.5, 2.5, -1]))
    rows = read_tap_log(path)
    assert [r["tap_id"] for r in rows] == [1, 2, 3, 4]
    assert [(r["address"], r["location"], r["x_mm"], r["y_mm"], r["level_db"]) for r in rows] == [
        ("/tap", 1, None, None, -1.0), ("/tap", 2, None, None, -2.0), ("/tap", 3, None, None, -3.0),
        ("/tap_xy", None, 1.5, 2.5, -1.0)]
    for reply, row in zip(played, rows):
        tail = dict(zip(PLAYED_FIELDS, reply.params[-len(PLAYED_FIELDS):]))
        assert (row["onset_host_s"], row["onset_device_s"], row["onset_clock"]) == (
            tail["onset_host_s"], tail["onset_device_s"], tail["onset_clock"])
    assert {r["method"] for r in rows} == {"inverse"}
    # A second server on the same log numbers on from the last tap.
    with TapLog(path) as log:
        assert log.last_tap_id == 4
        server, client, _ = serve(tap_log=log)
        assert _ask(client, "/tap", 6).params[-len(PLAYED_FIELDS)] == 5
    assert [r["tap_id"] for r in read_tap_log(path)] == [1, 2, 3, 4, 5]


def test_a_tap_that_cannot_be_logged_is_an_error_and_stops_the_server(serve, tmp_path):
    class Full:
        last_tap_id = 0

        def append(self, record):
            raise OSError(28, "No space left on device")

    server, client, rig = serve(tap_log=Full())
    reply = _ask(client, "/tap", 3)
    assert reply.address == "/error" and "not recorded" in reply.params[0] and "stops" in reply.params[0]
    assert np.all(rig.outputs_v == 0)
    assert server.stopped_by.startswith("the tap log")
    assert isinstance(server.log_error, OSError) and len(server.records) == 1


def test_markers_go_to_the_sink_stamped_with_the_host_onset(serve):
    got = []
    server, client, _ = serve(marker_sink=lambda marker, host_s: got.append((marker, host_s)))
    _ask(client, "/tap", [5, -6])
    _ask(client, "/tap_xy", [1.0, -2.0])
    assert [(m["event"], m["source"], m["tap_id"], m["target"], m["x_mm"], m["level_db"]) for m, _ in got] == [
        ("stimulus_onset", "serve-osc", 1, 5, None, -6.0), ("stimulus_onset", "serve-osc", 2, None, 1.0, 0.0)]
    assert [h for _, h in got] == [r.onset_host_s for r in server.records]
    assert [m["onset_device_s"] for m, _ in got] == [r.onset_device_s for r in server.records]
