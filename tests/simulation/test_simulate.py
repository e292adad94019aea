"""A whole simulated study: 3 participants through both studies, exported and analysed."""

import csv
import json
from collections import Counter

import numpy as np
import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.layout import ArrayLayout
from vibrofocus.studies import TRIALS_COLUMNS, StudyStore
from vibrofocus.io.trials_csv import POINT_COLUMNS, PROTOCOL_COLUMNS, STIMULUS_COLUMNS
from vibrofocus.studies.export import ONSET_COLUMNS, SESSION_COLUMNS
from vibrofocus.simulation.simulate import participant_seeds, simulate_studies

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim3")
    db, out = root / "study.db", root / "trials.csv"
    result = CliRunner().invoke(app, [
        "simulate-study", "--participants", "3", "--seed", "11", "--db", str(db), "--trials-csv", str(out), "--quiet",
    ])
    assert result.exit_code == 0, result.output
    return db, out, result.output


def test_export_has_the_contract_columns_and_every_trial(simulated):
    db, out, output = simulated
    with open(out, newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        rows = [dict(zip(header, r)) for r in reader]
    # A database export: the contract's columns, the session columns, the onset columns, the
    # stimulus columns, the protocol and the point columns, the xrun and the block columns
    # (docs/file-formats.md), then the flag that these participants are simulated (a model,
    # not data) and the model's label.
    assert tuple(header) == (TRIALS_COLUMNS + SESSION_COLUMNS + ONSET_COLUMNS + STIMULUS_COLUMNS
                             + PROTOCOL_COLUMNS + POINT_COLUMNS + ("xrun_represented", "level_db", "allowed",
                                                                   "simulated", "model"))
    assert {r["response_x_mm"] for r in rows} == {""}  # the paper's studies answer with location keys
    assert {r["levels"] for r in rows} == {"paper"}
    # Every row names the model and the hypothesis that answered.
    from vibrofocus.simulation.hypotheses import DEFAULT_HYPOTHESIS, hypothesis

    (label,) = {r["model"] for r in rows}
    assert label == hypothesis().label()  # the default hypothesis, with its version and fit
    assert f"hypothesis {DEFAULT_HYPOTHESIS} v{hypothesis().version} fitted at paper levels" in label
    assert label.startswith("simulated participants: model v3.0") and label.endswith("not data")
    assert {r["onset_clock"] for r in rows} == {"simulated_samples"}
    for session in {r["session"] for r in rows}:  # the rig's sample clock runs on through a session
        device = [float(r["onset_device_s"]) for r in rows if r["session"] == session]
        assert all(b > a for a, b in zip(device, device[1:]))
    assert {r["dry_run"] for r in rows} == {"0"}, "simulated sessions are calibrated"
    assert {r["simulated"] for r in rows} == {"1"}
    assert len(rows) == 3 * 2 * 86
    keys = Counter((r["participant"], r["study"], r["phase"], r["trial"]) for r in rows)
    assert max(keys.values()) == 1  # no duplicates
    assert {r["participant"] for r in rows} == {"sim-001", "sim-002", "sim-003"}
    for r in rows:
        assert r["study"] in ("1", "2") and r["phase"] in ("training", "main")
        assert r["method"] in ("funneling", "inverse", "combination")
        assert 1 <= int(r["target"]) <= 9
        resp = [int(x) for x in r["response"].split(" ")]
        assert all(1 <= x <= 9 for x in resp) and resp == sorted(set(resp))
        assert len(resp) == 1 or r["study"] == "2"
        assert 0.2 < float(r["rt_s"]) < 10.0
    # Each participant, study: each condition exactly 3 times in the main phase.
    for pid in ("sim-001", "sim-002", "sim-003"):
        for study in ("1", "2"):
            main = Counter((r["method"], r["target"]) for r in rows
                           if r["participant"] == pid and r["study"] == study and r["phase"] == "main")
            assert len(main) == 27 and set(main.values()) == {3}
    assert "model" in output.lower() and "not data" in output


def test_simulated_localization_lands_in_human_ranges(simulated):
    db, out, _ = simulated
    loc = ArrayLayout.reference().locations_xy * 1e3
    with open(out, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["phase"] == "main"]
    for method in ("funneling", "inverse", "combination"):
        s1 = [r for r in rows if r["study"] == "1" and r["method"] == method]
        err = np.mean([np.linalg.norm(loc[int(r["response"]) - 1] - loc[int(r["target"]) - 1]) for r in s1])
        # Answers on a 10 mm grid: between perfect and chance (about 13 mm), as people are.
        assert 2.0 < err < 13.0, (method, err)
        s2 = [len(r["response"].split()) for r in rows if r["study"] == "2" and r["method"] == method]
        assert 1.0 < np.mean(s2) < 5.0
        rts = [float(r["rt_s"]) for r in s1]
        assert 0.8 < np.median(rts) < 1.8


def test_sessions_store_seeds_calibration_and_status(simulated):
    db, _, _ = simulated
    with StudyStore(db) as store:
        assert all(p.simulated for p in store.participants())
        for k, pid in enumerate(("sim-001", "sim-002", "sim-003"), start=1):
            pseed, s1, s2 = participant_seeds(11, k)
            sessions = store.sessions(pid)
            assert [(s.study, s.seed, s.status) for s in sessions] == [(1, s1, "completed"), (2, s2, "completed")]
            assert sessions[0].calibration_id == sessions[1].calibration_id is not None
            store.verify_calibration(sessions[0].calibration_id)
            assert all(a.drive_sha256 and a.calibration_id == sessions[0].calibration_id
                       for s in sessions for a in store.answers(s.session_id))


def test_running_again_on_a_finished_database_adds_nothing(simulated):
    db, _, _ = simulated
    result = simulate_studies(db, n_participants=3, seed=11)
    assert result == {"n_answered": 516, "n_total": 516, "n_new": 0, "n_participants": 3}


def test_a_run_over_fewer_participants_reports_the_databases_count(simulated):
    db, _, _ = simulated
    result = CliRunner().invoke(app, ["simulate-study", "-n", "1", "--seed", "11", "--db", str(db), "--quiet"])
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    assert "516 answers stored" in text and "for 3 simulated participant(s) (1 in this run)" in text


def test_a_database_keeps_its_participants_and_methods_in_any_order(tmp_path):
    from vibrofocus.defaults import STUDY_METHODS

    db = tmp_path / "two.db"
    small = {"repetitions": 1, "n_training": 0, "locations": [4, 6]}
    first = simulate_studies(db, n_participants=2, seed=5, config=dict(small))
    # The same methods in another order are the same study: nothing refused, nothing added.
    again = simulate_studies(db, n_participants=2, seed=5, config=dict(small), methods=tuple(reversed(STUDY_METHODS)))
    assert again == {**first, "n_new": 0}
    # Without -n, a database of 2 keeps 2 (the default 3 added one silently).
    result = CliRunner().invoke(app, ["simulate-study", "--seed", "5", "--db", str(db), "--quiet"])
    assert result.exit_code == 0, result.output
    assert "for 2 simulated participant(s)." in " ".join(result.output.split())
    with StudyStore(db, create=False) as store:
        assert [p.participant_id for p in store.participants()] == ["sim-001", "sim-002"]


def test_another_seed_on_the_same_database_is_refused(simulated):
    db, _, _ = simulated
    result = CliRunner().invoke(app, ["simulate-study", "--participants", "1", "--seed", "12", "--db", str(db), "--quiet"])
    assert result.exit_code == 2
    assert "seed 11, not 12" in " ".join(result.output.split())


def test_analysis_reads_the_export(simulated, tmp_path):
    _, out, _ = simulated
    # The analysis ships with the package: an import failure is a failure, not a skip.
    result = CliRunner().invoke(app, ["analyze", str(out), "--out", str(tmp_path / "report"), "--quiet",
                                      "--simulated"])
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    effects = {row["effect"] for row in report["study1"]["anova"]}
    assert {"location", "method"} <= effects
    assert set(report["study2"]["friedman"]) >= {"location", "method"}
    # The report says at which levels the methods played: per method and location.
    levels = {(r["method"], r["target"]): r for r in report["stimulus_levels"]}
    assert len(levels) == 27 and {r["levels"] for r in levels.values()} == {"paper"}
    assert levels[("funneling", 5)]["drive_peak_v"] == pytest.approx(2.5)
    assert all(levels[("inverse", t)]["drive_peak_v"] > levels[("funneling", t)]["drive_peak_v"] for t in range(1, 10))
    from vibrofocus.simulation.hypotheses import DEFAULT_HYPOTHESIS

    assert f"hypothesis {DEFAULT_HYPOTHESIS} v" in report["simulated"]["model"]


def test_other_methods_are_studied_and_a_resume_keeps_them(tmp_path):
    # Any registered method can be compared, the minimax design among them; the stimuli
    # are rendered from each participant's calibration as for the paper's methods.
    db = tmp_path / "minimax.db"
    result = CliRunner().invoke(app, ["simulate-study", "-n", "1", "--seed", "4", "--db", str(db), "--quiet",
                                      "--methods", "inverse,minimax"])
    assert result.exit_code == 0, result.output
    with StudyStore(db, create=False) as store:
        rows = store.trial_rows()
    main = Counter((r["study"], r["method"]) for r in rows if r["phase"] == "main")
    assert main == {(s, m): 27 for s in (1, 2) for m in ("inverse", "minimax")}
    assert all(r["drive_sha256"] for r in rows)  # every stimulus was rendered and played
    # The same database with the paper's methods would mix two designs: refused, nothing added.
    again = CliRunner().invoke(app, ["simulate-study", "-n", "2", "--seed", "4", "--db", str(db), "--quiet"])
    assert again.exit_code != 0 and "simulated with the methods inverse, minimax" in again.output
    with StudyStore(db, create=False) as store:
        assert len(store.trial_rows()) == len(rows) and [p.participant_id for p in store.participants()] == ["sim-001"]


def test_the_paper_levels_reach_the_trials_file(simulated):
    # Issue 42's check, from the trials file alone: funneling by eq. 3 at A = 10 V (the
    # paper's 2.5 V at the centre, (1 - 12.5/45)^2 * 10 = 5.22 V at a corner's nearest
    # exciter), the inverse filter within 10 V and above funneling at every location.
    _, out, _ = simulated
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    peak = {}
    for r in rows:
        peak.setdefault((r["participant"], r["method"], int(r["target"])), set()).add(float(r["drive_peak_v"]))
    assert all(len(v) == 1 for v in peak.values())  # one stimulus per condition and participant
    peak = {k: v.pop() for k, v in peak.items()}
    for pid in ("sim-001", "sim-002", "sim-003"):
        assert peak[(pid, "funneling", 5)] == pytest.approx(2.50, abs=0.05)
        for corner in (1, 3, 7, 9):
            assert peak[(pid, "funneling", corner)] == pytest.approx(10 * (1 - 12.5 / 45) ** 2, abs=1e-6)
            assert peak[(pid, "funneling", corner)] == pytest.approx(5.22, abs=0.1)
        for loc in range(1, 10):
            assert peak[(pid, "funneling", loc)] < peak[(pid, "inverse", loc)] <= 10.0 + 1e-9
    assert all(float(r["target_peak_um"]) > 0 for r in rows)


def test_other_levels_on_the_same_database_are_refused(simulated):
    db, _, _ = simulated
    result = CliRunner().invoke(app, ["simulate-study", "-n", "1", "--seed", "11", "--db", str(db), "--quiet",
                                      "--levels", "equal-peak"])
    assert result.exit_code == 2
    assert "simulated at 'paper' levels, not 'equal-peak'" in " ".join(result.output.split())
