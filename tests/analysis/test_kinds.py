"""One kind of participant per analysis: people on hardware, simulated participants, or
rehearsals on the simulated rig, never pooled; the report says what it left out and why
(docs/file-formats.md, trials file)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from vibrofocus.analysis import load_trials
from vibrofocus.cli.main import app
from vibrofocus.errors import ValidationError
from vibrofocus.studies import StudyStore

#: (participant, simulated, the session's stored rig): simulated sessions of an older
#: vibrofocus stored no rig; P07 rehearsed on the simulated rig.
PEOPLE = [("S01", True, None), ("S02", True, None), ("S03", True, None), ("P07", False, "simulated")]


def _database(path, people, seed=5):
    rng = np.random.default_rng(seed)
    with StudyStore(path) as store:
        for pid, simulated, rig in people:
            store.add_participant(pid, simulated=simulated)
            config = {"repetitions": 1, "n_training": 1, **({"rig": rig} if rig else {})}
            sid = store.create_session(pid, 1, seed=int(rng.integers(2**31)), config=config)
            while (t := store.next_trial(sid)) is not None:
                store.record_answer(sid, t.trial_index, int(rng.integers(1, 10)), float(rng.uniform(0.4, 1.5)),
                                    answer_id=f"{pid}-{t.trial_index}")
    return path


def test_every_export_row_names_its_rig(tmp_path):
    db = _database(tmp_path / "study.db", PEOPLE)
    out = tmp_path / "trials.csv"
    with StudyStore(db, create=False) as store:
        store.export_trials_csv(out)
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {(r["participant"], r["rig"], r["simulated"]) for r in rows} == {
        ("S01", "simulated", "1"), ("S02", "simulated", "1"), ("S03", "simulated", "1"), ("P07", "simulated", "0")}


def test_the_default_refuses_a_database_without_people_on_hardware(tmp_path):
    db = _database(tmp_path / "study.db", PEOPLE)
    res = CliRunner().invoke(app, ["analyze", str(db), "--out", str(tmp_path / "r"), "--keep-dry-runs"])
    assert res.exit_code == 2, res.output
    said = " ".join(res.output.split())
    assert "no people on hardware" in said and "3 simulated participant(s) (--simulated)" in said
    assert "1 person(s) rehearsing on the simulated rig (--rehearsals)" in said
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_simulated_participants_are_analysed_alone_and_the_rehearsal_is_listed(tmp_path):
    db = _database(tmp_path / "study.db", PEOPLE)
    res = CliRunner().invoke(app, ["analyze", str(db), "--out", str(tmp_path / "r"), "--keep-dry-runs",
                                   "--simulated"])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["study1"]["participants"] == ["S01", "S02", "S03"]
    assert report["simulated"]["participants"] == ["S01", "S02", "S03"]
    (left,) = [e for e in report["exclusions"] if e["participant"] == "P07"]
    assert "rehearsal on the simulated rig" in left["reason"] and "--rehearsals" in left["reason"]
    assert "rehearsal on the simulated rig" in (tmp_path / "r" / "report.html").read_text()
    assert "P07" in res.output and "rehearsal on the simulated rig" in " ".join(res.output.split())


def test_people_on_hardware_are_the_default_and_rehearsals_come_only_on_request(tmp_path):
    db = _database(tmp_path / "study.db", PEOPLE + [("P08", False, "audio")])
    with StudyStore(db, create=False) as store:
        store.export_trials_csv(tmp_path / "trials.csv")
    people = load_trials(tmp_path / "trials.csv", keep_dry_runs=True, kind="people")
    assert sorted(people["participant"].unique()) == ["P08"]
    reasons = {e["participant"]: e["reason"] for e in people.attrs["exclusions"]}
    assert set(reasons) == {"S01", "S02", "S03", "P07"}
    assert "simulated participant" in reasons["S01"] and "--simulated" in reasons["S01"]
    assert reasons["P07"].startswith("session ") and "felt nothing" in reasons["P07"]
    assert people.attrs["simulated_participants"] == []  # none analysed: no banner
    rehearsals = load_trials(tmp_path / "trials.csv", keep_dry_runs=True, kind="rehearsals")
    assert sorted(rehearsals["participant"].unique()) == ["P07"]
    assert len(load_trials(tmp_path / "trials.csv", keep_dry_runs=True)) == len(people) * 5  # "all": every row
    with pytest.raises(ValidationError, match="kind must be one of"):
        load_trials(tmp_path / "trials.csv", kind="everyone")
