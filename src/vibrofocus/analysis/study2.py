"""Study 2 (confidence): number of selected locations and its non-parametric statistics.

In study 2 a participant may select several locations. The count of selected locations
is averaged per participant and condition (location × method); Friedman tests compare
the levels of each factor on the per-participant means over the other factor, followed by
Bonferroni-corrected pairwise Wilcoxon signed-rank tests (pingouin). The same analysis
can be restricted to the trials whose selection contains the target.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..errors import ValidationError
from .study1 import _only_study, _require, _sort
from .trials import method_order

__all__ = ["study2_counts", "friedman_tests", "wilcoxon_posthoc"]


def study2_counts(trials: pd.DataFrame, *, contains_target: bool = False) -> tuple[pd.DataFrame, list[dict]]:
    """Mean number of selected locations per participant and condition.

    Parameters
    ----------
    trials : DataFrame
        Trials with ``participant``, ``target``, ``method`` and ``selection``: the
        output of :func:`vibrofocus.analysis.load_trials` (only its study-2 main-phase
        rows are used) or of :func:`vibrofocus.analysis.check_design`.
    contains_target : bool
        Keep only the trials whose selection contains the target.

    Returns
    -------
    counts : DataFrame
        ``participant``, ``location`` (the target), ``method``, ``n_selected`` (mean
        count), ``n_trials``, ``hit_rate`` (fraction of the condition's trials whose
        selection contains the target; with ``contains_target`` this is 1).
    exclusions : list of dict
        With ``contains_target``, the participants with no such trial at all
        (``participant``, ``reason``). A participant with such trials in only some
        conditions keeps those cells: the tests run on per-participant marginal means
        (:func:`friedman_tests` with ``incomplete="drop"``), so one empty cell does not
        drop a participant.
    """
    _require(trials, ("participant", "target", "method", "selection"), "study-2 trials")
    trials = _only_study(trials, 2)
    data = trials.copy()
    data["hit"] = [t in s for t, s in zip(data["target"], data["selection"])]
    data["n_selected"] = data["selection"].map(len)
    exclusions: list[dict] = []
    conditions = data[["target", "method"]].drop_duplicates()
    if contains_target:
        data = data[data["hit"]]
    out = (
        data.groupby(["participant", "target", "method"], sort=False)
        .agg(n_selected=("n_selected", "mean"), n_trials=("n_selected", "size"), hit_rate=("hit", "mean"))
        .reset_index()
        .rename(columns={"target": "location"})
    )
    if contains_target:
        have = set(out["participant"])
        exclusions = [
            {"participant": str(participant), "reason": "no trial whose selection contains the target"}
            for participant in sorted(set(trials["participant"])) if participant not in have
        ]
    if out.empty:
        return out.reset_index(drop=True), exclusions
    return _sort(out.reset_index(drop=True), ("participant", "location", "method")), exclusions


def _denoise(values: np.ndarray) -> np.ndarray:
    """Round away float noise (to 1e-9 of the largest value, in decimal places so that
    integers stay exact) so that means equal as fractions (17/9 reached along different
    sums) tie when ranked."""
    values = np.asarray(values, dtype=float)
    finite = values[np.isfinite(values)]
    scale = max(float(np.max(np.abs(finite))) if finite.size else 1.0, 1.0)
    return np.round(values, 9 - int(np.ceil(np.log10(scale))))


def _per_subject_means(data: pd.DataFrame, dv: str, factor: str, subject: str) -> pd.DataFrame:
    means = data.groupby([subject, factor], as_index=False, sort=True)[dv].mean()
    means[dv] = _denoise(means[dv].to_numpy(float))
    return means


def friedman_tests(
    counts: pd.DataFrame,
    *,
    dv: str = "n_selected",
    factors: Sequence[str] = ("location", "method"),
    subject: str = "participant",
    incomplete: str = "raise",
) -> pd.DataFrame:
    """Friedman test for each factor on the per-subject means over the other factors.

    Uses :func:`pingouin.friedman` (chi-square version, corrected for ties). A subject's
    mean at one level of a factor is the mean of its cells at that level (its marginal
    mean over the other factors' cells that it has).

    Parameters
    ----------
    counts : DataFrame
        One row per subject and condition (see :func:`study2_counts`).
    dv : str
        Dependent variable.
    factors : sequence of str
        Within-subject factors, each tested separately.
    subject : str
        Subject column.
    incomplete : {"raise", "drop"}
        What to do with a subject that has no cell at some level of the tested factor:
        refuse (``"raise"``), or leave it out of that factor's test (``"drop"``; the
        target-containing tests, docs/method.md (Analysis)).

    Returns
    -------
    DataFrame
        Indexed by factor: ``chi2``, ``dof``, ``p``, ``kendall_w``, ``n`` (subjects in the
        test), ``n_trials`` (their trials, where ``counts`` has ``n_trials``; else NaN).

    Raises
    ------
    ValidationError
        Missing columns, fewer than 2 subjects or levels, or (``incomplete="raise"``) a
        subject missing a level.
    """
    import pingouin as pg

    _require(counts, (dv, subject, *factors), "counts")
    if incomplete not in ("raise", "drop"):
        raise ValidationError(f"incomplete must be 'raise' or 'drop', got {incomplete!r}")
    rows = {}
    for factor in factors:
        means = _per_subject_means(counts, dv, factor, subject)
        wide = means.pivot(index=subject, columns=factor, values=dv)
        if incomplete == "drop":
            wide = wide.dropna()
            means = means[means[subject].isin(wide.index)]
        kept = counts[counts[subject].isin(wide.index)]
        n_trials = float(kept["n_trials"].sum()) if "n_trials" in counts else float("nan")
        if wide.isna().any().any():
            bad = sorted(map(str, wide.index[wide.isna().any(axis=1)]))
            raise ValidationError(f"Friedman test on {factor}: {subject}(s) {', '.join(bad)} miss a level of {factor}")
        if wide.shape[0] < 2 or wide.shape[1] < 2:
            raise ValidationError(
                f"Friedman test on {factor} needs at least 2 {subject}s and 2 levels, got {wide.shape[0]} and {wide.shape[1]}"
            )
        if np.ptp(wide.to_numpy(), axis=1).max() == 0:
            # All values tied within every subject: the statistic is 0/0; no evidence of a difference.
            rows[factor] = {"chi2": 0.0, "dof": wide.shape[1] - 1, "p": 1.0, "kendall_w": 0.0, "n": wide.shape[0],
                            "n_trials": n_trials}
            continue
        res = pg.friedman(data=means, dv=dv, within=factor, subject=subject, method="chisq")
        rows[factor] = {
            "chi2": float(res["Q"].iloc[0]),
            "dof": int(res["ddof1"].iloc[0]),
            "p": float(res["p_unc"].iloc[0]),
            "kendall_w": float(res["W"].iloc[0]),
            "n": int(wide.shape[0]),
            "n_trials": n_trials,
        }
    out = pd.DataFrame.from_dict(rows, orient="index")
    out.index.name = "factor"
    return out


def _wilcoxon_pair(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Wilcoxon signed-rank statistic and two-sided p of paired samples.

    Exact p without ties or zero differences; otherwise the normal approximation with
    continuity correction, as R's ``wilcox.test`` does (zero differences dropped). All
    differences zero: no evidence of a difference (W = 0, p = 1).
    """
    import pingouin as pg

    # Differences of means of counts are multiples of simple fractions; round away float
    # noise so that zero differences and ties are recognised as such.
    scale = max(float(np.max(np.abs(np.concatenate([x, y])))), 1.0)
    d = np.round((x - y) / scale, 9) * scale
    nonzero = d[d != 0]
    if nonzero.size == 0:
        return 0.0, 1.0
    tied = np.unique(np.abs(nonzero)).size < nonzero.size
    kwargs = {"method": "approx", "correction": True} if tied or nonzero.size < d.size else {"method": "exact"}
    res = pg.wilcoxon(d, np.zeros_like(d), **kwargs)
    return float(res["W_val"].iloc[0]), float(res["p_val"].iloc[0])


def wilcoxon_posthoc(
    counts: pd.DataFrame, factor: str, *, dv: str = "n_selected", subject: str = "participant"
) -> pd.DataFrame:
    """Pairwise Wilcoxon signed-rank tests between the levels of ``factor``, Bonferroni.

    Each subject contributes its mean over the other factors. The tests use
    :func:`pingouin.wilcoxon` (exact without ties, else normal approximation with
    continuity correction) and :func:`pingouin.multicomp` (``"bonf"``).

    Parameters
    ----------
    counts : DataFrame
        One row per subject and condition (see :func:`study2_counts`).
    factor : str
        The compared factor.
    dv, subject : str
        Dependent variable and subject column.

    Returns
    -------
    DataFrame
        ``A``, ``B``, ``median_A``, ``median_B``, ``W``, ``p_unc``, ``p_bonf``; one row
        per pair of levels (methods in :func:`~vibrofocus.analysis.method_order`).

    Raises
    ------
    ValidationError
        Missing columns, or fewer than 2 subjects with every level of ``factor``.
    """
    import pingouin as pg

    _require(counts, (dv, subject, factor), "counts")
    wide = _per_subject_means(counts, dv, factor, subject).pivot(index=subject, columns=factor, values=dv)
    wide = wide.dropna()
    if wide.shape[0] < 2:
        raise ValidationError(
            f"pairwise Wilcoxon tests on {factor} need at least 2 {subject}s with every level, got {wide.shape[0]}"
        )
    levels = method_order(wide.columns) if factor == "method" else list(wide.columns)
    rows = []
    for i, a in enumerate(levels):
        for b in levels[i + 1 :]:
            w, p = _wilcoxon_pair(wide[a].to_numpy(float), wide[b].to_numpy(float))
            rows.append({"A": a, "B": b, "median_A": wide[a].median(), "median_B": wide[b].median(), "W": w, "p_unc": p})
    out = pd.DataFrame(rows, columns=["A", "B", "median_A", "median_B", "W", "p_unc"])
    if len(out):
        out["p_bonf"] = pg.multicomp(out["p_unc"].to_numpy(), method="bonf")[1]
    else:
        out["p_bonf"] = pd.Series(dtype=float)
    return out
