"""A calibration is never replaced silently: not another participant's, not another kind of file."""

from __future__ import annotations

import dataclasses
import hashlib
import sqlite3

import pytest
from typer.testing import CliRunner

from vibrofocus.calibration import export_sofa, load_calibration, save_calibration
from vibrofocus.calibration.replacing import calibration_owner, reserve_free_name
from vibrofocus.cli.main import app
from vibrofocus.errors import OutputError

runner = CliRunner()


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _database(path):
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE t (x)")
    return path


def test_the_api_keeps_the_previous_calibration_and_refuses_another_participants(fir_calibration, tmp_path):
    cal = fir_calibration[1]
    path = tmp_path / "FIR.nc"
    save_calibration(cal, path)
    first = _sha(path)
    save_calibration(cal, path)  # the same participant's again: the previous one is kept
    assert _sha(tmp_path / "FIR.1.nc") == first and calibration_owner(path) == "FIR"
    save_calibration(cal, path)
    assert (tmp_path / "FIR.2.nc").is_file()
    other = dataclasses.replace(cal, participant_id="P02")
    before = _sha(path)
    with pytest.raises(OutputError, match="calibration of participant 'FIR'"):
        save_calibration(other, path)
    assert _sha(path) == before and not (tmp_path / "FIR.3.nc").exists()
    save_calibration(other, path, force=True)
    assert calibration_owner(path) == "P02" and _sha(tmp_path / "FIR.3.nc") == before
    assert load_calibration(tmp_path / "FIR.1.nc").participant_id == "FIR"


def test_the_api_never_writes_over_a_study_database_or_a_calibration_as_sofa(fir_calibration, tmp_path):
    cal = fir_calibration[1]
    db = _database(tmp_path / "study.sqlite")
    before = _sha(db)
    with pytest.raises(OutputError, match="SQLite database"):
        save_calibration(cal, db)
    with pytest.raises(OutputError, match="SQLite database"):
        export_sofa(cal, db)
    assert _sha(db) == before
    nc = save_calibration(cal, tmp_path / "FIR.nc")
    with pytest.raises(OutputError, match="calibration of participant 'FIR'"):
        export_sofa(cal, nc)
    assert calibration_owner(nc) == "FIR"
    sofa = export_sofa(cal, tmp_path / "FIR.sofa")
    export_sofa(cal, sofa)  # an earlier SOFA export is replaced
    assert [p.name for p in tmp_path.iterdir() if ".1." in p.name] == []


def test_calibrate_twice_keeps_the_first_calibration_and_its_figure(tmp_path):
    out = tmp_path / "P01.nc"
    args = ["calibrate", "-p", "P01", "--out", str(out), "--yes", "--figure"]
    assert runner.invoke(app, args).exit_code == 0
    first_nc, first_png = _sha(out), _sha(out.with_suffix(".png"))
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "kept the previous calibration as" in result.output
    assert _sha(tmp_path / "P01.1.nc") == first_nc and _sha(tmp_path / "P01.1.png") == first_png
    # Another participant's calibration at --out is refused before anything is measured.
    result = runner.invoke(app, ["calibrate", "-p", "P02", "--out", str(out), "--yes"])
    assert result.exit_code == 2 and "calibration of participant 'P01'" in result.output
    assert "calibrating" not in result.output and calibration_owner(out) == "P01"


def test_a_free_name_is_reserved_once(tmp_path):
    names = [reserve_free_name(tmp_path / "sim-001.nc") for _ in range(3)]
    assert [p.name for p in names] == ["sim-001.nc", "sim-001.1.nc", "sim-001.2.nc"]
