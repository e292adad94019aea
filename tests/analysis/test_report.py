"""report.json contract, results sentences, figures, HTML and the ``analyze`` command."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose
from typer.testing import CliRunner

from vibrofocus.analysis import analyze, format_p, load_trials, report_dict, results_sentences, write_report
from vibrofocus.cli.main import app

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    """Run ``vibrofocus analyze`` once on a synthetic file with planted effects."""
    from .synthetic import make_trials

    tmp = tmp_path_factory.mktemp("cli")
    df = make_trials(
        12,
        seed=11,
        sd_mm={"funneling": 9.0, "inverse": 4.5, "combination": 5.0},
        extra_mean={"funneling": 2.0, "inverse": 0.6, "combination": 0.7},
    )
    drop = (df["participant"] == "P12") & (df["study"] == 1) & (df["target"] == 3) & (df["phase"] == "main")
    df = df[~drop].astype(str).reset_index(drop=True)  # P12 misses a study-1 condition: must be excluded and reported
    df.loc[df.index[df["participant"] == "P11"][9], "response"] = "0"  # invalid: P11 is excluded
    csv = tmp / "trials.csv"
    df.to_csv(csv, index=False)
    out = tmp / "report"
    result = CliRunner().invoke(app, ["analyze", str(csv), "--out", str(out), "--exclude-invalid"])
    return result, out, df


@pytest.fixture(scope="module")
def planted_result(cli_run):
    """The Python API's analysis of the same file as the CLI run."""
    return analyze(load_trials(cli_run[2], on_invalid="exclude"))


def test_cli_writes_contract_report(cli_run):
    result, out, _ = cli_run
    assert result.exit_code == 0, result.output
    report = json.loads((out / "report.json").read_text())
    anova = report["study1"]["anova"]
    assert [row["effect"] for row in anova] == ["location", "method", "location * method"]
    for row in anova:
        for key in ("F", "ddof1", "ddof2", "p_unc", "p_gg", "eps"):
            assert isinstance(row[key], (int, float)), key
        assert 0 < row["eps"] <= 1 and 0 <= row["p_gg"] <= 1
    for factor in ("location", "method"):
        f = report["study2"]["friedman"][factor]
        assert set(f) >= {"chi2", "dof", "p"}
    assert report["study2"]["friedman"]["location"]["dof"] == 8
    assert report["study2"]["friedman"]["method"]["dof"] == 2
    method = next(r for r in anova if r["effect"] == "method")
    assert method["p_gg"] < 0.05 and report["study2"]["friedman"]["method"]["p"] < 0.05  # planted
    assert "contains_target" in report["study2"] and "posthoc" in report["study1"]


def test_cli_reports_exclusions_in_json_and_terminal(cli_run):
    result, out, df = cli_run
    report = json.loads((out / "report.json").read_text())
    line = int(df.index[df["response"] == "0"][0]) + 2  # 1-based, after the header
    assert report["exclusions"] == [
        {
            "participant": "P11",
            "study": None,
            "reason": f"invalid row(s) in the trials file: line {line}: response '0' names location 0, outside 1..9",
        },
        {
            "participant": "P12",
            "study": 1,
            "reason": "incomplete: no main-phase trial for 3 of the 27 conditions in study 1 "
            "(location 3 × funneling, location 3 × inverse, location 3 × combination)",
        },
    ]
    assert report["study1"]["n_participants"] == 10 and report["study2"]["n_participants"] == 11
    assert "excluded P11 (all studies)" in result.output and "excluded P12 (study 1)" in result.output
    assert "Study 1" in result.output and "Friedman" in result.output


def test_cli_writes_figures_and_self_contained_html(cli_run):
    _, out, _ = cli_run
    report = json.loads((out / "report.json").read_text())
    for name in ("study1_localization.png", "study1_errors.png", "study2_counts.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
        assert name in report["figures"].values()
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    assert "P12" in html and "Greenhouse–Geisser" in html and "Friedman" in html
    assert re.search(r"F\(\d+\.\d\d, \d+\.\d\d\) = \d+\.\d\d, p [<=] ", html)  # GG-corrected dofs


def test_report_values_match_the_python_api(cli_run, planted_result):
    _, out, _ = cli_run
    result = planted_result
    report = json.loads((out / "report.json").read_text())
    api = result.study1.anova.set_index("effect")
    for row in report["study1"]["anova"]:
        assert_allclose([row["F"], row["p_gg"], row["eps"]], api.loc[row["effect"], ["F", "p_gg", "eps"]].astype(float))
    fr = result.study2.all_trials.friedman
    assert_allclose(report["study2"]["friedman"]["method"]["chi2"], fr.loc["method", "chi2"])


def test_sentences_use_gg_dofs_when_sphericity_is_not_assumed(planted_result):
    result = planted_result
    sentences = results_sentences(result)
    aov = result.study1.anova.set_index("effect")
    inter = aov.loc["location * method"]
    assert not inter["mauchly_defined"]  # 10 participants < 17 needed for 16 contrasts
    expected = f"F({inter['ddof1_gg']:.2f}, {inter['ddof2_gg']:.2f}) = {inter['F']:.2f}, {format_p(inter['p_gg'])}"
    assert any(expected in s for s in sentences["study1"]), sentences["study1"]
    method = aov.loc["method"]
    if method["sphericity_violated"] is False:  # spherical: uncorrected integer dofs
        plain = f"F({method['ddof1']}, {method['ddof2']}) = {method['F']:.2f}"
        assert any(plain in s for s in sentences["study1"])
    assert any(s.startswith("Friedman tests") and "χ²(2)" in s for s in sentences["study2"])


def test_format_p():
    assert format_p(3e-7) == "p < 0.0001"
    assert format_p(0.00042) == "p = 0.0004"
    assert format_p(0.0123) == "p = 0.012"
    assert format_p(float("nan")) == "p = n/a"


def test_report_for_a_single_study_says_why(tmp_path, synthetic):
    result = analyze(load_trials(synthetic(4, seed=21, studies=(2,))))
    paths = write_report(result, tmp_path)
    report = json.loads(paths["json"].read_text())
    assert report["study1"] == {
        "available": False,
        "reason": "study 1: the trials file has no rows for this study",
        "anova": [],
    }
    assert report["study2"]["available"] and set(report["study2"]["friedman"]) == {"location", "method"}
    assert "Study 1 was not analysed" in paths["html"].read_text()
    assert not (tmp_path / "study1_localization.png").exists()


def test_report_dict_is_strict_json(planted_result):
    d = report_dict(planted_result)
    json.dumps(d, allow_nan=False)  # NaN would raise
    # NaN (undefined Mauchly) becomes null
    inter = next(r for r in d["study1"]["anova"] if r["effect"] == "location * method")
    assert inter["p_mauchly"] is None and inter["sphericity_violated"] is None


def test_cli_bad_input_is_one_line_error(tmp_path):
    bad = pd.DataFrame(
        [["P1", 1, "main", 1, "inverse", 5, "12", 0.8]],
        columns=["participant", "study", "phase", "trial", "method", "target", "response", "rt_s"],
    )
    csv = tmp_path / "bad.csv"
    bad.to_csv(csv, index=False)
    result = CliRunner().invoke(app, ["analyze", str(csv), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "error:" in result.output and "line 2" in result.output and "outside 1..9" in result.output
    assert not (tmp_path / "o" / "report.json").exists()


def test_cli_help_mentions_the_contract():
    result = CliRunner().invoke(app, ["analyze", "--help"])
    assert result.exit_code == 0
    assert "--out" in result.output and "--exclude-invalid" in result.output
    assert "Friedman" in result.output and "Greenhouse" in result.output


def test_localization_panels_follow_the_grid(planted_result):
    from vibrofocus.analysis import plot_localization

    result = planted_result
    fig = plot_localization(result.study1.positions)
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible() and ax.get_title()]
    assert titles == [f"target {i}" for i in range(1, 10)]  # row by row from the wrist side
    # each panel: 3 method means and 3 ellipses
    first = next(ax for ax in fig.axes if ax.get_title() == "target 1")
    assert len(first.patches) == 3
    centre = np.array(first.patches[0].center)
    pos = result.study1.positions.set_index(["location", "method"])
    assert_allclose(centre, pos.loc[(1, "funneling"), ["mean_x_mm", "mean_y_mm"]].astype(float))



# --------------------------------------------------------------------------- too few participants


@pytest.mark.parametrize("n", [1, 2, 3])
def test_few_participants_degrade_clearly(tmp_path, n):
    """1-3 participants: descriptive results and figures always; each test that needs more is
    reported as unavailable with its reason (JSON, HTML, terminal), and the command exits 0."""
    from .synthetic import make_trials

    df = make_trials(n, seed=3)
    csv = tmp_path / "trials.csv"
    df.to_csv(csv, index=False)
    out = tmp_path / "report"
    run = CliRunner().invoke(app, ["analyze", str(csv), "--out", str(out)])
    assert run.exit_code == 0, run.output
    assert "Traceback" not in run.output and "Error" not in run.output
    for name in ("study1_localization.png", "study1_errors.png", "study2_counts.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
    report = json.loads((out / "report.json").read_text())
    s1, s2 = report["study1"], report["study2"]
    assert s1["available"] and s2["available"] and s1["n_participants"] == n
    for key in ("anova_unavailable", "posthoc_unavailable", "shapiro_unavailable"):
        assert key in s1
    assert "friedman_unavailable" in s2 and "wilcoxon_unavailable" in s2
    # descriptive results are there whatever n is
    assert len(s1["positions"]) == 27 and len(s1["cell_means"]) == 27 and len(s1["errors"]) == 27 * n
    assert len(s2["counts"]) == 27 * n
    text = " ".join(run.output.split())  # the terminal wraps lines
    page = (out / "report.html").read_text()
    if n < 3:
        assert s1["anova"] == [] and s1["mauchly"] == []
        assert s1["anova_unavailable"].startswith(f"the two-way repeated-measures ANOVA needs at least 3 participants, got {n}")
        assert "not computed: the two-way repeated-measures ANOVA needs at least 3" in text
        assert "Not computed: the two-way repeated-measures ANOVA needs at least 3" in page
        assert s1["shapiro"] == [] and "at least 3 participants per condition" in s1["shapiro_unavailable"]
    else:
        assert [r["effect"] for r in s1["anova"]] == ["location", "method", "location * method"]
        assert s1["anova_unavailable"] is None and s1["shapiro_unavailable"] is None
    if n < 2:
        assert s1["posthoc"]["method"] == [] and "at least 2 participants, got 1" in s1["posthoc_unavailable"]
        assert s2["friedman"] == {f: {"chi2": None, "dof": None, "p": None} for f in ("location", "method")}
        assert s2["wilcoxon"] == {}
        assert s2["friedman_unavailable"] == "Friedman and Wilcoxon tests need at least 2 participants, got 1"
        assert "Study 2 Friedman (all trials): not computed" in text
        assert "Friedman tests on all trials were not computed" in " ".join(s2["sentences"])
    else:
        assert len(s1["posthoc"]["method"]) == 3 and s1["posthoc_unavailable"] is None
        assert set(s2["friedman"]) == {"location", "method"} and s2["friedman_unavailable"] is None
        ref = friedman_reference(report, n)
        assert_allclose(s2["friedman"]["method"]["chi2"], ref, rtol=1e-10)


def friedman_reference(report: dict, n: int) -> float:
    """Friedman chi-square on method from the per-participant cell counts (SciPy, independent)."""
    from scipy import stats

    counts = pd.DataFrame(report["study2"]["counts"])
    wide = counts.groupby(["participant", "method"])["n_selected"].mean().unstack()
    assert wide.shape[0] == n
    # Means of counts are fractions (62/27); equal ones reached along different float sums
    # differ in the last bit and must still rank as ties: round away that noise.
    wide = wide.round(9)
    return stats.friedmanchisquare(*(wide[c].to_numpy() for c in wide.columns)).statistic


def test_one_participant_analysis_api_keeps_descriptives():
    from .synthetic import make_trials

    result = analyze(load_trials(make_trials(1, seed=4)))
    s1 = result.study1
    assert set(s1.unavailable) == {"anova", "posthoc", "shapiro"}
    assert s1.anova.empty and list(s1.anova.columns[:7]) == ["effect", "SS", "MS", "F", "ddof1", "ddof2", "p_unc"]
    assert s1.positions["n"].eq(3).all()  # 3 repetitions pooled per target and method
    sentences = results_sentences(result)["study1"]
    assert "N = 1 participant," in sentences[0] and "ANOVA" not in sentences[0]
    assert any(s.startswith("The two-way repeated-measures ANOVA needs at least 3") for s in sentences)


def test_the_report_counts_the_trials_presented_again_after_an_xrun():
    from .synthetic import make_trials

    trials = make_trials(1, seed=4, studies=(1,))
    assert analyze(load_trials(trials)).xrun_represented is None  # a file without the column does not say
    trials["xrun_represented"] = 0
    trials.loc[[6, 9], "xrun_represented"] = [1, 2]  # two main trials, one presented twice more
    result = analyze(load_trials(trials))
    assert result.xrun_represented == 2 and report_dict(result)["xrun_represented"] == 2
    assert any(w.startswith("2 answered trial(s) were presented again") for w in result.warnings)


@pytest.mark.slow
def test_simulated_participants_are_flagged_in_json_and_html(tmp_path, synthetic):
    # A trials file whose optional 'simulated' column marks some participants.
    df = synthetic(4, seed=3)
    sims = sorted(df["participant"].unique())[:2]
    df["simulated"] = df["participant"].isin(sims).astype(int)
    path = tmp_path / "trials.csv"
    df.to_csv(path, index=False)
    paths = write_report(analyze(load_trials(path)), tmp_path / "out")
    report = json.loads(paths["json"].read_text())
    assert report["simulated"]["any"] is True and report["simulated"]["participants"] == sims
    assert "model v3" in report["simulated"]["model"] and "not data" in report["simulated"]["model"]
    page = paths["html"].read_text()
    assert "id='simulated-banner'" in page and "SIMULATED DATA" in page and sims[0] in page
    # Without the column (or with only zeros): no flag, no banner.
    df["simulated"] = 0
    df.to_csv(path, index=False)
    paths = write_report(analyze(load_trials(path)), tmp_path / "out2")
    report = json.loads(paths["json"].read_text())
    assert report["simulated"] == {"any": False, "participants": [], "model": None, "model_version": None,
                                   "notice": None}
    assert "simulated-banner" not in paths["html"].read_text()


@pytest.mark.slow
def test_html_shows_ids_and_method_names_as_text_never_as_markup(tmp_path, synthetic):
    # A participant id and a method name from the trials file are data: the page must show
    # them escaped, in the tables, the sentences and the simulated-data banner alike.
    df = synthetic(6, seed=4).astype(str)
    evil_id, evil_method = "<script>alert('id')</script>", "<img src=x onerror=alert(1)>"
    df.loc[df["participant"] == "P01", "participant"] = evil_id
    df.loc[df["method"] == "combination", "method"] = evil_method
    df["simulated"] = np.where(df["participant"] == evil_id, "1", "0")
    paths = write_report(analyze(load_trials(df)), tmp_path / "r")
    page = paths["html"].read_text(encoding="utf-8")
    assert "<script" not in page and "<img src=x" not in page
    assert "&lt;script&gt;alert(" in page and "&lt;img src=x onerror=alert(1)&gt;" in page
    report = json.loads(paths["json"].read_text(encoding="utf-8"))
    assert evil_id in report["simulated"]["participants"] and evil_method in report["study1"]["methods"]


def test_the_simulated_footer_sits_below_every_axis_label(tmp_path, synthetic, monkeypatch):
    """The 'SIMULATED' footer of a report figure has its own room: it covers no axis or label."""
    import vibrofocus.analysis.figures as figures

    saved = []
    real_save = figures.save_figure
    monkeypatch.setattr(figures, "save_figure", lambda fig, path, **kw: saved.append(fig) or real_save(fig, path, **kw))
    df = synthetic(3, seed=3)
    df["simulated"] = 1
    path = tmp_path / "trials.csv"
    df.to_csv(path, index=False)
    write_report(analyze(load_trials(path)), tmp_path / "out")
    assert saved
    for fig in saved:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        canvas = FigureCanvasAgg(fig)
        canvas.draw()  # the layout as saved: the constrained engine runs again
        renderer = canvas.get_renderer()
        footers = [t for t in fig.texts if t.get_text().startswith("SIMULATED: ")]
        assert len(footers) == 1
        top = footers[0].get_window_extent(renderer).y1
        lowest = min(ax.get_tightbbox(renderer).y0 for ax in fig.axes if ax.get_visible())
        assert top <= lowest + 0.5, (fig.axes[0].get_title(), top, lowest)
