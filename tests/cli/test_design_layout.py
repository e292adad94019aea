"""``vibrofocus design-layout``: a small search writes a layout that ``calibrate --layout`` takes."""

from __future__ import annotations

import csv
import json

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.rigs import load_layout

SMALL = ["--targets-mm", "-10,10;10,-10", "--rect-mm", "60,30", "--pitch-mm", "30", "--actuators", "2",
         "--no-dask", "--quiet"]


@pytest.mark.slow
def test_a_small_search_writes_the_layout_the_figure_and_the_table(tmp_path):
    out = tmp_path / "layout"
    result = CliRunner().invoke(app, ["design-layout", "--out", str(out), *SMALL])
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} == {"layout.json", "layout.png", "comparison.csv", "design-layout.json"}
    layout = load_layout(out / "layout.json")
    assert layout.n_actuators == 2 and layout.n_locations == 2
    rows = list(csv.DictReader((out / "comparison.csv").open()))
    assert [r["target"] for r in rows] == ["1", "2", "worst", "mean"]
    assert {"designed_contrast_db", "paper_contrast_db", "designed_tap_um"} <= set(rows[0])
    report = json.loads((out / "design-layout.json").read_text())
    assert report["settings"]["n_actuators"] == 2 and report["n_layouts"] > 0
    assert "against the paper's 2x2 at 45 mm" in result.output
    # The layout file is one calibrate takes (checked up to the rig: the calibration itself is tested elsewhere).
    bad = CliRunner().invoke(app, ["calibrate", "--participant", "P01", "--out", str(tmp_path / "c.nc"), "--yes",
                                   "--layout", str(out / "design-layout.json")])
    assert bad.exit_code != 0 and "lacks the key 'actuators_xy'" in bad.output, bad.output


def test_two_regions_are_refused_in_one_line(tmp_path):
    result = CliRunner().invoke(app, ["design-layout", "--out", str(tmp_path / "x"), "--rect-mm", "60,60",
                                      "--band-mm", "210,60"])
    assert result.exit_code != 0 and "give --rect-mm or --band-mm, not both" in result.output
    assert not (tmp_path / "x").exists()
