"""``vibrofocus export --bids``: a simulated study as a BIDS dataset that pybids loads, and back into analyze."""

from __future__ import annotations

import csv
import json

import pytest
from typer.testing import CliRunner

from vibrofocus import __version__
from vibrofocus.cli.main import app
from vibrofocus.errors import StudyError
from vibrofocus.io.bids import EVENT_COLUMNS, bids_label
from vibrofocus.simulation import STUDY_SKIN
from vibrofocus.studies import StudyStore
from vibrofocus.studies.bids import export_bids

bids = pytest.importorskip("bids")
pytestmark = pytest.mark.slow
runner = CliRunner()
REQUIRED = ("onset", "duration", "trial_type", "method", "target", "response", "response_time", "phase")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("bids-study")
    db, trials = root / "study.db", root / "trials.csv"
    result = runner.invoke(app, ["simulate-study", "-n", "2", "--seed", "8", "--db", str(db), "--trials-csv",
                                 str(trials), "--quiet"])
    assert result.exit_code == 0, result.output
    return root, db, trials


def _events(layout):
    return layout.get(suffix="events", extension=".tsv")


def test_every_trial_of_a_simulated_study_is_an_events_row_in_pybids(study):
    root, db, _ = study
    out = root / "bids-db"
    result = runner.invoke(app, ["export", str(db), "--bids", str(out)])
    assert result.exit_code == 0, result.output
    with StudyStore(db, create=False) as store:
        rows = store.trial_rows()
        sha = {c.calibration_id: c.sha256 for p in store.participants() for c in store.calibrations(p.participant_id)}
    layout = bids.BIDSLayout(out, validate=True)
    assert sorted(layout.get_subjects()) == sorted(bids_label(r["participant"]) for r in {r["participant"]: r for r in rows}.values())
    assert sorted(layout.get_tasks()) == ["localization1", "localization2"]
    files = _events(layout)
    assert len(files) == 4  # 2 participants x 2 studies
    n = 0
    for f in files:
        df = f.get_df()
        meta = f.get_metadata()
        ents = f.get_entities()
        mine = [r for r in rows if bids_label(r["participant"]) == ents["subject"]
                and f"localization{r['study']}" == ents["task"]]
        assert len(df) == len(mine) > 0
        assert list(df.columns) == list(EVENT_COLUMNS)
        assert list(df["trial"]) == [r["trial"] for r in mine] and list(df["method"]) == [r["method"] for r in mine]
        assert list(df["response_time"]) == pytest.approx([r["rt_s"] for r in mine], abs=0)
        # onset: the monotonic onset the database stores, from the session's first (not the wall clock).
        host = [r["onset_host_s"] for r in mine]
        assert list(df["onset"]) == pytest.approx([h - min(host) for h in host], abs=1e-9)
        assert ents["session"] == str(mine[0]["session"]) and {r["session"] for r in mine} == {mine[0]["session"]}
        # The onset on the rig's own clock, every digit as the database holds it.
        assert list(df["device_onset"]) == [r["onset_device_s"] for r in mine]
        assert set(df["device_clock"]) == {"simulated_samples"}
        assert set(meta["device_clock"]["Levels"]) == {"simulated_samples", "portaudio_dac", "nidaq_start_trigger", "nidaq_samples"}
        assert meta["device_onset"]["Units"] == "s"
        assert meta["Simulated"] is True and "not data" in meta["SimulatedModel"]
        session = meta["Sessions"][0]
        assert session["Rig"] == "simulated" and session["SkinPreset"] == STUDY_SKIN  # simulate-study's default
        assert session["CalibrationSHA256"] == sha[mine[0]["calibration_id"]]
        for column in REQUIRED:
            assert meta[column]["Description"]
        assert {meta[c]["Units"] for c in ("onset", "duration", "response_time")} == {"s"}
        assert set(meta["phase"]["Levels"]) == {"training", "main"} and "inverse" in meta["method"]["Levels"]
        n += len(df)
    assert n == len(rows)
    description = json.loads((out / "dataset_description.json").read_text())
    assert description["GeneratedBy"][0]["Name"] == "vibrofocus" and description["GeneratedBy"][0]["Version"] == __version__
    participants = layout.get(suffix="participants", extension=".tsv")[0].get_df()
    assert set(participants["simulated"]) == {True} or set(participants["simulated"].astype(str)) == {"true", "True"}
    assert "SIMULATED" in (out / "README").read_text()


def test_a_trials_csv_exports_the_same_rows_and_onsets_and_analyze_reads_the_folder(study):
    root, db, trials = study
    out = root / "bids-csv"
    assert runner.invoke(app, ["export", str(trials), "--bids", str(out)]).exit_code == 0
    with open(trials, newline="") as fh:
        n_csv = sum(1 for _ in csv.DictReader(fh))
    layout = bids.BIDSLayout(out, validate=True)
    dfs = [f.get_df() for f in _events(layout)]
    assert sum(len(df) for df in dfs) == n_csv
    # The CSV's onset_host_s gives the same onsets as the database.
    assert runner.invoke(app, ["export", str(db), "--bids", str(root / "bids-db-onsets")]).exit_code == 0
    from_db = {f.filename: f.get_df()["onset"] for f in _events(bids.BIDSLayout(root / "bids-db-onsets"))}
    for f in _events(layout):
        assert f.get_df()["onset"].notna().all()
        assert list(f.get_df()["onset"]) == pytest.approx(list(from_db[f.filename]), abs=1e-9)
    reports = {}
    for name, source in (("csv", trials), ("bids", out)):
        result = runner.invoke(app, ["analyze", str(source), "--out", str(root / f"report-{name}"), "-q",
                                     "--simulated"])
        assert result.exit_code == 0, result.output
        reports[name] = json.loads((root / f"report-{name}" / "report.json").read_text())
        reports[name].pop("source")
    assert reports["bids"] == reports["csv"]
    assert reports["bids"]["simulated"]["any"] is True


def test_the_official_validator_accepts_the_database_and_csv_exports_and_mne_bids_reads_every_event(study):
    from tests.studies.test_bids_validator import METADATA, every_event_read_by_mne_bids, expected_warnings, validate

    root, db, trials = study
    expected = expected_warnings()["always"]
    template = root / "template.json"
    template.write_text(json.dumps({"BIDSVersion": "1.9.0", "InstitutionAddress": METADATA["InstitutionAddress"],
                                    "InstitutionalDepartmentName": "Haptics"}))
    for name, source in (("db", db), ("csv", trials)):
        out = root / f"bids-validated-{name}"
        result = runner.invoke(app, ["export", str(source), "--bids", str(out), "--author", "Ada Lovelace",
                                     "--author", "Alan Turing", "--license", "CC0", "--institution", "Example Lab",
                                     "--metadata", str(template)])
        assert result.exit_code == 0, result.output
        status, issues = validate(out)
        assert status == 0 and {i[1:] for i in issues} <= expected, issues
        every_event_read_by_mne_bids(out)


def test_a_dataset_written_before_the_device_columns_and_sessions_is_still_read(study):
    from vibrofocus.io.bids import read_bids_trials_table

    root, db, _ = study
    out = root / "bids-old"
    assert runner.invoke(app, ["export", str(db), "--bids", str(out)]).exit_code == 0
    new = read_bids_trials_table(out)
    for path in list(out.glob("sub-*/ses-*/beh/*_events.tsv")):  # as an older vibrofocus wrote it
        # No ses- (a session_id column instead), no device or stimulus columns.
        session = path.parent.parent.name.removeprefix("ses-")
        lines = [line.split("\t")[:11] for line in path.read_text().splitlines()]
        assert lines[0][-1] == "dry_run"
        lines = [cells[:9] + [session if k else "session_id"] + cells[9:] for k, cells in enumerate(lines)]
        old_path = path.parent.parent.parent / "beh" / path.name.replace(f"_ses-{session}", "")
        old_path.parent.mkdir(exist_ok=True)
        old_path.write_text("".join("\t".join(cells) + "\n" for cells in lines))
        path.with_suffix(".json").rename(old_path.with_suffix(".json"))
        path.unlink()
    old = read_bids_trials_table(out)
    assert set(new.columns) - set(old.columns) == {"levels", "drive_peak_v", "target_peak_um", "xrun_represented",
                                                   "protocol", "level_db", "allowed", "response_x_mm",
                                                   "response_y_mm"}
    key = ["participant", "study", "phase", "trial"]
    assert old.drop(columns="line").sort_values(key).reset_index(drop=True).equals(
        new[list(old.columns)].drop(columns="line").sort_values(key).reset_index(drop=True))


def test_the_export_never_replaces_its_input_and_keeps_the_users_files(study):
    root, db, trials = study
    inside = root / "holder"
    inside.mkdir()
    (inside / "notes.txt").write_text("mine")
    copy = inside / "trials.csv"
    copy.write_bytes(trials.read_bytes())
    result = runner.invoke(app, ["export", str(copy), "--bids", str(inside)])
    assert result.exit_code == 2 and result.output.count("error:") == 1 and "would replace its input" in result.output
    result = runner.invoke(app, ["export", str(trials), "--bids", str(trials)])
    assert result.exit_code == 2 and result.output.count("error:") == 1 and "would replace its input" in result.output
    assert trials.is_file() and (inside / "trials.csv").is_file()
    target = root / "again"
    target.mkdir()
    (target / "notes.txt").write_text("mine")
    (target / "sub-old").mkdir()  # not written by vibrofocus (not in its manifest): kept
    assert export_bids(trials, target)["events"] > 0
    assert (target / "notes.txt").read_text() == "mine" and (target / "sub-old").is_dir()
    assert (target / "dataset_description.json").is_file()


def test_participant_ids_become_bids_labels_and_a_clash_is_refused(tmp_path):
    assert bids_label("sim-001") == "sim001" and bids_label("P_01.a") == "P01a"
    path = tmp_path / "t.csv"
    path.write_text("participant,study,phase,trial,method,target,response,rt_s\n"
                    "P-1,1,main,1,inverse,5,5,0.5\nP1,1,main,1,inverse,5,4,0.5\n")
    with pytest.raises(StudyError, match="would both be sub-P1"):
        export_bids(path, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_labs_own_clock_is_a_described_level(tmp_path, monkeypatch):
    # Recorded by a process that named its clock; exported by one that did not.
    from vibrofocus.rigs import onset as onset_module
    from vibrofocus.rigs import register_clock

    db = tmp_path / "own-clock.db"
    monkeypatch.setattr(onset_module, "CLOCKS", dict(onset_module.CLOCKS))
    register_clock("lab_fpga", "our FPGA's sample counter / rate")
    with StudyStore(db) as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 1, seed=5, config={"repetitions": 1, "n_training": 0, "methods": ["inverse"],
                                                             "locations": [4, 6]})
        store.record_answer(sid, 0, 4, 0.5, answer_id="a0", onset_s=10.0, onset_device_s=2.5, onset_clock="lab_fpga")
        store.record_answer(sid, 1, 6, 0.5, answer_id="a1", onset_s=11.0, onset_device_s=3.5, onset_clock="lab_fpga")
    monkeypatch.undo()
    assert "lab_fpga" not in onset_module.CLOCKS
    export_bids(db, tmp_path / "bids")
    layout = bids.BIDSLayout(tmp_path / "bids", validate=True)
    (events,) = _events(layout)
    assert list(events.get_df()["device_clock"]) == ["lab_fpga", "lab_fpga"]
    levels = events.get_metadata()["device_clock"]["Levels"]
    assert "register_clock" in levels["lab_fpga"] and "portaudio_dac" in levels
