"""``vibrofocus design-experiment``: a designed protocol that simulate-study accepts, and a report."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.studies.protocol_files import load_protocol

runner = CliRunner()
SMALL = ["--forearms", "1", "--traits", "2", "--parameter-draws", "1", "--budget", "12", "--levels", "0,-20",
         "--methods", "funneling,inverse"]


def test_design_experiment_writes_a_protocol_and_its_report(tmp_path):
    out = tmp_path / "design"
    res = runner.invoke(app, ["design-experiment", *SMALL, "--participants", "1,2", "--studies", "4", "--pool", "4",
                              "--score-forearms", "2", "--score-draws", "2", "--no-dask",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    proto = load_protocol(out / "protocol.toml")
    proto.check_runnable()
    report = json.loads((out / "design.json").read_text())
    assert sum(b["trials"] for b in report["blocks"]) == report["trials"] <= 12
    assert set(report["identification"]["rates"]) == {"designed", "paper"}
    assert (out / "identification.png").stat().st_size > 0 and (out / "design-map.png").stat().st_size > 0
    assert "not data" in (out / "design.md").read_text()


def test_design_experiment_refuses_bad_input_in_one_line():
    for args, words in ((["--levels", "loud"], "--levels must be numbers"),
                        (["--levels", "6"], "drive limit"),
                        (["--hypotheses", "telepathy"], "telepathy"),
                        (["--parameter-spread", "2"], "--parameter-spread")):
        res = runner.invoke(app, ["design-experiment", *SMALL[:-4], *args, "--studies", "0"])
        assert res.exit_code != 0
        assert words in res.output and "Traceback" not in res.output, res.output
