"""One place for a study database's files, ``<db stem>-files/`` (vibrofocus._db_files), used
by serve, the terminal stop and simulate-study; the former ``<db>.calibrations/`` is read
where it is, never moved, and no folder on the way may be a link."""

from __future__ import annotations

import os
import stat

import pytest

from vibrofocus._db_files import calibrations_dir, files_dir, former_calibrations_dir, make_private_dir
from vibrofocus.errors import OutputError


def test_one_name_for_the_files_of_a_database(tmp_path):
    db = tmp_path / "study.sqlite"
    assert files_dir(db) == tmp_path / "study-files"
    assert calibrations_dir(db) == tmp_path / "study-files" / "calibrations"
    from vibrofocus._stop_client import stop_socket_path

    assert stop_socket_path(db) == (tmp_path / "study-files" / "stop.sock").resolve()


def test_the_former_calibration_folder_is_found_only_as_a_real_folder(tmp_path):
    db = tmp_path / "study.sqlite"
    assert former_calibrations_dir(db) is None
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "study.sqlite.calibrations").symlink_to(elsewhere)
    assert former_calibrations_dir(db) is None, "a link is never followed"
    (tmp_path / "study.sqlite.calibrations").unlink()
    (tmp_path / "study.sqlite.calibrations").mkdir()
    assert former_calibrations_dir(db) == tmp_path / "study.sqlite.calibrations"


@pytest.mark.skipif(os.name == "nt", reason="POSIX modes and links")
def test_the_files_folders_are_made_private_and_never_through_a_link(tmp_path):
    db = tmp_path / "study.sqlite"
    make_private_dir(calibrations_dir(db), db)
    for folder in (files_dir(db), calibrations_dir(db)):
        assert stat.S_IMODE(os.lstat(folder).st_mode) == 0o700, folder
    other = tmp_path / "other.sqlite"
    target = tmp_path / "target"
    target.mkdir()
    files_dir(other).symlink_to(target)
    with pytest.raises(OutputError, match="other-files.*link"):
        make_private_dir(calibrations_dir(other), other)
    assert list(target.iterdir()) == [], "nothing was made through the link"

