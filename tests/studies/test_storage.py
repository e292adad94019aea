"""StudyStore: nothing acknowledged is lost, nothing duplicated, bad input refused."""

import sqlite3

import pytest

from vibrofocus.errors import AnswerRefused, StudyError
from vibrofocus.studies import SCHEMA_VERSION, StudyStore


@pytest.fixture
def store(tmp_path):
    with StudyStore(tmp_path / "study.db") as s:
        yield s


@pytest.fixture
def session(store):
    store.add_participant("p01")
    return store.create_session("p01", 1, seed=42)


def _answer_all(store, sid, n, response=5):
    for k in range(n):
        t = store.next_trial(sid)
        store.record_answer(sid, t.trial_index, response, 1.0 + k / 100, answer_id=f"s{sid}-t{t.trial_index}")


def test_database_uses_wal_full_sync_and_schema_version(store):
    raw = sqlite3.connect(store.path)
    assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert raw.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert store._conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    raw.close()


def test_plan_is_written_before_the_first_stimulus(store, session):
    trials = store.planned_trials(session)
    assert len(trials) == 86
    assert store.next_trial(session) == trials[0]
    info = store.session(session)
    assert (info.status, info.seed, info.n_answered, info.study) == ("planned", 42, 0, 1)
    assert info.config["repetitions"] == 3


def test_answer_is_committed_and_visible_to_another_connection(store, session):
    t = store.next_trial(session)
    receipt = store.record_answer(session, t.trial_index, "3", 0.9, answer_id="a-1", drive_sha256="ab" * 32)
    other = sqlite3.connect(store.path)
    row = other.execute("SELECT response, rt_s, drive_sha256 FROM answers WHERE answer_id = 'a-1'").fetchone()
    other.close()
    assert row == ("3", 0.9, "ab" * 32)
    assert receipt.response == (3,)
    assert store.next_trial(session).trial_index == t.trial_index + 1
    assert store.session(session).status == "running"


def test_same_answer_id_returns_same_receipt_without_duplicate(store, session):
    first = store.record_answer(session, 0, 4, 1.1, answer_id="retry-me")
    again = store.record_answer(session, 0, 4, 1.1, answer_id="retry-me")
    assert again == first
    assert len(store.answers(session)) == 1
    assert len(store.events(session, kind="answer")) == 1


def test_second_different_answer_to_a_trial_is_refused(store, session):
    store.record_answer(session, 0, 4, 1.1, answer_id="one")
    with pytest.raises(StudyError, match="already answered"):
        store.record_answer(session, 0, 6, 1.2, answer_id="two")
    with pytest.raises(StudyError, match="already used"):
        store.record_answer(session, 0, 6, 1.2, answer_id="one")
    assert [a.response for a in store.answers(session)] == [(4,)]


def test_bad_requests_are_refused_with_clear_messages(store, session):
    with pytest.raises(StudyError, match="unknown participant 'ghost'"):
        store.create_session("ghost", 1, seed=1)
    with pytest.raises(StudyError, match="unknown session 999"):
        store.record_answer(999, 0, 5, 1.0, answer_id="x")
    with pytest.raises(StudyError, match="unknown session"):
        store.next_trial(999)
    with pytest.raises(StudyError, match="outside the study's locations 1-9"):
        store.record_answer(session, 0, 10, 1.0, answer_id="x")
    with pytest.raises(StudyError, match="outside"):
        store.record_answer(session, 0, 0, 1.0, answer_id="x")
    with pytest.raises(StudyError, match="exactly one location"):
        store.record_answer(session, 0, "4 5", 1.0, answer_id="x")
    with pytest.raises(StudyError, match="has no trial 86"):
        store.record_answer(session, 86, 5, 1.0, answer_id="x")
    with pytest.raises(StudyError, match="not the next trial"):
        store.record_answer(session, 3, 5, 1.0, answer_id="x")
    with pytest.raises(StudyError, match="rt_s"):
        store.record_answer(session, 0, 5, float("nan"), answer_id="x")
    with pytest.raises(StudyError, match="answer_id"):
        store.record_answer(session, 0, 5, 1.0, answer_id="has space")
    with pytest.raises(StudyError, match="study must be 1 or 2"):
        store.create_session("p01", 3, seed=1)
    with pytest.raises(StudyError, match="participant id"):
        store.add_participant("bad,id")
    with pytest.raises(StudyError, match="status must be one of"):
        store.set_status(session, "exploded")
    assert store.answers(session) == []  # nothing half-written by refused requests


def test_study2_takes_several_distinct_locations(store):
    store.add_participant("p02")
    sid = store.create_session("p02", 2, seed=1)
    r = store.record_answer(sid, 0, "6 4 5", 2.0, answer_id="m1")
    assert r.response == (4, 5, 6)
    with pytest.raises(StudyError, match="more than once"):
        store.record_answer(sid, 1, "4 4", 2.0, answer_id="m2")


def test_newer_schema_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "future.db"
    StudyStore(path).close()
    raw = sqlite3.connect(path)
    raw.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    raw.commit()
    raw.close()
    with pytest.raises(StudyError, match="newer than this vibrofocus"):
        StudyStore(path)
    raw = sqlite3.connect(path)
    assert raw.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION + 1
    raw.close()


def test_foreign_files_are_refused(tmp_path):
    text = tmp_path / "notes.db"
    text.write_text("not a database at all, just some text that is long enough " * 20)
    with pytest.raises(StudyError, match="not a vibrofocus study database"):
        StudyStore(text)
    other = tmp_path / "other.db"
    raw = sqlite3.connect(other)
    raw.execute("CREATE TABLE t (x)")
    raw.commit()
    raw.close()
    with pytest.raises(StudyError, match="not a vibrofocus study database"):
        StudyStore(other)
    with pytest.raises(StudyError, match="does not exist"):
        StudyStore(tmp_path / "missing" / "x.db")


def test_answers_and_events_are_append_only(store, session):
    store.record_answer(session, 0, 5, 1.0, answer_id="keep")
    store.log_event(session, "cue", {"trial_index": 1})
    raw = sqlite3.connect(store.path)
    for sql in ("UPDATE answers SET response = '1'", "DELETE FROM answers", "UPDATE events SET kind = 'x'",
                "DELETE FROM events", "DELETE FROM sessions", "DELETE FROM planned_trials"):
        with pytest.raises(sqlite3.IntegrityError, match="append-only"):
            raw.execute(sql)
    raw.close()
    assert store.answers(session)[0].response == (5,)


def test_status_changes_are_logged_and_abort_keeps_data(store, session):
    _answer_all(store, session, 3)
    store.set_status(session, "paused")
    store.set_status(session, "running")
    store.set_status(session, "aborted")
    assert len(store.answers(session)) == 3
    kinds = [e.kind for e in store.events(session)]
    assert kinds[-3:] == ["pause", "resume", "abort"]
    with pytest.raises(StudyError, match="3 of 86"):
        store.set_status(session, "completed")
    # An aborted session resumes where it stopped.
    store.set_status(session, "running")
    assert store.next_trial(session).trial_index == 3


def test_last_answer_completes_the_session(store, session):
    _answer_all(store, session, 86)
    info = store.session(session)
    assert (info.status, info.n_answered) == ("completed", 86)
    assert store.next_trial(session) is None
    store.set_status(session, "completed")  # idempotent
    with pytest.raises(StudyError, match="is completed"):
        store.set_status(session, "running")


def test_calibration_is_registered_with_its_hash_and_checked(store, tmp_path):
    store.add_participant("p03")
    cal = tmp_path / "cal.nc"
    cal.write_bytes(b"calibration bytes")
    cid = store.add_calibration("p03", cal)
    assert store.add_calibration("p03", cal) == cid  # same content: same record
    sid = store.create_session("p03", 1, seed=0, calibration_id=cid)
    r = store.record_answer(sid, 0, 1, 1.0, answer_id="c1")
    assert r.calibration_id == cid
    assert store.verify_calibration(cid) == cal.resolve()
    cal.write_bytes(b"tampered")
    with pytest.raises(StudyError, match="changed since it was registered"):
        store.verify_calibration(cid)
    store.add_participant("p04")
    with pytest.raises(StudyError, match="belongs to participant 'p03'"):
        store.create_session("p04", 1, seed=0, calibration_id=cid)
    with pytest.raises(StudyError, match="cannot read the calibration file"):
        store.add_calibration("p03", tmp_path / "none.nc")


def test_full_disk_is_a_clear_error_and_committed_answers_survive(store, session):
    _answer_all(store, session, 2)
    before = store.answers(session)
    # Cap the file at its current size: the next write meets SQLITE_FULL, as on a full disk.
    pages = store._conn.execute("PRAGMA page_count").fetchone()[0]
    store._conn.execute(f"PRAGMA max_page_count = {pages}")
    payload = {"blob": "x" * 200_000}  # more than fits: forces new pages
    with pytest.raises(StudyError, match="disk holding .* is full.*intact"):
        store.log_event(session, "note", payload)
    full_error = None
    for k in range(2, 86):
        try:
            store.record_answer(session, k, 5, 1.0, answer_id=f"late-{k}")
        except StudyError as exc:
            full_error = exc
            break
    assert full_error is not None and "full" in str(full_error)
    store._conn.execute("PRAGMA max_page_count = 1073741823")
    after = store.answers(session)
    assert after[: len(before)] == before
    # The refused answer is not half-stored: its trial is still the next one.
    assert store.next_trial(session).trial_index == len(after)
    store.record_answer(session, len(after), 5, 1.0, answer_id="after-space-freed")


def test_export_writes_only_answered_trials_in_order(store, session, tmp_path):
    _answer_all(store, session, 7)
    out = tmp_path / "trials.csv"
    assert store.export_trials_csv(out) == 7
    lines = out.read_text().splitlines()
    # The contract's columns first, in order, then the session's (id, status, dry run, rig), then the onset's,
    # then the stimulus's (level rule, peak drive, predicted peak at the target), then the protocol's name,
    # then a point answer's place (mm; empty for a location answer), then the count of presentations again
    # after an xrun, then the block's level (dB re the level rule) and allowed answers.
    assert lines[0] == ("participant,study,phase,trial,method,target,response,rt_s,session,session_status,dry_run,rig,"
                        "onset_host_s,onset_device_s,onset_clock,levels,drive_peak_v,target_peak_um,protocol,"
                        "response_x_mm,response_y_mm,xrun_represented,level_db,allowed")
    plan = store.planned_trials(session)
    fields = [line.split(",") for line in lines[1:]]
    assert [f[2] for f in fields] == ["training"] * 5 + ["main"] * 2
    assert [f[4] for f in fields] == [t.method for t in plan[:7]]
    assert [int(f[5]) for f in fields] == [t.target for t in plan[:7]]


def test_concurrent_retries_of_one_answer_store_it_once(store, session):
    # Two threads (a double-clicked submit reaching two request handlers) race on one answer.
    import threading

    receipts, errors = [], []

    def submit():
        try:
            receipts.append(store.record_answer(session, 0, 2, 0.8, answer_id="double-click"))
        except StudyError as exc:  # pragma: no cover - would make the test fail below
            errors.append(exc)

    threads = [threading.Thread(target=submit) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert len(set(receipts)) == 1 and len(receipts) == 8
    assert len(store.answers(session)) == 1


def test_two_processes_share_the_database(store, session):
    # A second StudyStore on the same file (the web app beside the CLI) sees every commit.
    with StudyStore(store.path) as other:
        store.record_answer(session, 0, 1, 1.0, answer_id="from-a")
        other.record_answer(session, 1, 2, 1.0, answer_id="from-b")
        with pytest.raises(StudyError, match="already answered"):
            other.record_answer(session, 0, 3, 1.0, answer_id="late")
    assert [a.answer_id for a in store.answers(session)] == ["from-a", "from-b"]


def test_an_answer_that_must_be_presented_waits_for_its_onset_and_takes_its_hash(store, session):
    with pytest.raises(AnswerRefused, match="not been presented") as refused:
        store.record_answer(session, 0, 4, 0.5, answer_id="early", require_presented=True)
    assert refused.value.reason == "not_presented" and store.answers(session) == []
    store.log_event(session, "stimulus_onset", {"trial_index": 0, "drive_sha256": "a" * 64})
    store.log_event(session, "stimulus_onset", {"trial_index": 0, "drive_sha256": "b" * 64})  # presented again
    receipt = store.record_answer(session, 0, 4, 0.5, answer_id="late", require_presented=True)
    assert receipt.drive_sha256 == "b" * 64, "the hash of the last presentation"
    again = store.record_answer(session, 0, 4, 0.5, answer_id="late", require_presented=True)
    assert again == receipt and again.duplicate and not receipt.duplicate
    assert len(store.answers(session)) == 1


@pytest.mark.parametrize("call, reason", [
    (lambda st, s: st.record_answer(s, 0, 99, 0.5, answer_id="x1"), "invalid"),
    (lambda st, s: st.record_answer(s, 0, 4, -1.0, answer_id="x2"), "invalid"),
    (lambda st, s: st.record_answer(s, 500, 4, 0.5, answer_id="x3"), "unknown_trial"),
    (lambda st, s: st.record_answer(s, 0, 5, 0.5, answer_id="x4"), "answered"),
    (lambda st, s: st.record_answer(s, 0, 5, 0.5, answer_id="first"), "answered"),
    (lambda st, s: st.record_answer(s, 1, 4, 0.5, answer_id="first"), "reused_id"),
    (lambda st, s: st.record_answer(s, 2, 4, 0.5, answer_id="x5"), "not_current"),
])
def test_each_refusal_says_which_rule(store, session, call, reason):
    store.record_answer(session, 0, 4, 0.5, answer_id="first")
    with pytest.raises(AnswerRefused) as refused:
        call(store, session)
    assert refused.value.reason == reason
    assert [a.answer_id for a in store.answers(session)] == ["first"]


def test_open_session_checks_and_creates_in_one_transaction(tmp_path):
    import threading

    db = tmp_path / "s.sqlite"
    design = {"repetitions": 1, "n_training": 0, "methods": ["inverse"], "locations": [4]}
    with StudyStore(db) as store:
        store.add_participant("P01")
    barrier, out = threading.Barrier(4), []

    def run():
        with StudyStore(db) as store:  # a connection of its own, as another process has
            barrier.wait(timeout=30)
            out.append(store.open_session("P01", 1, seed=len(out), config=design))

    threads = [threading.Thread(target=run) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(created for _, created in out) == [False, False, False, True]
    assert len({sid for sid, _ in out}) == 1
    with StudyStore(db) as store:
        (info,) = store.sessions("P01", study=1)
        store.set_status(info.session_id, "aborted")  # unfinished: still the one to resume
        assert store.open_session("P01", 1, seed=1, config=design) == (info.session_id, False)
        store.record_answer(info.session_id, 0, 4, 0.5, answer_id="a-0")  # every trial answered
        # "open": a finished session is not resumed; "latest": it is the one.
        assert store.open_session("P01", 1, seed=1, config=design, reuse="latest") == (info.session_id, False)
        sid, created = store.open_session("P01", 1, seed=1, config=design)
        assert created and sid != info.session_id
        with pytest.raises(StudyError, match="reuse must be"):
            store.open_session("P01", 1, seed=1, reuse="any")
