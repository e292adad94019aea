"""The whole analysis of a trials table: both studies, with exclusions accounted for."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from .._docs import fill_doc
from ..errors import ValidationError
from ..layout import ArrayLayout
from .study1 import localization_summary, shapiro_tests, study1_anova, study1_errors, study1_posthoc
from .study2 import friedman_tests, study2_counts, wilcoxon_posthoc
from .levels import stimulus_levels
from .trials import check_design, method_order

#: Below this many complete participants a study's results carry a warning.
_FEW_PARTICIPANTS = 6

#: Fewest participants each statistic needs; with fewer it is reported as unavailable.
#: The two-way RM-ANOVA needs 3: with 2 the error terms have one degree of freedom per
#: contrast, the contrast covariance has rank 1 (so the Greenhouse–Geisser epsilon is
#: pinned at its lower bound instead of estimated) and Mauchly's test is undefined for
#: every effect (pingouin divides by zero). Shapiro–Wilk needs 3 values per condition;
#: paired t-tests, Friedman and Wilcoxon tests need 2 participants.
MIN_PARTICIPANTS = {"anova": 3, "shapiro": 3, "posthoc": 2, "friedman": 2, "wilcoxon": 2}

#: How a reason names each statistic, and why it needs that many participants.
_STAT_NAMES = {
    "anova": ("the two-way repeated-measures ANOVA needs", ""),
    "shapiro": ("Shapiro–Wilk tests need", " per condition"),
    "posthoc": ("post hoc paired t-tests need", ""),
    "friedman": ("Friedman tests need", ""),
    "wilcoxon": ("pairwise Wilcoxon signed-rank tests need", ""),
}
_ANOVA_WHY = (
    "; with 2 the error terms have one degree of freedom per contrast, the Greenhouse–Geisser "
    "epsilon cannot be estimated and Mauchly's test is undefined"
)

__all__ = ["Study1Result", "Study2Counts", "Study2Result", "AnalysisResult", "analyze"]


@dataclass
class Study1Result:
    """Results of study 1 (performance); every table is a DataFrame.

    Attributes
    ----------
    participants : list of str
        Participants analysed (complete main phase).
    methods, locations : list
        Levels of the two factors.
    trials : DataFrame
        The analysed trials with perceived positions and errors (mm).
    positions : DataFrame
        Mean perceived position and 1-SD ellipse per target and method
        (:func:`~vibrofocus.analysis.localization_summary`).
    errors : DataFrame
        Mean error (mm) per participant and condition.
    cell_means : DataFrame
        Mean and SD over participants of ``errors`` per condition.
    shapiro : DataFrame
        Shapiro–Wilk per condition.
    anova : DataFrame
        Two-way RM-ANOVA with Mauchly and Greenhouse–Geisser.
    posthoc_method, posthoc_interaction : DataFrame
        Bonferroni-corrected paired t-tests.
    unavailable : dict of str to str
        Reason for each statistic that could not be computed (keys ``"anova"``,
        ``"shapiro"``, ``"posthoc"``); its table is then empty. The descriptive tables
        (``positions``, ``errors``, ``cell_means``) are always filled.
    """

    participants: list[str]
    methods: list[str]
    locations: list[int]
    trials: pd.DataFrame
    positions: pd.DataFrame
    errors: pd.DataFrame
    cell_means: pd.DataFrame
    shapiro: pd.DataFrame
    anova: pd.DataFrame
    posthoc_method: pd.DataFrame
    posthoc_interaction: pd.DataFrame
    unavailable: dict[str, str] = field(default_factory=dict)


@dataclass
class Study2Counts:
    """Counts of selected locations and their tests, on all trials or on target-containing ones.

    Attributes
    ----------
    participants : list of str
        Participants in this part of the analysis.
    counts, cell_means : DataFrame
        Mean count per participant and condition, and its mean and SD over participants.
    friedman : DataFrame or None
        None where the Friedman tests could not be computed (reason in ``unavailable``).
    wilcoxon : dict of str to DataFrame
        Pairwise tests per factor; empty where not computed (reason in
        ``wilcoxon_unavailable``).
    excluded : list of dict
        Participants left out of this part and why.
    unavailable, wilcoxon_unavailable : str or None
        Why the Friedman / Wilcoxon tests were not computed.
    """

    participants: list[str]
    counts: pd.DataFrame
    cell_means: pd.DataFrame
    friedman: pd.DataFrame | None
    wilcoxon: dict[str, pd.DataFrame]
    excluded: list[dict] = field(default_factory=list)
    unavailable: str | None = None
    wilcoxon_unavailable: str | None = None


@dataclass
class Study2Result:
    """Results of study 2 (confidence): all trials and trials containing the target.

    Attributes
    ----------
    participants : list of str
        Participants analysed.
    methods, locations : list
        Levels of the two factors.
    all_trials : Study2Counts
        Counts of selected locations on every main trial.
    contains_target : Study2Counts
        The same on the trials whose selection contains the target.
    """

    participants: list[str]
    methods: list[str]
    locations: list[int]
    all_trials: Study2Counts
    contains_target: Study2Counts


@dataclass
class AnalysisResult:
    """Everything :func:`analyze` found.

    Attributes
    ----------
    source : str
        Where the trials came from.
    n_trials : int
        Rows of the table (both phases, after row-level exclusions).
    study1, study2 : Study1Result or Study2Result or None
        None where the study has no usable data; the reason is in ``unavailable``.
    exclusions : DataFrame
        ``participant``, ``study`` (None: the whole file), ``reason``.
    warnings : list of str
        Remarks that exclude no one.
    unavailable : dict
        ``{"study1": reason, ...}`` for the studies that could not be analysed.
    alpha : float
        Significance level used in sentences and flags.
    layout : ArrayLayout or None
        Layout the locations refer to (None: the reference layout).
    simulated_participants : list of str
        Participants marked simulated in the trials (answers from the perceptual model,
        not from people).
    simulated_models : list of str
        Labels of the models (version and hypothesis) that answered for them, as the trials
        name them (empty: not named; model v3 then).
    stimulus_levels : DataFrame or None
        Each method's peak drive and predicted peak at the target per location
        (:func:`~vibrofocus.analysis.levels.stimulus_levels`); None when the trials do
        not record them.
    xrun_represented : int or None
        Answered trials presented again because the audio stream lost samples during their
        stimulus (the trials' ``xrun_represented`` column); None when the trials do not say.
    """

    source: str
    n_trials: int
    study1: Study1Result | None
    study2: Study2Result | None
    exclusions: pd.DataFrame
    warnings: list[str]
    unavailable: dict[str, str]
    alpha: float = 0.05
    layout: ArrayLayout | None = None
    simulated_participants: list[str] = field(default_factory=list)
    stimulus_levels: pd.DataFrame | None = None
    simulated_models: list[str] = field(default_factory=list)
    xrun_represented: int | None = None


def _cell_means(df: pd.DataFrame, dv: str) -> pd.DataFrame:
    from .study1 import _sort

    out = df.groupby(["location", "method"], sort=False)[dv].agg(["mean", "std", "median", "count"]).reset_index()
    out = out.rename(columns={"std": "sd", "count": "n"})
    return _sort(out)


def _study_levels(data: pd.DataFrame) -> tuple[list[str], list[int]]:
    return method_order(data["method"].unique()), sorted(int(t) for t in data["target"].unique())


def _participants(n: int) -> str:
    return f"{n} participant" if n == 1 else f"{n} participants"


def _too_few(stat: str, n: int) -> str | None:
    """Why ``stat`` cannot be computed with ``n`` participants, or None."""
    need = MIN_PARTICIPANTS[stat]
    if n >= need:
        return None
    name, per = _STAT_NAMES[stat]
    why = _ANOVA_WHY if stat == "anova" and n == 2 else ""
    return f"{name} at least {need} participants{per}, got {n}{why}"


def _why_no_complete_cells(counts: pd.DataFrame, n: int) -> str:
    """Why the target-containing Wilcoxon tests are missing: too few participants have such a
    trial in every cell of a factor (a selection often misses the target)."""
    complete = {factor: int((counts.groupby("participant")[factor].nunique() == counts[factor].nunique()).sum())
                for factor in ("location", "method")}
    return (f"of the {_participants(n)} with a target-containing trial, {complete['location']} have one at every "
            f"location and {complete['method']} with every method; the pairwise Wilcoxon tests need at least 2 "
            "with every level. More repetitions per condition, or more participants, would give them (the paper "
            "had 20 participants)")


def _guarded(stat: str, n: int, compute: Callable[[], Any]) -> tuple[Any, str | None]:
    """Run ``compute()`` unless ``n`` is too few for ``stat``; return ``(value, reason)``.

    A library failure (pingouin or SciPy dividing by zero on a degenerate sample, say)
    becomes a reason too, so one statistic that cannot be computed never stops the rest.
    """
    reason = _too_few(stat, n)
    if reason is not None:
        return None, reason
    try:
        return compute(), None
    except (ArithmeticError, ValueError, np.linalg.LinAlgError, KeyError) as exc:
        message = str(exc) if isinstance(exc, ValidationError) else f"{type(exc).__name__}: {exc}"
        name = _STAT_NAMES[stat][0].rsplit(" ", 1)[0]
        return None, f"{name} could not be computed ({message})"


def _usable(data: pd.DataFrame, study: int) -> str | None:
    """Reason why the complete-participant trials of a study cannot be analysed, or None."""
    if data.empty:
        return None  # caller words this
    methods, locations = _study_levels(data)
    if len(methods) < 2:
        return f"study {study}: only one method ({methods[0]}); nothing to compare"
    if len(locations) < 2:
        return f"study {study}: only one location ({locations[0]}); nothing to compare"
    return None


_ANOVA_COLUMNS = ["effect", "SS", "MS", "F", "ddof1", "ddof2", "p_unc", "p_gg", "eps", "ddof1_gg", "ddof2_gg",
                  "ng2", "W_mauchly", "p_mauchly", "sphericity_violated", "mauchly_defined"]  # fmt: skip
_POSTHOC_COLUMNS = ["A", "B", "mean_A", "mean_B", "T", "dof", "p_unc", "p_bonf", "hedges", "note"]


def _analyze_study1(data: pd.DataFrame, layout: ArrayLayout) -> Study1Result:
    from .study1 import perceived_positions

    errors = study1_errors(data, layout)
    n = errors["participant"].nunique()
    unavailable: dict[str, str] = {}
    anova, why = _guarded("anova", n, lambda: study1_anova(errors))
    if why:
        unavailable["anova"] = why
        anova = pd.DataFrame(columns=_ANOVA_COLUMNS)
    posthoc, why = _guarded("posthoc", n, lambda: study1_posthoc(errors))
    if why:
        unavailable["posthoc"] = why
        posthoc = (pd.DataFrame(columns=_POSTHOC_COLUMNS), pd.DataFrame(columns=["location", *_POSTHOC_COLUMNS]))
    main, inter = posthoc
    shapiro, why = _guarded("shapiro", n, lambda: shapiro_tests(errors))
    if why:
        unavailable["shapiro"] = why
        shapiro = pd.DataFrame(columns=["location", "method", "n", "W", "p", "normal"])
    methods, locations = _study_levels(data)
    return Study1Result(
        participants=sorted(map(str, data["participant"].unique())),
        methods=methods,
        locations=locations,
        trials=perceived_positions(data, layout),
        positions=localization_summary(data, layout),
        errors=errors,
        cell_means=_cell_means(errors, "error_mm"),
        shapiro=shapiro,
        anova=anova,
        posthoc_method=main,
        posthoc_interaction=inter,
        unavailable=unavailable,
    )


def _study2_part(data: pd.DataFrame, contains_target: bool) -> Study2Counts:
    counts, excluded = study2_counts(data, contains_target=contains_target)
    participants = sorted(map(str, counts["participant"].unique())) if len(counts) else []
    n = len(participants)
    cell_means = _cell_means(counts, "n_selected") if n else pd.DataFrame()
    incomplete = "drop" if contains_target else "raise"
    friedman, why_f = _guarded("friedman", n, lambda: friedman_tests(counts, incomplete=incomplete))
    wilcoxon, why_w = _guarded(
        "wilcoxon", n, lambda: {factor: wilcoxon_posthoc(counts, factor) for factor in ("location", "method")}
    )
    if why_f and why_w and n < min(MIN_PARTICIPANTS["friedman"], MIN_PARTICIPANTS["wilcoxon"]):
        # One cause for both: say it once.
        why_f = why_w = f"Friedman and Wilcoxon tests need at least 2 participants, got {n}"
        if contains_target:
            left = (
                f"only {_participants(n)} with a target-containing trial"
                if n
                else "no participant has a target-containing trial"
            )
            why_f = why_w = f"{left}; Friedman and Wilcoxon tests need at least 2"
    elif contains_target and why_w and "with every level" in why_w:
        why_w = _why_no_complete_cells(counts, n)
    return Study2Counts(participants, counts, cell_means, friedman, wilcoxon or {}, excluded, why_f, why_w)


@fill_doc
def analyze(trials: pd.DataFrame, *, layout: ArrayLayout | None = None, alpha: float = 0.05) -> AnalysisResult:
    """Analyse both studies of a trials table (docs/file-formats.md, report.json).

    Training rows are left out. Per study, participants missing a condition are excluded
    and reported; a study without usable data is reported as unavailable while the other
    is still analysed. With too few participants for a statistic (see
    :data:`MIN_PARTICIPANTS`; one participant is enough for the descriptive results),
    that statistic is left out with its reason in the study's ``unavailable`` and the
    rest is still computed.

    Parameters
    ----------
    trials : DataFrame
        Output of :func:`~vibrofocus.analysis.load_trials` (its ``attrs["exclusions"]``
        are carried into the result).
    %(layout_default)s
    alpha : float
        Significance level for flags and sentences.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    ValidationError
        If neither study has usable data (not even for descriptive results).
    """
    if not isinstance(trials, pd.DataFrame) or "selection" not in trials.columns:
        raise ValidationError("analyze() takes the table returned by load_trials(path)")
    layout = ArrayLayout.reference() if layout is None else layout
    exclusions: list[dict] = list(trials.attrs.get("exclusions", []))
    warnings: list[str] = []
    unavailable: dict[str, str] = {}
    results: dict[int, object] = {}
    for study in (1, 2):
        complete, excl, warn = check_design(trials, study)
        exclusions += excl
        warnings += warn
        in_file = (trials["study"] == study).any()
        if complete.empty:
            if not in_file:
                reason = f"study {study}: the trials file has no rows for this study"
            elif not ((trials["study"] == study) & (trials["phase"] == "main")).any():
                reason = f"study {study}: only training trials; no main-phase trials to analyse"
            else:
                reason = f"study {study}: no participant completed every condition"
            unavailable[f"study{study}"] = reason
            continue
        reason = _usable(complete, study)
        if reason is not None:
            unavailable[f"study{study}"] = reason
            continue
        n = complete["participant"].nunique()
        if 1 < n < _FEW_PARTICIPANTS:
            warnings.append(
                f"study {study}: only {n} participants; the tests have little power and their "
                "large-sample approximations (Mauchly, Friedman chi-square) are rough"
            )
        if study == 1:
            results[1] = _analyze_study1(complete, layout)
        else:
            methods, locations = _study_levels(complete)
            results[2] = Study2Result(
                participants=sorted(map(str, complete["participant"].unique())),
                methods=methods,
                locations=locations,
                all_trials=_study2_part(complete, False),
                contains_target=_study2_part(complete, True),
            )
    if not results:
        raise ValidationError("no usable data in either study: " + "; ".join(unavailable.values()))
    represented = trials.attrs.get("xrun_represented")
    if represented:
        warnings.append(f"{represented} answered trial(s) were presented again because the audio stream lost "
                        "samples (an xrun) during their stimulus; each answer is to the trial's last presentation")
    excl_df = pd.DataFrame.from_records(exclusions, columns=["participant", "study", "reason"])
    excl_df["study"] = excl_df["study"].astype("Int64")  # <NA>: excluded from the whole file
    return AnalysisResult(
        source=str(trials.attrs.get("source", "<DataFrame>")),
        n_trials=len(trials),
        study1=results.get(1),
        study2=results.get(2),
        exclusions=excl_df,
        warnings=warnings,
        unavailable=unavailable,
        alpha=alpha,
        layout=layout,
        simulated_participants=list(trials.attrs.get("simulated_participants", [])),
        stimulus_levels=stimulus_levels(trials),
        simulated_models=list(trials.attrs.get("simulated_models", [])),
        xrun_represented=represented,
    )
