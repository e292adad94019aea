"""The tap log of ``serve-osc --log``: real SQLite and CSV files, continued across runs,
never written over a file that is not a tap log."""

from __future__ import annotations

import sqlite3

import pytest

from vibrofocus.errors import OutputError, ValidationError
from vibrofocus.realtime import TAP_LOG_COLUMNS, TapLog, TapRecord, read_tap_log


def _record(tap_id, **kw):
    base = dict(tap_id=tap_id, address="/tap", location=3, level_db=-6.0, onset_host_s=12345.678901234567,
                onset_device_s=0.8191999999999999, onset_clock="simulated_samples", sender="127.0.0.1:5000",
                drive_peak_v=5.011872336272722)
    base.update(kw)
    return TapRecord(0.0, 0.1, "location 3", "inverse", **base)


@pytest.mark.parametrize("name", ["taps.csv", "taps.db", "taps.sqlite3"])
def test_taps_round_trip_with_every_digit_and_ids_go_on(tmp_path, name):
    path = tmp_path / name
    with TapLog(path) as log:
        assert log.last_tap_id == 0
        log.append(_record(1))
        log.append(_record(2, address="/tap_xy", location=None, x_mm=1.5, y_mm=-2.25, onset_device_s=None,
                           onset_clock=None, level_db=0.0))
    rows = read_tap_log(path)
    assert [r["tap_id"] for r in rows] == [1, 2]
    assert rows[0]["onset_host_s"] == 12345.678901234567 and rows[0]["onset_device_s"] == 0.8191999999999999
    assert (rows[0]["location"], rows[0]["x_mm"], rows[0]["level_db"], rows[0]["onset_clock"]) == (
        3, None, -6.0, "simulated_samples")
    assert (rows[1]["location"], rows[1]["x_mm"], rows[1]["y_mm"], rows[1]["onset_device_s"],
            rows[1]["onset_clock"]) == (None, 1.5, -2.25, None, None)
    assert set(rows[0]) == set(TAP_LOG_COLUMNS)
    with TapLog(path) as log:
        assert log.last_tap_id == 2
        log.append(_record(3))
    assert [r["tap_id"] for r in read_tap_log(path)] == [1, 2, 3]


def test_a_sqlite_log_is_append_only(tmp_path):
    path = tmp_path / "taps.db"
    with TapLog(path) as log:
        log.append(_record(1))
    conn = sqlite3.connect(path)
    try:
        for sql in ("UPDATE taps SET level_db = 0", "DELETE FROM taps"):
            with pytest.raises(sqlite3.IntegrityError, match="append-only"):
                conn.execute(sql)
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    finally:
        conn.close()


def test_a_row_cut_by_a_crash_is_dropped_when_the_log_is_opened_again(tmp_path):
    path = tmp_path / "taps.csv"
    with TapLog(path) as log:
        log.append(_record(1))
        log.append(_record(2))
    whole = path.read_bytes()
    path.write_bytes(whole + b"3,2026-01-01T00:00:00+00:00,127.0.0.1:1,/tap,4,,,-3")  # no newline: cut
    with TapLog(path) as log:
        assert log.last_tap_id == 2
        log.append(_record(3))
    assert [r["tap_id"] for r in read_tap_log(path)] == [1, 2, 3]
    assert path.read_bytes().startswith(whole)


def test_files_that_are_no_tap_log_are_refused_and_untouched(tmp_path):
    from vibrofocus.studies import StudyStore

    study = tmp_path / "study.db"
    StudyStore(study).close()
    other = tmp_path / "other.sqlite"
    conn = sqlite3.connect(other)
    conn.execute("CREATE TABLE t (x)")
    conn.commit()
    conn.close()
    text = tmp_path / "trials.csv"
    text.write_text("participant,trial\nP01,1\n")
    binary = tmp_path / "data.db"
    binary.write_bytes(b"\x00" * 64)
    cases = [(study, "another kind"), (other, "another kind"), (text, "not a tap log"), (binary, "not a SQLite")]
    for path, needle in cases:
        before = path.read_bytes()
        with pytest.raises(OutputError, match=needle):
            TapLog(path)
        assert path.read_bytes() == before, path
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(OutputError, match="folder"):
        TapLog(tmp_path / "folder.csv")
    with pytest.raises(ValidationError, match=r"\.csv or a SQLite file"):
        TapLog(tmp_path / "taps.txt")
    assert not (tmp_path / "taps.txt").exists()


def test_a_closed_log_refuses_a_tap(tmp_path):
    log = TapLog(tmp_path / "taps.csv")
    log.close()
    log.close()
    with pytest.raises(OutputError, match="closed"):
        log.append(_record(1))


@pytest.mark.parametrize("tap_id", ["²", "٣", "9" * 5000, "-1", " 7", "7.0", "9" * 19])
def test_a_hand_edited_tap_id_is_not_a_tap_log(tmp_path, tap_id):
    """Issue 53: a Unicode digit ('²' passes str.isdigit) or 5000 digits (past int()'s limit) gave "unexpected
    ValueError ... this is a bug" from serve-osc --log; the file is refused as not a tap log, unchanged."""
    path = tmp_path / "taps.csv"
    with TapLog(path) as log:
        log.append(_record(1))
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    path.write_text(lines[0] + lines[1] + lines[1].replace("1", tap_id, 1), encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(OutputError, match=r"it is not a tap log \(line 3: the tap_id .* is not a whole number of 1 to "
                                          r"18 digits 0-9\); it was not changed"):
        TapLog(path)
    assert path.read_bytes() == before
    with pytest.raises(ValidationError, match=r"is not a tap log \(line 3: the tap_id"):
        read_tap_log(path)


def test_a_cell_that_is_no_number_is_named_when_the_log_is_read(tmp_path):
    path = tmp_path / "taps.csv"
    with TapLog(path) as log:
        log.append(_record(1))
    header, row = path.read_text(encoding="utf-8").splitlines(keepends=True)
    cells = row.split(",")
    cells[TAP_LOG_COLUMNS.index("location")] = "²"
    path.write_text(header + ",".join(cells), encoding="utf-8")
    with pytest.raises(ValidationError, match=r"is not a tap log \(line 2: location '²' is not a number\)"):
        read_tap_log(path)
