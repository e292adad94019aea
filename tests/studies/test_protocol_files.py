"""Study protocols as data: the paper's two studies are their shipped files (the same trials
for the same seed), a bad protocol gets one line naming its field and writes nothing, and
a small protocol runs through ``simulate-study --protocol``."""

import csv
import hashlib
import json
import sqlite3
from collections import Counter

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.errors import StudyError
from vibrofocus.studies import StudyStore
from vibrofocus.studies.protocol import StudyDesign, plan_trials
from vibrofocus.studies.protocol_files import (MAX_PROTOCOL_BYTES, load_protocol, parse_protocol,
                                               shipped_protocol)

from .corner_protocol import corner_protocol

SEEDS = (0, 1, 2**40 + 3)
PAPER_METHODS = ("funneling", "inverse", "combination")

#: sha256 (first 16 hex digits) of the trial list, as planned by vibrofocus before protocol
#: files (main at 37770a8: StudyDesign(study=s) and plan_trials), per seed; the same for both
#: studies, whose designs differ only in the answer they take.
BEFORE = {0: "aff964b3675bec70", 1: "03942c5f6c06f56f", 2**40 + 3: "d5dad084db3800c3"}

SMALL = corner_protocol("corner-pilot", "location")


def _digest(trials):
    return hashlib.sha256(repr([(t.phase, t.trial, t.method, t.target) for t in trials]).encode()).hexdigest()[:16]


@pytest.mark.parametrize("study", [1, 2])
@pytest.mark.parametrize("seed", SEEDS)
def test_paper_protocol_files_plan_todays_trials(study, seed):
    shipped = shipped_protocol(f"paper-study{study}")
    assert [b.study for b in shipped.blocks] == [study]
    from_file = plan_trials(shipped.design(0), seed)
    built_in = plan_trials(StudyDesign.from_config(study, None), seed)
    # The paper's design written out independently of the files (PAPER: 3 methods x 9
    # locations x 3 repetitions after 5 training trials).
    written = StudyDesign(study=study, methods=PAPER_METHODS, locations=tuple(range(1, 10)), repetitions=3,
                          n_training=5, levels="paper")
    assert from_file == built_in == plan_trials(written, seed)
    assert _digest(from_file) == BEFORE[seed]
    main = [t.condition() for t in from_file if t.phase == "main"]
    assert len(main) == 81 and len(from_file) == 86
    assert set(Counter(main).values()) == {3} and len(Counter(main)) == 27


def test_block_seed_is_stored_and_plans_the_same_order_for_everyone(tmp_path):
    protocol = parse_protocol(SMALL, "small.toml")
    block = protocol.blocks[0]
    assert block.session_seed(123) == 7 and protocol.design(0).level_db == -6.0
    config = protocol.session_config(0)
    assert config["protocol"] == "corner-pilot" and config["level_db"] == -6.0 and config["level_unit"] == "dB"
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 1, seed=block.session_seed(99), config=config)
        info = store.session(sid)
        assert info.config["protocol"] == "corner-pilot" and info.design == protocol.design(0)
        assert store.planned_trials(sid) == plan_trials(protocol.design(0), 7, session_id=sid)


def test_a_blocks_represent_after_xrun_reaches_its_session_config():
    assert parse_protocol(SMALL, "small.toml").session_config(0)["represent_after_xrun"] == 1
    three = parse_protocol(SMALL + "represent_after_xrun = 3\n", "small.toml")
    assert three.session_config(0)["represent_after_xrun"] == 3
    with pytest.raises(StudyError, match=r"line 12, blocks\[0\].represent_after_xrun"):
        parse_protocol(SMALL + "represent_after_xrun = 11\n", "small.toml")


def test_an_old_database_reads_as_the_papers_protocol(tmp_path):
    db = tmp_path / "old.db"
    with StudyStore(db) as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 2, seed=3)
        trial = store.next_trial(sid)
        store.record_answer(sid, trial.trial_index, "4 5", 1.0, answer_id="a1")
    con = sqlite3.connect(db)  # a session stored before sessions named their protocol
    config = json.loads(con.execute("SELECT config FROM sessions").fetchone()[0])
    assert config.pop("protocol") == "paper-study2" and config.pop("block") == 0
    con.execute("UPDATE sessions SET config = ?", (json.dumps(config),))
    con.commit()
    con.close()
    with StudyStore(db, create=False) as store:
        assert store.trial_rows()[0]["protocol"] == "paper-study2"
        n = store.export_trials_csv(tmp_path / "t.csv")
        # resumed, not planned again, by a run of the paper's Study 2
        again, created = store.open_session("p1", 2, seed=9, reuse="open")
        assert (again, created) == (sid, False)
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert n == 1 and rows[0]["protocol"] == "paper-study2"


# ------------------------------------------------------------------ bad protocols
BAD = {
    "unknown-method": (SMALL.replace('"inverse"]', '"telepathy"]'), "line 6, blocks[0].methods: unknown method 'telepathy'"),
    "missing-field": (SMALL.replace("repetitions = 1\n", ""), "line 4, blocks[0].repetitions: missing"),
    "wrong-type": (SMALL.replace("repetitions = 1", 'repetitions = "three"'), "line 9, blocks[0].repetitions: Input"),
    "unknown-field": (SMALL.replace("seed = 7", "sead = 7"), "line 11, blocks[0].sead: unknown field"),
    "not-toml": (SMALL.replace("levels = [-6.0]", "levels = [-6.0"), "not valid TOML"),
    "db-sl": (SMALL.replace("levels = [-6.0]", 'levels = [20.0]\nlevel_unit = "dB SL"'),
              "line 9, blocks[0].level_unit: levels in dB SL need"),
}


def _run(tmp_path, text, *, size=None):
    path = tmp_path / "protocol.toml"
    path.write_text(text if size is None else text + "#" * (size - len(text)))
    before = set(tmp_path.iterdir())
    result = CliRunner().invoke(app, ["simulate-study", "--protocol", str(path), "-n", "1", "--db",
                                      str(tmp_path / "s.db"), "--quiet"])
    assert result.exit_code != 0
    assert set(tmp_path.iterdir()) == before, "a refused protocol wrote something"
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    return lines[0]


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_protocol_gets_one_line_naming_its_field_and_writes_nothing(tmp_path, case):
    text, expected = BAD[case]
    line = _run(tmp_path, text)
    assert "protocol.toml" in line and expected in line, line


def test_a_10_mb_protocol_is_refused_before_it_is_read(tmp_path):
    line = _run(tmp_path, SMALL, size=10_000_000)
    assert f"10000000 bytes, more than the {MAX_PROTOCOL_BYTES} allowed" in line, line


@pytest.mark.slow
def test_a_level_over_the_drive_limit_is_refused_before_anything_is_written(tmp_path):
    line = _run(tmp_path, SMALL.replace("levels = [-6.0]", "levels = [12.0]"))
    assert "line 8, blocks[0].levels: +12 dB re the paper levels needs" in line and "10 V drive limit" in line, line


def test_study_run_refuses_a_bad_protocol_before_anything(tmp_path, calibration_file):
    path = tmp_path / "protocol.toml"
    path.write_text(SMALL.replace('"inverse"]', '"telepathy"]'))
    result = CliRunner().invoke(app, ["study", "run", "--participant", "p-real", "--db", str(tmp_path / "s.db"),
                                      "--calibration", str(calibration_file), "--protocol", str(path)])
    assert result.exit_code != 0 and "line 6, blocks[0].methods: unknown method 'telepathy'" in result.output
    assert not (tmp_path / "s.db").exists()


def test_load_protocol_names_the_file(tmp_path):
    with pytest.raises(StudyError, match="no such file"):
        load_protocol(tmp_path / "none.toml")


# ------------------------------------------------------------------ a small protocol, end to end
@pytest.mark.slow
def test_a_small_protocol_runs_through_simulate_study(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(SMALL + SMALL.split("\n\n", 1)[1].replace('"location"', '"locations"').replace("seed = 7",
                                                                                                       'seed = "session"'))
    db, out = tmp_path / "s.db", tmp_path / "t.csv"
    result = CliRunner().invoke(app, ["simulate-study", "--protocol", str(path), "-n", "1", "--db", str(db),
                                      "--trials-csv", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == 2 * (4 + 1)  # per block: 2 methods x 2 locations x 1 repetition + 1 training
    assert {r["protocol"] for r in rows} == {"corner-pilot"} and {r["study"] for r in rows} == {"1", "2"}
    with StudyStore(db, create=False) as store:
        sessions = store.sessions()
        assert [(s.config["protocol"], s.config["block"], s.design.level_db) for s in sessions] == [
            ("corner-pilot", 0, -6.0), ("corner-pilot", 1, -6.0)]
        assert sessions[0].seed == 7
    # -6 dB re the paper's levels: every drive half the paper's (the inverse filter, scaled to
    # the 10 V limit at paper levels, plays at 10 V x 10^(-6/20)).
    inverse = {float(r["drive_peak_v"]) for r in rows if r["method"] == "inverse"}
    assert max(inverse) == pytest.approx(10.0 * 10 ** (-6 / 20), rel=1e-9)
