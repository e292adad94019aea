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


# --------------------------------------------------------------------------- a dataset someone else can write
EVENTS = "sub-sim001/beh/sub-sim001_task-localization1_events.tsv"


def _plant(kind, ds, source, outside):
    """Issue 53 item 3: a link inside the dataset, to a file or folder outside it. Returns the --force flag."""
    victim = outside / "precious.txt"
    if kind in ("events_known_hash", "events_other_hash"):
        events = ds / EVENTS
        events.parent.mkdir(parents=True)
        events.symlink_to(victim)
        digest = hashlib.sha256(victim.read_bytes()).hexdigest() if kind == "events_known_hash" else "0" * 64
        (ds / MANIFEST_NAME).write_text(json.dumps({"format": "vibrofocus BIDS export manifest", "version": 1,
                                                    "files": {EVENTS: digest},
                                                    "sources": {EVENTS: str(source.resolve())}}))
        return kind == "events_other_hash"
    if kind == "manifest":
        (ds / MANIFEST_NAME).symlink_to(victim)
        return True
    if kind == "participants":
        victim.write_text(PARTICIPANTS)
        (ds / "participants.tsv").unlink()
        (ds / "participants.tsv").symlink_to(victim)
        return False
    if kind == "sidecar_folder":  # a whole beh/ folder of a subject without data of the lab
        (ds / "sub-sim001/beh").symlink_to(outside, target_is_directory=True)
        return True
    (ds / "sub-sim002").symlink_to(outside, target_is_directory=True)
    return False


@pytest.mark.parametrize("kind, link", [
    ("events_known_hash", EVENTS), ("events_other_hash", EVENTS), ("manifest", MANIFEST_NAME),
    ("participants", "participants.tsv"), ("subject_folder", "sub-sim002"), ("sidecar_folder", "sub-sim001/beh"),
])
def test_a_link_inside_the_dataset_is_refused_even_with_force_and_nothing_outside_changes(tmp_path, kind, link):
    """On 37770a8 each of these replaced or merged a file outside the dataset (a plain export, no --force, when
    the manifest gave the outside file's hash), or made ses-*/ folders in a folder outside."""
    ds = _lab_dataset(tmp_path)
    source = _trials(tmp_path / "a.csv", "sim-001")
    source.write_text(source.read_text() + "sim-002,1,main,1,inverse,4,4,0.5\n")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "precious.txt").write_text("the user's own file\n")
    force = _plant(kind, ds, source, outside)
    before, inside = _hashes(outside), _hashes(ds)
    links = sorted(str(p.relative_to(ds)) for p in ds.rglob("*") if p.is_symlink())
    for flags in ([], ["--force"]) if force else ([],):
        result = runner.invoke(app, ["export", str(source), "--bids", str(ds), *flags])
        assert result.exit_code == 2 and result.output.count("error:") == 1, result.output
        assert f"{link} is a link: refused" in result.output and "nothing was changed" in result.output
    assert _hashes(outside) == before and sorted(p.name for p in outside.iterdir()) == ["precious.txt"]
    assert _hashes(ds) == inside and links == sorted(str(p.relative_to(ds)) for p in ds.rglob("*") if p.is_symlink())


def test_the_write_itself_never_follows_a_link_below_its_root(tmp_path):
    """The atomic layer's own rule (for a link made between the export's check and its write): a link at the
    file or on a folder below ``within`` is refused, and the rename replaces names, never a link's target."""
    from vibrofocus._atomic import atomic_write, read_below, write_text

    root, outside = tmp_path / "ds", tmp_path / "outside"
    (root / "sub-1").mkdir(parents=True)
    outside.mkdir()
    victim = outside / "x.tsv"
    victim.write_text("mine\n")
    (root / "sub-1" / "x.tsv").symlink_to(victim)
    (root / "sub-2").symlink_to(outside, target_is_directory=True)
    for target in (root / "sub-1" / "x.tsv", root / "sub-2" / "x.tsv", root / "sub-2" / "new" / "y.tsv"):
        with pytest.raises(OutputError, match=r"is a link: refused"):
            write_text(target, "export\n", within=root, parents=True)
        with pytest.raises(OutputError, match=r"is a link: refused"):
            read_below(root, target)
    assert victim.read_text() == "mine\n" and sorted(p.name for p in outside.iterdir()) == ["x.tsv"]
    # A link made while the file is being written: the rename is refused, the target untouched.
    with pytest.raises(OutputError, match=r"sub-3/x.tsv is a link: refused"):
        with atomic_write(root / "sub-3" / "x.tsv", "w", within=root, parents=True) as fh:
            fh.write("export\n")
            (root / "sub-3" / "x.tsv").symlink_to(victim)
    assert victim.read_text() == "mine\n" and [p.name for p in (root / "sub-3").iterdir()] == ["x.tsv"]
    # A FIFO where a file is read is refused without being opened (it would block).
    os.mkfifo(root / "fifo")
    with pytest.raises(OutputError, match="not a regular file"):
        read_below(root, root / "fifo")
    write_text(root / "sub-4" / "beh" / "z.tsv", "ok\n", within=root, parents=True)
    assert read_below(root, root / "sub-4" / "beh" / "z.tsv") == b"ok\n"


def test_a_crlf_participants_file_keeps_its_line_endings(tmp_path):
    """On 37770a8 the file was read with universal newlines, so the merge never saw \\r\\n and wrote \\n."""
    ds = _lab_dataset(tmp_path)
    (ds / "participants.tsv").write_bytes(PARTICIPANTS.replace("\n", "\r\n").encode())
    (ds / "participants.json").write_bytes(b'{\r\n  "age": {"Units": "years"}\r\n}\r\n')
    export_bids(_trials(tmp_path / "a.csv", "sim-001"), ds)
    tsv = (ds / "participants.tsv").read_bytes()
    assert tsv.startswith(b"participant_id\tage\tsex\t") and tsv.count(b"\r\n") == tsv.count(b"\n") == 3
    assert b"sub-X\t25\tM\tn/a" in tsv
    js = (ds / "participants.json").read_bytes()
    assert js.count(b"\r\n") == js.count(b"\n") > 3 and json.loads(js)["age"] == {"Units": "years"}


def test_a_second_export_into_a_dataset_being_written_says_so(tmp_path):
    """On 37770a8 two exports at once failed with false reasons ("it is the study database this command reads",
    files "vibrofocus did not write"); the dataset's folder is locked while one export writes it."""
    import fcntl

    ds = _lab_dataset(tmp_path)
    before = _hashes(ds)
    source = _trials(tmp_path / "a.csv", "sim-001")
    fd = os.open(ds, os.O_RDONLY | os.O_DIRECTORY)  # what the other export holds while it writes
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        result = runner.invoke(app, ["export", str(source), "--bids", str(ds)])
        assert result.exit_code == 2 and result.output.count("error:") == 1
        assert f"another export is writing the BIDS dataset {ds} now; nothing was changed" in \
            " ".join(result.output.split())
        assert _hashes(ds) == before
    finally:
        os.close(fd)
    assert runner.invoke(app, ["export", str(source), "--bids", str(ds)]).exit_code == 0
