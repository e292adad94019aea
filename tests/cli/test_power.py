"""``vibrofocus power``: the table, the files and the model label; bad input in one line."""

from __future__ import annotations

import json

import pandas as pd
from typer.testing import CliRunner

from vibrofocus.cli.main import app

runner = CliRunner()


def test_power_writes_table_plot_and_json(tmp_path):
    out = tmp_path / "power"
    res = runner.invoke(app, ["power", "-n", "4,6", "--studies", "5", "--no-dask", "-q", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "model v2" in res.output and "not data" in res.output
    assert "Study 1 RM-ANOVA, location (GG)" in res.output
    table = pd.read_csv(out / "power.csv")
    assert set(table["n_participants"]) == {4, 6} and len(table) == 14
    assert table["power"].between(0, 1).all()
    report = json.loads((out / "power.json").read_text())
    assert report["design"]["n_studies"] == 5 and "not data" in report["label"]
    assert (out / "power.png").stat().st_size > 1000


def test_power_refuses_bad_input():
    res = runner.invoke(app, ["power", "-n", "2", "--studies", "5", "--no-dask", "-q"])
    assert res.exit_code != 0 and "n_participants" in res.output
    res = runner.invoke(app, ["power", "-n", "ten", "--no-dask", "-q"])
    assert res.exit_code != 0 and "--participants" in res.output
