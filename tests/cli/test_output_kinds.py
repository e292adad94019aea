"""A trials CSV, a drives CSV and a report JSON are different kinds of file: no command
replaces one with another without ``--force`` (issue 54, item 2). All three are text, so
their kind is told by their first lines, not by magic bytes or the name's suffix."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from vibrofocus import _atomic
from vibrofocus.calibration import save_calibration
from vibrofocus.cli.main import app
from vibrofocus.errors import OutputError
from vibrofocus.io import write_report_json
from vibrofocus.io.drives import write_drives
from vibrofocus.io.trials_csv import write_trials_csv

import numpy as np

runner = CliRunner()

ROW = {"participant": "P01", "study": 1, "phase": "main", "trial": 1, "method": "inverse", "target": 5,
       "response": "5", "rt_s": 1.25}
REPORT = {"generator": "vibrofocus 0.0", "source": "trials.csv", "n_trials": 1,
          "study1": {"anova": []},
          "study2": {"friedman": {f: {"chi2": None, "dof": None, "p": None} for f in ("location", "method")}}}


def _trials(path):
    write_trials_csv([ROW], path)


def _drives(path):
    write_drives(path, np.zeros((2, 4)), 1000.0, actuator_names=["A1", "A2"], metadata={"software": "vibrofocus"})


def _report(path):
    write_report_json(REPORT, path)


WRITERS = {"trials CSV": _trials, "drives CSV": _drives, "report JSON": _report}


@pytest.mark.parametrize("kind", WRITERS)
def test_each_writer_gives_its_kind(tmp_path, kind):
    path = tmp_path / "out.csv"
    WRITERS[kind](path)
    assert _atomic.file_kind(path) == kind


def test_a_lab_csv_and_a_bom_are_read_as_what_they_are(tmp_path):
    lab = tmp_path / "lab.csv"
    lab.write_text("subject,block,answer\n1,2,3\n")
    assert _atomic.file_kind(lab) == "text file"
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + b"participant,study,phase,trial,method\n")
    assert _atomic.file_kind(bom) == "trials CSV"


@pytest.mark.parametrize("old", [*WRITERS, "text file"])
@pytest.mark.parametrize("new", WRITERS)
def test_replacing_another_kind_needs_force(tmp_path, old, new):
    path = tmp_path / "file.csv"
    if old == "text file":
        path.write_text("subject,block,answer\n1,2,3\n")
    else:
        WRITERS[old](path)
    before = path.read_bytes()
    with _atomic.output_guard():
        if old == new:
            WRITERS[new](path)  # the same kind: replaced, as a re-run does
            assert _atomic.file_kind(path) == new
            return
        with pytest.raises(OutputError, match=f"holds a {old}, not a {new}.*--force"):
            WRITERS[new](path)
    assert path.read_bytes() == before
    with _atomic.output_guard(force=True):
        WRITERS[new](path)
    assert _atomic.file_kind(path) == new


@pytest.fixture(scope="module")
def cal_file(simulated_calibration, tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "S00.nc"
    save_calibration(simulated_calibration[1], path)
    return path


def test_render_keeps_a_trials_csv_and_export_keeps_a_drives_csv(cal_file, tmp_path):
    trials = tmp_path / "trials.csv"
    _trials(trials)
    before = trials.read_bytes()
    result = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5", "--out", str(trials)])
    assert result.exit_code == 2 and "holds a trials CSV, not a drives CSV" in " ".join(result.output.split())
    assert trials.read_bytes() == before
    drives = tmp_path / "drives.csv"
    assert runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "5",
                               "--out", str(drives)]).exit_code == 0
    again = runner.invoke(app, ["render", "--calibration", str(cal_file), "--location", "4", "--out", str(drives)])
    assert again.exit_code == 0, again.output  # its own kind: a re-run replaces it
    kept = drives.read_bytes()
    from vibrofocus.studies import StudyStore

    db = tmp_path / "study.sqlite"
    with StudyStore(db) as store:
        store.add_participant("P01")
    result = runner.invoke(app, ["study", "export", "--db", str(db), "--out", str(drives)])
    assert result.exit_code == 2 and "holds a drives CSV, not a trials CSV" in " ".join(result.output.split())
    assert drives.read_bytes() == kept
