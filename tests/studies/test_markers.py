"""``simulate-study --lsl``: the markers as a real pylsl inlet receives them, against the database."""

from __future__ import annotations

import json
import threading

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.io.lsl import clock_offset, stable_source_id
from vibrofocus.studies import StudyStore
from vibrofocus.studies.markers import send_marker, sending_markers

pylsl = pytest.importorskip("pylsl")
pytestmark = pytest.mark.slow


class Receiver(threading.Thread):
    """A pylsl inlet on this process's marker outlet, pulling until it has every marker sent.

    Its sink, added before the command opens the outlet, counts the markers sent and holds
    the first one until the inlet is connected: no marker is sent to nobody.
    """

    def __init__(self, source_id: str):
        super().__init__(daemon=True)
        self.source_id = source_id
        self.connected = threading.Event()
        self.markers: list[tuple[dict, float]] = []
        self.sent = 0
        self.expected: int | None = None  # set when the command has ended
        self.error: BaseException | None = None

    def sink(self, marker, host_time_s):
        assert self.connected.wait(60.0), "no inlet connected to the marker outlet"
        self.sent += 1

    def run(self):
        try:
            # The detail stream (JSON), whose source id follows the database's.
            pred = f"name='vibrofocus-markers-detail' and source_id='{self.source_id}-detail'"
            streams = pylsl.resolve_bypred(pred, 1, 60.0)
            assert streams, "the marker outlet was not found"
            inlet = pylsl.StreamInlet(streams[0], max_buflen=3600)
            inlet.open_stream(timeout=60.0)
            self.connected.set()
            idle = 0
            while self.expected is None or (len(self.markers) < self.expected and idle < 12):
                sample, stamp = inlet.pull_sample(timeout=5.0)
                if sample is None:
                    idle += self.expected is not None  # counts only once nothing more is coming
                    continue
                self.markers.append((json.loads(sample[0]), stamp))
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            self.error = exc
            self.connected.set()


def test_simulate_study_sends_one_marker_per_cue_onset_and_answer_at_the_stored_onsets(tmp_path, lsl_config):
    db = tmp_path / "study.db"
    receiver = Receiver(stable_source_id(db))
    receiver.start()
    with sending_markers(receiver.sink):
        result = CliRunner().invoke(app, ["simulate-study", "-n", "1", "--seed", "4", "--db", str(db), "--quiet", "--lsl"])
    assert result.exit_code == 0, result.output
    receiver.expected = receiver.sent
    receiver.join(120.0)
    assert not receiver.is_alive() and receiver.error is None, receiver.error
    offset = clock_offset(pylsl.local_clock)  # this process's clocks, as the outlet measured them

    with StudyStore(db, create=False) as store:
        rows = store.trial_rows()
        answers = {(e.session_id, e.payload["trial_index"]): e.payload
                   for s in store.sessions() for e in store.events(s.session_id, kind="answer")}
    markers = receiver.markers
    onsets = [(m, t) for m, t in markers if m["event"] == "stimulus_onset"]
    assert len(rows) > 100 and len(onsets) == len(rows)
    assert len(markers) == receiver.sent == 3 * len(rows)
    # Order: cue, onset, answer for each trial, trials in the database's order.
    assert [m["event"] for m, _ in markers] == ["cue", "stimulus_onset", "answer"] * len(rows)
    keys = [(r["session_id"], r["trial_index"]) for r in rows]
    assert [(m["session"], m["trial_index"]) for m, _ in onsets] == keys
    for (m, _), row in zip(onsets, rows):
        assert (m["participant"], m["study"], m["trial"], m["phase"], m["method"], m["target"], m["response"]) == (
            row["participant"], row["study"], row["trial"], row["phase"], row["method"], row["target"], None)
        # The onset on the rig's own clock, as the database stores it (JSON keeps every digit).
        assert (m["onset_device_s"], m["onset_clock"]) == (row["onset_device_s"], "simulated_samples")
    answered = [m for m, _ in markers if m["event"] == "answer"]
    assert [" ".join(map(str, m["response"])) for m in answered] == [r["response"] for r in rows]
    # Stamps: each onset's stored host time on LSL's clock; each answer at onset + response time.
    errors = [abs(t - (answers[(m["session"], m["trial_index"])]["onset_s"] + offset)) for m, t in onsets]
    assert max(errors) < 1e-3
    # The outlet measured its own offset, microseconds from this test's: every onset carries
    # that one offset, which the answers' bounds below use (a bound of 1e-9 s on this test's
    # offset failed by the two measurements' difference).
    outlet_offsets = [t - answers[(m["session"], m["trial_index"])]["onset_s"] for m, t in onsets]
    assert max(outlet_offsets) - min(outlet_offsets) < 1e-6
    outlet_offset = outlet_offsets[0]
    # Each answer at onset + response time, or earlier where that time had not yet come
    # (--pace 0: the model's response times are longer than the run takes), never before
    # its stimulus or after the next cue: the stamps never step back.
    answer_stamps = [t for m, t in markers if m["event"] == "answer"]
    latest = [answers[k]["onset_s"] + answers[k]["rt_s"] + outlet_offset for k in keys]
    assert all(a <= b + 1e-6 for a, b in zip(answer_stamps, latest))
    assert [m["code"] for m, _ in markers] == [
        code for r in rows for code in ("cue", f"tap/{r['method']}/{r['phase']}/study{r['study']}", "answer")]
    stamps = [t for _, t in markers]
    assert stamps == sorted(stamps)
    # The simulated rig knows its latency: none (the marker is at the hand-over).
    assert {m["onset_latency_s"] for m, _ in onsets} == {0.0}
    print(f"markers {len(markers)}, trials {len(rows)}, onset stamp max error {max(errors):.3g} s")


def test_a_failing_sink_never_stops_a_study(caplog):
    calls = []

    def broken(marker, host_time_s):
        calls.append(marker)
        raise OSError("network down")

    with sending_markers(broken):
        send_marker("cue", 1.0, trial=1)
        send_marker("cue", 2.0, trial=2)
    send_marker("cue", 3.0, trial=3)  # no sink: nothing happens
    assert [c["trial"] for c in calls] == [1, 2]
    assert sum("could not be sent" in r.message for r in caplog.records) == 1

