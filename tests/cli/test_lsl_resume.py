"""``simulate-study --lsl`` killed with SIGKILL and resumed, recorded as LabRecorder records.

Real processes, a real SIGKILL, real pylsl inlets opened with ``recover=True`` (what
LabRecorder uses) on both marker streams. The resumed run must reach the same inlets: one
stream, the same source id, and every marker of the resumed trials, in order.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import threading

import pytest

from vibrofocus.io.lsl import DETAIL_STREAM_NAME, STREAM_NAME, stable_source_id
from vibrofocus.studies import StudyStore

pylsl = pytest.importorskip("pylsl")
pytestmark = pytest.mark.slow

KILL_AFTER = 20  # answers received before the first run is killed


class Recorder(threading.Thread):
    """One recover=True inlet, pulling everything into ``samples`` until told to stop."""

    def __init__(self, source_id: str):
        super().__init__(daemon=True)
        self.source_id = source_id
        self.samples: list[tuple[str, float]] = []
        self.connected = threading.Event()
        self.stop = threading.Event()
        self.changed = threading.Condition()
        self.error: BaseException | None = None

    def run(self):
        try:
            found = pylsl.resolve_bypred(f"source_id='{self.source_id}'", 1, 120.0)
            assert found, f"no stream with source id {self.source_id}"
            self.info = found[0]
            inlet = pylsl.StreamInlet(found[0], max_buflen=3600, recover=True)
            inlet.open_stream(timeout=120.0)
            self.connected.set()
            while not self.stop.is_set():
                sample, stamp = inlet.pull_sample(timeout=0.2)
                if sample is not None:
                    with self.changed:
                        self.samples.append((sample[0], stamp))
                        self.changed.notify_all()
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            self.error = exc
            self.connected.set()

    def wait_for(self, predicate, timeout_s: float) -> bool:
        with self.changed:
            return self.changed.wait_for(lambda: predicate(self.samples), timeout_s)


def test_a_killed_and_resumed_run_keeps_one_stream_whose_recovering_inlets_get_every_resumed_marker(
        tmp_path, lsl_config):
    db = tmp_path / "study.db"
    env = {**os.environ, "LSLAPICFG": str(lsl_config)}
    # --lsl-wait: each run waits for the recorder before its first trial (the resumed run
    # for the inlets recovering the killed run's stream), so no marker goes to nobody.
    cmd = [sys.executable, "-m", "vibrofocus", "simulate-study", "-n", "1", "--seed", "4", "--db", str(db),
           "--quiet", "--lsl", "--lsl-wait", "120"]
    source_id = stable_source_id(db)
    codes, details = Recorder(source_id), Recorder(f"{source_id}-detail")
    first = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        details.start()
        codes.start()
        while not codes.wait_for(lambda s: sum(c == "answer" for c, _ in s) >= KILL_AFTER, 1.0):
            assert first.poll() is None and codes.error is None, (
                f"the first run ended (exit {first.poll()}) before {KILL_AFTER} answers came: {codes.error}")
        first.send_signal(signal.SIGKILL)
        first.wait(60.0)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    killed = pylsl.local_clock()  # every marker of the first run was stamped before this
    with sqlite3.connect(db) as conn:
        answered_before = conn.execute("SELECT COUNT(*) FROM answers").fetchone()[0]
    assert answered_before >= KILL_AFTER

    second = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=400)
    assert second.returncode == 0, second.stderr[-2000:]
    with StudyStore(db, create=False) as store:
        rows = store.trial_rows()
    resumed_rows = rows[answered_before:]  # trial_rows: sessions and trials in the order they ran
    expected = 3 * len(resumed_rows)
    try:
        for recorder in (codes, details):
            recorder.wait_for(lambda s: sum(t > killed for _, t in s) >= expected, 60.0)
    finally:
        codes.stop.set()
        details.stop.set()
        codes.join(10.0)
        details.join(10.0)
    assert codes.error is None and details.error is None, (codes.error, details.error)
    assert (codes.info.name(), details.info.name()) == (STREAM_NAME, DETAIL_STREAM_NAME)

    resumed = [(c, t) for c, t in codes.samples if t > killed]
    resumed_detail = [(json.loads(d), t) for d, t in details.samples if t > killed]
    assert len(rows) == 172 and len(resumed_rows) >= 150
    assert len(resumed) == len(resumed_detail) == expected  # every marker of the resumed run, once
    # The codes, trial by trial, from the database's own rows.
    want = []
    for row in resumed_rows:
        want += ["cue", f"tap/{row['method']}/{row['phase']}/study{row['study']}", "answer"]
    assert [c for c, _ in resumed] == want
    assert [d["code"] for d, _ in resumed_detail] == want
    assert [t for _, t in resumed] == [t for _, t in resumed_detail]
    answers = [d for d, _ in resumed_detail if d["event"] == "answer"]
    assert [" ".join(map(str, d["response"])) for d in answers] == [r["response"] for r in resumed_rows]
    # The time axis never steps back: each answer between its own stimulus and the next cue.
    stamps = [t for _, t in resumed]
    assert stamps == sorted(stamps)
