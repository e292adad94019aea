"""The trials file contract (docs/file-formats.md, "Trials file")."""

import pytest

from vibrofocus.errors import StudyError
from vibrofocus.studies import TRIALS_COLUMNS, read_trials_csv, write_trials_csv


def test_columns_are_the_contract_in_order():
    assert TRIALS_COLUMNS == ("participant", "study", "phase", "trial", "method", "target", "response", "rt_s")


def test_write_read_round_trip_keeps_every_value(tmp_path):
    rows = [
        {"participant": "p1", "study": 1, "phase": "training", "trial": 1, "method": "inverse",
         "target": 5, "response": (5,), "rt_s": 1.0 / 3.0},
        {"participant": "p1", "study": 2, "phase": "main", "trial": 1, "method": "funneling",
         "target": 4, "response": [5, 4], "rt_s": 0.75, "extra": "ignored"},
    ]
    out = tmp_path / "trials.csv"
    assert write_trials_csv(rows, out) == 2
    lines = out.read_text().splitlines()
    assert lines[0] == ",".join(TRIALS_COLUMNS)
    assert lines[2] == "p1,2,main,1,funneling,4,4 5,0.75"
    back = read_trials_csv(out)
    assert back[0]["rt_s"] == 1.0 / 3.0  # exact round trip
    assert back[1]["response"] == (4, 5)


def test_missing_folder_and_foreign_file_are_refused(tmp_path):
    with pytest.raises(StudyError, match="does not exist"):
        write_trials_csv([], tmp_path / "nope" / "t.csv")
    foreign = tmp_path / "f.csv"
    foreign.write_text("a,b\n1,2\n")
    with pytest.raises(StudyError, match="not a trials file"):
        read_trials_csv(foreign)


def test_trials_file_gets_the_usual_permissions_not_those_of_a_temporary_file(tmp_path):
    import os
    import stat

    from vibrofocus.studies.export import write_trials_csv

    row = {"participant": "p1", "study": 1, "phase": "main", "trial": 1, "method": "inverse",
           "target": 5, "response": "5", "rt_s": 0.5}
    old = os.umask(0o022)
    try:
        write_trials_csv([row], tmp_path / "t.csv")
        (tmp_path / "plain.txt").write_text("x")  # what any program writing a file gets
    finally:
        os.umask(old)
    mode = stat.S_IMODE((tmp_path / "t.csv").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "plain.txt").stat().st_mode) == 0o644


def test_simulated_flag_column_round_trips(tmp_path):
    rows = [
        {"participant": "sim-001", "study": 1, "phase": "main", "trial": 1, "method": "inverse", "target": 5,
         "response": (5,), "rt_s": 1.25, "simulated": 1},
        {"participant": "P02", "study": 1, "phase": "main", "trial": 1, "method": "inverse", "target": 4,
         "response": "4 5", "rt_s": 0.5, "simulated": 0},
    ]
    path = tmp_path / "t.csv"
    assert write_trials_csv(rows, path) == 2
    assert path.read_text().splitlines()[0] == ",".join(TRIALS_COLUMNS) + ",simulated"
    back = read_trials_csv(path)
    assert [r["simulated"] for r in back] == [True, False]


def test_real_participants_only_keep_the_contract_columns(tmp_path):
    rows = [{"participant": "P01", "study": 1, "phase": "main", "trial": 1, "method": "inverse", "target": 5,
             "response": (5,), "rt_s": 1.0, "simulated": 0}]
    path = tmp_path / "t.csv"
    write_trials_csv(rows, path)
    assert path.read_text().splitlines()[0] == ",".join(TRIALS_COLUMNS)
    # A simulated participant anywhere in the file adds the flag to every row.
    write_trials_csv(rows + [dict(rows[0], participant="sim-001", simulated=1)], path)
    assert [line.rsplit(",", 1)[1] for line in path.read_text().splitlines()] == ["simulated", "0", "1"]


def _designed_rows():
    return [{"participant": "p1", "study": 1, "phase": "main", "trial": k + 1, "method": "inverse", "target": 1,
             "response": (1,), "rt_s": 0.5, "session": 1, "session_status": "completed", "dry_run": 0,
             "protocol": "designed", "level_db": -10.0, "allowed": (1, 3, 7, 9),
             "response_x_mm": -9.25 if k else None, "response_y_mm": 8.5 if k else None} for k in range(2)]


#: Every column of a study database's export (``StudyStore.export_trials_csv``).
EXPORT = dict(sessions=True, onsets=True, stimuli=True, protocols=True, points=True, xruns=True, blocks=True)


def test_the_block_columns_round_trip(tmp_path):
    out = tmp_path / "trials.csv"
    write_trials_csv(_designed_rows(), out, **EXPORT)
    assert out.read_text().splitlines()[2].endswith(",designed,-9.25,8.5,0,-10.0,1 3 7 9")
    back = read_trials_csv(out)
    assert [(r["level_db"], r["allowed"], r["response_x_mm"], r["response_y_mm"]) for r in back] == [
        (-10.0, (1, 3, 7, 9), None, None), (-10.0, (1, 3, 7, 9), -9.25, 8.5)]


@pytest.mark.parametrize("column, cell, words", [
    ("level_db", "NaN", "level_db must be a finite number of dB within +-120"),
    ("level_db", "1e300", "level_db must be a finite number of dB within +-120"),
    ("level_db", "-10 dB", "level_db must be a finite number of dB within +-120"),
    ("allowed", "1 3 1", "allowed '1 3 1' names the same location more than once"),
    ("allowed", "1;3", "allowed '1;3' is not a list of location numbers"),
    ("response_x_mm", "inf", "response_x_mm and response_y_mm must both be finite numbers of mm within +-1000"),
    ("response_x_mm", "1e9", "response_x_mm and response_y_mm must both be finite numbers of mm within +-1000"),
    ("response_y_mm", "", "response_x_mm and response_y_mm must both be finite numbers of mm within +-1000"),
])
def test_a_hostile_block_or_point_cell_gets_one_line_and_nothing_is_written(tmp_path, column, cell, words):
    from vibrofocus.studies import export_bids

    src = tmp_path / "trials.csv"
    write_trials_csv(_designed_rows(), src, **EXPORT)
    lines = src.read_text().splitlines()
    header, row = lines[0].split(","), lines[2].split(",")
    row[header.index(column)] = cell
    src.write_text("\n".join([lines[0], lines[1], ",".join(row)]) + "\n")
    with pytest.raises(StudyError, match=rf"^{src}:3: ") as info:
        export_bids(src, tmp_path / "bids")
    assert words in str(info.value) and "\n" not in str(info.value)
    assert not (tmp_path / "bids").exists()
