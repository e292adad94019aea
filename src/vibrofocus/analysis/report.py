"""report.json (docs/file-formats.md, report.json contract), results sentences, PNG figures and a readable HTML page."""

from __future__ import annotations

import base64
import html
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .pipeline import AnalysisResult, Study1Result, Study2Counts, Study2Result

__all__ = ["report_dict", "results_sentences", "format_p", "write_report"]

#: Columns of ``study1.anova`` that the docs/file-formats.md, report.json contract requires.
ANOVA_CONTRACT = ("effect", "F", "ddof1", "ddof2", "p_unc", "p_gg", "eps")


# --------------------------------------------------------------------------- helpers
def _clean(value: Any) -> Any:
    """Make ``value`` JSON-safe: numpy scalars to Python, NaN/Inf to None, recursively."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, pd.DataFrame):
        return [_clean(r) for r in value.to_dict(orient="records")]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if value is None or value is pd.NA or value is pd.NaT:
        return None
    return value


def format_p(p: float) -> str:
    """APA-like p: ``"p < 0.0001"``, ``"p = 0.0003"`` or ``"p = 0.012"``.

    Parameters
    ----------
    p : float
        The p-value; None or NaN gives ``"p = n/a"``.

    Returns
    -------
    str
    """
    if p is None or not np.isfinite(p):
        return "p = n/a"
    if p < 1e-4:
        return "p < 0.0001"
    if p < 1e-3:
        return f"p = {p:.4f}"
    return f"p = {p:.3f}"


def _dof(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}"


def _effect_name(effect: str) -> str:
    return effect.replace(" * ", " × ")


def _num(x: float, digits: int = 2) -> str:
    """``x`` with ``digits`` decimals, never ``-0.00``; ``n/a`` for NaN."""
    if x is None or not np.isfinite(x):
        return "n/a"
    text = f"{x:.{digits}f}"
    return text.lstrip("-") if float(text) == 0 else text


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _capital(text: str) -> str:
    """``text`` with its first letter upper-case (the rest untouched)."""
    return text[:1].upper() + text[1:]


# --------------------------------------------------------------------------- sentences
def _anova_uses_gg(row) -> bool:
    """GG correction is reported where Mauchly rejects sphericity or cannot be computed."""
    return row.ddof1 > 1 and (row.sphericity_violated is None or bool(row.sphericity_violated))


def _study1_sentences(s1: Study1Result, alpha: float) -> list[str]:
    n = len(s1.participants)
    design = (
        f"Localization error was the Euclidean distance between the perceived and the target location, averaged "
        f"per participant and condition (N = {n} participant{'s' if n != 1 else ''}, {len(s1.locations)} "
        f"locations × {len(s1.methods)} methods: {', '.join(s1.methods)})"
    )
    if "anova" in s1.unavailable:
        out = [design + "."]
    else:
        out = [design + "; it was analysed with a two-way repeated-measures ANOVA (location × method)."]
    means = s1.errors.groupby("method")["error_mm"].mean()
    out.append(
        "Mean error: " + ", ".join(f"{m} {means[m]:.2f} mm" for m in s1.methods if m in means.index) + "."
    )
    for key in ("shapiro", "anova", "posthoc"):
        if key in s1.unavailable:
            out.append(_capital(s1.unavailable[key]) + "; not computed.")
    sh = s1.shapiro.dropna(subset=["p"])
    n_untestable = len(s1.shapiro) - len(sh)
    untestable = (
        f"; {n_untestable} condition{'s' if n_untestable != 1 else ''} could not be tested (tied participant "
        "averages)"
        if n_untestable and len(s1.shapiro) else ""
    )
    if len(sh):
        n_bad = int((sh["p"] < alpha).sum())
        out.append(
            f"Shapiro–Wilk tests rejected normality of the participant averages in {n_bad} of {len(sh)} testable "
            f"conditions (p < {alpha:g}){untestable}."
        )
    elif n_untestable and "shapiro" not in s1.unavailable:
        out.append(
            f"Shapiro–Wilk tests could not be run: in all {n_untestable} conditions the participant averages are "
            "tied (fewer than three distinct values)."
        )
    for row in s1.anova.itertuples(index=False):
        if row.ddof1 == 1:
            continue
        name = _effect_name(row.effect)
        if not row.mauchly_defined:
            out.append(
                f"Mauchly's test is undefined for {name} with N = {n} (it needs at least {row.ddof1 + 1} "
                f"participants); the Greenhouse–Geisser correction was applied (ε = {row.eps:.2f})."
            )
        elif row.sphericity_violated:
            out.append(
                f"Mauchly's test indicated a violation of sphericity for {name} (W = {row.W_mauchly:.3f}, "
                f"{format_p(row.p_mauchly)}); the Greenhouse–Geisser correction was applied (ε = {row.eps:.2f})."
            )
        else:
            out.append(
                f"Mauchly's test did not indicate a violation of sphericity for {name} (W = {row.W_mauchly:.3f}, "
                f"{format_p(row.p_mauchly)})."
            )
    for row in s1.anova.itertuples(index=False):
        gg = _anova_uses_gg(row)
        d1, d2, p = (row.ddof1_gg, row.ddof2_gg, row.p_gg) if gg else (row.ddof1, row.ddof2, row.p_unc)
        subject = (
            f"The {_effect_name(row.effect)} interaction" if "*" in row.effect else f"The main effect of {row.effect}"
        )
        verdict = "was significant" if p < alpha else "was not significant"
        out.append(
            f"{subject} {verdict}, F({_dof(d1)}, {_dof(d2)}) = {row.F:.2f}, "
            f"{format_p(p)}, η²G = {row.ng2:.3f}{' (Greenhouse–Geisser corrected)' if gg else ''}."
        )
    parts = []
    for r in s1.posthoc_method.itertuples(index=False):
        parts.append(
            f"{r.A} (M = {r.mean_A:.2f} mm) vs {r.B} (M = {r.mean_B:.2f} mm), t({_dof(r.dof)}) = {_num(r.T)}, "
            f"{format_p(r.p_bonf)}"
        )
    if parts:
        out.append("Post hoc paired t-tests between methods (Bonferroni-corrected): " + "; ".join(parts) + ".")
    inter = s1.posthoc_interaction
    if len(inter):
        sig = inter[inter["p_bonf"] < alpha]
        if len(sig):
            by_loc = [
                f"location {loc}: " + ", ".join(
                    f"{r.A} vs {r.B} ({format_p(r.p_bonf)})" for r in g.itertuples(index=False)
                )
                for loc, g in sig.groupby("location", sort=True)
            ]
            out.append(
                "Within each location (paired t-tests, Bonferroni-corrected per location), methods differed at "
                + "; ".join(by_loc) + "."
            )
        else:
            out.append("Within each location, no pair of methods differed after Bonferroni correction.")
    return out


def _friedman_sentence(part: Study2Counts, label: str, alpha: float) -> list[str]:
    if part.friedman is None:
        return [f"Friedman tests {label} were not computed: {part.unavailable}."] + (
            [f"Pairwise Wilcoxon tests {label} were not computed: {part.wilcoxon_unavailable}."]
            if part.wilcoxon_unavailable and part.wilcoxon_unavailable != part.unavailable
            else []
        )
    n = int(part.friedman["n"].iloc[0])
    bits = []
    for factor, r in part.friedman.iterrows():
        verdict = "a significant" if r["p"] < alpha else "no significant"
        bits.append(
            f"{verdict} effect of {factor}, χ²({int(r['dof'])}) = {r['chi2']:.2f}, {format_p(r['p'])}, "
            f"Kendall's W = {r['kendall_w']:.2f}"
        )
    out = [
        f"Friedman tests on the mean number of selected locations per participant, {label} (N = {n}), showed "
        + "; and ".join(bits) + "."
    ]
    if part.wilcoxon_unavailable:
        out.append(f"Pairwise Wilcoxon tests {label} were not computed: {part.wilcoxon_unavailable}.")
    for factor, table in part.wilcoxon.items():
        sig = table[table["p_bonf"] < alpha]
        if len(sig):
            out.append(
                f"Pairwise Wilcoxon signed-rank tests on {factor} (Bonferroni-corrected) found differences between "
                + "; ".join(
                    f"{r.A} (Mdn = {r.median_A:.2f}) and {r.B} (Mdn = {r.median_B:.2f}), W = {r.W:.1f}, "
                    f"{format_p(r.p_bonf)}"
                    for r in sig.itertuples(index=False)
                )
                + "."
            )
        else:
            out.append(f"Pairwise Wilcoxon signed-rank tests on {factor} found no difference after Bonferroni correction.")
    return out


def _study2_sentences(s2: Study2Result, alpha: float) -> list[str]:
    out = _friedman_sentence(s2.all_trials, "on all trials", alpha)
    ct = s2.contains_target
    label = "on the trials whose selection contains the target"
    if ct.excluded:
        out.append(
            f"For the trials whose selection contains the target, "
            f"{_count(len(ct.excluded), 'participant')} ({', '.join(e['participant'] for e in ct.excluded)}) "
            f"had no such trial in some condition and {'was' if len(ct.excluded) == 1 else 'were'} left out of "
            f"that analysis."
        )
    out += _friedman_sentence(ct, label, alpha)
    return out


def results_sentences(result: AnalysisResult) -> dict[str, list[str]]:
    """Results sentences as a methods/results section would write them.

    Degrees of freedom are Greenhouse–Geisser corrected where Mauchly's test rejects
    sphericity (or is undefined for the sample size).

    Parameters
    ----------
    result : AnalysisResult
        What :func:`~vibrofocus.analysis.analyze` found.

    Returns
    -------
    dict
        ``{"study1": [...], "study2": [...]}``; a study without data gets one sentence
        saying why.
    """
    out: dict[str, list[str]] = {}
    out["study1"] = (
        _study1_sentences(result.study1, result.alpha)
        if result.study1 is not None
        else [f"Study 1 was not analysed: {result.unavailable.get('study1', 'no data')}."]
    )
    out["study2"] = (
        _study2_sentences(result.study2, result.alpha)
        if result.study2 is not None
        else [f"Study 2 was not analysed: {result.unavailable.get('study2', 'no data')}."]
    )
    return out


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
                "chi2": r["chi2"], "dof": int(r["dof"]), "p": r["p"], "kendall_w": r["kendall_w"], "n": int(r["n"])
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
    return {factor: {"chi2": None, "dof": None, "p": None} for factor in ("location", "method")}


def _simulated(result: AnalysisResult) -> dict[str, Any]:
    """``report.json["simulated"]``: which participants are simulated, and the model label."""
    from ..studies.perception import MODEL_LABEL, MODEL_VERSION

    sim = list(result.simulated_participants)
    return {
        "any": bool(sim),
        "participants": sim,
        "model": MODEL_LABEL if sim else None,
        "model_version": MODEL_VERSION if sim else None,
        "notice": (
            f"{len(sim)} participant(s) are simulated ({MODEL_LABEL}): their answers come from a "
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
    d["figures"] = figures or {}
    return _clean(d)


# --------------------------------------------------------------------------- HTML
_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.8em}
table{border-collapse:collapse;margin:.6em 0 1.2em;font-size:.88em}
th,td{border:1px solid #ddd;padding:.25em .55em;text-align:right}th{background:#f3f3f3}
td:first-child,th:first-child{text-align:left}
.results p{background:#f8f8fb;border-left:3px solid #0072B2;padding:.4em .8em;margin:.5em 0}
.warn{color:#8a4b00}img{max-width:100%;border:1px solid #eee}details{margin:.5em 0}
summary{cursor:pointer;font-weight:600}.small{color:#666;font-size:.85em}
"""


#: Smallest p-value the report tables print as a number; smaller ones read "< 1e-12".
P_DISPLAY_FLOOR = 1e-12


def _is_p_column(name: object) -> bool:
    """p-value columns of pingouin and vibrofocus tables (``p_unc``, ``p-corr``, ``p``, ...)."""
    text = str(name).lower()
    return text == "p" or text.startswith(("p_", "p-")) or text.endswith(("_p", "-p"))


def _table(df: pd.DataFrame, *, max_rows: int | None = None) -> str:
    if df is None or len(df) == 0:
        return "<p class='small'>(empty)</p>"
    shown = df if max_rows is None else df.head(max_rows)

    def fmt(x):
        if x is None:
            return "–"
        if isinstance(x, (float, np.floating)):
            if not np.isfinite(x):
                return ""
            if abs(x) < 1e-12:  # float noise around zero (e.g. a t of -6e-16): show 0, not -0 or 1e-16
                return "0"
            text = f"{x:.3g}" if abs(x) < 1e-3 else f"{x:.4f}".rstrip("0").rstrip(".")
            return "0" if text == "-0" else text
        return html.escape(str(x))

    def fmt_p(x):
        # A p-value that underflows the display is bounded, never shown as 0.
        if isinstance(x, (float, np.floating)) and np.isfinite(x) and 0 <= x < P_DISPLAY_FLOOR:
            return f"&lt; {P_DISPLAY_FLOOR:.0e}".replace("e-0", "e-")
        return fmt(x)

    cells = shown.astype(object).map(lambda x: None if x is None or (isinstance(x, float) and x != x) else x)
    cells = cells.apply(lambda col: col.map(fmt_p if _is_p_column(col.name) else fmt))
    body = cells.to_html(index=False, escape=False, border=0)
    note = f"<p class='small'>first {max_rows} of {len(df)} rows</p>" if max_rows and len(df) > max_rows else ""
    return body + note


def _not_computed(reason: str) -> str:
    return f"<p class='warn'>Not computed: {html.escape(reason)}.</p>"


def _img(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f"<p><img alt='{html.escape(path.stem)}' src='data:image/png;base64,{data}'></p>"


def _html(result: AnalysisResult, figures: dict[str, Path]) -> str:
    from .. import __version__

    sentences = results_sentences(result)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<title>vibrofocus localization report</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>Localization studies: analysis report</h1>",
        *([f"<p class='warn' id='simulated-banner' style='border:2px solid #b45309;padding:0.6em;font-weight:bold'>"
           f"SIMULATED DATA — {html.escape(_simulated(result)['notice'])} Simulated: "
           f"{html.escape(', '.join(result.simulated_participants))}.</p>"] if result.simulated_participants else []),
        f"<p class='small'>Source: {html.escape(result.source)} · {result.n_trials} trial rows (training rows not "
        f"analysed) · α = {result.alpha:g} · vibrofocus {html.escape(__version__)}</p>",
    ]
    parts.append("<h2>Participants and exclusions</h2>")
    if len(result.exclusions):
        parts.append("<p class='warn'>Some participants were excluded from an analysis:</p>")
        parts.append(_table(result.exclusions.astype(object).fillna("all")))
    else:
        parts.append("<p>No participant was excluded.</p>")
    for w in result.warnings:
        parts.append(f"<p class='warn'>Note: {html.escape(w.rstrip('.'))}.</p>")
    for reason in result.unavailable.values():
        parts.append(f"<p class='warn'><b>{html.escape(reason)}</b></p>")

    parts.append("<h2>Study 1: localization performance</h2>")
    s1 = result.study1
    parts.append("<div class='results'>" + "".join(f"<p>{html.escape(s)}</p>" for s in sentences["study1"]) + "</div>")
    if s1 is not None:
        for key in ("localization", "errors"):
            if key in figures:
                parts.append(_img(figures[key]))
        parts.append("<h3>Two-way repeated-measures ANOVA (location × method)</h3>")
        if "anova" in s1.unavailable:
            parts.append(_not_computed(s1.unavailable["anova"]))
        else:
            anova = s1.anova.copy()
            anova["effect"] = anova["effect"].map(_effect_name)
            shown = ["effect", "F", "ddof1", "ddof2", "p_unc", "eps", "p_gg", "ng2", "W_mauchly", "p_mauchly",
                     "sphericity_violated"]  # fmt: skip
            parts.append(_table(anova[shown]))
            parts.append(
                "<p class='small'>p_gg: Greenhouse–Geisser corrected p (ε = eps); W_mauchly, p_mauchly: Mauchly's "
                "test (empty where undefined for this N or with two levels); ng2: generalized η². Full table in "
                "report.json.</p>"
            )
        parts.append("<h3>Post hoc: methods (paired t-tests, Bonferroni)</h3>")
        if "posthoc" in s1.unavailable:
            parts.append(_not_computed(s1.unavailable["posthoc"]))
        else:
            parts.append(_table(s1.posthoc_method))
            parts.append("<details><summary>Post hoc per location (interaction)</summary>")
            parts.append(_table(s1.posthoc_interaction) + "</details>")
        parts.append("<details><summary>Mean error per condition (mm)</summary>")
        parts.append(_table(s1.cell_means) + "</details>")
        parts.append("<details><summary>Shapiro–Wilk per condition</summary>")
        parts.append(
            (_not_computed(s1.unavailable["shapiro"]) if "shapiro" in s1.unavailable else _table(s1.shapiro))
            + "</details>"
        )
        parts.append("<details><summary>Mean perceived positions and 1-SD ellipses (mm)</summary>")
        parts.append(_table(s1.positions) + "</details>")

    parts.append("<h2>Study 2: number of selected locations</h2>")
    s2 = result.study2
    parts.append("<div class='results'>" + "".join(f"<p>{html.escape(s)}</p>" for s in sentences["study2"]) + "</div>")
    if s2 is not None:
        if "counts" in figures:
            parts.append(_img(figures["counts"]))
        for label, part in (("all trials", s2.all_trials), ("trials whose selection contains the target", s2.contains_target)):
            parts.append(f"<h3>Friedman tests ({label})</h3>")
            if part.friedman is None:
                parts.append(_not_computed(str(part.unavailable)))
            else:
                parts.append(_table(part.friedman.reset_index()))
            if part.wilcoxon_unavailable and part.wilcoxon_unavailable != part.unavailable:
                parts.append(_not_computed(f"pairwise Wilcoxon tests: {part.wilcoxon_unavailable}"))
            for factor, table in part.wilcoxon.items():
                parts.append(f"<details><summary>Pairwise Wilcoxon on {factor} ({label}, Bonferroni)</summary>")
                parts.append(_table(table) + "</details>")
            parts.append(f"<details><summary>Mean count per condition ({label})</summary>")
            parts.append(_table(part.cell_means) + "</details>")
            if part.excluded:
                parts.append(_table(pd.DataFrame(part.excluded)))
    parts.append(
        "<h2>Methods</h2><p class='small'>Two-way repeated-measures ANOVA, Mauchly's test and Greenhouse–Geisser "
        "correction, paired t-tests, Friedman and Wilcoxon signed-rank tests with pingouin; Shapiro–Wilk with SciPy. "
        "The Greenhouse–Geisser correction is reported where Mauchly's test rejects sphericity or is undefined "
        "(fewer participants than levels of the effect). Figures: mean perceived position with the 1-SD ellipse of "
        "the pooled perceived positions per target and method; box plots of per-participant means.</p>"
    )
    parts.append("</body></html>")
    return "\n".join(parts)


# --------------------------------------------------------------------------- writer
#: Names a report writes into its folder; only these are replaced (other files are left alone).
REPORT_FILES = ("report.json", "report.html", "study1_localization.png", "study1_errors.png", "study2_counts.png")


def write_report(result: AnalysisResult, out_dir: str | os.PathLike) -> dict[str, Path]:
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

    Returns
    -------
    dict of str to Path
        ``"json"``, ``"html"`` and one entry per figure (``"localization"``,
        ``"errors"``, ``"counts"``).

    Raises
    ------
    OutputError
        The folder cannot be written; the previous report is unchanged.
    """
    from .._atomic import atomic_directory, write_text
    from .figures import plot_counts, plot_errors, plot_localization, save_figure

    out = Path(out_dir)
    names = {"localization": "study1_localization.png", "errors": "study1_errors.png", "counts": "study2_counts.png"}
    with atomic_directory(out, owned=REPORT_FILES, what="report folder") as build:
        figures: dict[str, Path] = {}
        if result.study1 is not None:
            figures["localization"] = save_figure(
                plot_localization(result.study1.positions, result.layout), build / names["localization"]
            )
            figures["errors"] = save_figure(plot_errors(result.study1.errors), build / names["errors"])
        if result.study2 is not None:
            hit = result.study2.contains_target.counts
            hit = hit if len(hit) else None
            figures["counts"] = save_figure(plot_counts(result.study2.all_trials.counts, hit), build / names["counts"])
        report = report_dict(result, figures={k: p.name for k, p in figures.items()})
        write_text(build / "report.json", json.dumps(report, indent=2, ensure_ascii=False, allow_nan=False),
                   what="report")
        write_text(build / "report.html", _html(result, figures), what="report")
    return {"json": out / "report.json", "html": out / "report.html", **{k: out / p.name for k, p in figures.items()}}
