"""A BIDS export into a lab's dataset keeps the lab's words and files its sessions where the
lab wants them (issue 54, item 5)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.errors import ValidationError
from vibrofocus.studies.bids import export_bids

runner = CliRunner()
HEADER = "participant,study,phase,trial,method,target,response,rt_s,session,session_status,dry_run\n"


@pytest.fixture
def trials(tmp_path):
    path = tmp_path / "trials.csv"
    path.write_text(HEADER + "P1,1,main,1,inverse,5,5,0.5,3,completed,0\nP1,1,main,2,funneling,4,4,0.6,3,completed,0\n"
                    "P1,2,main,1,inverse,5,5 6,0.7,4,completed,0\nP1,1,main,1,inverse,1,1,0.5,5,completed,0\n")
    return path


def _lab_dataset(root):
    root.mkdir()
    (root / "participants.tsv").write_text("participant_id\tage\nsub-P1\t31\n")
    (root / "participants.json").write_text(json.dumps({
        "participant_id": {"Description": "Our lab's pseudonym, as on the consent form."},
        "age": {"Description": "Age in years.", "Units": "year"}}))
    (root / "dataset_description.json").write_text(json.dumps({"Name": "Our EEG study", "BIDSVersion": "1.10.0",
                                                               "Authors": ["Our PI"]}))


def test_the_labs_participant_id_description_stays(tmp_path, trials):
    root = tmp_path / "lab"
    _lab_dataset(root)
    export_bids(trials, root, session_labels={3: "01"})
    described = json.loads((root / "participants.json").read_text())
    assert described["participant_id"] == {"Description": "Our lab's pseudonym, as on the consent form."}
    assert described["age"]["Units"] == "year" and "source_id" in described and "simulated" in described


def test_sessions_are_filed_under_the_labels_given(tmp_path, trials):
    root = tmp_path / "lab"
    _lab_dataset(root)
    export_bids(trials, root, session_labels={3: "01", 4: "02"})
    beh = sorted(p.relative_to(root).as_posix() for p in root.glob("sub-P1/*/beh/*_events.tsv"))
    assert beh == ["sub-P1/ses-01/beh/sub-P1_ses-01_task-localization1_events.tsv",
                   "sub-P1/ses-02/beh/sub-P1_ses-02_task-localization2_events.tsv",
                   "sub-P1/ses-5/beh/sub-P1_ses-5_task-localization1_events.tsv"]


@pytest.mark.parametrize("labels, words", [({3: "01", 5: "01"}, "would both be ses-01"), ({3: "0-1"}, "ASCII"),
                                           ({"3": "01"}, "database id")])
def test_bad_session_labels_are_refused_before_anything_is_written(tmp_path, trials, labels, words):
    with pytest.raises(ValidationError, match=words):
        export_bids(trials, tmp_path / "out", session_labels=labels)
    assert not (tmp_path / "out").exists()


def test_author_and_license_not_applied_to_the_labs_description_are_named(tmp_path, trials):
    root = tmp_path / "lab"
    _lab_dataset(root)
    before = (root / "dataset_description.json").read_bytes()
    result = runner.invoke(app, ["export", str(trials), "--bids", str(root), "--author", "Ada Lovelace",
                                 "--license", "CC0", "--session-label", "3=01"])
    assert result.exit_code == 0, result.output
    out = " ".join(result.output.split())
    assert "--author and --license not applied" in out and "add them there" in out
    assert (root / "dataset_description.json").read_bytes() == before  # the lab's file is not touched
    bad = runner.invoke(app, ["export", str(trials), "--bids", str(tmp_path / "x"), "--session-label", "three"])
    assert bad.exit_code == 2 and "e.g. 3=01" in " ".join(bad.output.split())
