"""``export --bids`` into an existing dataset: a lab's files stay byte for byte, vibrofocus replaces only its own."""

from __future__ import annotations

import hashlib
import json
import os

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.errors import OutputError, StudyError, ValidationError
from vibrofocus.io.bids import bids_label, read_bids_trials_table
from vibrofocus.io.bids_merge import MANIFEST_NAME, merge_participants_tsv
from vibrofocus.studies.bids import export_bids

runner = CliRunner()
HEADER = "participant,study,phase,trial,method,target,response,rt_s\n"
PARTICIPANTS = "participant_id\tage\tsex\nsub-sim001\t31\tF\nsub-X\t25\tM\n"


def _trials(path, pid, target=5, n=2):
    path.write_text(HEADER + "".join(f"{pid},1,main,{i + 1},inverse,{target},{target},0.5\n" for i in range(n)))
    return path


def _lab_dataset(root):
    """A lab's dataset with EEG and MRI of two subjects, one of whom also does the tactile study."""
    rng = __import__("numpy").random.default_rng(3)
    ds = root / "ds"
    ds.mkdir()
    (ds / "dataset_description.json").write_text('{"Name": "lab EEG", "BIDSVersion": "1.8.0"}\n')
    (ds / "participants.tsv").write_text(PARTICIPANTS)
    (ds / "participants.json").write_text('{"age": {"Units": "years"}}\n')
    for sub in ("sim001", "X"):
        for datatype, name in (("eeg", "task-rest_eeg.edf"), ("anat", "T1w.nii.gz")):
            folder = ds / f"sub-{sub}" / datatype
            folder.mkdir(parents=True)
            (folder / f"sub-{sub}_{name}").write_bytes(rng.bytes(500))
    return ds


def _hashes(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in folder.rglob("*") if p.is_file()}


def _tsv(path):
    lines = path.read_text().splitlines()
    header = lines[0].split("\t")
    return [dict(zip(header, line.split("\t"))) for line in lines[1:]]


def test_a_labs_eeg_and_mri_files_stay_byte_for_byte_and_participants_keep_their_columns(tmp_path):
    ds = _lab_dataset(tmp_path)
    before = _hashes(ds)
    result = runner.invoke(app, ["export", str(_trials(tmp_path / "a.csv", "sim-001")), "--bids", str(ds)])
    assert result.exit_code == 0, result.output
    assert "added to the existing BIDS dataset" in result.output and "kept the dataset's own" in result.output
    after = _hashes(ds)
    foreign = set(before) - {"participants.tsv", "participants.json"}
    assert {k: after.get(k) for k in foreign} == {k: before[k] for k in foreign}
    # participants.tsv: every cell of the lab's kept; vibrofocus's columns added after them.
    rows = _tsv(ds / "participants.tsv")
    assert [(r["participant_id"], r["age"], r["sex"]) for r in rows] == [("sub-sim001", "31", "F"), ("sub-X", "25", "M")]
    assert [(r["source_id"], r["simulated"]) for r in rows] == [("sim-001", "false"), ("n/a", "n/a")]
    assert json.loads((ds / "participants.json").read_text())["age"] == {"Units": "years"}
    assert (ds / "sub-sim001/beh/sub-sim001_task-localization1_events.tsv").is_file()
    assert set(json.loads((ds / MANIFEST_NAME).read_text())["files"]) == {
        "README", "sub-sim001/beh/sub-sim001_task-localization1_events.tsv",
        "sub-sim001/beh/sub-sim001_task-localization1_events.json"}
    assert len(read_bids_trials_table(ds)) == 2


def test_a_second_study_keeps_the_first_and_a_re_export_replaces_only_its_own(tmp_path):
    ds = _lab_dataset(tmp_path)
    first, second = _trials(tmp_path / "a.csv", "sim-001"), _trials(tmp_path / "b.csv", "sim-002", target=4, n=3)
    export_bids(first, ds)
    export_bids(second, ds)
    assert sorted(p.name for p in ds.glob("sub-*")) == ["sub-X", "sub-sim001", "sub-sim002"]
    table = read_bids_trials_table(ds)
    assert sorted(table.groupby("participant").size().items()) == [("sim-001", 2), ("sim-002", 3)]
    rows = _tsv(ds / "participants.tsv")
    assert [r["participant_id"] for r in rows] == ["sub-sim001", "sub-X", "sub-sim002"]
    assert rows[2]["age"] == "n/a" and rows[0]["age"] == "31"
    # Exporting the first study again (more trials now) replaces its files, and only them.
    snapshot = _hashes(ds)
    export_bids(_trials(first, "sim-001", n=4), ds)
    changed = {k for k, v in _hashes(ds).items() if snapshot.get(k) != v}
    assert changed == {"sub-sim001/beh/sub-sim001_task-localization1_events.tsv", MANIFEST_NAME}
    assert len(read_bids_trials_table(ds)) == 4 + 3


def test_a_file_in_the_way_is_refused_and_nothing_changes_unless_forced(tmp_path):
    ds = _lab_dataset(tmp_path)
    source = _trials(tmp_path / "a.csv", "sim-001")
    own = ds / "sub-sim001/beh/sub-sim001_task-localization1_events.tsv"
    own.parent.mkdir()
    own.write_text("onset\tduration\nthe lab's own\n")
    before = _hashes(ds)
    result = runner.invoke(app, ["export", str(source), "--bids", str(ds)])
    assert result.exit_code == 2 and result.output.count("error:") == 1
    assert "vibrofocus did not write" in result.output and "--force" in result.output
    assert _hashes(ds) == before and not (ds / MANIFEST_NAME).exists()
    result = runner.invoke(app, ["export", str(source), "--bids", str(ds), "--force"])
    assert result.exit_code == 0, result.output
    assert "the lab's own" not in own.read_text() and (ds / "sub-X/eeg/sub-X_task-rest_eeg.edf").is_file()
    # An export's file edited afterwards is the lab's now: refused again.
    own.write_text(own.read_text() + "edited\n")
    with pytest.raises(OutputError, match="edited since"):
        export_bids(source, ds)
    assert own.read_text().endswith("edited\n")


def test_a_new_folder_is_written_whole_with_its_manifest(tmp_path):
    out = tmp_path / "new"
    counts = export_bids(_trials(tmp_path / "a.csv", "sim-001"), out)
    assert counts["merged"] is False and counts["kept"] == []
    manifest = json.loads((out / MANIFEST_NAME).read_text())["files"]
    assert manifest["dataset_description.json"] == hashlib.sha256((out / "dataset_description.json").read_bytes()).hexdigest()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left


def test_a_symlinked_dataset_folder_is_written_through(tmp_path):
    target = _lab_dataset(tmp_path)
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    for _ in range(2):
        result = runner.invoke(app, ["export", str(_trials(tmp_path / "a.csv", "sim-001")), "--bids", str(link)])
        assert result.exit_code == 0, result.output
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert (target / "sub-sim001/beh/sub-sim001_task-localization1_events.tsv").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "ds", "link"]  # no .link.*.tmp
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "missing")
    result = runner.invoke(app, ["export", str(tmp_path / "a.csv"), "--bids", str(dangling)])
    assert result.exit_code == 2 and "symbolic link to a missing folder" in result.output


def test_participants_rows_untouched_by_the_export_stay_byte_for_byte():
    text = "participant_id\tage\r\nsub-A\t 30 \r\nsub-B\tn/a\r\n"
    merged = merge_participants_tsv(text, ["participant_id", "age"], [{"participant_id": "sub-B", "age": "40"}])
    assert merged == "participant_id\tage\r\nsub-A\t 30 \r\nsub-B\t40\r\n"
    assert merge_participants_tsv("age\n1\n", ["participant_id"], [{"participant_id": "sub-A"}]) is None


def test_ids_bids_cannot_label_are_refused_with_the_reason(tmp_path):
    with pytest.raises(ValidationError, match="only A-Z, a-z and 0-9"):
        bids_label("李")
    assert bids_label("李-01") == "01"
    with pytest.raises(ValidationError, match="control character"):
        bids_label("P\t01")
    with pytest.raises(StudyError, match="control character"):
        export_bids(_trials(tmp_path / "t.csv", '"P\t01"'), tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_the_same_label_from_another_study_is_a_file_in_the_way(tmp_path):
    ds = tmp_path / "ds"
    export_bids(_trials(tmp_path / "a.csv", "sim-001"), ds)
    events = ds / "sub-sim001/beh/sub-sim001_task-localization1_events.tsv"
    before = events.read_bytes()
    other = _trials(tmp_path / "b.csv", "sim-001", target=4, n=3)  # another study's sim-001
    with pytest.raises(OutputError, match="vibrofocus did not write"):
        export_bids(other, ds)
    assert events.read_bytes() == before
    export_bids(other, ds, force=True)
    assert len(read_bids_trials_table(ds)) == 3
