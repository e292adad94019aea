"""``vibrofocus power``: the table, the files and the model label; bad input in one line."""

from __future__ import annotations

import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from vibrofocus.cli.main import app

runner = CliRunner()


def test_power_writes_table_plot_and_json(tmp_path):
    out = tmp_path / "power"
    res = runner.invoke(app, ["power", "-n", "4,6", "--studies", "5", "--no-dask", "-q", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "model v3" in res.output and "not data" in res.output
    assert "Study 1 RM-ANOVA, location (GG)" in res.output
    # The paper's directional claims beside the omnibus tests, for every hypothesis.
    assert "inverse error below funneling" in " ".join(res.output.split())
    table = pd.read_csv(out / "power.csv")
    assert set(table["hypothesis"]) == {"v3-centroid", "grid-peak", "level-reliability", "intensity"}
    assert set(table["n_participants"]) == {4, 6} and len(table) == 4 * 2 * (7 + 2 + 2)
    assert {"s1_inverse_below", "s2_inverse_fewer", "s1_inverse_above", "s2_inverse_more"} <= set(table["test"])
    report = json.loads((out / "power.json").read_text())
    directions = report["directions"]
    method_tests = {"s1_method": "s1_inverse_vs_funneling", "s1_inverse_below": "s1_inverse_vs_funneling",
                    "s1_inverse_above": "s1_inverse_vs_funneling", "s2_method": "s2_inverse_vs_funneling",
                    "s2_inverse_fewer": "s2_inverse_vs_funneling", "s2_inverse_more": "s2_inverse_vs_funneling"}
    # Robust only where every hypothesis agrees on powered (>= 0.8) or not and, for a method
    # test, on the direction of the effect.
    for (test, n), rows in table.groupby(["test", "n_participants"]):
        verdicts = set(rows["power"].dropna() >= 0.8)
        agree = len(verdicts) == 1 and rows["power"].notna().all()
        if test in method_tests:
            agree = agree and len({d[str(n)] for d in directions[method_tests[test]].values()}) == 1
        assert rows["robust"].iloc[0] == agree
    # The directional shares: contrast -> hypothesis -> N -> paper / reverse / neither.
    for contrast in ("s1_inverse_vs_funneling", "s2_inverse_vs_funneling"):
        assert set(report["directional"][contrast]) == set(table["hypothesis"])
        for by_n in report["directional"][contrast].values():
            assert set(by_n) == {"4", "6"}
            for shares in by_n.values():
                assert set(shares) == {"paper", "reverse", "neither"}
                assert abs(sum(shares.values()) - 1) < 1e-12 and min(shares.values()) >= 0
        assert contrast in report["direction_sentences"]
    flat = " ".join(res.output.split())
    assert "the reverse" in flat and "d_z = 0.79" in flat
    assert report["paper_implied"]["d_z"] == pytest.approx(0.785, abs=0.001)
    assert report["paper_implied_study2"]["z"] == pytest.approx(2.853, abs=0.001)
    assert "z = 2.85" in flat  # the Study 2 row of the paper's own effect
    ran = table["n_studies"] > 0  # a test that never ran (too few participants kept) has no power
    assert table.loc[ran, "power"].between(0, 1).all() and table.loc[~ran, "power"].isna().all()
    assert ran[table["test"].str.startswith("s1_")].all()
    assert (table["model"].str.contains("not data") & table["model"].str.contains("model v3")).all()
    assert report["design"]["n_studies"] == 5 and "not data" in report["label"]
    assert set(report["hypotheses"]) == set(table["hypothesis"]) and report["levels"] == "paper"
    assert (out / "power.png").stat().st_size > 1000


def test_power_refuses_bad_input():
    res = runner.invoke(app, ["power", "-n", "2", "--studies", "5", "--no-dask", "-q"])
    assert res.exit_code != 0 and "n_participants" in res.output
    res = runner.invoke(app, ["power", "-n", "ten", "--no-dask", "-q"])
    assert res.exit_code != 0 and "--participants" in res.output


def test_power_checks_the_output_folder_before_simulating(tmp_path, monkeypatch):
    from tests.cli.test_nothing_half_written import Faults, assert_one_error

    out = tmp_path / "power"
    out.mkdir()
    Faults(monkeypatch).read_only(out)
    calls = []
    import vibrofocus.simulation.power as power

    monkeypatch.setattr(power, "run_power", lambda *a, **k: calls.append(1))
    res = runner.invoke(app, ["power", "-n", "4", "--studies", "2", "--no-dask", "-q", "--out", str(out)])
    assert_one_error(res, str(out / "power.json"), "read-only")
    assert calls == [] and list(out.iterdir()) == []


def test_power_files_are_whole_or_absent_on_a_full_disk(tmp_path, monkeypatch):
    from tests.cli.test_nothing_half_written import Faults, assert_one_error, no_temp_files

    out = tmp_path / "power"
    Faults(monkeypatch).disk_full_on_write(after_bytes=100, only="power.csv")
    res = runner.invoke(app, ["power", "-n", "4", "--studies", "2", "--no-dask", "-q", "--out", str(out)])
    assert_one_error(res, "power.csv", "no space")
    assert not (out / "power.csv").exists() and no_temp_files(out) == []


def test_power_names_its_skin_and_refuses_one_its_model_was_not_fitted_on():
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    result = CliRunner().invoke(app, ["power", "--skin", "voigt-fit", "-n", "10", "--studies", "2", "--no-dask"])
    assert result.exit_code == 2
    assert "fitted on the nominal skin only" in " ".join(result.output.split())


def test_power_from_a_bank_file_and_its_methods(tmp_path):
    from vibrofocus.simulation.bank import default_bank

    # A bank file with two of the shipped bank's methods, as scripts/build_feature_bank.py writes one.
    shipped = default_bank()
    keep = [shipped.methods.index(m) for m in ("inverse", "combination")]
    per_stimulus = {k: getattr(shipped, k)[:, keep] for k in ("energy", "actuator_energy", "drive_peak_v", "target_peak_m")
                    if getattr(shipped, k) is not None}
    bank = type(shipped)(**{**vars(shipped), "methods": ("inverse", "combination"), **per_stimulus})
    bank.save(tmp_path / "bank.npz")
    res = runner.invoke(app, ["power", "-n", "4", "--studies", "2", "--no-dask", "-q", "--bank", str(tmp_path / "bank.npz"),
                              "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "out" / "power.json").read_text())["design"]["methods"] == ["inverse", "combination"]
    res = runner.invoke(app, ["power", "-n", "4", "--studies", "2", "--no-dask", "-q", "--bank", str(tmp_path / "bank.npz"),
                              "--methods", "inverse,minimax"])
    assert res.exit_code != 0 and "no stimuli of minimax" in res.output and "Traceback" not in res.output
    res = runner.invoke(app, ["power", "--bank", str(tmp_path / "missing.npz"), "--no-dask"])
    assert res.exit_code != 0 and "missing.npz: no such file" in res.output


def test_a_bank_that_lies_is_one_line_before_any_study(tmp_path):
    """All-NaN energies printed a confident power table on main; a mismatched shape ended as
    'unexpected ... this is a bug' (exit 1)."""
    from importlib import resources

    import numpy as np

    from vibrofocus.simulation.bank import DEFAULT_BANK

    with resources.as_file(resources.files("vibrofocus.simulation").joinpath(DEFAULT_BANK)) as shipped:
        arrays = dict(np.load(shipped))
    for name, edit, words in [
        ("nan", dict(energy=np.full_like(arrays["energy"], np.nan)), "energy contains 130680 non-finite"),
        ("shape", dict(energy=arrays["energy"][..., :100]), "points_xy must have shape (100, 2), got (121, 2)"),
    ]:
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{**arrays, **edit})
        res = runner.invoke(app, ["power", "--bank", str(path), "-n", "4", "--studies", "2", "--no-dask", "-q"])
        assert res.exit_code == 2, res.output
        assert f"feature bank {path}: {words}" in res.output.replace("\n", "")
        assert "this is a bug" not in res.output and "Power by simulation" not in res.output
