"""The file formats of vibrofocus.io: each written and read back by its one module."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from vibrofocus.errors import OutputError, StudyError, ValidationError
from vibrofocus.io import (
    check_report,
    format_response,
    json_safe,
    parse_response_text,
    read_drives,
    read_report_json,
    read_trials_csv,
    read_trials_table,
    write_drives,
    write_drives_wav,
    write_report_json,
    write_trials_csv,
)


# --------------------------------------------------------------------------- responses
@pytest.mark.parametrize("text, expected", [("5", (5,)), ("5 4", (4, 5)), ("4,5", (4, 5)), (" 9  1 ", (1, 9)),
                                            ("3.0", (3,))])
def test_a_stored_response_reads_as_ascending_locations(text, expected):
    assert parse_response_text(text) == expected


@pytest.mark.parametrize("text, n, words", [("", None, "empty"), ("4 x", None, "not a list"),
                                            ("2 2", None, "more than once"), ("10", 9, "outside 1..9"),
                                            ("0", 9, "outside 1..9"), ("4.5", None, "not a list")])
def test_a_bad_stored_response_is_refused_saying_why(text, n, words):
    with pytest.raises(ValidationError, match=words):
        parse_response_text(text, n_locations=n)


def test_format_and_parse_are_inverse():
    for locations in [(1,), (9, 2, 5), [3, 4]]:
        assert parse_response_text(format_response(locations)) == tuple(sorted(locations))
    assert format_response(np.array([5, 4])) == "4 5"


# --------------------------------------------------------------------------- JSON
def test_json_safe_gives_strict_json():
    value = {1: np.float32(np.nan), "a": (np.int64(3), np.bool_(True)), "b": np.array([[1.5, np.inf]]),
             "c": pd.DataFrame({"x": [1.0, np.nan]}), "d": pd.NA, "e": float("-inf")}
    out = json_safe(value)
    assert out == {"1": None, "a": [3, True], "b": [[1.5, None]], "c": [{"x": 1.0}, {"x": None}], "d": None,
                   "e": None}
    json.dumps(out, allow_nan=False)  # strict JSON
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool


def test_json_safe_can_keep_non_finite_numbers():
    out = json_safe({"x": np.float64(np.nan), "y": [np.inf]}, finite=False)
    assert math.isnan(out["x"]) and out["y"] == [math.inf]


# --------------------------------------------------------------------------- trials CSV
ROWS = [
    {"participant": "P01", "study": 2, "phase": "main", "trial": 1, "method": "inverse", "target": 5,
     "response": (5, 4), "rt_s": 0.1 + 0.2},
    {"participant": "P01", "study": 1, "phase": "training", "trial": 1, "method": "funneling", "target": 2,
     "response": "2", "rt_s": 1.25},
]


def test_trials_file_round_trips(tmp_path):
    path = tmp_path / "t.csv"
    assert write_trials_csv(ROWS, path) == 2
    assert path.read_text().splitlines()[1] == f"P01,2,main,1,inverse,5,4 5,{0.1 + 0.2!r}"
    back = read_trials_csv(path)
    assert back[0]["response"] == (4, 5) and back[0]["rt_s"] == 0.1 + 0.2  # every digit kept
    assert back[1]["response"] == (2,) and back[1]["study"] == 1
    table = read_trials_table(path)
    assert list(table["line"]) == [2, 3] and table["response"].tolist() == ["4 5", "2"]


def test_a_bad_response_in_a_trials_file_names_the_line(tmp_path):
    path = tmp_path / "t.csv"
    write_trials_csv(ROWS, path)
    path.write_text(path.read_text().replace(",4 5,", ",4 x,"))
    with pytest.raises(StudyError, match=r"t\.csv:2: response '4 x'"):
        read_trials_csv(path)


def test_read_trials_table_refuses_missing_and_empty_files(tmp_path):
    with pytest.raises(ValidationError, match="does not exist"):
        read_trials_table(tmp_path / "none.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValidationError, match="is empty"):
        read_trials_table(tmp_path / "empty.csv")


# --------------------------------------------------------------------------- drives
def test_drives_npz_round_trips_and_csv_has_one_column_per_actuator(tmp_path):
    drives = np.random.default_rng(0).normal(size=(3, 50))
    meta = {"method": "inverse", "limit_v": 10.0}
    write_drives(tmp_path / "d.npz", drives, 48000.0, actuator_names=["A", "B", "C"], metadata=meta,
                 predicted=np.zeros((2, 50)), desired=np.ones(50))
    back, fs = read_drives(tmp_path / "d.npz")
    np.testing.assert_array_equal(back, drives)
    assert fs == 48000.0
    with np.load(tmp_path / "d.npz") as z:
        assert json.loads(str(z["metadata"])) == meta and z["predicted"].shape == (2, 50)
    write_drives(tmp_path / "d.csv", drives, 1000.0, actuator_names=["A", "B", "C"], metadata=meta)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    assert lines[:2] == ['# method: "inverse"', "# limit_v: 10.0"] and lines[2] == "# time_s,A_V,B_V,C_V"
    table = np.loadtxt(tmp_path / "d.csv", delimiter=",")
    np.testing.assert_allclose(table[:, 0], np.arange(50) / 1000.0)
    np.testing.assert_allclose(table[:, 1:].T, drives, rtol=1e-8)


def test_drives_file_name_and_content_are_checked(tmp_path):
    with pytest.raises(ValidationError, match="use a .npz or .csv"):
        write_drives(tmp_path / "d.txt", np.zeros((1, 4)), 1.0, actuator_names=["A"], metadata={})
    np.savez(tmp_path / "bad.npz", drives=np.zeros((2, 4)))
    with pytest.raises(ValidationError, match="missing array"):
        read_drives(tmp_path / "bad.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(ValidationError, match="not a readable .npz"):
        read_drives(tmp_path / "text.npz")


def test_drives_wav_is_scaled_to_full_scale_with_a_sidecar(tmp_path):
    from scipy.io import wavfile

    drives = np.array([[0.0, 5.0, -10.0], [2.5, 0.0, 0.0]])
    wav, sidecar = write_drives_wav(tmp_path / "d.wav", drives, 48000.4, volts_per_full_scale=10.0,
                                    metadata={"method": "inverse"})
    rate, data = wavfile.read(wav)
    assert rate == 48000 and data.dtype == np.float32
    np.testing.assert_array_equal(data, [[0.0, 0.25], [0.5, 0.0], [-1.0, 0.0]])
    assert json.loads(sidecar.read_text()) == {"method": "inverse", "volts_per_full_scale": 10.0}


def test_writing_into_a_missing_folder_is_an_output_error(tmp_path):
    with pytest.raises(OutputError):
        write_drives(tmp_path / "no" / "d.npz", np.zeros((1, 4)), 1.0, actuator_names=["A"], metadata={})


# --------------------------------------------------------------------------- report.json
def _report():
    return {"study1": {"anova": [dict.fromkeys(("effect", "F", "ddof1", "ddof2", "p_unc", "p_gg", "eps"), 1.0)]},
            "study2": {"friedman": {f: {"chi2": None, "dof": None, "p": None} for f in ("location", "method")}},
            "x": np.float64(np.nan)}


def test_report_json_round_trips_as_strict_json(tmp_path):
    path = write_report_json(_report(), tmp_path / "report.json")
    assert "NaN" not in path.read_text()
    back = read_report_json(path)
    assert back["x"] is None and back["study1"]["anova"][0]["eps"] == 1.0


@pytest.mark.parametrize("breakage, missing", [
    (lambda r: r["study1"]["anova"][0].pop("p_gg"), "study1.anova[0].p_gg"),
    (lambda r: r["study2"]["friedman"].pop("method"), "study2.friedman.method"),
    (lambda r: r["study2"]["friedman"]["location"].pop("dof"), "study2.friedman.location.dof"),
    (lambda r: r.pop("study1"), "study1"),
])
def test_a_report_breaking_the_contract_is_refused_naming_the_key(tmp_path, breakage, missing):
    report = _report()
    breakage(report)
    with pytest.raises(ValidationError, match=missing.replace("[", r"\[").replace("]", r"\]")):
        check_report(report)
    with pytest.raises(ValidationError):
        write_report_json(report, tmp_path / "report.json")
    assert not (tmp_path / "report.json").exists()
    (tmp_path / "old.json").write_text(json.dumps(json_safe(report)))
    with pytest.raises(ValidationError, match="old.json breaks the report.json contract"):
        read_report_json(tmp_path / "old.json")


# --------------------------------------------------------------------------- feature bank
def test_feature_bank_round_trips_and_the_shipped_one_loads(tmp_path):
    from vibrofocus.io import load_feature_bank, save_feature_bank
    from vibrofocus.simulation.bank import FeatureBank, default_bank

    rng = np.random.default_rng(1)
    bank = FeatureBank(energy=rng.random((2, 3, 9, 5)), points_xy=rng.random((5, 2)), locations_xy=rng.random((9, 2)),
                       centre_xy=np.array([0.0, 0.01]), methods=("funneling", "inverse", "combination"),
                       forearm_seeds=np.array([11, 12]), seed=4, actuator_energy=rng.random((2, 3, 9, 4)),
                       actuators_xy=rng.random((4, 2)))
    import dataclasses

    save_feature_bank(dataclasses.asdict(bank), tmp_path / "b.npz", model_version="test")
    back = FeatureBank(**load_feature_bank(tmp_path / "b.npz"))
    loaded = load_feature_bank(tmp_path / "b.npz")
    assert all(isinstance(v, (np.ndarray, tuple, int, str, type(None))) for v in loaded.values())
    # A bank written before banks stored their level rule was rendered at equal peak drive.
    assert (loaded["levels"], loaded["drive_peak_v"], loaded["target_peak_m"]) == ("equal-peak", None, None)
    paper = dataclasses.replace(bank, levels="paper", drive_peak_v=rng.random((2, 3, 9)),
                                target_peak_m=rng.random((2, 3, 9)))
    save_feature_bank(dataclasses.asdict(paper), tmp_path / "p.npz", model_version="test")
    again = FeatureBank(**load_feature_bank(tmp_path / "p.npz"))
    assert again.levels == "paper"
    np.testing.assert_array_equal(again.drive_peak_v, paper.drive_peak_v)
    np.testing.assert_allclose(back.energy, bank.energy, rtol=1e-6)  # stored as float32
    np.testing.assert_array_equal(back.points_xy, bank.points_xy)
    np.testing.assert_allclose(back.actuator_energy, bank.actuator_energy, rtol=1e-6)
    np.testing.assert_array_equal(back.actuators_xy, bank.actuators_xy)
    assert back.methods == bank.methods and back.seed == 4 and list(back.forearm_seeds) == [11, 12]
    with np.load(tmp_path / "b.npz") as z:
        assert str(z["model_version"]) == "test"
    with pytest.raises(ValidationError, match=r"feature bank .*none.npz: no such file"):
        load_feature_bank(tmp_path / "none.npz")
    shipped = default_bank()
    assert shipped.energy.ndim == 4 and shipped.n_forearms >= 1
