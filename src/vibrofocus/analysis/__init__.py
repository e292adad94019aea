"""Statistics, figures and reports of the localization studies (docs/file-formats.md, report.json).

Typical use in a notebook::

    from vibrofocus.analysis import load_trials, analyze, write_report

    trials = load_trials("trials.csv")
    result = analyze(trials)
    result.study1.anova            # two-way RM-ANOVA (location × method), GG-corrected
    result.study2.all_trials.friedman
    write_report(result, "report/")   # report.json, PNG figures, report.html

Each step is also available on its own (:func:`study1_errors`, :func:`study1_anova`,
:func:`study2_counts`, :func:`friedman_tests`, ...), returning pandas DataFrames.
"""

from .figures import method_colors, plot_counts, plot_errors, plot_localization, save_figure
from .pipeline import AnalysisResult, Study1Result, Study2Counts, Study2Result, analyze
from .levels import stimulus_levels
from .report import format_p, report_dict, report_trials_file, results_sentences, write_report
from .study1 import (
    localization_summary,
    perceived_positions,
    point_errors,
    shapiro_tests,
    study1_anova,
    study1_errors,
    study1_posthoc,
)
from .study2 import friedman_tests, study2_counts, wilcoxon_posthoc
from .trials import REQUIRED_COLUMNS, check_design, load_trials, main_trials, method_order, trial_problems

__all__ = [
    "stimulus_levels",
    "REQUIRED_COLUMNS",
    "load_trials",
    "trial_problems",
    "check_design",
    "main_trials",
    "method_order",
    "perceived_positions",
    "point_errors",
    "localization_summary",
    "study1_errors",
    "shapiro_tests",
    "study1_anova",
    "study1_posthoc",
    "study2_counts",
    "friedman_tests",
    "wilcoxon_posthoc",
    "analyze",
    "AnalysisResult",
    "Study1Result",
    "Study2Result",
    "Study2Counts",
    "report_dict",
    "results_sentences",
    "format_p",
    "write_report",
    "report_trials_file",
    "plot_localization",
    "plot_errors",
    "plot_counts",
    "save_figure",
    "method_colors",
]
