"""Threshold blocks: a protocol's staircase run by the engine, stored, exported, and used by dB SL blocks."""

import csv
import sqlite3

import numpy as np
import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies import StudyStore
from vibrofocus.studies.engine import Response, StudyEngine, check_drive_levels
from vibrofocus.studies.protocol_files import parse_protocol

THRESHOLD_BLOCK = """
[[blocks]]
name = "threshold"
response = "detection"
methods = ["funneling"]
locations = [5]
levels = [-6.0]
steps_db = [4.0, 2.0]
repetitions = 24
"""
SL_BLOCK = """
[[blocks]]
name = "localize"
response = "location"
methods = ["funneling", "inverse"]
locations = [1, 9]
levels = [20.0]
level_unit = "dB SL"
repetitions = 1
"""


def _protocol(*blocks):
    return parse_protocol('format = 1\nname = "thr"\n' + "".join(blocks), "thr.toml")


class Rig:
    """Plays nothing; keeps the drives' peaks."""

    fs = 48000.0

    def __init__(self):
        self.peaks = []

    def play(self, drives):
        self.peaks.append(float(np.max(np.abs(drives))))


def renderer(method, target):
    return np.full((4, 64), 2.0)  # a 2 V drive at 0 dB re the level rule


class Observer:
    """Feels a tap at or above threshold_db (from the played drive: 2 V at 0 dB)."""

    def __init__(self, threshold_db):
        self.threshold_db = threshold_db

    def respond(self, presentation):
        level = 20 * np.log10(presentation.stimulus.drive_peak_v / 2.0)
        return Response((int(level >= self.threshold_db - 1e-9),), 0.4)

    def wait_resume(self):
        return True


def test_a_threshold_session_runs_the_staircase_and_stores_its_threshold(tmp_path):
    protocol = _protocol(THRESHOLD_BLOCK, SL_BLOCK)
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("P1")
        sid = store.create_session("P1", 1, seed=1, config=protocol.session_config(0))
        rig = Rig()
        summary = StudyEngine(store, sid, rig, renderer=renderer).run(Observer(-15.0))
        assert summary.status == "completed" and summary.n_answered == 24
        # The levels played: 4 dB steps down from -6 until the first miss, then 2 dB around -15.
        played = [round(20 * np.log10(p / 2.0), 9) for p in rig.peaks]
        assert played[:4] == [-6.0, -10.0, -14.0, -18.0]
        assert set(played[4:]) <= {-18.0, -16.0, -14.0, -12.0}
        onsets = [e.payload["level_db"] for e in store.events(sid, kind="stimulus_onset")]
        np.testing.assert_allclose(played, onsets, rtol=0, atol=1e-9)
        found = store.threshold("P1", protocol="thr", block=0)
        assert found is not None and found[0] == sid and -16.0 <= found[1] <= -14.0
        # Felt-or-not answers are no localization trials: their own file.
        assert store.trial_rows() == []
        n = store.export_thresholds_csv(tmp_path / "thresholds.csv")
        with open(tmp_path / "thresholds.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert n == 24 and [float(r["level_db"]) for r in rows] == played
        assert {r["threshold_db"] for r in rows} == {repr(found[1])}
        assert sum(int(r["reversal"]) for r in rows) >= 6
        # The dB SL block is planned on it: 20 dB above the threshold, re the level rule.
        config = protocol.session_config(1, found[1])
        assert config["level_db"] == pytest.approx(found[1] + 20.0, abs=1e-12)
        assert config["threshold_db"] == found[1] and config["level_sl_db"] == 20.0


def test_levels_over_the_drive_limit_are_refused_at_planning():
    loud = THRESHOLD_BLOCK.replace("steps_db", "max_db = 20.0\nsteps_db")
    design = _protocol(loud).design(0)
    with pytest.raises(StudyError, match=r"\+20 dB re the paper levels needs 20 V for funneling at location 5"):
        check_drive_levels(renderer, design, limit_v=10.0)
    sl = _protocol(THRESHOLD_BLOCK, SL_BLOCK)
    with pytest.raises(StudyError, match=r"\+12 dB re the paper levels needs 7.96 V"):
        check_drive_levels(renderer, sl.design(1, threshold_db=-8.0), limit_v=5.0)


def test_bad_threshold_protocols_get_one_line():
    with pytest.raises(StudyError, match=r"line 10, blocks\[0\].level_unit: levels in dB SL need .* threshold block"):
        _protocol(SL_BLOCK).check_runnable()
    with pytest.raises(StudyError, match="has none yet"):
        _protocol(THRESHOLD_BLOCK, SL_BLOCK).design(1)
    with pytest.raises(StudyError, match=r"blocks\[0\]: steps_db and max_db belong to a threshold block"):
        _protocol(SL_BLOCK.replace("level_unit", "steps_db = [2.0]\nlevel_unit"))
    with pytest.raises(StudyError, match="one level in dB"):
        _protocol(THRESHOLD_BLOCK.replace("levels = [-6.0]", "levels = [-6.0, -3.0]"))
    with pytest.raises(StudyError, match="start_db 6 must lie within"):
        _protocol(THRESHOLD_BLOCK.replace("levels = [-6.0]", "levels = [6.0]"))


def test_detection_answers_are_checked_and_a_schema_2_database_is_upgraded(tmp_path):
    protocol = _protocol(THRESHOLD_BLOCK)
    path = tmp_path / "s.db"
    with StudyStore(path) as store:
        store.add_participant("P1")
        sid = store.create_session("P1", 1, seed=1, config=protocol.session_config(0))
    # The same file as vibrofocus with schema 2 wrote it: no thresholds table.
    conn = sqlite3.connect(path)
    conn.executescript("DROP TRIGGER thresholds_no_update; DROP TRIGGER thresholds_no_delete; DROP TABLE thresholds; "
                       "PRAGMA user_version = 2;")
    conn.close()
    with StudyStore(path) as store:
        from vibrofocus.errors import AnswerRefused

        with pytest.raises(AnswerRefused, match="1 \\(felt\\) or 0"):
            store.record_answer(sid, 0, 3, 0.5, answer_id="a0")
        with pytest.raises(AnswerRefused, match="not where"):
            store.record_answer(sid, 0, 1, 0.5, answer_id="a0", point_mm=(0.0, 0.0))
        for k in range(24):
            store.record_answer(sid, k, "yes" if k % 3 else "no", 0.5, answer_id=f"a{k}")
        assert store.threshold("P1") is not None
        with pytest.raises(StudyError, match="append-only"):
            with store._write("change a threshold") as conn:
                conn.execute("UPDATE thresholds SET threshold_db = 0")


def test_the_keypad_answers_felt_or_not(tmp_path):
    import io

    from rich.console import Console

    from vibrofocus.studies.terminal import TerminalResponder

    protocol = _protocol(THRESHOLD_BLOCK.replace("repetitions = 24", "repetitions = 3"))
    keys = iter(["5", "1", "no", "y"])
    out = io.StringIO()
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("P1")
        sid = store.create_session("P1", 1, seed=1, config=protocol.session_config(0))
        responder = TerminalResponder(console=Console(file=out), input_fn=lambda _: next(keys))
        assert StudyEngine(store, sid, Rig(), renderer=renderer).run(responder).status == "completed"
        assert [a.response for a in store.answers(sid)] == [(1,), (0,), (1,)]
    assert "did you feel it? 1 yes, 0 no" in out.getvalue() and "1 (felt) or 0" in out.getvalue()
