"""``--skin NAME``: every simulating command runs on every preset and names it in its output."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.calibration import load_calibration
from vibrofocus.skin import SKIN_PRESETS


@pytest.mark.slow
@pytest.mark.parametrize("skin", list(SKIN_PRESETS))
def test_demo_runs_on_every_preset_and_names_it(skin, tmp_path):
    result = CliRunner().invoke(app, ["demo", "--json", "--no-figures", "--no-peak-bound", "--skin", skin, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert payload["skin"] == skin
    assert payload["participant"]["skin"] == skin
    cal = load_calibration(tmp_path / "calibration.nc")
    assert cal.rig["skin"] == skin
    rows = {(r["location"], r["method"]): r for r in payload["results"]}
    assert max(r["peak_drive_v"] for r in rows.values()) <= 10.0 + 1e-9
    if skin == "nominal":  # issue 24's bar for the default arm, designed from its calibration
        inverse = [rows[(loc, "inverse")]["fidelity"] for loc in range(1, 10)]
        assert rows[(5, "inverse")]["fidelity"] >= 0.65
        assert np.median(inverse) >= 0.6
        funneling = [rows[(loc, "funneling")]["contrast_db"] for loc in range(1, 10)]
        contrast = [rows[(loc, "inverse")]["contrast_db"] for loc in range(1, 10)]
        assert np.mean(contrast) >= np.mean(funneling)  # at least as sharp as funneling
        assert payload["calibration"]["trust"]["covers_tap_band"]


def test_demo_table_names_the_preset(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--no-figures", "--no-peak-bound", "--skin", "low", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "skin low" in result.output


def test_calibrate_simulated_stores_and_prints_the_preset(tmp_path):
    out = tmp_path / "p.nc"
    result = CliRunner().invoke(app, ["calibrate", "--rig", "simulated", "--skin", "high", "--participant", "P1",
                                      "--out", str(out), "--yes", "--no-figure", "--method", "paper"])
    assert result.exit_code == 0, result.output
    assert "skin high" in result.output
    assert load_calibration(out).rig["skin"] == "high"


def test_an_unknown_preset_is_one_clear_error(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--skin", "soft", "--out", str(tmp_path)])
    assert result.exit_code != 0
    assert "skin must be one of" in result.output
