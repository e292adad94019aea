"""Sessions in a study database's trials export: aborted sessions and dry runs are left
out of the analysis by default and listed as excluded; two sessions of one participant
are not duplicates of each other."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.analysis import load_trials
from vibrofocus.studies.export import SESSION_COLUMNS, TRIALS_COLUMNS, read_trials_csv, write_trials_csv


def _rows(session: int, status: str, dry: bool, n: int, rng) -> list[dict]:
    return [
        {"participant": "P01", "study": 1, "phase": "main", "trial": t + 1, "method": "inverse",
         "target": int(rng.integers(1, 10)), "response": [int(rng.integers(1, 10))], "rt_s": float(rng.uniform(0.3, 2)),
         "session": session, "session_status": status, "dry_run": dry}
        for t in range(n)
    ]


@pytest.fixture
def export(tmp_path):
    rng = np.random.default_rng(3)
    rows = _rows(1, "aborted", False, 4, rng) + _rows(2, "completed", True, 3, rng) + _rows(3, "completed", False, 5, rng)
    path = tmp_path / "trials.csv"
    assert write_trials_csv(rows, path, sessions=True) == 12
    return path, rows


def test_session_columns_follow_the_contract_columns_and_round_trip(export):
    path, rows = export
    header = path.read_text().splitlines()[0].split(",")
    assert tuple(header) == TRIALS_COLUMNS + SESSION_COLUMNS
    back = read_trials_csv(path)
    assert [(r["session"], r["session_status"], r["dry_run"]) for r in back] == [
        (r["session"], r["session_status"], r["dry_run"]) for r in rows]


def test_aborted_and_dry_run_sessions_are_left_out_and_listed(export):
    path, rows = export
    trials = load_trials(path)  # trial numbers 1.. repeat across the three sessions: not duplicates
    assert sorted(trials["session"].astype(int).unique()) == [3]
    assert len(trials) == 5
    reasons = {e["reason"].split(" ")[1]: e["reason"] for e in trials.attrs["exclusions"]}
    assert set(reasons) == {"1", "2"}
    assert "aborted" in reasons["1"] and "4 answered trials" in reasons["1"]
    assert "dry run" in reasons["2"] and "3 answered trials" in reasons["2"]
    both = load_trials(path, keep_aborted=True, keep_dry_runs=True)
    assert len(both) == 12 and both.attrs["exclusions"] == []


def test_a_duplicated_trial_within_one_session_is_still_refused(tmp_path):
    rng = np.random.default_rng(4)
    rows = _rows(5, "completed", False, 2, rng)
    rows.append(dict(rows[0]))
    path = tmp_path / "trials.csv"
    write_trials_csv(rows, path, sessions=True)
    with pytest.raises(Exception, match="appears twice"):
        load_trials(path)
