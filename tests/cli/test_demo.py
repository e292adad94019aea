"""``vibrofocus demo --json`` prints one JSON object with the results table."""

import os
import json

import numpy as np

from typer.testing import CliRunner

from vibrofocus.cli.main import app


def test_demo_json_has_every_location_and_method(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--json", "--no-figures", "--seed", "2", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    rows = payload["results"]
    methods = ("funneling", "inverse", "combination", "time_reversal", "contrast", "constrained")
    assert len(rows) == 9 * len(methods)
    assert {(r["location"], r["method"]) for r in rows} == {(loc, m) for loc in range(1, 10) for m in methods}
    for row in rows:
        for key in ("fidelity", "contrast_db", "peak_drive_v", "target_peak_m", "contrast_all_points_db",
                    "energy_contrast_db", "bound_db"):
            assert isinstance(row[key], float)
    assert set(payload["summary"]) == set(methods)
    # The peak bound (on by default) is a property of the location, so every method's row
    # there carries the same value; it is finite wherever the pseudo-inverse's fidelity is
    # within the support's reach, as it is on this arm.
    for loc in range(1, 10):
        bounds = {r["peak_bound_db"] for r in rows if r["location"] == loc}
        assert len(bounds) == 1 and all(isinstance(b, float) and np.isfinite(b) for b in bounds), bounds
    assert np.isfinite(payload["summary"]["inverse"]["peak_bound_db"])


def test_demo_without_the_peak_bound_leaves_the_column_out(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--no-figures", "--no-peak-bound", "--seed", "2", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "peak bound" not in result.output and "bound" in result.output


def test_demo_refuses_an_unknown_field_location(tmp_path):
    result = CliRunner().invoke(app, ["demo", "--field-location", "10", "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert "location 10" in result.output


def test_the_metrics_table_fits_80_columns_uncut():
    # Issue 38: piped (or in a default terminal) the table was cut at 80 columns, funneling's
    # fidelity shown as "-0.…".
    from rich.console import Console

    from vibrofocus.cli.demo import METRIC_COLUMNS as columns
    from vibrofocus.cli.demo import _fmt, metrics_table

    worst = [_fmt(-0.999), _fmt(-0.999), _fmt(-38.25, 1), _fmt(-38.25, 1), _fmt(-38.25, 1), _fmt(-38.25, 1),
             _fmt(-38.25, 1), _fmt(12.3456, 3), _fmt(10.0, 1)]
    for location, first in ((False, ["time_reversal"]), (True, ["9", "time_reversal"])):
        console = Console(width=80, record=True, file=open(os.devnull, "w"), color_system=None)
        console.print(metrics_table("title", columns, [first + worst, [*first[:-1], "funneling", _fmt(-0.0004), *worst[1:]]],
                                    location=location))
        text = console.export_text()
        assert "…" not in text, text
        assert max(len(line.rstrip()) for line in text.splitlines()) <= 80, text
        assert "-0.00" not in text and " 0.00 " in text, text  # funneling's fidelity reads 0.00, never -0.00
        assert "time_reversal" in text and "-38.2" in text and "12.346" in text
