"""The LSL marker outlet, received by a real pylsl inlet on this machine."""

from __future__ import annotations

import itertools
import json
import uuid

import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.io.lsl import (CODES, DETAIL_STREAM_NAME, DETAIL_STREAM_TYPE, STREAM_NAME, STREAM_TYPE, MarkerOutlet,
                               check_source_id, clock_offset, marker_code, stable_source_id)

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


def _inlet(source_id: str, *, recover: bool = False):
    streams = pylsl.resolve_bypred(f"source_id='{source_id}'", 1, 30.0)
    assert streams, "the outlet was not found on this machine"
    inlet = pylsl.StreamInlet(streams[0], max_buflen=360, recover=recover)
    inlet.open_stream(timeout=30.0)
    return inlet, streams[0]


def _pull(inlet, n):
    got = []
    for _ in itertools.repeat(None, n):
        sample, stamp = inlet.pull_sample(timeout=30.0)
        assert sample is not None, "a marker was lost"
        got.append((sample[0], stamp))
    return got


def test_markers_arrive_in_order_with_their_events_own_times(lsl_config):
    source_id = f"vibrofocus-test-{uuid.uuid4().hex}"
    with MarkerOutlet(source_id=source_id) as outlet:
        inlet, info = _inlet(source_id)
        detail, dinfo = _inlet(f"{source_id}-detail")
        assert (info.name(), info.type(), info.channel_format()) == (STREAM_NAME, STREAM_TYPE, pylsl.cf_string)
        assert (dinfo.name(), dinfo.type()) == (DETAIL_STREAM_NAME, DETAIL_STREAM_TYPE)
        assert outlet.wait_for_consumers(30.0)
        # Events that happened in the past (host times 5 s ago and before): stamped then, not now.
        import time

        base = time.monotonic() - 5.0
        sent = [outlet.push({"event": "stimulus_onset", "trial": k, "target": 5, "x": float("nan"), "method": "inverse",
                             "phase": "main", "study": 2}, base + 0.25 * k)
                for k in range(6)]
        codes, details = _pull(inlet, 6), _pull(detail, 6)
    got = [json.loads(text) for text, _ in details]
    assert [m["trial"] for m in got] == list(range(6))
    assert got[0] == {"event": "stimulus_onset", "trial": 0, "target": 5, "x": None, "method": "inverse",
                      "phase": "main", "study": 2, "code": "tap/inverse/main/study2"}
    assert [c for c, _ in codes] == ["tap/inverse/main/study2"] * 6
    stamps = [t for _, t in codes]
    assert stamps == [t for _, t in details]  # one event, one time on both streams
    assert stamps == pytest.approx(sent, abs=1e-9)
    assert stamps == pytest.approx([base + outlet.offset_s + 0.25 * k for k in range(6)], abs=1e-9)
    assert max(stamps) < pylsl.local_clock() - 3.0  # the events' times, not the sending time


#: A process that sends a burst of markers to its first inlet and closes its outlet at once.
_BURST_THEN_EXIT = """
import sys
from vibrofocus.io.lsl import MarkerOutlet
with MarkerOutlet(source_id=sys.argv[1]) as outlet:
    assert outlet.wait_for_consumers(60.0)
    for k in range(int(sys.argv[2])):
        outlet.push({"event": "answer", "trial": k, "response": [5]}, 0.0)
"""


def test_markers_sent_just_before_a_process_closes_its_outlet_all_arrive(lsl_config):
    # liblsl has no flush: without the close's wait, a burst pushed right before the outlet
    # is destroyed nearly never reaches the inlet (394 of 400 markers lost over 8 runs).
    import subprocess
    import sys

    source_id, n = f"vibrofocus-test-{uuid.uuid4().hex}", 50
    sender = subprocess.Popen([sys.executable, "-c", _BURST_THEN_EXIT, source_id, str(n)])
    try:
        inlet, _ = _inlet(source_id, recover=True)  # a recorder's inlet, as LabRecorder opens it
        got = []
        while len(got) < n:  # recover=True: a stream gone is a timeout, not an error
            sample, _ = inlet.pull_sample(timeout=10.0)
            if sample is None:
                break
            got.append(sample[0])
        assert sender.wait(60) == 0
    finally:
        sender.kill()
    assert got == ["answer"] * n


def test_an_inlet_that_never_reads_holds_the_close_no_longer_than_the_linger(lsl_config, monkeypatch):
    # Another local program may connect an inlet and never pull: the close waits once, at
    # most CLOSE_LINGER_S after the last marker, whatever that inlet does.
    import vibrofocus.io.lsl as lsl

    slept = []
    monkeypatch.setattr(lsl.time, "sleep", slept.append)
    source_id = f"vibrofocus-test-{uuid.uuid4().hex}"
    with MarkerOutlet(source_id=source_id) as outlet:
        idle, _ = _inlet(source_id)
        assert outlet.wait_for_consumers(30.0)
        outlet.push({"event": "answer", "trial": 0, "response": [5]}, 0.0)
    assert len(slept) == 1 and 0.0 < slept[0] <= lsl.CLOSE_LINGER_S
    del idle


def test_closing_with_no_inlet_does_not_wait(lsl_config, monkeypatch):
    import vibrofocus.io.lsl as lsl

    slept = []
    monkeypatch.setattr(lsl.time, "sleep", slept.append)
    with MarkerOutlet(source_id=f"vibrofocus-test-{uuid.uuid4().hex}") as outlet:
        outlet.push({"event": "answer", "trial": 0, "response": [5]}, 0.0)
    assert slept == []


@pytest.mark.parametrize("marker, code", [
    ({"event": "cue", "method": "inverse", "study": 1}, "cue"),
    ({"event": "answer", "response": [4, 5], "study": 2}, "answer"),
    ({"event": "stimulus_onset", "method": "funneling", "phase": "training", "study": 1, "played": True},
     "tap/funneling/training/study1"),
    ({"event": "stimulus_onset", "method": "combination", "phase": "main", "study": 2, "played": False},
     "dry/combination/main/study2"),
    ({"event": "tap", "method": "my method/v2"}, "tap/my_method_v2"),  # a tap from elsewhere: no phase, no study
    ({"event": "tap", "code": "tap/custom"}, "tap/custom"),
])
def test_each_kind_of_marker_has_one_short_code(marker, code):
    assert marker_code(marker) == code


def test_a_two_study_run_has_a_small_vocabulary_whatever_the_trials():
    # Every trial of a 2-study run with the paper's three methods over nine locations.
    markers = [{"event": event, "method": method, "phase": phase, "study": study, "target": target, "trial": trial,
                "response": [target] if event == "answer" else None}
               for study in (1, 2) for method in ("funneling", "inverse", "combination") for phase in ("training", "main")
               for target in range(1, 10) for trial in range(3) for event in ("cue", "stimulus_onset", "answer")]
    codes = {marker_code(m) for m in markers}
    assert len(codes) == 14 <= 20
    assert codes >= {"cue", "answer", "tap/inverse/main/study2"}


def test_the_source_id_is_stable_for_a_database_and_refuses_what_a_recorder_cannot_query(tmp_path, monkeypatch):
    db = tmp_path / "study.db"
    first = stable_source_id(db)
    monkeypatch.chdir(tmp_path)
    assert stable_source_id("study.db") == first  # the same file, named relatively
    assert stable_source_id(db, 2) == f"{first}-study2"
    assert stable_source_id(tmp_path / "other.db") != first
    assert check_source_id(first) == first
    for bad in ["", "a'b", "has space", "x" * 101, "-leading", None]:
        with pytest.raises(ValidationError, match="--lsl-source-id"):
            check_source_id(bad)


def test_the_stream_info_says_who_made_it_and_lists_the_codes(lsl_config):
    import vibrofocus

    source_id = f"vibrofocus-test-{uuid.uuid4().hex}"
    with MarkerOutlet(source_id=source_id):
        inlet, _ = _inlet(source_id)
        info = inlet.info(timeout=30.0)
    acq = info.desc().child("acquisition")
    assert (acq.child_value("manufacturer"), acq.child_value("software"), acq.child_value("version")) == (
        "vibrofocus", "vibrofocus", vibrofocus.__version__)
    own = info.desc().child("vibrofocus")
    assert own.child_value("detail_stream") == DETAIL_STREAM_NAME
    codes, entry = [], own.child("codes").child("code")
    while not entry.empty():
        codes.append(entry.child_value("name"))
        entry = entry.next_sibling()
    assert codes == list(CODES)


@pytest.mark.parametrize("how", ["database", "given", "random"])
def test_the_stream_says_where_its_source_id_came_from(lsl_config, tmp_path, how):
    # Issue 54, item 6: an id derived from the database's path said "given".
    if how == "database":
        source_id = stable_source_id(tmp_path / f"study-{uuid.uuid4().hex}.db")
    else:
        source_id = f"vibrofocus-test-{uuid.uuid4().hex}" if how == "given" else None
    with MarkerOutlet(source_id=source_id) as outlet:
        inlet, _ = _inlet(outlet.source_id)
        said = inlet.info(timeout=30.0).desc().child("vibrofocus").child_value("source_id_from")
    expected = {"database": f"a hash of this machine's name and the file {tmp_path.resolve()}",
                "given": "given (--lsl-source-id)", "random": "random (this process)"}[how]
    assert said.startswith(expected), said
