"""The LSL marker outlet, received by a real pylsl inlet on this machine."""

from __future__ import annotations

import itertools
import json
import uuid

import pytest

from vibrofocus.io.lsl import STREAM_NAME, STREAM_TYPE, MarkerOutlet, clock_offset

pylsl = pytest.importorskip("pylsl")


def test_the_clock_offset_is_taken_from_the_shortest_bracket():
    # Host reads 0, 1 | 10, 10.5 | ...: the second bracket is the shortest; LSL = host + 100.
    host = iter([0.0, 1.0, 10.0, 10.5, 20.0, 22.0])
    lsl = iter([100.9, 110.25, 121.0])
    assert clock_offset(lambda: next(lsl), lambda: next(host), tries=3) == pytest.approx(100.0, abs=1e-12)


def test_the_offset_maps_monotonic_time_onto_lsl_clock(lsl_config):
    import time

    offset = clock_offset(pylsl.local_clock)
    before = time.monotonic() + offset
    now = pylsl.local_clock()
    after = time.monotonic() + offset
    assert before - 1e-3 <= now <= after + 1e-3


def _inlet(source_id: str):
    streams = pylsl.resolve_bypred(f"source_id='{source_id}'", 1, 30.0)
    assert streams, "the outlet was not found on this machine"
    inlet = pylsl.StreamInlet(streams[0], recover=False)
    inlet.open_stream(timeout=30.0)
    return inlet, streams[0]


def test_markers_arrive_in_order_with_their_events_own_times(lsl_config):
    source_id = f"vibrofocus-test-{uuid.uuid4().hex}"
    with MarkerOutlet(source_id=source_id) as outlet:
        inlet, info = _inlet(source_id)
        assert (info.name(), info.type(), info.channel_format()) == (STREAM_NAME, STREAM_TYPE, pylsl.cf_string)
        assert outlet.wait_for_consumers(30.0)
        # Events that happened in the past (host times 5 s ago and before): stamped then, not now.
        import time

        base = time.monotonic() - 5.0
        sent = [outlet.push({"event": "stimulus_onset", "trial": k, "target": 5, "x": float("nan")}, base + 0.25 * k)
                for k in range(6)]
        got, stamps = [], []
        for _ in itertools.repeat(None, 6):
            sample, stamp = inlet.pull_sample(timeout=30.0)
            assert sample is not None, "a marker was lost"
            got.append(json.loads(sample[0]))
            stamps.append(stamp)
    assert [m["trial"] for m in got] == list(range(6))
    assert got[0] == {"event": "stimulus_onset", "trial": 0, "target": 5, "x": None}
    assert stamps == pytest.approx(sent, abs=1e-9)
    assert stamps == pytest.approx([base + outlet.offset_s + 0.25 * k for k in range(6)], abs=1e-9)
    assert max(stamps) < pylsl.local_clock() - 3.0  # the events' times, not the sending time
