"""The command line: a SIGKILL in the middle of a study loses nothing; export; the
terminal runner."""

import csv
import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app
from vibrofocus.studies import StudyStore

pytestmark = pytest.mark.slow


def _answers(db):
    # A separate read-only connection, as another program would read the file.
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=30)
    try:
        return con.execute(
            "SELECT answer_id, session_id, trial_index, response, rt_s, drive_sha256, calibration_id, recorded_at "
            "FROM answers ORDER BY session_id, trial_index"
        ).fetchall()
    except sqlite3.OperationalError:  # the schema is not there yet
        return []
    finally:
        con.close()


def _simulate(db, *extra):
    return [sys.executable, "-m", "vibrofocus", "simulate-study", "--participants", "1", "--seed", "7",
            "--db", str(db), "--quiet", *extra]


def test_sigkill_mid_study_loses_and_duplicates_nothing(tmp_path):
    db = tmp_path / "study.db"
    proc = subprocess.Popen(_simulate(db, "--pace", "0.05"), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            if db.exists() and len(_answers(db)) >= 25:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"simulate-study ended before the kill: {proc.stderr.read().decode()[-2000:]}"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    before = _answers(db)
    assert 25 <= len(before) < 172, "the kill must land in the middle of the study"

    rerun = subprocess.run(_simulate(db), capture_output=True, text=True, timeout=400)
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    after = _answers(db)
    assert after[: len(before)] == before  # every committed answer, unchanged
    assert len(after) == 172 == len({(a[1], a[2]) for a in after}) == len({a[0] for a in after})

    out = tmp_path / "trials.csv"
    result = CliRunner().invoke(app, ["study", "export", "--db", str(db), "--out", str(out)])
    assert result.exit_code == 0, result.output
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 172
    assert len({(r["study"], r["phase"], r["trial"]) for r in rows}) == 172

    # The resumed run answered as an uninterrupted one would: recompute every answer
    # from the stored calibration, the participant seed and the trial.
    from vibrofocus.calibration import load_calibration
    from vibrofocus.rigs import make_rig
    from vibrofocus.studies.engine import calibration_renderer, drive_sha256
    from vibrofocus.simulation.participants import SimulatedParticipant

    with StudyStore(db) as store:
        info = store.sessions("sim-001")[0]
        rig = make_rig("simulated", seed=info.config["participant_seed"], skin=info.config["skin"])
        cal = load_calibration(store.verify_calibration(info.calibration_id))
        renderer = calibration_renderer(cal)
        model = SimulatedParticipant(rig, info.config["participant_seed"])
        cache = {}
        for session in store.sessions("sim-001"):
            plan = store.planned_trials(session.session_id)
            for trial, answer in zip(plan, store.answers(session.session_id)):
                key = (trial.method, trial.target)
                if key not in cache:
                    cache[key] = renderer(*key)
                expected = model.answer(cache[key], session.study, trial.trial_index, session.design)
                assert answer.response == expected.locations
                assert answer.rt_s == pytest.approx(expected.rt_s, rel=1e-12)
                assert answer.drive_sha256 == drive_sha256(cache[key])


def test_export_refuses_a_missing_database(tmp_path):
    result = CliRunner().invoke(app, ["study", "export", "--db", str(tmp_path / "none.db"), "--out", str(tmp_path / "t.csv")])
    assert result.exit_code == 2
    assert "no study database" in " ".join(result.output.split())


def test_terminal_runner_takes_keypad_answers_pause_and_abort(tmp_path, calibration_file):
    db = tmp_path / "real.db"
    args = ["study", "run", "--participant", "p-real", "--study", "2", "--db", str(db),
            "--calibration", str(calibration_file), "--seed", "3", "--no-beep"]
    # Trial 1: "45"; trial 2: a bad answer then "9"; pause and resume; trial 3: "1 2 3"; abort.
    result = CliRunner().invoke(app, args, input="45\n0\n9\np\n\n1 2 3\nq\n")
    assert result.exit_code == 0, result.output
    assert "outside the study's locations" in " ".join(result.output.split())
    with StudyStore(db) as store:
        (session,) = store.sessions("p-real")
        assert session.status == "aborted"
        assert [a.response for a in store.answers(session.session_id)] == [(4, 5), (9,), (1, 2, 3)]
        assert all(a.drive_sha256 for a in store.answers(session.session_id))
    # Running again resumes the same session at trial 4; the end of the input (nobody is
    # answering any more) pauses it, with one error line and exit 2 (issue 31).
    result = CliRunner().invoke(app, args, input="5\n")
    assert result.exit_code == 2, result.output
    assert "resuming session 1: 3 of 86" in " ".join(result.output.split())
    assert [line for line in result.output.splitlines() if line.startswith("error:")] == [
        line for line in result.output.splitlines() if "input ended" in line and "paused" in line]
    with StudyStore(db) as store:
        assert [a.trial_index for a in store.answers(1)] == [0, 1, 2, 3]
        assert store.session(1).status == "paused"


def test_terminal_runner_refuses_a_calibration_of_someone_else(tmp_path, calibration_file):
    result = CliRunner().invoke(app, [
        "study", "run", "--participant", "p-other", "--study", "1", "--db", str(tmp_path / "x.db"),
        "--calibration", str(calibration_file), "--no-beep",
    ])
    assert result.exit_code == 2
    assert "belongs to participant 'p-real'" in " ".join(result.output.split())




@pytest.mark.parametrize("content", [b"", b"not a database at all\n"])
def test_export_refuses_an_empty_or_foreign_file_and_leaves_it_untouched(tmp_path, content):
    db = tmp_path / "empty.sqlite"
    db.write_bytes(content)
    out = tmp_path / "t.csv"
    result = CliRunner().invoke(app, ["study", "export", "--db", str(db), "--out", str(out)])
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.split())
    assert text.startswith("error:") and "not a vibrofocus study database" in text
    assert "Traceback" not in result.output
    assert db.read_bytes() == content  # an export writes nothing into the database file
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.sqlite"]  # no -wal / -shm left


def test_export_of_a_study_database_keeps_the_csv_contract(tmp_path, calibration_file):
    db = tmp_path / "s.db"
    with StudyStore(db) as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 2, seed=4, config={"repetitions": 1, "n_training": 2})
        trials = store.planned_trials(sid)
        for t, resp in zip(trials[:4], ([5], [4, 5], [1], [9, 2, 3])):
            store.record_answer(sid, t.trial_index, resp, 0.25 * (t.trial_index + 1), answer_id=f"a{t.trial_index}")
    out = tmp_path / "t.csv"
    result = CliRunner().invoke(app, ["study", "export", "--db", str(db), "--out", str(out)])
    assert result.exit_code == 0, result.output
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:8] == ["participant", "study", "phase", "trial", "method", "target", "response", "rt_s"]
    assert rows[0][8:] == ["session", "session_status", "dry_run", "rig", "onset_host_s", "onset_device_s", "onset_clock",
                           "levels", "drive_peak_v", "target_peak_um", "protocol", "response_x_mm", "response_y_mm",
                           "xrun_represented", "level_db", "allowed"]
    # No calibration: a dry run, whose answers (given here without onsets) have empty onset and peak cells;
    # the session stored no rig: an empty rig cell.
    assert {tuple(r[8:]) for r in rows[1:]} == {(str(sid), "running", "1", "", "", "", "", "paper", "", "",
                                                 "paper-study2", "", "", "0", "0.0", "1 2 3 4 5 6 7 8 9")}
    assert [r[2:4] for r in rows[1:]] == [["training", "1"], ["training", "2"], ["main", "1"], ["main", "2"]]
    assert [r[6] for r in rows[1:]] == ["5", "4 5", "1", "2 3 9"]
    assert [float(r[7]) for r in rows[1:]] == [0.25, 0.5, 0.75, 1.0]
    assert [(int(r[5]), r[4]) for r in rows[1:]] == [(t.target, t.method) for t in trials[:4]]


def test_terminal_runner_with_a_bad_rig_writes_nothing(tmp_path, calibration_file):
    db = tmp_path / "x.db"
    result = CliRunner().invoke(app, [
        "study", "run", "--participant", "p-real", "--study", "1", "--db", str(db),
        "--calibration", str(calibration_file), "--rig", "audio", "--no-beep",
    ], input="")
    assert result.exit_code == 2, result.output
    assert "rig config" in " ".join(result.output.split())
    if db.exists():  # nothing of this refused run is stored
        with StudyStore(db) as store:
            assert store.participants() == [] and store.sessions() == []


def test_simulate_study_refuses_a_trials_csv_folder_that_does_not_exist_before_simulating(tmp_path):
    db = tmp_path / "study.sqlite"
    result = CliRunner().invoke(
        app, ["simulate-study", "--participants", "1", "--seed", "1", "--db", str(db),
              "--trials-csv", str(tmp_path / "missing" / "trials.csv")],
    )
    assert result.exit_code == 2
    message = " ".join(result.output.split())
    assert "--trials-csv" in message and "does not exist" in message
    assert not db.exists()  # refused before anything was simulated or stored


def test_keys_typed_ahead_at_a_terminal_are_not_the_next_trials_answers(tmp_path, calibration_file):
    # Issue 54, item 2b: at a real terminal (a pty), "5⏎5⏎5⏎" typed once is one answer.
    import pty
    import select

    db = tmp_path / "typed.db"
    main, child_tty = pty.openpty()
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", COLUMNS="200", TERM="dumb")
    proc = subprocess.Popen([sys.executable, "-m", "vibrofocus", "study", "run", "--participant", "p-real",
                             "--study", "1", "--db", str(db), "--calibration", str(calibration_file), "--seed", "3",
                             "--no-beep"], stdin=child_tty, stdout=child_tty, stderr=child_tty, env=env)
    os.close(child_tty)
    seen = b""

    def wait_for(text: bytes, timeout_s: float = 600.0) -> None:
        nonlocal seen
        deadline = time.monotonic() + timeout_s
        while text not in seen:
            assert time.monotonic() < deadline and proc.poll() is None, seen[-2000:]
            ready, _, _ = select.select([main], [], [], 1.0)
            if ready:
                try:
                    seen += os.read(main, 4096)
                except OSError:
                    break

    try:
        wait_for(b"trial 1/")
        os.write(main, b"5\n5\n5\n")  # typed at once: the first prompt takes the first line
        wait_for(b"trial 2/")
        time.sleep(1.0)  # whatever was typed ahead has reached the terminal's buffer
        os.write(main, b"q\n")
        assert proc.wait(timeout=120) == 0, seen[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(main)
    assert b"trial 3/" not in seen, seen[-2000:]
    with StudyStore(db) as store:
        (session,) = store.sessions("p-real")
        assert [a.trial_index for a in store.answers(session.session_id)] == [0]
        assert session.status == "aborted"
