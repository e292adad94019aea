"""Reading and validating trials files; exclusions are specific and never silent."""

from __future__ import annotations

import pandas as pd
import pytest

from vibrofocus.analysis import analyze, check_design, load_trials, trial_problems
from vibrofocus.errors import ValidationError

COLUMNS = ["participant", "study", "phase", "trial", "method", "target", "response", "rt_s"]


def _write(tmp_path, df: pd.DataFrame, name="trials.csv"):
    path = tmp_path / name
    df.to_csv(path, index=False)
    return path


@pytest.fixture
def small(synthetic):
    """Four participants, both studies, training included (all values valid)."""
    return synthetic(4, seed=3)


def test_valid_file_is_typed(tmp_path, small):
    trials = load_trials(_write(tmp_path, small))
    assert len(trials) == len(small)
    assert trials["study"].dtype.kind == "i" and trials["target"].dtype.kind == "i"
    s2 = trials[trials["study"] == 2]
    assert (s2["n_selected"] == s2["response"].str.split().map(len)).all()
    assert all(isinstance(s, tuple) for s in trials["selection"])
    assert set(trials["phase"]) == {"training", "main"}
    assert trials.attrs["exclusions"] == []


def test_missing_column_is_named(tmp_path, small):
    with pytest.raises(ValidationError, match=r"missing the column\(s\) response"):
        load_trials(_write(tmp_path, small.drop(columns="response")))


@pytest.mark.parametrize(
    ("column", "value", "message"),
    [
        ("response", "10", r"line 5: response '10' names location 10, outside 1\.\.9"),
        ("response", "4 x", r"line 5: response '4 x' is not a list of location numbers"),
        ("response", "", r"line 5: response is empty"),
        ("response", "3 3", r"line 5: response '3 3' names the same location more than once"),
        ("target", "0", r"line 5: target must be a location number 1\.\.9, got '0'"),
        ("target", "2.5", r"line 5: target must be a location number 1\.\.9, got '2\.5'"),
        ("phase", "warmup", r"line 5: phase must be 'training' or 'main', got 'warmup'"),
        ("study", "3", r"line 5: study must be 1 or 2, got '3'"),
        ("rt_s", "-1", r"line 5: rt_s must be a time >= 0"),
        ("trial", "first", r"line 5: trial must be an integer"),
    ],
)
def test_invalid_value_is_refused_with_line_and_reason(tmp_path, small, column, value, message):
    bad = small.astype(str)
    bad.loc[3, column] = value  # row index 3 is line 5 (header is line 1)
    with pytest.raises(ValidationError, match=message):
        load_trials(_write(tmp_path, bad))


def test_study1_takes_one_location(tmp_path, small):
    bad = small.astype(str)
    row = bad.index[(bad["study"] == "1") & (bad["phase"] == "main")][0]
    bad.loc[row, "response"] = "4 5"
    with pytest.raises(ValidationError, match="study 1 takes exactly one location per trial, got 2"):
        load_trials(_write(tmp_path, bad))


def test_duplicated_trial_is_refused(tmp_path, small):
    bad = pd.concat([small, small.iloc[[10]]], ignore_index=True)
    with pytest.raises(ValidationError, match="appears twice"):
        load_trials(_write(tmp_path, bad))


def test_empty_and_header_only_files(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(ValidationError, match="is empty"):
        load_trials(empty)
    header = tmp_path / "header.csv"
    header.write_text(",".join(COLUMNS) + "\n")
    with pytest.raises(ValidationError, match="no trials"):
        load_trials(header)
    with pytest.raises(ValidationError, match="does not exist"):
        load_trials(tmp_path / "nope.csv")


def test_exclude_invalid_participant_is_reported(tmp_path, small):
    bad = small.astype(str)
    row = bad.index[bad["participant"] == "P02"][7]
    bad.loc[row, "response"] = "12"
    trials = load_trials(_write(tmp_path, bad), on_invalid="exclude")
    assert "P02" not in set(trials["participant"])
    (excl,) = trials.attrs["exclusions"]
    assert excl["participant"] == "P02" and "names location 12" in excl["reason"]
    result = analyze(trials)
    assert result.exclusions["participant"].tolist() == ["P02"]
    assert "P02" not in result.study1.participants and len(result.study1.participants) == 3


def test_trial_problems_lists_every_problem(small):
    bad = small.astype(str)
    bad.loc[0, "target"] = "11"
    bad.loc[1, "phase"] = "x"
    bad.loc[1, "response"] = "0"
    _, problems = trial_problems(bad)
    assert problems["line"].tolist() == [2, 3, 3]
    assert set(problems["column"]) == {"target", "phase", "response"}


def test_incomplete_participant_is_excluded_from_that_study_only(small):
    df = small.copy()
    drop = (df["participant"] == "P03") & (df["study"] == 1) & (df["phase"] == "main")
    drop &= (df["target"] == 7) & (df["method"] == "inverse")
    trials = load_trials(df[~drop])
    _, exclusions, _ = check_design(trials, 1)
    (excl,) = exclusions
    assert excl["participant"] == "P03" and excl["study"] == 1
    assert "1 of the 27 conditions" in excl["reason"] and "location 7 × inverse" in excl["reason"]
    result = analyze(trials)
    assert "P03" not in result.study1.participants
    assert "P03" in result.study2.participants  # study 2 is complete for P03
    assert result.exclusions.to_dict("records") == [excl]


def test_unequal_repetitions_are_kept_with_a_note(small):
    df = small.copy()
    extra = df[(df["participant"] == "P01") & (df["study"] == 1) & (df["phase"] == "main")].iloc[[0]].copy()
    extra["trial"] = 999
    trials = load_trials(pd.concat([df, extra], ignore_index=True))
    complete, exclusions, warnings = check_design(trials, 1)
    assert exclusions == [] and "P01" in set(complete["participant"])
    assert len(warnings) == 1 and "P01" in warnings[0] and "unequal repetitions" in warnings[0]


def test_empty_study_is_reported_and_other_study_analysed(synthetic):
    trials = load_trials(synthetic(4, seed=5, studies=(2,)))
    result = analyze(trials)
    assert result.study1 is None and result.study2 is not None
    assert result.unavailable["study1"] == "study 1: the trials file has no rows for this study"


def test_training_only_study_is_reported(small):
    df = small[(small["study"] == 2) | (small["phase"] == "training")]
    result = analyze(load_trials(df))
    assert result.study1 is None
    assert "only training trials" in result.unavailable["study1"]


def test_no_usable_data_at_all_is_refused(small):
    only_training = small[small["phase"] == "training"]
    with pytest.raises(ValidationError, match="no usable data in either study.*only training trials"):
        analyze(load_trials(only_training))


def test_other_method_names_are_allowed(synthetic):
    df = synthetic(3, seed=8, sd_mm={"funneling": 7.0, "time_reversal": 7.0, "my_method": 7.0}, studies=(1,))
    result = analyze(load_trials(df))
    assert result.study1.methods == ["funneling", "time_reversal", "my_method"]


def test_api_steps_take_the_whole_table(tmp_path, small):
    from vibrofocus.analysis import study1_errors, study2_counts

    # The file as Excel writes it: UTF-8 with a byte-order mark.
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + small.to_csv(index=False).encode())
    trials = load_trials(path)
    errors = study1_errors(trials)  # training and study-2 rows are left out
    expected = small[(small["study"] == 1) & (small["phase"] == "main")]
    assert errors["n_trials"].sum() == len(expected)
    counts, _ = study2_counts(trials)
    assert counts["n_trials"].sum() == len(small[(small["study"] == 2) & (small["phase"] == "main")])


def test_few_participants_carry_a_warning(small):
    result = analyze(load_trials(small))
    assert any("only 4 participants" in w for w in result.warnings)
