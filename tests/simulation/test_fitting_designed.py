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



def _designed_database(path):
    """A real study database of a designed study: Study 1 at -10 dB among the corners, a point
    block at -20 dB, and the paper's Study 2, two participants (answers chosen by hand)."""
    from vibrofocus.studies import StudyStore

    rng = np.random.default_rng(3)
    with StudyStore(path) as store:
        for pid in ("p-01", "p-02"):
            store.add_participant(pid)
            blocks = [(1, {"methods": ["inverse", "combination"], "locations": [1, 3, 7, 9], "level_db": -10.0}),
                      (1, {"methods": ["funneling", "inverse"], "locations": [1, 3, 7, 9], "level_db": -20.0,
                           "point": True}),
                      (2, {"protocol": "paper-study2", "methods": ["funneling", "inverse"], "locations": [2, 5]})]
            for k, (study, config) in enumerate(blocks):
                sid = store.create_session(pid, study, seed=k, config={
                    "protocol": "designed-check", "block": k, "repetitions": 1, "n_training": 1, **config})
                for t in store.planned_trials(sid):
                    if config.get("point"):
                        point = tuple(float(v) for v in rng.uniform(-25.0, 25.0, 2))
                        store.record_answer(sid, t.trial_index, None, 0.5, answer_id=f"{pid}-{k}-{t.trial_index}",
                                            point_mm=point)
                    else:
                        answer = [int(rng.choice(config["locations"]))] if study == 1 else config["locations"]
                        store.record_answer(sid, t.trial_index, answer, 0.5, answer_id=f"{pid}-{k}-{t.trial_index}")
    return path


def test_a_designed_study_fits_the_same_from_its_database_csv_and_bids(tmp_path):
    # The fit of analyze --hypotheses reads a designed study's levels, allowed answers and
    # point answers from its database, its trials CSV, its BIDS export and the BIDS export of
    # that CSV alike: the same trials, so the same likelihood.
    from vibrofocus.studies import StudyStore, export_bids
    from vibrofocus.simulation.fitting import trials_source

    db = _designed_database(tmp_path / "s.db")
    with StudyStore(db) as store:
        store.export_trials_csv(tmp_path / "trials.csv")
    export_bids(db, tmp_path / "bids")
    export_bids(tmp_path / "trials.csv", tmp_path / "bids-of-csv")
    one = _one_forearm()
    sources = {"database": trials_source(db), "csv": tmp_path / "trials.csv", "bids": tmp_path / "bids",
               "bids of the csv": tmp_path / "bids-of-csv"}
    # Sessions without a calibration (dry runs) are what this database holds: kept.
    read = {name: lab_trials(load_trials(source, keep_dry_runs=True), one) for name, source in sources.items()}
    want = read.pop("database")
    assert set(want.level1) == {-10.0, -20.0} and want.allowed1[:, [0, 2, 6, 8]].all()
    assert np.isfinite(want.point1[:, 0]).sum() == 16 and not want.allowed1[:, [1, 3, 4, 5, 7]].any()
    settings = FitSettings(n_draws=2, lapse=0.0, seed=1)
    loglik = participant_loglik("v3-centroid", want, bank=one, settings=settings)
    for name, got in read.items():
        assert got.participants == want.participants, name
        for field in ("part1", "stim1", "answer1", "level1", "allowed1", "point1", "part2", "stim2", "selected2",
                      "level2", "allowed2"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=f"{name}: {field}")
        np.testing.assert_allclose(participant_loglik("v3-centroid", got, bank=one, settings=settings), loglik,
                                   rtol=1e-12, err_msg=name)
    # An export without the block columns (an older vibrofocus) is refused in one line, for
    # the CSV and for BIDS alike; the paper's protocol needs none of them.
    old = pd.read_csv(tmp_path / "trials.csv", dtype=str, keep_default_na=False).drop(columns=["level_db", "allowed"])
    old.to_csv(tmp_path / "old.csv", index=False)
    with pytest.raises(ValidationError, match=r"^study 1 of .*old.csv' comes from protocol 'designed-check', and the "
                                              r"trials do not say each block's level_db and allowed: export them again"):
        lab_trials(load_trials(tmp_path / "old.csv", keep_dry_runs=True), one)
    for events in (tmp_path / "bids").glob("sub-*/ses-*/beh/*_events.tsv"):
        table = pd.read_csv(events, sep="\t", dtype=str, keep_default_na=False)
        table.drop(columns="allowed").to_csv(events, sep="\t", index=False)
    with pytest.raises(ValidationError, match="protocol 'designed-check', and the trials do not say each block's "
                                              "allowed: export them again"):
        lab_trials(load_trials(tmp_path / "bids", keep_dry_runs=True), one)
    old.assign(protocol="paper-study1").to_csv(tmp_path / "paper.csv", index=False)
    paper = lab_trials(load_trials(tmp_path / "paper.csv", keep_dry_runs=True), one)  # read at 0 dB among every location
    assert paper.level1 is None and paper.allowed1 is None and np.isfinite(paper.point1[:, 0]).sum() == 16
