"""The stimulus-level table of a report: each method's peak drive and predicted peak at the
target per location, from the stimulus columns of a study database's export."""

import numpy as np
import pytest

from vibrofocus.analysis import load_trials
from vibrofocus.analysis.levels import stimulus_levels
from vibrofocus.io.trials_csv import write_trials_csv


def _rows():
    rows = []
    for p, scale in (("P1", 1.0), ("P2", 1.2), ("P3", 0.9)):
        for k, (method, target, drive, um) in enumerate(
                [("funneling", 5, 2.5, 0.15), ("inverse", 5, 10.0 * min(scale, 1.0), 0.5 * scale),
                 ("funneling", 1, 5.216, 0.11)]):
            rows.append({"participant": p, "study": 1, "phase": "main", "trial": k + 1, "method": method,
                         "target": target, "response": "5", "rt_s": 0.5, "session": 1, "session_status": "completed",
                         "dry_run": 0, "levels": "paper", "drive_peak_v": drive, "target_peak_um": um})
    rows.append({**rows[0], "phase": "training", "drive_peak_v": 99.0})  # training: not in the table
    return rows


def test_the_table_has_the_median_peaks_per_method_and_location(tmp_path):
    path = tmp_path / "t.csv"
    write_trials_csv(_rows(), path, sessions=True, onsets=True, stimuli=True)
    trials = load_trials(path)
    table = stimulus_levels(trials)
    inverse5 = table[(table["method"] == "inverse") & (table["target"] == 5)].iloc[0]
    assert inverse5["levels"] == "paper" and inverse5["n"] == 3
    assert inverse5["drive_peak_v"] == pytest.approx(10.0)  # median of 10, 10, 9
    assert inverse5["drive_peak_v_min"] == pytest.approx(9.0)
    assert inverse5["target_peak_um"] == pytest.approx(0.5)  # median of 0.5, 0.6, 0.45
    funneling5 = table[(table["method"] == "funneling") & (table["target"] == 5)].iloc[0]
    assert funneling5["drive_peak_v"] == pytest.approx(2.5)  # the training row's 99 V is left out
    assert len(table) == 3


def test_no_stimulus_columns_no_table(tmp_path):
    rows = [{k: v for k, v in r.items() if k not in ("levels", "drive_peak_v", "target_peak_um")} for r in _rows()]
    write_trials_csv(rows, tmp_path / "t.csv", sessions=True)
    assert stimulus_levels(load_trials(tmp_path / "t.csv")) is None


def test_an_empty_peak_is_nan_not_zero(tmp_path):
    rows = _rows()
    for r in rows:
        if r["method"] == "inverse":
            r["drive_peak_v"] = r["target_peak_um"] = None  # a dry run played nothing
    write_trials_csv(rows, tmp_path / "t.csv", sessions=True, onsets=True, stimuli=True)
    table = stimulus_levels(load_trials(tmp_path / "t.csv"))
    inverse5 = table[table["method"] == "inverse"].iloc[0]
    assert inverse5["n"] == 0 and np.isnan(inverse5["drive_peak_v"]) and np.isnan(inverse5["target_peak_um"])
