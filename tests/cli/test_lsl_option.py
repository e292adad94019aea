"""``--lsl`` on the commands that run trials; without pylsl it is one error line."""

from __future__ import annotations

import sys

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app

runner = CliRunner()


@pytest.mark.parametrize("args", [["study", "run"], ["simulate-study"], ["serve"]])
def test_the_commands_that_run_trials_take_lsl(args):
    result = runner.invoke(app, [*args, "--help"], terminal_width=200)
    assert result.exit_code == 0 and "--lsl" in result.output and "vibrofocus-markers" in result.output


def test_without_pylsl_lsl_is_one_error_line_and_nothing_is_simulated(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pylsl", None)  # import pylsl raises ImportError
    db = tmp_path / "study.db"
    result = runner.invoke(app, ["simulate-study", "-n", "1", "--db", str(db), "--quiet", "--lsl"])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "vibrofocus[lsl]" in errors[0]
    assert list(tmp_path.iterdir()) == []  # no database, no calibration folder


@pytest.mark.parametrize("args", [["study", "run"], ["simulate-study"], ["serve"]])
def test_the_commands_that_run_trials_take_a_source_id_and_a_wait(args):
    result = runner.invoke(app, [*args, "--help"], env={"COLUMNS": "250"})
    assert result.exit_code == 0 and "--lsl-source-id" in result.output and "--lsl-wait" in result.output
    assert "tap/METHOD/PHASE/studyN" in result.output


@pytest.mark.parametrize("extra, words", [
    (["--lsl", "--lsl-source-id", "lab's stream"], "--lsl-source-id must be 1-100 letters"),
    (["--lsl-source-id", "eeg-room-2"], "--lsl-source-id needs --lsl"),
])
def test_a_bad_source_id_is_one_error_line_and_nothing_is_simulated(tmp_path, extra, words):
    db = tmp_path / "study.db"
    result = runner.invoke(app, ["simulate-study", "-n", "1", "--db", str(db), "--quiet", *extra])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and words in errors[0]
    assert list(tmp_path.iterdir()) == []
