"""The folder of the error logs is the user's own: ``vibrofocus-logs-<uid>`` in the temporary
folder, mode 0700, and a folder of that name that is a link or another user's is not written."""

from __future__ import annotations

import os
import stat
import tempfile

import pytest

from vibrofocus.cli import _errors

pytestmark = pytest.mark.skipif(os.name == "nt", reason="POSIX modes, owners and links")


@pytest.fixture
def tmp_root(tmp_path, monkeypatch):
    """The temporary folder is tmp_path, and no VIBROFOCUS_LOG_DIR."""
    monkeypatch.delenv("VIBROFOCUS_LOG_DIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    said = []
    monkeypatch.setattr(_errors, "print_error", said.append)
    return tmp_path, said


def _report() -> None:
    try:
        raise RuntimeError("injected failure")
    except RuntimeError:
        assert _errors.report_unexpected() == _errors.EXIT_UNEXPECTED


def test_the_log_folder_is_per_user_and_closed_to_others(tmp_root):
    root, said = tmp_root
    old = os.umask(0o022)
    try:
        _report()
    finally:
        os.umask(old)
    folder = root / f"vibrofocus-logs-{os.getuid()}"
    assert _errors.log_folder() == folder
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    (log,) = folder.iterdir()
    assert str(log) in said[0] and "injected failure" in log.read_text()


def test_an_own_folder_open_to_others_is_closed(tmp_root):
    root, _ = tmp_root
    folder = root / f"vibrofocus-logs-{os.getuid()}"
    folder.mkdir()
    os.chmod(folder, 0o777)
    _report()
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    assert len(list(folder.iterdir())) == 1


def test_a_link_in_its_place_is_not_followed(tmp_root):
    root, said = tmp_root
    elsewhere = root / "attacker"
    elsewhere.mkdir()
    (root / f"vibrofocus-logs-{os.getuid()}").symlink_to(elsewhere)
    _report()
    assert list(elsewhere.iterdir()) == []
    assert "nowhere (the log folder" in said[0] and "is a symbolic link" in said[0]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="giving a folder away needs root")
def test_another_users_folder_in_its_place_is_not_written(tmp_root):
    root, said = tmp_root
    folder = root / f"vibrofocus-logs-{os.getuid()}"
    folder.mkdir(mode=0o777)
    os.chown(folder, 65534, 65534)
    _report()
    assert list(folder.iterdir()) == []
    assert "not to you" in said[0]
