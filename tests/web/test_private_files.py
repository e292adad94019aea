"""The server adopts no database, journal, secret or files folder that another user made or can change
(issue 53, item 2).

Before issue 53, ``create_app`` used each of these as it found it ("not ours: leave it as
it is"): another user's 0666 database (and SQLite gave its -wal and -shm the same owner
and mode), a secret they knew (so they could compute every participant key), and a files
folder of theirs, whose ``reports`` link was served as the lab's reports.
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys

import pytest
from fastapi.testclient import TestClient

from vibrofocus.errors import StudyError
from vibrofocus.web import create_app


TOKEN = "test-token-" + "x" * 20


def _lab(tmp_path):
    lab = tmp_path / "lab"
    lab.mkdir(mode=0o700)
    return lab, lab / "study.sqlite"


def _refused(db, *expected: str) -> str:
    with pytest.raises(StudyError) as caught:
        create_app(db, token=TOKEN)
    message = str(caught.value)
    for part in expected:
        assert part in message, message
    assert "\n" not in message
    return message


def _accepted(db) -> None:
    app = create_app(db, token=TOKEN)
    app.state.web.store.close()


@pytest.mark.parametrize("suffix", ["", "-wal", "-shm", "-journal", ".web-secret", ".web-logins"])
def test_files_of_another_user_beside_the_database_are_refused(tmp_path, other_user, suffix):
    lab, db = _lab(tmp_path)
    if suffix:
        _accepted(db)  # a real database of ours first
    planted = db.with_name(db.name + suffix)
    planted.write_text("00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff" if suffix == ".web-secret" else "")
    os.chmod(planted, 0o644 if suffix == ".web-secret" else 0o666)
    other_user.chown(planted)
    _refused(db, str(planted), f"belongs to user {other_user.name}", "refused")


def test_a_planted_secret_gives_no_participant_key(tmp_path, other_user):
    """The other user's known secret is never used: before issue 53, its HMAC keys opened the sessions."""
    lab, db = _lab(tmp_path)
    secret = db.with_name(db.name + ".web-secret")
    secret.write_text("00" * 32)
    os.chmod(secret, 0o644)
    other_user.chown(secret)
    _refused(db, "secret of the participant keys")
    assert db.stat().st_size == 0  # refused before SQLite wrote anything


@pytest.mark.parametrize("suffix", ["", "-wal", ".web-secret"])
def test_our_files_that_others_can_write_are_refused(tmp_path, suffix):
    lab, db = _lab(tmp_path)
    _accepted(db)
    path = db.with_name(db.name + suffix)
    path.touch()
    os.chmod(path, 0o666)
    _refused(db, str(path), "can be written by other users (mode 0666)")


def test_a_secret_that_is_a_link_is_refused(tmp_path):
    lab, db = _lab(tmp_path)
    ours = lab / "elsewhere"
    ours.write_text("00" * 32)
    os.symlink(ours, db.with_name(db.name + ".web-secret"))
    _refused(db, "is a symbolic link")


def test_a_files_folder_of_another_user_is_refused(tmp_path, other_user):
    lab, db = _lab(tmp_path)
    files = lab / "study-files"
    files.mkdir(mode=0o755)
    other_user.chown(files)
    _refused(db, f"the files folder {files} belongs to user {other_user.name}")


@pytest.mark.parametrize("case", ["link to a folder of ours", "ours, open to writers"])
def test_a_files_folder_that_is_a_link_or_open_to_writers_is_refused(tmp_path, case):
    lab, db = _lab(tmp_path)
    files = lab / "study-files"
    if case.startswith("link"):
        (lab / "real").mkdir(mode=0o700)
        os.symlink(lab / "real", files)
        _refused(db, f"the files folder {files} is a symbolic link")
    else:
        files.mkdir()
        os.chmod(files, 0o777)
        _refused(db, "can be written by other users (mode 0777)")


def test_a_reports_link_in_the_files_folder_is_not_served(tmp_path):
    """Before issue 53, /reports/x/report.html was served from wherever `reports` led."""
    lab, db = _lab(tmp_path)
    theirs = tmp_path / "theirs"
    (theirs / "x").mkdir(parents=True)
    (theirs / "x" / "report.html").write_text("<h1>their page</h1>")
    files = lab / "study-files"
    files.mkdir(mode=0o700)
    os.symlink(theirs, files / "reports")
    app = create_app(db, token=TOKEN, allowed_hosts=("testserver",), resume=False)
    try:
        client = TestClient(app, headers={"X-Vibrofocus-Token": TOKEN})
        r = client.get("/reports/x/report.html")
        assert r.status_code == 409, (r.status_code, r.text)
        assert "their page" not in r.text and "symbolic link" in r.json()["detail"]
        assert str(lab) not in r.text  # no absolute path in a response
    finally:
        app.state.web.store.close()


def test_a_database_directly_in_a_shared_folder_is_refused(shared_dir):
    db = shared_dir / "study.sqlite"
    _refused(db, "is in a folder other users can write in (mode 1777)", f"mkdir -m 700 {shared_dir / 'mine'}")
    assert not db.exists(), "refused before anything was made"


def test_a_database_in_our_own_folder_in_a_shared_folder_is_used(shared_dir):
    mine = shared_dir / "mine"
    mine.mkdir(mode=0o700)
    _accepted(mine / "study.sqlite")
    assert sqlite3.connect(mine / "study.sqlite").execute("PRAGMA integrity_check").fetchone() == ("ok",)


def test_a_database_in_a_folder_of_another_user_is_refused(tmp_path, other_user):
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o755)
    other_user.chown(theirs)
    _refused(theirs / "study.sqlite", f"is in a folder of user {other_user.name}")


def test_a_folder_their_group_can_write_in_is_refused_ours_alone_is_not(tmp_path, other_user):
    from vibrofocus.web.private import writable_by_others

    lab, db = _lab(tmp_path)
    os.chown(lab, os.getuid(), other_user.gid)
    os.chmod(lab, 0o770)
    assert writable_by_others(os.stat(lab))
    _refused(db, "is in a folder other users can write in (mode 0770)")
    os.chown(lab, os.getuid(), os.getgid())
    if writable_by_others(os.stat(lab)):
        pytest.skip("this user's group is not its own private group")
    _accepted(db)  # group-writable, but the group is this user's alone (user private groups)


def test_serve_refuses_a_planted_database_in_one_line(tmp_path, other_user):
    lab, db = _lab(tmp_path)
    db.touch()
    os.chmod(db, 0o666)
    other_user.chown(db)
    env = dict(os.environ, VIBROFOCUS_TOKEN=TOKEN)
    done = subprocess.run([sys.executable, "-m", "vibrofocus", "serve", "--db", str(db), "--port", "0", "--no-browser"],
                          capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stdout == ""
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: the study database") and f"belongs to user {other_user.name}" in line, line
    assert db.stat().st_size == 0 and os.stat(db).st_uid == other_user.uid  # untouched
