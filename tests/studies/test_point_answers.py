"""Point answers (issue 55, part 3): stored in mm beside the nearest location, exported as
``response_x_mm`` / ``response_y_mm``, analysed as an error in mm; an old database (schema 1)
is upgraded and still reads; a small point-response protocol runs in simulation."""

import csv
import json
import sqlite3

import pandas as pd
import pytest
from typer.testing import CliRunner

from vibrofocus.analysis import point_errors
from vibrofocus.errors import AnswerRefused, StudyError
from vibrofocus.studies import StudyStore
from vibrofocus.studies import database as dbmod
from vibrofocus.studies.points import point_area
from vibrofocus.studies.protocol import StudyDesign
from vibrofocus.studies.protocol_files import parse_protocol

from .corner_protocol import corner_protocol

POINT_PROTOCOL = corner_protocol("point-pilot", "point")


@pytest.fixture
def store(tmp_path):
    with StudyStore(tmp_path / "study.db") as s:
        s.add_participant("p01")
        yield s


def _point_session(store, **config):
    return store.create_session("p01", 1, seed=3, config={"point": True, "repetitions": 1, "n_training": 1, **config})


def test_the_picture_covers_the_grid_the_actuators_and_a_margin():
    area = point_area()  # the reference layout: actuators at +-22.5 mm, locations at 10 mm pitch
    assert area["x_mm"] == pytest.approx([-32.5, 32.5]) and area["y_mm"] == pytest.approx([-32.5, 32.5])
    assert area["locations_mm"]["1"] == pytest.approx([-10.0, 10.0])
    assert area["locations_mm"]["9"] == pytest.approx([10.0, -10.0])
    assert len(area["actuators_mm"]) == 4


def test_a_point_answer_round_trips_beside_its_nearest_location(store):
    sid = _point_session(store)
    assert store.session(sid).design.point and store.session(sid).config["point_area"]["x_mm"] == [-32.5, 32.5]
    t = store.next_trial(sid)
    receipt = store.record_answer(sid, t.trial_index, None, 0.9, answer_id="pt-0", point_mm=(8.25, -11.5))
    assert receipt.point_mm == (8.25, -11.5) and receipt.response == (9,)
    again = store.record_answer(sid, t.trial_index, None, 0.9, answer_id="pt-0", point_mm=(8.25, -11.5))
    assert again.duplicate and again == receipt
    assert store.answers(sid) == [receipt]
    # The same id with another point is another answer: refused.
    with pytest.raises(AnswerRefused, match="already used"):
        store.record_answer(sid, t.trial_index, None, 0.9, answer_id="pt-0", point_mm=(8.0, -11.5))
    # Stored as numbers, read by another connection.
    raw = sqlite3.connect(store.path)
    assert raw.execute("SELECT response, response_x_mm, response_y_mm FROM answers").fetchall() == [("9", 8.25, -11.5)]
    raw.close()
    event = store.events(sid, kind="answer")[-1]
    assert event.payload["point_mm"] == [8.25, -11.5]


@pytest.mark.parametrize("point, response, words", [
    ((40.0, 0.0), None, "outside the picture's area (x -32.5 to 32.5 mm"),
    ((0.0, -33.0), None, "outside the picture's area"),
    ((float("nan"), 0.0), None, "finite"),
    (("1", 0.0), None, "two numbers"),
    ((1.0, 2.0, 3.0), None, "two numbers"),
    (None, 5, "takes a point answer"),
    ((10.0, 10.0), 9, "not the point's nearest location 3"),
])
def test_a_bad_point_is_refused_and_nothing_is_stored(store, point, response, words):
    sid = _point_session(store)
    with pytest.raises(AnswerRefused, match=words.replace("(", r"\(").replace(".", r"\.")):
        store.record_answer(sid, 0, response, 0.5, answer_id="bad-0", point_mm=point)
    assert store.answers(sid) == []


def test_a_location_session_refuses_a_point(store):
    sid = store.create_session("p01", 1, seed=3)
    with pytest.raises(AnswerRefused, match="takes locations, not a point"):
        store.record_answer(sid, 0, 5, 0.5, answer_id="loc-0", point_mm=(0.0, 0.0))


def test_a_point_design_is_study_1_only():
    with pytest.raises(StudyError, match="needs study 1"):
        StudyDesign(study=2, point=True)
    design = parse_protocol(POINT_PROTOCOL).design(0)  # no longer refused at planning
    assert design.point and design.study == 1 and design.locations == (1, 9)


def test_the_export_has_the_point_columns_and_the_analysis_an_error_in_mm(store, tmp_path):
    sid = _point_session(store, methods=["funneling", "inverse"], locations=[1, 9])
    trials = store.planned_trials(sid)
    loc = store.create_session("p01", 1, seed=4, config={"repetitions": 1, "n_training": 0, "locations": [5]})
    points = {}
    for t in trials:
        target = point_area()["locations_mm"][str(t.target)]
        # 3 mm right of the target for funneling, 4 mm above for the inverse filter
        p = (target[0] + 3.0, target[1]) if t.method == "funneling" else (target[0], target[1] + 4.0)
        points[t.trial_index] = p
        store.record_answer(sid, t.trial_index, None, 1.0, answer_id=f"a{t.trial_index}", point_mm=p)
    for t in store.planned_trials(loc):
        store.record_answer(loc, t.trial_index, 5, 1.0, answer_id=f"l{t.trial_index}")
    out = tmp_path / "t.csv"
    store.export_trials_csv(out)
    rows = list(csv.DictReader(open(out)))
    header = next(csv.reader(open(out)))
    assert header[-5:] == ["response_x_mm", "response_y_mm", "xrun_represented", "level_db", "allowed"]
    by_session = {}
    for r in rows:
        by_session.setdefault(int(r["session"]), []).append(r)
    for r in by_session[sid]:
        i = int(r["trial"]) - 1 + (1 if r["phase"] == "main" else 0)
        assert (float(r["response_x_mm"]), float(r["response_y_mm"])) == points[i]
        assert r["response"] == r["target"]  # a point 3-4 mm from its target: the target is the nearest
    assert {(r["response_x_mm"], r["response_y_mm"]) for r in by_session[loc]} == {("", "")}
    # Each row says its block: the level and the answers it allowed (what the fit of hypotheses reads).
    assert {(r["level_db"], r["allowed"]) for r in by_session[sid]} == {("0.0", "1 9")}
    assert {(r["level_db"], r["allowed"]) for r in by_session[loc]} == {("0.0", "5")}
    summary = point_errors(pd.read_csv(out, dtype=str, keep_default_na=False))
    assert list(summary["method"]) == ["funneling", "inverse"]
    assert list(summary["n"]) == [2, 2]  # main trials only: 2 locations x 1 repetition each
    assert summary["mean_error_mm"].tolist() == pytest.approx([3.0, 4.0], abs=1e-12)


def _v1_database(path):
    """A database as vibrofocus wrote it at schema version 1 (answers without the point columns)."""
    schema = dbmod._SCHEMA.replace("    response_x_mm  REAL,\n    response_y_mm  REAL,\n", "")
    assert "response_x_mm" not in schema
    con = sqlite3.connect(path, isolation_level=None)
    triggers = "".join(t + "\n" for t in dbmod._TRIGGERS.splitlines() if " ON thresholds " not in t)
    for statement in (schema + triggers).split(";\n"):
        if statement.strip():
            con.execute(statement)
    con.execute(f"PRAGMA application_id = {dbmod.APPLICATION_ID}")
    con.execute("PRAGMA user_version = 1")
    now = "2026-01-01T00:00:00.000000+00:00"
    con.execute("INSERT INTO participants VALUES ('old', 0, ?)", (now,))
    con.execute("INSERT INTO sessions (session_id, participant_id, study, seed, status, config, software_version, "
                "created_at, updated_at) VALUES (1, 'old', 1, 1, 'running', ?, '0.1', ?, ?)",
                (json.dumps({"levels": "paper", "repetitions": 1, "n_training": 0}), now, now))
    con.execute("INSERT INTO planned_trials VALUES (1, 0, 'main', 1, 'funneling', 5)")
    con.execute("INSERT INTO answers (answer_id, session_id, trial_index, response, rt_s, recorded_at) "
                "VALUES ('old-0', 1, 0, '4', 0.7, ?)", (now,))
    con.close()


def test_an_old_database_is_upgraded_and_reads_as_before(tmp_path):
    db = tmp_path / "old.db"
    _v1_database(db)
    with StudyStore(db, create=False) as store:
        (receipt,) = store.answers(1)
        assert receipt.response == (4,) and receipt.point_mm is None
        store.export_trials_csv(tmp_path / "t.csv")
    raw = sqlite3.connect(db)
    assert raw.execute("PRAGMA user_version").fetchone()[0] == dbmod.SCHEMA_VERSION == 3
    assert raw.execute("SELECT COUNT(*) FROM thresholds").fetchone()[0] == 0  # schema 3's table, empty
    assert raw.execute("SELECT response, response_x_mm FROM answers").fetchall() == [("4", None)]
    raw.close()
    (row,) = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert row["response"] == "4" and row["response_x_mm"] == "" and row["response_y_mm"] == ""


@pytest.mark.slow
def test_a_point_protocol_runs_in_simulation(tmp_path):
    from vibrofocus.cli.main import app

    path = tmp_path / "point.toml"
    path.write_text(POINT_PROTOCOL)
    db, out = tmp_path / "s.db", tmp_path / "t.csv"
    result = CliRunner().invoke(app, ["simulate-study", "--protocol", str(path), "-n", "1", "--db", str(db),
                                      "--trials-csv", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == 2 * 2 + 1 and {r["protocol"] for r in rows} == {"point-pilot"}
    area = point_area(None, (1, 9))
    for r in rows:
        x, y = float(r["response_x_mm"]), float(r["response_y_mm"])
        assert area["x_mm"][0] <= x <= area["x_mm"][1] and area["y_mm"][0] <= y <= area["y_mm"][1]
        # The stored location is the point's nearest of the block's locations (1 at (-10, 10), 9 at (10, -10)).
        nearest = "1" if (x + 10) ** 2 + (y - 10) ** 2 < (x - 10) ** 2 + (y + 10) ** 2 else "9"
        assert r["response"] == nearest
    # Points are the model's perceived places, not the locations' centres.
    centres = {(-10.0, 10.0), (10.0, -10.0)}
    assert not {(float(r["response_x_mm"]), float(r["response_y_mm"])) for r in rows} & centres
    with StudyStore(db, create=False) as store:
        (info,) = store.sessions()
        assert info.design.point and info.config["protocol"] == "point-pilot"
    # analyze reports the points' error in mm per method, as point_errors computes it.
    result = CliRunner().invoke(app, ["analyze", str(out), "--out", str(tmp_path / "report"), "--simulated"])
    assert result.exit_code == 0, result.output
    expected = point_errors(pd.read_csv(out, dtype=str, keep_default_na=False))
    text = " ".join(result.output.split())
    assert "Point answers, mean localization error (point to target):" in text, text
    for r in expected.itertuples():
        assert f"{r.method} {r.mean_error_mm:.2f} mm (n = {r.n})" in text, text


def test_study_run_in_the_terminal_refuses_a_point_block_before_anything(tmp_path, calibration_file):
    from vibrofocus.cli.main import app

    path = tmp_path / "point.toml"
    path.write_text(POINT_PROTOCOL)
    result = CliRunner().invoke(app, ["study", "run", "--participant", "p-real", "--db", str(tmp_path / "s.db"),
                                      "--calibration", str(calibration_file), "--protocol", str(path)])
    assert result.exit_code != 0
    assert "line 5, blocks[0].response: point answers are given on the web participant page" in result.output
    assert not (tmp_path / "s.db").exists()
