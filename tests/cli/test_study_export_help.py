"""``study export --help`` names every column of the trials file, and ``--bids`` there points to ``export``."""

from __future__ import annotations

from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.io.trials_csv import ONSET_COLUMNS, SESSION_COLUMNS, SIMULATED_COLUMN, TRIALS_COLUMNS

runner = CliRunner()


def test_the_help_lists_every_column_without_markup():
    result = runner.invoke(app, ["study", "export", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    text = " ".join(result.output.split())
    columns = TRIALS_COLUMNS + SESSION_COLUMNS + ONSET_COLUMNS + (SIMULATED_COLUMN,)
    assert len(columns) == 16  # docs/file-formats.md: 8 trial, 4 session, 3 onset columns and simulated
    assert [c for c in columns if c not in text] == []
    assert "``" not in result.output


def test_bids_under_study_export_says_where_it_is(tmp_path):
    result = runner.invoke(app, ["study", "export", "--db", str(tmp_path / "s.db"), "--out", str(tmp_path / "t.csv"),
                                 "--bids", str(tmp_path / "b")])
    assert result.exit_code == 2 and result.output.count("error:") == 1
    assert "No such option: --bids" in result.output and "vibrofocus export SRC --bids DIR" in result.output
    assert list(tmp_path.iterdir()) == []
