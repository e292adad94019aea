"""report.html: the analysis report as one self-contained page, from a Jinja2 template.

The page is ``templates/report.html`` (with ``templates/report.css``), autoescaped: a
participant id, a method name or a file name from the trials file is always shown as
text. Tables are built here from HTML-escaped cells (:func:`_table`) and passed in as
markup; figures are embedded as base64 PNG.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .._templates import template_environment
from .pipeline import AnalysisResult, Study1Result, Study2Counts
from .sentences import _effect_name, results_sentences

__all__ = ["P_DISPLAY_FLOOR", "render_html"]

#: Smallest p-value the report tables print as a number; smaller ones read "< 1e-12".
P_DISPLAY_FLOOR = 1e-12
_TEMPLATES = Path(__file__).with_name("templates")


def _is_p_column(name: object) -> bool:
    """p-value columns of pingouin and vibrofocus tables (``p_unc``, ``p-corr``, ``p``, ...)."""
    text = str(name).lower()
    return text == "p" or text.startswith(("p_", "p-")) or text.endswith(("_p", "-p"))


def _cell(x: Any) -> str:
    """One table cell as escaped HTML: numbers rounded for reading, missing values blank."""
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


def _p_cell(x: Any) -> str:
    """A p-value cell: one that underflows the display is bounded, never shown as 0."""
    if isinstance(x, (float, np.floating)) and np.isfinite(x) and 0 <= x < P_DISPLAY_FLOOR:
        return f"&lt; {P_DISPLAY_FLOOR:.0e}".replace("e-0", "e-")
    return _cell(x)


def _table(df: pd.DataFrame | None, *, max_rows: int | None = None):
    """``df`` as an HTML table (markup: every cell and column name escaped here)."""
    from markupsafe import Markup

    if df is None or len(df) == 0:
        return Markup("<p class='small'>(empty)</p>")
    shown = df if max_rows is None else df.head(max_rows)
    cells = shown.astype(object).map(lambda x: None if x is None or (isinstance(x, float) and x != x) else x)
    cells = cells.apply(lambda col: col.map(_p_cell if _is_p_column(col.name) else _cell))
    cells.columns = [html.escape(str(c)) for c in cells.columns]
    body = cells.to_html(index=False, escape=False, border=0)
    note = f"<p class='small'>first {max_rows} of {len(df)} rows</p>" if max_rows and len(df) > max_rows else ""
    return Markup(body + note)


def _unavailable(reasons: dict[str, str], key: str) -> str | None:
    return str(reasons[key]) if key in reasons else None


def _study1(s1: Study1Result) -> dict[str, Any]:
    anova = s1.anova.copy()
    anova["effect"] = anova["effect"].map(_effect_name)
    shown = ["effect", "F", "ddof1", "ddof2", "p_unc", "eps", "p_gg", "ng2", "W_mauchly", "p_mauchly",
             "sphericity_violated"]  # fmt: skip
    return {
        "anova_unavailable": _unavailable(s1.unavailable, "anova"),
        "anova": _table(anova[shown]) if "anova" not in s1.unavailable else None,
        "posthoc_unavailable": _unavailable(s1.unavailable, "posthoc"),
        "posthoc_method": _table(s1.posthoc_method),
        "posthoc_interaction": _table(s1.posthoc_interaction),
        "cell_means": _table(s1.cell_means),
        "shapiro_unavailable": _unavailable(s1.unavailable, "shapiro"),
        "shapiro": _table(s1.shapiro),
        "positions": _table(s1.positions),
    }


def _study2_part(part: Study2Counts, label: str) -> dict[str, Any]:
    separate = part.wilcoxon_unavailable and part.wilcoxon_unavailable != part.unavailable
    return {
        "label": label,
        "friedman_unavailable": str(part.unavailable) if part.friedman is None else None,
        "friedman": _table(part.friedman.reset_index()) if part.friedman is not None else None,
        "wilcoxon_unavailable": part.wilcoxon_unavailable if separate else None,
        "wilcoxon": [(factor, _table(table)) for factor, table in part.wilcoxon.items()],
        "cell_means": _table(part.cell_means),
        "excluded": _table(pd.DataFrame(part.excluded)) if part.excluded else None,
    }


def _figure(path: Path) -> dict[str, str]:
    return {"alt": path.stem, "data": base64.b64encode(path.read_bytes()).decode("ascii")}


def _hypotheses(fit: dict[str, Any]) -> dict[str, Any]:
    from .hypotheses import MODEL_OUTPUT, hypotheses_table

    diff, se = fit.get("difference"), fit.get("difference_se")
    return {"notice": MODEL_OUTPUT, "chosen": fit["chosen"], "runner_up": fit.get("runner_up"),
            "difference": None if diff is None else f"{diff:.1f}", "difference_se": None if se is None else f"{se:.1f}",
            "table": _table(hypotheses_table(fit)), "n_participants": len(fit.get("participants", []))}


def render_html(result: AnalysisResult, figures: dict[str, Path], *, simulated_notice: str | None = None,
                hypotheses: dict[str, Any] | None = None) -> str:
    """The report page for ``result``, with the PNG ``figures`` embedded.

    Parameters
    ----------
    result : AnalysisResult
        What :func:`~vibrofocus.analysis.analyze` found.
    figures : dict of str to Path
        PNG files by name (``"localization"``, ``"errors"``, ``"counts"``); missing
        names are left out.
    simulated_notice : str, optional
        The notice on simulated participants (report.json ``simulated.notice``); shown
        in a banner when ``result`` has simulated participants.
    hypotheses : dict, optional
        A hypotheses fit (``hypotheses.json``, :mod:`vibrofocus.analysis.hypotheses`):
        adds the section "Hypotheses fitted to these trials (model output)".

    Returns
    -------
    str
        A self-contained HTML document.
    """
    from markupsafe import Markup

    from .. import __version__

    sentences = results_sentences(result)
    s2 = result.study2
    context = {
        "css": Markup((_TEMPLATES / "report.css").read_text(encoding="utf-8")),
        "simulated": ({"notice": simulated_notice or "", "participants": list(result.simulated_participants)}
                      if result.simulated_participants else None),
        # The file's name: a report is a document to share, and the path of the folder it
        # was made in says nothing to its readers (report.json keeps the path as given).
        "source": Path(result.source).name if result.source != "<DataFrame>" else result.source,
        "n_trials": result.n_trials,
        "alpha": f"{result.alpha:g}",
        "version": __version__,
        "exclusions": _table(result.exclusions.astype(object).fillna("all")) if len(result.exclusions) else None,
        "warnings": [w.rstrip(".") for w in result.warnings],
        "unavailable": list(result.unavailable.values()),
        "study1_sentences": sentences["study1"],
        "study1": _study1(result.study1) if result.study1 is not None else None,
        "study2_sentences": sentences["study2"],
        "study2": [_study2_part(s2.all_trials, "all trials"),
                   _study2_part(s2.contains_target, "trials whose selection contains the target")]
        if s2 is not None else None,
        "figures": {name: _figure(path) for name, path in figures.items()},
        "stimulus_levels": _table(result.stimulus_levels) if result.stimulus_levels is not None else None,
        "hypotheses": _hypotheses(hypotheses) if hypotheses is not None else None,
    }
    return template_environment(_TEMPLATES).get_template("report.html").render(context)
