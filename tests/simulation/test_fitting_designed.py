"""Fitting hypotheses to a designed study's trials: block levels, allowed answers and point answers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from vibrofocus.analysis import load_trials
from vibrofocus.errors import ValidationError
from vibrofocus.simulation import default_bank
from vibrofocus.simulation.design import participant_loglik as design_loglik
from vibrofocus.simulation.fitting import FitSettings, lab_trials, participant_loglik

#: Study 1 trials of one participant, (method, target, answer, level_db, allowed): a block at
#: -10 dB among the corners, one at 0 dB among every location, and a point block (m).
TRIALS = [("inverse", 1, 1, -10.0, (1, 3, 7, 9)), ("inverse", 9, 7, -10.0, (1, 3, 7, 9)),
          ("combination", 3, 3, -10.0, (1, 3, 7, 9)), ("funneling", 5, 4, 0.0, tuple(range(1, 10))),
          ("funneling", 1, (0.004, -0.011), -20.0, (1, 3, 7, 9)), ("inverse", 7, (-0.018, 0.002), -20.0, (1, 3, 7, 9))]


def _table(trials, protocol="designed-study1"):
    rows = []
    for i, (method, target, answer, level, allowed) in enumerate(trials):
        point = isinstance(answer, tuple)
        rows.append({"participant": "sim-001", "study": "1", "phase": "main", "trial": str(i + 1), "method": method,
                     "target": str(target), "response": str(target if point else answer), "rt_s": "",
                     "protocol": protocol, "level_db": str(level), "allowed": " ".join(map(str, allowed)),
                     "response_x_mm": f"{answer[0] * 1e3:.6f}" if point else "",
                     "response_y_mm": f"{answer[1] * 1e3:.6f}" if point else ""})
    return pd.DataFrame(rows)


def _one_forearm():
    b = default_bank()
    return dataclasses.replace(b, energy=b.energy[:1], actuator_energy=b.actuator_energy[:1],
                               forearm_seeds=b.forearm_seeds[:1], drive_peak_v=None if b.drive_peak_v is None
                               else b.drive_peak_v[:1], target_peak_m=None if b.target_peak_m is None
                               else b.target_peak_m[:1])


@pytest.mark.parametrize("name", ["intensity", "v3-centroid"])
def test_the_fit_scores_designed_trials_as_the_design_does(name):
    # One forearm and no lapse: the fit's likelihood of a designed study's trials (levels,
    # allowed answers, points) is the design module's, the same trait draws.
    one = _one_forearm()
    data = lab_trials(load_trials(_table(TRIALS)), one)
    assert data.level1 is not None and data.allowed1 is not None and np.isfinite(data.point1).sum() == 4
    got = participant_loglik(name, data, bank=one, settings=FitSettings(n_draws=4, lapse=0.0, seed=5))
    want = design_loglik(name, one, 0, TRIALS, n_draws=4, seed=5)
    np.testing.assert_allclose(got, [want], rtol=1e-9)


def test_a_designed_trials_file_without_its_blocks_is_refused():
    table = _table(TRIALS).drop(columns=["level_db", "allowed"])
    with pytest.raises(ValidationError, match="protocol 'designed-study1'.*level_db and allowed: export them again"):
        lab_trials(load_trials(table), default_bank())
    # An export that has the columns but left a designed row's cells empty says no more.
    with pytest.raises(ValidationError, match="protocol 'designed-study1'.* block's allowed: export them again"):
        lab_trials(load_trials(_table(TRIALS).assign(allowed="")), default_bank())
    # The paper's own protocol needs neither: every trial at 0 dB among every location.
    paper = _table([t[:3] + (0.0, tuple(range(1, 10))) for t in TRIALS[:4]], protocol="paper-study1")
    data = lab_trials(load_trials(paper.drop(columns=["level_db", "allowed"])), default_bank())
    assert data.level1 is None and data.allowed1 is None and data.point1 is None


@pytest.mark.parametrize("column, value, match", [
    ("allowed", "1 3", "answer outside its block's allowed locations"),
    ("allowed", "0 12", "line 5: allowed '0 12' names location 0, outside 1..9"),
    ("level_db", "loud", "line 5: level_db must be a finite number of dB within"),
    ("level_db", "NaN", "line 5: level_db must be a finite number of dB within .*'NaN'"),
    ("level_db", "1e300", "line 5: level_db must be a finite number of dB within .*'1e300'"),
    ("response_x_mm", "far", "line 5: response_x_mm and response_y_mm must both be finite numbers"),
    ("response_x_mm", "1e9", "line 5: response_x_mm and response_y_mm must both be finite numbers .*'1e9'"),
])
def test_block_values_the_fit_cannot_read_are_refused(column, value, match):
    table = _table(TRIALS[:4])
    table.loc[3, column] = value
    if column == "response_x_mm":
        table.loc[3, "response_y_mm"] = "1"
    with pytest.raises(ValidationError, match=match):
        lab_trials(load_trials(table), default_bank())

