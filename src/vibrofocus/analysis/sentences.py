"""The results in words: sentences as a methods/results section would write them (APA-like numbers)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .pipeline import AnalysisResult, Study1Result, Study2Counts, Study2Result

__all__ = ["results_sentences", "format_p"]


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


def _size(row) -> str:
    """"N = 20" or "N = 20, 1512 trials": who and what entered a test."""
    trials = row.get("n_trials", float("nan"))
    return f"N = {int(row['n'])}" + ("" if pd.isna(trials) else f", {int(trials)} trials")


def _friedman_sentence(part: Study2Counts, label: str, alpha: float) -> list[str]:
    if part.friedman is None:
        return [f"Friedman tests {label} were not computed: {part.unavailable}."] + (
            [f"Pairwise Wilcoxon tests {label} were not computed: {part.wilcoxon_unavailable}."]
            if part.wilcoxon_unavailable and part.wilcoxon_unavailable != part.unavailable
            else []
        )
    sizes = {(int(r["n"]), r.get("n_trials", float("nan"))) for _, r in part.friedman.iterrows()}
    bits = []
    for factor, r in part.friedman.iterrows():
        verdict = "a significant" if r["p"] < alpha else "no significant"
        size = "" if len(sizes) == 1 else f" ({_size(r)})"
        bits.append(
            f"{verdict} effect of {factor}{size}, χ²({int(r['dof'])}) = {r['chi2']:.2f}, {format_p(r['p'])}, "
            f"Kendall's W = {r['kendall_w']:.2f}"
        )
    common = f" ({_size(part.friedman.iloc[0])})" if len(sizes) == 1 else ""
    out = [
        f"Friedman tests on the mean number of selected locations per participant, {label}{common}, showed "
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
            f"had no such trial and {'was' if len(ct.excluded) == 1 else 'were'} left out of "
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
