"""Two processes simulating into one study database get one Study 1 session per participant."""

from __future__ import annotations

import multiprocessing

import pytest

from vibrofocus.studies import StudyStore

pytestmark = pytest.mark.slow

DESIGN = {"repetitions": 1, "n_training": 0, "locations": [4, 6]}


def _simulate(db, barrier, results, name):
    from vibrofocus.errors import VibrofocusError
    from vibrofocus.simulation import simulate

    calibration_for = simulate._calibration_for

    def in_step(*args, **kwargs):
        # Both processes have checked for a session and calibrated before either plans
        # one: the check-then-create gap, held open deterministically.
        out = calibration_for(*args, **kwargs)
        barrier.wait(timeout=240)
        return out

    simulate._calibration_for = in_step
    try:
        simulate.simulate_studies(db, n_participants=1, seed=3, studies=(1,), config=dict(DESIGN))
        results.put((name, "ok"))
    except VibrofocusError as exc:
        results.put((name, f"error: {exc}"))
    except BaseException:
        import traceback

        results.put((name, f"unexpected: {traceback.format_exc()}"))


def test_two_processes_on_one_database_make_one_session_per_participant(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(2), ctx.Queue()
    db = tmp_path / "same.sqlite"
    procs = [ctx.Process(target=_simulate, args=(db, barrier, results, name))
             for name in ("a", "b")]
    for p in procs:
        p.start()
    outcomes = dict(results.get(timeout=400) for _ in procs)
    for p in procs:
        p.join(60)
        assert p.exitcode == 0, outcomes
    with StudyStore(db, create=False) as store:
        sessions = store.sessions("sim-001", study=1)
        assert len(sessions) == 1, outcomes
        (info,) = sessions
        assert info.status == "completed" and info.n_answered == info.n_trials == 3 * len(DESIGN["locations"])
        assert [a.trial_index for a in store.answers(info.session_id)] == list(range(info.n_trials))
        for rec in store.calibrations("sim-001"):  # each process's calibration kept, under its own name
            store.verify_calibration(rec.calibration_id)
    # The loser resumed the winner's session, or said that another process runs it.
    assert "ok" in outcomes.values(), outcomes
    assert all(v == "ok" or "another process" in v for v in outcomes.values()), outcomes


def test_two_databases_sharing_a_calibration_folder_keep_each_others_calibrations(tmp_path):
    from vibrofocus.simulation import simulate_studies

    shared = tmp_path / "shared"
    for name in ("a", "b"):
        simulate_studies(tmp_path / f"{name}.sqlite", n_participants=1, seed=3, studies=(1,), config=dict(DESIGN),
                         calibration_dir=shared)
    paths = {}
    for name in ("a", "b"):
        with StudyStore(tmp_path / f"{name}.sqlite", create=False) as store:
            (rec,) = store.calibrations("sim-001")
            store.verify_calibration(rec.calibration_id)  # unchanged since registered
            paths[name] = rec.path
    assert sorted(p.name for p in shared.iterdir()) == ["sim-001.1.nc", "sim-001.nc"]
    assert paths["a"] != paths["b"]
