"""The one rule of what an output may replace (:func:`vibrofocus._atomic.output_target`), on real files."""

from __future__ import annotations

import os
import stat

import pytest

from vibrofocus import _atomic
from vibrofocus.errors import OutputError


def test_a_file_read_under_the_guard_is_never_replaced_whatever_its_name(tmp_path):
    source = tmp_path / "study.db"
    source.write_bytes(b"SQLite format 3\x00 rows")
    hard = tmp_path / "hard.csv"
    os.link(source, hard)
    soft = tmp_path / "soft.csv"
    soft.symlink_to(source)
    with _atomic.output_guard(force=True):
        _atomic.protect(source, "study database")
        for name in (source, hard, soft, tmp_path / "." / "study.db"):
            with pytest.raises(OutputError, match="study database this command reads"):
                _atomic.write_text(name, "participant,study\n")
    assert source.read_bytes() == b"SQLite format 3\x00 rows"
    # Outside the guard (the Python API) the same write goes through: the rule is per
    # command. The new file takes the name; the other name keeps the old file.
    _atomic.write_text(hard, "participant,study\n")
    assert hard.read_text() == "participant,study\n"
    assert source.read_bytes() == b"SQLite format 3\x00 rows"


def test_a_protected_path_that_does_not_exist_yet_is_refused_too(tmp_path):
    with _atomic.output_guard():
        _atomic.protect(tmp_path / "new.db", "study database")
        with pytest.raises(OutputError, match="same file"):
            _atomic.check_writable(tmp_path / "new.db", what="trials file")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("old, new_suffix, refused", [
    (b"\x89HDF\r\n\x1a\nrest", ".csv", True),
    (b"SQLite format 3\x00", ".csv", True),
    (b"PK\x03\x04rest", ".csv", True),
    (b"a,b\n1,2\n", ".csv", False),   # same kind
    (b"", ".csv", False),             # empty: nothing to lose
    (b"a,b\n", ".npz", True),
])
def test_another_kind_needs_force(tmp_path, old, new_suffix, refused):
    target = tmp_path / f"out{new_suffix}"
    target.write_bytes(old)
    data = b"PK\x05\x06" + bytes(18) if new_suffix == ".npz" else b"x,y\n"
    with _atomic.output_guard():
        if refused:
            with pytest.raises(OutputError, match="--force"):
                _atomic.write_bytes(target, data)
            assert target.read_bytes() == old
        else:
            _atomic.write_bytes(target, data)
            assert target.read_bytes() == data
    with _atomic.output_guard(force=True):
        _atomic.write_bytes(target, data)
    assert target.read_bytes() == data
    assert [p.name for p in tmp_path.iterdir()] == [target.name]  # no temporary file left


def test_the_kind_of_what_was_written_decides_not_the_name(tmp_path):
    """A CSV written under a .nc name over a calibration is caught at the commit."""
    target = tmp_path / "cal.nc"
    target.write_bytes(b"\x89HDF\r\n\x1a\ncalibration")
    with _atomic.output_guard(), pytest.raises(OutputError, match="holds a HDF5"):
        _atomic.write_text(target, "participant,study\n")
    assert target.read_bytes() == b"\x89HDF\r\n\x1a\ncalibration"


def test_non_regular_targets_are_refused_even_through_links(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    link = tmp_path / "link.csv"
    link.symlink_to(fifo)
    dangling = tmp_path / "dangling.csv"
    dangling.symlink_to(tmp_path / "nowhere")
    for target, message in ((fifo, "FIFO"), (link, "points to a FIFO"), (dangling, "missing file"),
                            (tmp_path, "folder")):
        with pytest.raises(OutputError, match=message):
            _atomic.write_text(target, "x")
    assert stat.S_ISFIFO(fifo.lstat().st_mode) and link.is_symlink() and dangling.is_symlink()


def test_a_link_to_a_regular_file_is_written_through(tmp_path):
    real = tmp_path / "real.csv"
    real.write_text("old\n")
    real.chmod(0o640)
    link = tmp_path / "link.csv"
    link.symlink_to("real.csv")
    _atomic.write_text(link, "new\n")
    assert link.is_symlink() and os.readlink(link) == "real.csv"
    assert real.read_text() == "new\n" and stat.S_IMODE(real.stat().st_mode) == 0o640


@pytest.mark.parametrize("content, kind", [
    (b"", None), (b"SQLite format 3\x00...", "SQLite database"), (b"RIFF\x00\x00\x00\x00WAVEfmt ", "WAV audio"),
    (b"participant,study\n", "text file"), ("é".encode() * 3000, "text file"), (b"\x00\x01", "binary file"),
    (b"\xff\xfe\xfa" * 100, "binary file"),
])
def test_file_kind(tmp_path, content, kind):
    path = tmp_path / "f"
    path.write_bytes(content)
    assert _atomic.file_kind(path) == kind


def test_make_output_folder_creates_one_level_only(tmp_path):
    assert _atomic.make_output_folder(tmp_path / "out").is_dir()
    with pytest.raises(OutputError, match="does not exist"):
        _atomic.make_output_folder(tmp_path / "a" / "b")
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="in the way"):
        _atomic.make_output_folder(tmp_path / "file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "out"]


def test_a_file_protected_before_it_existed_stays_protected_once_created(tmp_path):
    db = tmp_path / "new.db"
    with _atomic.output_guard(force=True):
        _atomic.protect(db, "study database")
        db.write_bytes(b"SQLite format 3\x00 created after")
        with pytest.raises(OutputError, match="same file"):
            _atomic.write_text(db, "participant\n")
    assert db.read_bytes() == b"SQLite format 3\x00 created after"


def test_a_folder_given_as_a_symbolic_link_is_written_through(tmp_path):
    target = tmp_path / "reports" / "r1"
    target.mkdir(parents=True)
    (target / "report.json").write_text("old")
    link = tmp_path / "latest"
    link.symlink_to(target, target_is_directory=True)
    for text in ("new", "newer"):
        with _atomic.atomic_directory(link, owned={"report.json"}, what="report folder") as build:
            (build / "report.json").write_text(text)
        assert link.is_symlink() and (target / "report.json").read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest", "reports"]  # no .latest.*.tmp
    assert sorted(p.name for p in target.parent.iterdir()) == ["r1"]
    (tmp_path / "gone").symlink_to(tmp_path / "missing")
    with pytest.raises(OutputError, match="symbolic link to a missing folder"):
        with _atomic.atomic_directory(tmp_path / "gone", what="report folder") as build:
            (build / "report.json").write_text("x")
    assert not (tmp_path / "missing").exists()


def test_a_deleted_protected_file_whose_inode_is_reused_is_not_the_input(tmp_path):
    """A study database's -wal is protected while it exists and deleted when the database closes; a new file
    that reuses its inode number was refused as "the study database this command reads" (issue 53, two
    exports at once)."""
    wal = tmp_path / "study.sqlite-wal"
    wal.write_bytes(b"journal")
    with _atomic.output_guard():
        _atomic.protect(wal, "study database")
        inode = os.stat(wal).st_ino
        os.unlink(wal)
        for i in range(200):  # file systems hand a freed inode number to the next new file, mostly
            other = tmp_path / f"out-{i}.txt"
            other.write_text("x")
            if os.stat(other).st_ino == inode:
                break
            other.unlink()
        else:
            pytest.skip("this file system did not reuse the inode number")
        _atomic.write_text(other, "the export's file\n")
        assert other.read_text() == "the export's file\n"
        wal.write_bytes(b"journal again")  # the same name again, another inode: still protected by name
        with pytest.raises(OutputError, match="study database this command reads"):
            _atomic.write_text(wal, "x")


def test_an_exclusive_folder_is_only_created_never_swapped_over_one_made_meanwhile(tmp_path):
    out = tmp_path / "ds"
    with pytest.raises(OutputError, match="another process created it meanwhile") as info:
        with _atomic.atomic_directory(out, exclusive=True) as build:
            (build / "mine.txt").write_text("mine")
            out.mkdir()  # another export's dataset, put in place while this one was built
            (out / "theirs.txt").write_text("theirs")
    assert info.value.errno == 17 and sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    assert [p.name for p in out.iterdir()] == ["theirs.txt"]
    with _atomic.atomic_directory(tmp_path / "new", exclusive=True) as build:
        (build / "mine.txt").write_text("mine")
    assert (tmp_path / "new" / "mine.txt").read_text() == "mine"
