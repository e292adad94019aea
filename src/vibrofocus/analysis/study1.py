"""Study 1 (performance): perceived positions, localization error and its statistics.

Each trial of study 1 names one location. Its *perceived position* is that location's
coordinate; its *error* is the Euclidean distance (mm) between the perceived and the
target position. Errors are averaged per participant and condition (location × method)
before the statistics: Shapiro–Wilk per condition, a two-way repeated-measures ANOVA
with Mauchly's test and the Greenhouse–Geisser correction (pingouin), and Bonferroni
corrected paired t-tests for the method effect and, per location, for the interaction.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd

from .._docs import fill_doc
from ..errors import ValidationError
from ..layout import ArrayLayout
from .trials import method_order

__all__ = [
    "perceived_positions",
    "point_errors",
    "localization_summary",
    "study1_errors",
    "shapiro_tests",
    "study1_anova",
    "study1_posthoc",
]

_M_TO_MM = 1e3


def _layout(layout: ArrayLayout | None) -> ArrayLayout:
    return ArrayLayout.reference() if layout is None else layout


def _require(df: pd.DataFrame, columns: Sequence[str], what: str) -> None:
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise ValidationError(f"{what} is missing the column(s) {', '.join(missing)}")


def _only_study(trials: pd.DataFrame, study: int) -> pd.DataFrame:
    """The main-phase rows of ``study`` when the table still holds other rows."""
    if "study" in trials.columns and "phase" in trials.columns:
        keep = (trials["study"] == study) & (trials["phase"] == "main")
        if not keep.all():
            return trials[keep].reset_index(drop=True)
    return trials


@fill_doc
def perceived_positions(trials: pd.DataFrame, layout: ArrayLayout | None = None) -> pd.DataFrame:
    """Add the target and perceived positions (mm) and the error (mm) to study-1 trials.

    Parameters
    ----------
    trials : DataFrame
        Trials with ``target`` and ``selection`` (one location per trial): the output
        of :func:`vibrofocus.analysis.load_trials` (only its study-1 main-phase rows are
        used) or of :func:`vibrofocus.analysis.check_design`.
    %(layout_default)s

    Returns
    -------
    DataFrame
        ``trials`` plus ``target_x_mm``, ``target_y_mm``, ``response_location``,
        ``perceived_x_mm``, ``perceived_y_mm`` and ``error_mm`` (Euclidean distance, mm).
    """
    _require(trials, ("target", "selection"), "study-1 trials")
    trials = _only_study(trials, 1)
    xy_mm = np.asarray(_layout(layout).locations_xy) * _M_TO_MM
    out = trials.copy()
    if out.empty:
        for col in ("target_x_mm", "target_y_mm", "perceived_x_mm", "perceived_y_mm", "error_mm"):
            out[col] = pd.Series(dtype=float)
        out["response_location"] = pd.Series(dtype=int)
        return out
    if (out["selection"].map(len) != 1).any():
        raise ValidationError("study-1 trials must each name exactly one location")
    response = out["selection"].map(lambda s: s[0]).to_numpy(dtype=int)
    target = out["target"].to_numpy(dtype=int)
    if target.min() < 1 or max(target.max(), response.max()) > len(xy_mm) or response.min() < 1:
        raise ValidationError(f"targets and responses must be location numbers 1..{len(xy_mm)}")
    out["response_location"] = response
    out["target_x_mm"], out["target_y_mm"] = xy_mm[target - 1].T
    out["perceived_x_mm"], out["perceived_y_mm"] = xy_mm[response - 1].T
    out["error_mm"] = np.hypot(out["perceived_x_mm"] - out["target_x_mm"], out["perceived_y_mm"] - out["target_y_mm"])
    return out


def point_errors(trials: pd.DataFrame, layout: ArrayLayout | None = None) -> pd.DataFrame:
    """Mean localization error of point answers per method, mm (docs/protocols.md, point responses).

    Parameters
    ----------
    trials : DataFrame
        Trials with ``phase``, ``method``, ``target`` and the point columns
        ``response_x_mm``, ``response_y_mm`` (a study database's export, read with
        :func:`pandas.read_csv`); rows without a point (empty cells) are left out, and
        only main-phase rows are used.
    layout : ArrayLayout, optional
        Location coordinates of the targets (m); default the reference layout.

    Returns
    -------
    DataFrame
        One row per method with point answers: ``method``, ``n`` (trials) and
        ``mean_error_mm`` (mean Euclidean distance between the point and the target, mm);
        empty when no trial has a point.
    """
    _require(trials, ("phase", "method", "target", "response_x_mm", "response_y_mm"), "point trials")
    xy_mm = np.asarray(_layout(layout).locations_xy) * _M_TO_MM
    x = pd.to_numeric(trials["response_x_mm"], errors="coerce")
    y = pd.to_numeric(trials["response_y_mm"], errors="coerce")
    keep = (trials["phase"].astype(str) == "main") & x.notna() & y.notna()
    if not keep.any():
        return pd.DataFrame({"method": pd.Series(dtype=str), "n": pd.Series(dtype=int),
                             "mean_error_mm": pd.Series(dtype=float)})
    target = pd.to_numeric(trials.loc[keep, "target"], errors="coerce").to_numpy()
    if np.isnan(target).any() or target.min() < 1 or target.max() > len(xy_mm):
        raise ValidationError(f"targets of point trials must be location numbers 1..{len(xy_mm)}")
    t = xy_mm[target.astype(int) - 1]
    err = np.hypot(x[keep].to_numpy() - t[:, 0], y[keep].to_numpy() - t[:, 1])
    frame = pd.DataFrame({"method": trials.loc[keep, "method"].astype(str).to_numpy(), "error_mm": err})
    out = frame.groupby("method", sort=True)["error_mm"].agg(n="size", mean_error_mm="mean").reset_index()
    out["n"] = out["n"].astype(int)
    return out


@fill_doc
def localization_summary(trials: pd.DataFrame, layout: ArrayLayout | None = None) -> pd.DataFrame:
    """Mean perceived position and its 1-SD covariance ellipse per target and method.

    Trials of all participants are pooled.

    Parameters
    ----------
    trials : DataFrame
        Study-1 trials (see :func:`perceived_positions`).
    %(layout_default)s

    Returns
    -------
    DataFrame
        One row per (``location`` = target, ``method``): ``n`` trials, ``target_x_mm``,
        ``target_y_mm``, ``mean_x_mm``, ``mean_y_mm``, the sample covariance
        ``cov_xx_mm2``, ``cov_xy_mm2``, ``cov_yy_mm2`` (ddof 1), the ellipse full axes
        ``ellipse_width_mm`` (major) and ``ellipse_height_mm`` (minor), i.e. twice the
        standard deviations along the principal axes, ``ellipse_angle_deg`` (major axis,
        counter-clockwise from +x), ``bias_mm`` (mean position to target) and
        ``mean_error_mm``.
    """
    pos = perceived_positions(trials, layout)
    rows = []
    for (location, method), g in pos.groupby(["target", "method"], sort=False):
        xy = g[["perceived_x_mm", "perceived_y_mm"]].to_numpy()
        mean = xy.mean(axis=0)
        if len(xy) > 1:
            cov = np.cov(xy, rowvar=False, ddof=1)
            evals, evecs = np.linalg.eigh(cov)  # ascending
            evals = np.clip(evals, 0.0, None)
            width, height = 2 * np.sqrt(evals[1]), 2 * np.sqrt(evals[0])
            angle = float(np.degrees(np.arctan2(evecs[1, 1], evecs[0, 1]))) % 180.0
        else:
            cov = np.full((2, 2), np.nan)
            width = height = angle = np.nan
        tx, ty = g["target_x_mm"].iloc[0], g["target_y_mm"].iloc[0]
        rows.append(
            {
                "location": int(location),
                "method": method,
                "n": len(xy),
                "target_x_mm": tx,
                "target_y_mm": ty,
                "mean_x_mm": mean[0],
                "mean_y_mm": mean[1],
                "cov_xx_mm2": cov[0, 0],
                "cov_xy_mm2": cov[0, 1],
                "cov_yy_mm2": cov[1, 1],
                "ellipse_width_mm": width,
                "ellipse_height_mm": height,
                "ellipse_angle_deg": angle,
                "bias_mm": float(np.hypot(mean[0] - tx, mean[1] - ty)),
                "mean_error_mm": g["error_mm"].mean(),
            }
        )
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    return _sort(out)


def _sort(df: pd.DataFrame, by: Sequence[str] = ("location", "method")) -> pd.DataFrame:
    order = {m: i for i, m in enumerate(method_order(df["method"].unique()))}
    keys = {c: (df[c].map(order) if c == "method" else df[c]) for c in by}
    idx = pd.DataFrame(keys).sort_values(list(by), kind="stable").index
    return df.loc[idx].reset_index(drop=True)


@fill_doc
def study1_errors(trials: pd.DataFrame, layout: ArrayLayout | None = None) -> pd.DataFrame:
    """Euclidean localization error averaged per participant and condition.

    Parameters
    ----------
    trials : DataFrame
        Study-1 main-phase trials of complete participants.
    %(layout_default)s

    Returns
    -------
    DataFrame
        ``participant``, ``location`` (the target), ``method``, ``error_mm`` (mean
        Euclidean error, mm), ``n_trials``, ``rt_s`` (mean response time, s).
    """
    pos = perceived_positions(trials, layout)
    grouped = pos.groupby(["participant", "target", "method"], sort=False)
    out = grouped.agg(error_mm=("error_mm", "mean"), n_trials=("error_mm", "size"), rt_s=("rt_s", "mean"))
    out = out.reset_index().rename(columns={"target": "location"})
    if out.empty:
        return out
    return _sort(out, ("participant", "location", "method"))


def shapiro_tests(
    errors: pd.DataFrame, *, dv: str = "error_mm", by: Sequence[str] = ("location", "method")
) -> pd.DataFrame:
    """Shapiro–Wilk test of the per-participant averages in each condition.

    Parameters
    ----------
    errors : DataFrame
        One row per participant and condition (see :func:`study1_errors`).
    dv : str
        Column tested.
    by : sequence of str
        Columns defining a condition.

    Returns
    -------
    DataFrame
        The ``by`` columns, ``n``, ``W``, ``p``, ``normal`` (``p >= 0.05``) and
        ``note``; ``W`` and ``p`` are NaN, and ``note`` says why, where there are fewer
        than 3 values or fewer than 3 distinct values (ties make the test degenerate).
    """
    from scipy import stats

    _require(errors, (dv, *by), "errors")
    rows = []
    for key, g in errors.groupby(list(by), sort=False):
        values = g[dv].to_numpy(dtype=float)
        # Ties make the test degenerate: with three values of which two are equal (two
        # participants localised perfectly), W is 0.75 and p ~ 0 whatever the data, so
        # such a "rejection" says nothing. Test only with >= 3 distinct values.
        distinct = np.unique(values[np.isfinite(values)]).size
        note = None
        if len(values) >= 3 and distinct >= 3:
            w, p = stats.shapiro(values)
        else:
            w = p = np.nan
            note = ("fewer than 3 values" if len(values) < 3
                    else f"only {distinct} distinct value(s) among {len(values)} (ties): not testable")
        row = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        row.update(n=len(values), W=float(w), p=float(p), normal=bool(p >= 0.05) if np.isfinite(p) else None,
                   note=note)
        rows.append(row)
    out = pd.DataFrame(rows)
    return _sort(out, tuple(by)) if "method" in by and not out.empty else out


def study1_anova(
    errors: pd.DataFrame,
    *,
    dv: str = "error_mm",
    within: tuple[str, str] = ("location", "method"),
    subject: str = "participant",
) -> pd.DataFrame:
    """Two-way repeated-measures ANOVA with Mauchly's test and Greenhouse–Geisser.

    Wraps :func:`pingouin.rm_anova` (``correction=True``) and renames its columns to the
    report contract.

    Parameters
    ----------
    errors : DataFrame
        Long table, one row per subject and cell of the two within factors.
    dv : str
        Dependent variable (default the mean error, mm).
    within : (str, str)
        The two within-subject factors.
    subject : str
        Subject identifier column.

    Returns
    -------
    DataFrame
        One row per effect (``within[0]``, ``within[1]``, ``"within[0] * within[1]"``):
        ``effect``, ``SS``, ``MS``, ``F``, ``ddof1``, ``ddof2``, ``p_unc``, ``eps``
        (Greenhouse–Geisser epsilon), ``p_gg`` (GG-corrected p), ``ddof1_gg`` and
        ``ddof2_gg`` (dofs multiplied by epsilon), ``ng2`` (generalized eta squared),
        ``W_mauchly``, ``p_mauchly``, ``sphericity_violated`` (Mauchly ``p < 0.05``; None
        where Mauchly's test is undefined) and ``mauchly_defined``. Mauchly's test
        needs at least as many subjects as the effect has levels (contrasts + 1);
        otherwise its statistic is NaN and, conservatively, the GG correction is used.

    Raises
    ------
    ValidationError
        Missing columns, fewer than three subjects, or a subject without every cell.
    """
    import pingouin as pg

    a, b = within
    _require(errors, (dv, a, b, subject), "errors")
    cells = errors.groupby([subject, a, b]).size()
    n_a, n_b = errors[a].nunique(), errors[b].nunique()
    per_subject = cells.groupby(level=subject).size()
    if (per_subject != n_a * n_b).any() or (cells != 1).any():
        bad = sorted(map(str, per_subject[per_subject != n_a * n_b].index))
        raise ValidationError(
            f"the ANOVA needs exactly one {dv} per {subject} and cell of {a} × {b}; "
            f"incomplete or duplicated for {subject}(s) {', '.join(bad) or '(duplicates)'}"
        )
    n = len(per_subject)
    if n < 3:
        raise ValidationError(
            f"the two-way repeated-measures ANOVA needs at least 3 {subject}s, got {n} (with 2 the error terms "
            "have one degree of freedom per contrast, the Greenhouse–Geisser epsilon cannot be estimated and "
            "Mauchly's test is undefined)"
        )
    if n_a < 2 or n_b < 2:
        raise ValidationError(f"the two-way ANOVA needs at least 2 levels of {a} and of {b}, got {n_a} and {n_b}")
    aov = pg.rm_anova(data=errors, dv=dv, within=[a, b], subject=subject, correction=True, detailed=True)
    aov = aov.rename(columns={"Source": "effect", "p_GG_corr": "p_gg", "W_spher": "W_mauchly", "p_spher": "p_mauchly"})
    aov = aov[aov["effect"].isin([a, b, f"{a} * {b}"])].reset_index(drop=True)
    aov["ddof1_gg"] = aov["eps"] * aov["ddof1"]
    aov["ddof2_gg"] = aov["eps"] * aov["ddof2"]
    # Mauchly's W is defined when the sample covariance of the effect's contrasts is
    # non-singular: n - 1 >= number of contrasts (= ddof1). Two levels: always spherical.
    defined = (aov["ddof1"] == 1) | (n - 1 >= aov["ddof1"])
    aov["mauchly_defined"] = defined
    aov.loc[aov["ddof1"] == 1, ["W_mauchly", "p_mauchly"]] = [np.nan, 1.0]
    aov.loc[~defined, ["W_mauchly", "p_mauchly"]] = np.nan
    aov["sphericity_violated"] = [
        (bool(p < 0.05) if ok else None) for p, ok in zip(aov["p_mauchly"], defined)
    ]
    cols = ["effect", "SS", "MS", "F", "ddof1", "ddof2", "p_unc", "p_gg", "eps", "ddof1_gg", "ddof2_gg", "ng2",
            "W_mauchly", "p_mauchly", "sphericity_violated", "mauchly_defined"]  # fmt: skip
    out = aov[cols].copy()
    out["ddof1"] = out["ddof1"].astype(int)
    out["ddof2"] = out["ddof2"].astype(int)
    out.attrs["n_subjects"] = n
    return out


def study1_posthoc(
    errors: pd.DataFrame,
    *,
    dv: str = "error_mm",
    factor: str = "method",
    by: str = "location",
    subject: str = "participant",
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Bonferroni-corrected paired t-tests between methods, overall and per location.

    Parameters
    ----------
    errors : DataFrame
        One row per subject and condition (see :func:`study1_errors`).
    dv, factor, by, subject : str
        Dependent variable, the compared factor, the factor within whose levels the
        interaction comparisons are made, and the subject column.

    Returns
    -------
    main : DataFrame
        Paired t-tests between the levels of ``factor`` on each subject's mean over
        ``by`` (Bonferroni over these comparisons): ``A``, ``B``, ``mean_A``, ``mean_B``,
        ``T``, ``dof``, ``p_unc``, ``p_bonf``, ``hedges``, ``note`` (why a test could not
        be computed, e.g. identical values in all pairs; its T and p are NaN).
    interaction : DataFrame
        The same within each level of ``by`` (one column ``by``), Bonferroni-corrected
        within each level's family of comparisons.

    Raises
    ------
    ValidationError
        Missing columns, or fewer than 2 subjects or levels of ``factor``.
    """
    import pingouin as pg

    _require(errors, (dv, factor, by, subject), "errors")

    def pairs(data: pd.DataFrame) -> pd.DataFrame:
        with warnings.catch_warnings():
            # Identical paired values give no t statistic; pingouin warns and returns NaN,
            # which the table keeps (and a note explains).
            warnings.simplefilter("ignore", UserWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            res = pg.pairwise_tests(data=data, dv=dv, within=factor, subject=subject, padjust="bonf")
        means = data.groupby(factor)[dv].mean()
        res = res.rename(columns={"p_corr": "p_bonf"})
        # Differences identical in every subject up to rounding (averages of a few discrete
        # errors often are) give a t statistic of ~1e15 instead of NaN: no test either.
        wide = data.pivot(index=subject, columns=factor, values=dv)
        scale = max(float(np.nanmax(np.abs(wide.to_numpy()))), 1.0)
        flat = [np.nanstd(wide[a] - wide[b], ddof=1) <= 1e-9 * scale for a, b in zip(res["A"], res["B"])]
        res.loc[flat, ["T", "p_unc", "p_bonf", "hedges"]] = np.nan
        # Known methods in their usual order (pingouin sorts alphabetically): swap A/B where needed.
        order = {m: i for i, m in enumerate(method_order(wide.columns))}
        swap = (res["A"].map(order) > res["B"].map(order)).to_numpy()
        res.loc[swap, ["A", "B"]] = res.loc[swap, ["B", "A"]].to_numpy()
        res.loc[swap, ["T", "hedges"]] = -res.loc[swap, ["T", "hedges"]]
        res = res.iloc[np.lexsort((res["B"].map(order), res["A"].map(order)))].reset_index(drop=True)
        res["mean_A"] = res["A"].map(means)
        res["mean_B"] = res["B"].map(means)
        res["note"] = np.where(res["T"].isna(), "no variance in the paired differences: no test", "")
        return res[["A", "B", "mean_A", "mean_B", "T", "dof", "p_unc", "p_bonf", "hedges", "note"]]

    n = errors[subject].nunique()
    if n < 2 or errors[factor].nunique() < 2:
        raise ValidationError(
            f"paired t-tests need at least 2 {subject}s and 2 levels of {factor}, got {n} and {errors[factor].nunique()}"
        )
    per_subject = errors.groupby([subject, factor], as_index=False)[dv].mean()
    main = pairs(per_subject)
    parts = []
    for level, g in errors.groupby(by, sort=True):
        res = pairs(g)
        res.insert(0, by, level)
        parts.append(res)
    interaction = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()
    return main, interaction
