"""``export --bids`` checked with the field's own tools: the official BIDS validator (bids-validator-deno)
and mne-bids' events reader; metadata from options, a template, and kept on re-export."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.errors import ValidationError
from vibrofocus.studies import StudyStore
from vibrofocus.studies.bids import export_bids

runner = CliRunner()
DOCS = Path(__file__).resolve().parents[2] / "docs" / "bids.md"
METADATA = {"Authors": ["Ada Lovelace", "Alan Turing"], "License": "CC0", "InstitutionName": "Example Lab",
            "InstitutionAddress": "1 Example Street, Example City", "InstitutionalDepartmentName": "Haptics"}
CSV_HEADER = ("participant,study,phase,trial,method,target,response,rt_s,session,session_status,dry_run,"
              "onset_host_s,onset_device_s,onset_clock\n")


def _validator() -> str:
    found = shutil.which("bids-validator-deno") or str(Path(sys.executable).with_name("bids-validator-deno"))
    if not Path(found).is_file():
        pytest.skip("bids-validator-deno is not installed (pip install 'vibrofocus[test]')")
    return found


def validate(folder: Path) -> tuple[int, list[tuple[str, str, str]]]:
    """The validator's exit status and its issues as (severity, code, subCode)."""
    out = subprocess.run([_validator(), str(folder), "--json"], capture_output=True, text=True, timeout=300)
    issues = json.loads(out.stdout)["issues"]["issues"]
    return out.returncode, [(i["severity"], i["code"], i.get("subCode") or "") for i in issues]


def expected_warnings() -> dict[str, set[tuple[str, str]]]:
    """docs/bids.md's table of the warnings behaviour-only data keeps: 'always' and 'without metadata'."""
    rows = re.findall(r"^\| `([A-Z_]+)` \|\s*`?([A-Za-z]*)`?\s*\| (always|without metadata) \|", DOCS.read_text(),
                      re.MULTILINE)
    table: dict[str, set[tuple[str, str]]] = {"always": set(), "without metadata": set()}
    for code, sub, when in rows:
        table[when].add((code, sub))
    assert table["always"] and table["without metadata"], "docs/bids.md lists the expected warnings"
    return table


def _minimax_database(path: Path) -> Path:
    """A real study database whose sessions compare inverse, minimax and constrained, with monotonic onsets."""
    with StudyStore(path) as store:
        store.add_participant("p-01")
        for study in (1, 2):
            sid = store.create_session("p-01", study, seed=study, config={
                "repetitions": 1, "n_training": 0, "methods": ["inverse", "minimax", "constrained"],
                "locations": [4, 6]})
            for k in range(6):
                store.record_answer(sid, k, 4 if study == 1 else [4, 6], 0.5 + 0.01 * k, answer_id=f"a{study}{k}",
                                    onset_s=1000.0 + 3.0 * k, onset_device_s=2.5 + 3.0 * k,
                                    onset_clock="simulated_samples")
    return path


def _onset_csv(path: Path) -> Path:
    path.write_text(CSV_HEADER + "".join(
        f"P01,1,main,{k + 1},{('inverse', 'minimax', 'lab_taps', 'inverse')[k]},5,5,0.4,3,completed,0,{500.25 + 2.5 * k!r},"
        f"{1.0 + 2.5 * k!r},simulated_samples\n" for k in range(4)))
    return path


def test_the_official_validator_accepts_every_export_with_only_the_documented_warnings(tmp_path):
    expected = expected_warnings()
    db = _minimax_database(tmp_path / "minimax.db")
    csv_path = _onset_csv(tmp_path / "trials.csv")
    for name, source in (("minimax", db), ("csv", csv_path)):
        out = tmp_path / f"bids-{name}"
        export_bids(source, out, metadata=METADATA)
        status, issues = validate(out)
        assert status == 0 and [i for i in issues if i[0] == "error"] == [], issues
        assert {i[1:] for i in issues} <= expected["always"], issues
        # Without metadata: still no error, and the warnings the docs list for that.
        bare = tmp_path / f"bare-{name}"
        export_bids(source, bare)
        status, issues = validate(bare)
        assert status == 0 and [i for i in issues if i[0] == "error"] == [], issues
        assert {i[1:] for i in issues} <= expected["always"] | expected["without metadata"], issues
        assert ("NO_AUTHORS", "Authors") in {i[1:] for i in issues}


def every_event_read_by_mne_bids(folder: Path) -> None:
    """mne-bids reads each events file's rows with numeric onsets (it drops rows whose onset is n/a)."""
    mne_bids = pytest.importorskip("mne_bids")
    files = sorted(folder.glob("sub-*/ses-*/beh/*_events.tsv"))
    assert files
    for path in files:
        rows = path.read_text().splitlines()[1:]
        kwargs = mne_bids.events_file_to_annotation_kwargs(path, verbose="error")
        assert len(kwargs["onset"]) == len(rows) > 0
        assert kwargs["onset"][0] == 0 and all(o >= 0 for o in kwargs["onset"])


def test_mne_bids_reads_every_event_of_a_csv_with_onsets(tmp_path):
    csv_path = _onset_csv(tmp_path / "trials.csv")
    out = tmp_path / "bids"
    export_bids(csv_path, out)
    every_event_read_by_mne_bids(out)
    (events,) = out.glob("sub-P01/ses-3/beh/sub-P01_ses-3_task-localization1_events.tsv")
    onsets = [float(line.split("\t")[0]) for line in events.read_text().splitlines()[1:]]
    assert onsets == pytest.approx([0.0, 2.5, 5.0, 7.5], abs=1e-12)  # onset_host_s - the first


def test_a_labs_own_method_is_a_described_level(tmp_path):
    out = tmp_path / "bids"
    export_bids(_onset_csv(tmp_path / "t.csv"), out)
    (sidecar,) = out.glob("sub-P01/ses-3/beh/*_events.json")
    levels = json.loads(sidecar.read_text())["method"]["Levels"]
    assert set(levels) == {"inverse", "minimax", "lab_taps"} and "lab's own" in levels["lab_taps"]


def test_levels_come_from_the_data_and_no_column_is_named_like_an_entity(tmp_path):
    out = tmp_path / "bids"
    export_bids(_minimax_database(tmp_path / "m.db"), out)
    sidecars = sorted(out.glob("sub-p01/ses-*/beh/*_events.json"))
    assert len(sidecars) == 2  # one per session
    for path in sidecars:
        meta = json.loads(path.read_text())
        assert set(meta["method"]["Levels"]) == {"inverse", "minimax", "constrained"}
        assert "energy-contrast" in meta["method"]["Levels"]["constrained"]
        assert meta["TaskDescription"] and meta["Instructions"]
        assert meta["StimulusPresentation"]["SoftwareName"] == "vibrofocus"
        header = path.with_suffix(".tsv").read_text().splitlines()[0].split("\t")
        entities = {"subject", "session", "task", "acquisition", "run", "session_id", "participant_id", "sub", "ses"}
        assert not set(header) & entities


def test_metadata_from_options_and_a_template_is_kept_on_re_export(tmp_path):
    csv_path = _onset_csv(tmp_path / "trials.csv")
    out = tmp_path / "bids"
    template = tmp_path / "dataset_description.json"  # a lab's description as the template
    template.write_text(json.dumps({"Name": "Forearm taps", "BIDSVersion": "1.8.0", "Funding": ["Grant 42"],
                                    "InstitutionAddress": "1 Example Street"}))
    result = runner.invoke(app, ["export", str(csv_path), "--bids", str(out), "--author", "Ada Lovelace",
                                 "--author", "Alan Turing", "--license", "CC-BY-4.0", "--institution", "Example Lab",
                                 "--metadata", str(template)])
    assert result.exit_code == 0, result.output
    description = json.loads((out / "dataset_description.json").read_text())
    assert description["Authors"] == ["Ada Lovelace", "Alan Turing"] and description["License"] == "CC-BY-4.0"
    assert description["Name"] == "Forearm taps" and description["Funding"] == ["Grant 42"]
    assert description["BIDSVersion"] != "1.8.0"  # vibrofocus's own keys are its own
    (sidecar,) = out.glob("sub-P01/ses-3/beh/*_events.json")
    meta = json.loads(sidecar.read_text())
    assert meta["InstitutionName"] == "Example Lab" and meta["InstitutionAddress"] == "1 Example Street"
    # A re-export without the options keeps them all; an option given anew replaces its key only.
    result = runner.invoke(app, ["export", str(csv_path), "--bids", str(out), "--license", "CC0"])
    assert result.exit_code == 0, result.output
    again = json.loads((out / "dataset_description.json").read_text())
    assert again == {**description, "License": "CC0"}
    assert json.loads(sidecar.read_text())["InstitutionName"] == "Example Lab"


@pytest.mark.parametrize("metadata, message", [
    ({"Author": ["A"]}, "key 'Author'"),
    ({"Authors": "Ada Lovelace"}, "Authors must be a list of texts"),
    ({"License": ""}, "License must be a non-empty text"),
    ({"InstitutionName": "Lab\nname"}, "without control characters"),
    (["Authors"], "must be a JSON object"),
])
def test_bad_metadata_is_refused_and_nothing_is_written(tmp_path, metadata, message):
    with pytest.raises(ValidationError, match=message):
        export_bids(_onset_csv(tmp_path / "t.csv"), tmp_path / "out", metadata=metadata)
    assert not (tmp_path / "out").exists()


def test_a_bad_template_is_one_error_line(tmp_path):
    template = tmp_path / "meta.json"
    template.write_text("[1, 2]")
    result = runner.invoke(app, ["export", str(_onset_csv(tmp_path / "t.csv")), "--bids", str(tmp_path / "out"),
                                 "--metadata", str(template)])
    assert result.exit_code == 2 and result.output.count("error:") == 1 and "JSON object" in result.output
    assert not (tmp_path / "out").exists()
