"""The analysis report: its content (report.json, docs/file-formats.md, report folder) and the folder that holds it.

Three jobs, three modules: the sentences are :mod:`.sentences`, the page
:mod:`.report_html` (a Jinja2 template) and the on-disk contract of report.json
:mod:`vibrofocus.io.report_json`; this module assembles the report's content
(:func:`report_dict`) and writes the folder (:func:`write_report`).
"""

from __future__ import annotations

import os
from pathlib import Path
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from ..io.jsonsafe import json_safe
from ..io.report_json import FRIEDMAN_FACTORS, FRIEDMAN_KEYS, REPORT_JSON, write_report_json
from .pipeline import AnalysisResult, Study2Counts
from .sentences import format_p, results_sentences

__all__ = ["report_dict", "results_sentences", "format_p", "write_report", "report_trials_file"]


# --------------------------------------------------------------------------- report.json
def _study2_part_dict(part: Study2Counts) -> dict:
    d: dict[str, Any] = {
        "n_participants": len(part.participants),
        "participants": part.participants,
        "excluded": part.excluded,
    }
    d["friedman_unavailable"] = part.unavailable if part.friedman is None else None
    d["wilcoxon_unavailable"] = part.wilcoxon_unavailable
    d["friedman"] = (
        _uncomputed_friedman()
        if part.friedman is None
        else {
            factor: {
                "chi2": r["chi2"], "dof": int(r["dof"]), "p": r["p"], "kendall_w": r["kendall_w"], "n": int(r["n"]),
                "n_trials": None if pd.isna(r.get("n_trials", np.nan)) else int(r["n_trials"]),
            }
            for factor, r in part.friedman.iterrows()
        }
    )  # fmt: skip
    d["wilcoxon"] = {factor: table for factor, table in part.wilcoxon.items()}
    d["cell_means"] = part.cell_means
    d["counts"] = part.counts
    return d


def _uncomputed_friedman() -> dict:
    """The docs/file-formats.md, report.json ``study2.friedman`` keys, with nulls where no test could be run."""
    return {factor: dict.fromkeys(FRIEDMAN_KEYS) for factor in FRIEDMAN_FACTORS}


def _simulated(result: AnalysisResult) -> dict[str, Any]:
    """``report.json["simulated"]``: which participants are simulated, and the model label."""
    from ..simulation.perception import MODEL_LABEL, MODEL_VERSION

    sim = list(result.simulated_participants)
    label = "; ".join(result.simulated_models) or MODEL_LABEL  # the trials' own labels (hypotheses) first
    return {
        "any": bool(sim),
        "participants": sim,
        "model": label if sim else None,
        "model_version": MODEL_VERSION if sim else None,
        "notice": (
            f"{len(sim)} participant(s) are simulated ({label}): their answers come from a "
            "perceptual model, not from people; statistics that include them are not evidence about perception."
            if sim else None
        ),
    }


def report_dict(result: AnalysisResult, *, figures: dict[str, str] | None = None) -> dict:
    """The content of report.json (docs/file-formats.md, report.json contract plus details), JSON-safe.

    ``study1.anova`` is a list of rows with ``effect`` (``location``, ``method``,
    ``location * method``), ``F``, ``ddof1``, ``ddof2``, ``p_unc``, ``p_gg``, ``eps`` and
    more; ``study2.friedman`` has ``location`` and ``method``, each with ``chi2``,
    ``dof``, ``p``. A study without usable data has ``available: false`` and a
    ``reason`` (and an empty ``anova``; ``friedman`` keeps its ``location`` and
    ``method`` keys with null values, so readers of the contract find them).

    A study analysed with too few participants for some statistic keeps
    ``available: true`` and its descriptive tables, while each statistic that could not
    be computed is empty (``anova: []``, ``posthoc.method: []``, ``shapiro: []``,
    ``friedman`` with null ``chi2``/``dof``/``p``, ``wilcoxon: {}``) and its reason is in the matching key
    ``study1.anova_unavailable``, ``study1.posthoc_unavailable``,
    ``study1.shapiro_unavailable``, ``study2.friedman_unavailable``,
    ``study2.wilcoxon_unavailable`` (and the same in ``study2.contains_target``);
    these keys are always present and null when the statistic was computed.
    ``xrun_represented`` counts the answered trials presented again because the audio
    stream lost samples during their stimulus (null when the trials do not say).
    ``stimulus_levels`` lists each method's median peak drive (V) and predicted peak at
    the target (µm) per location with the level rule (null when the trials do not record
    them).

    Parameters
    ----------
    result : AnalysisResult
        What :func:`~vibrofocus.analysis.analyze` found.
    figures : dict of str to str, optional
        Figure name to file name, listed under ``figures``.

    Returns
    -------
    dict
        JSON-safe (no NaN: missing values are null).
    """
    from .. import __version__

    sentences = results_sentences(result)
    d: dict[str, Any] = {
        "generator": f"vibrofocus {__version__}",
        "source": result.source,
        "n_trials": result.n_trials,
        "alpha": result.alpha,
        "exclusions": result.exclusions,
        "warnings": result.warnings,
        "unavailable": result.unavailable,
        "simulated": _simulated(result),
        "xrun_represented": result.xrun_represented,
    }
    s1 = result.study1
    if s1 is None:
        d["study1"] = {"available": False, "reason": result.unavailable.get("study1"), "anova": []}
    else:
        anova = s1.anova.copy()
        d["study1"] = {
            "available": True,
            "n_participants": len(s1.participants),
            "participants": s1.participants,
            "methods": s1.methods,
            "locations": s1.locations,
            "dv": "mean Euclidean error per participant and condition (mm)",
            "anova": anova,
            "anova_unavailable": s1.unavailable.get("anova"),
            "posthoc_unavailable": s1.unavailable.get("posthoc"),
            "shapiro_unavailable": s1.unavailable.get("shapiro"),
            "mauchly": anova[["effect", "W_mauchly", "p_mauchly", "mauchly_defined", "sphericity_violated", "eps"]],
            "shapiro": s1.shapiro,
            "posthoc": {"method": s1.posthoc_method, "location_method": s1.posthoc_interaction},
            "cell_means": s1.cell_means,
            "positions": s1.positions,
            "errors": s1.errors,
            "sentences": sentences["study1"],
        }
    s2 = result.study2
    if s2 is None:
        d["study2"] = {"available": False, "reason": result.unavailable.get("study2"), "friedman": _uncomputed_friedman()}
    else:
        all_trials = _study2_part_dict(s2.all_trials)
        d["study2"] = {
            "available": True,
            "n_participants": len(s2.participants),
            "participants": s2.participants,
            "methods": s2.methods,
            "locations": s2.locations,
            "dv": "mean number of selected locations per participant and condition",
            **{k: v for k, v in all_trials.items() if k not in ("participants", "n_participants", "excluded")},
            "contains_target": _study2_part_dict(s2.contains_target),
            "sentences": sentences["study2"],
        }
    # Each method's peak drive and predicted peak at the target per location (null: not recorded).
    d["stimulus_levels"] = result.stimulus_levels
    d["figures"] = figures or {}
    return json_safe(d)


# --------------------------------------------------------------------------- writer
#: Names a report writes into its folder; only these are replaced (other files are left alone).
REPORT_FILES = (REPORT_JSON, "report.html", "study1_localization.png", "study1_errors.png", "study2_counts.png",
                "hypotheses.json", "hypotheses_check.png")


def write_report(result: AnalysisResult, out_dir: str | os.PathLike, *,
                 hypotheses: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write report.json, PNG figures and a self-contained report.html into ``out_dir``.

    The report is built in a temporary folder beside ``out_dir`` and put in place as a
    whole (:func:`vibrofocus._atomic.atomic_directory`): after a failure (a full disk,
    a read-only folder, Ctrl-C) ``out_dir`` holds the previous report unchanged, never a
    mix of old and new files. Files in ``out_dir`` that a report does not write
    (:data:`REPORT_FILES`) are left alone.

    Parameters
    ----------
    result : AnalysisResult
        Output of :func:`~vibrofocus.analysis.analyze`.
    out_dir : path
        Created if needed; a previous report there is replaced.
    hypotheses : dict, optional
        A hypotheses fit (:func:`vibrofocus.simulation.fitting.fit_trials`): written as
        ``hypotheses.json`` with its figure ``hypotheses_check.png`` and a section of
        report.html (model output).

    Returns
    -------
    dict of str to Path
        ``"json"``, ``"html"`` and one entry per figure (``"localization"``,
        ``"errors"``, ``"counts"``, ``"hypotheses"``), and ``"hypotheses_json"``.

    Raises
    ------
    OutputError
        The folder cannot be written; the previous report is unchanged.
    """
    from .._atomic import atomic_directory, write_text
    from .figures import plot_counts, plot_errors, plot_localization, save_figure
    from .report_html import render_html

    out = Path(out_dir)
    names = {"localization": "study1_localization.png", "errors": "study1_errors.png", "counts": "study2_counts.png"}
    simulated = _simulated(result)
    # A figure made from simulated participants says so, with the model and hypothesis, in a footer.
    footer = f"SIMULATED: {simulated['model']}" if simulated["any"] else None

    def save(fig, path: Path) -> Path:
        if footer is not None:
            from .._style import model_footer

            # Room kept under the constrained layout, so the footer never covers an axis label.
            model_footer(fig, footer, color="#b45309")
        return save_figure(fig, path)

    with atomic_directory(out, owned=REPORT_FILES, what="report folder") as build:
        figures: dict[str, Path] = {}
        if result.study1 is not None:
            figures["localization"] = save(plot_localization(result.study1.positions, result.layout),
                                           build / names["localization"])
            figures["errors"] = save(plot_errors(result.study1.errors), build / names["errors"])
        if result.study2 is not None:
            hit = result.study2.contains_target.counts
            hit = hit if len(hit) else None
            figures["counts"] = save(plot_counts(result.study2.all_trials.counts, hit), build / names["counts"])
        extra: dict[str, Path] = {}
        if hypotheses is not None:
            import json

            from .hypotheses import HYPOTHESES_FIGURE, HYPOTHESES_JSON, plot_hypotheses_check

            figures["hypotheses"] = save_figure(plot_hypotheses_check(hypotheses), build / HYPOTHESES_FIGURE)
            write_text(build / HYPOTHESES_JSON, json.dumps(json_safe(hypotheses), indent=1) + "\n",
                       what="hypotheses fit")
            extra["hypotheses_json"] = out / HYPOTHESES_JSON
        report = report_dict(result, figures={k: p.name for k, p in figures.items()})
        write_report_json(report, build / REPORT_JSON)
        write_text(build / "report.html", render_html(result, figures, simulated_notice=report["simulated"]["notice"],
                                                      hypotheses=hypotheses), what="report")
    return {"json": out / REPORT_JSON, "html": out / "report.html", **{k: out / p.name for k, p in figures.items()},
            **extra}


def report_trials_file(
    trials: str | os.PathLike | pd.DataFrame,
    out_dir: str | os.PathLike,
    *,
    on_invalid: str = "raise",
    keep_aborted: bool = False,
    keep_dry_runs: bool = False,
    alpha: float = 0.05,
    hypotheses: Callable[[pd.DataFrame], dict[str, Any]] | None = None,
    kind: str = "people",
) -> tuple[AnalysisResult, dict[str, Path]]:
    """Analyse a trials file and write its report folder: what ``vibrofocus analyze`` and the web app do.

    Parameters
    ----------
    trials : path-like or DataFrame
        A trials CSV (docs/file-formats.md, trials file), a BIDS folder, or a table
        (what :func:`~vibrofocus.analysis.load_trials` reads).
    out_dir : path-like
        Report folder, created if needed (see :func:`write_report`).
    on_invalid : {"raise", "exclude"}
        Rows that break the contract refuse the file, or exclude their participants
        (see :func:`~vibrofocus.analysis.load_trials`).
    keep_aborted, keep_dry_runs : bool
        Analyse aborted sessions and dry runs of a study database's export too.
    alpha : float
        Significance level of the results sentences, in (0, 1).
    hypotheses : callable, optional
        ``hypotheses(trials)``: a hypotheses fit of the loaded trials
        (``vibrofocus analyze --hypotheses`` passes
        :func:`vibrofocus.simulation.fitting.fit_trials`), written with the report.
    kind : {"people", "simulated", "rehearsals", "all"}
        Which participants to analyse (:data:`vibrofocus.analysis.trials.KINDS`): people on
        hardware (default), simulated participants, or people's rehearsals on the simulated
        rig; the others are listed in the report as left out, and why. A source without
        any of the kind is refused, naming the kinds it holds.

    Returns
    -------
    result : AnalysisResult
        What :func:`~vibrofocus.analysis.analyze` found.
    paths : dict of str to Path
        What :func:`write_report` wrote.

    Raises
    ------
    ValidationError
        An unreadable or invalid trials file, or ``alpha`` outside (0, 1).
    OutputError
        The folder cannot be written; a previous report there is unchanged.
    """
    from .._validation import check_in_range
    from .pipeline import analyze
    from .trials import load_trials

    check_in_range(alpha, "alpha", 0.0, 1.0, inclusive=False)
    data = load_trials(trials, on_invalid=on_invalid, keep_aborted=keep_aborted, keep_dry_runs=keep_dry_runs,
                       kind=kind)
    result = analyze(data, alpha=alpha)
    fit = hypotheses(data) if hypotheses is not None else None
    return result, write_report(result, out_dir, hypotheses=fit)
