"""``vibrofocus analyze``: statistics, figures and reports from a trials file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from ._errors import user_errors
from ._command import command

#: ``analyze --fix``: a hypothesis fitted with part of its freedom switched off.
FIX_HELP = ("With --hypotheses: fit hypothesis NAME with these free parameters fixed at its own fitted values, e.g. "
            "intensity:sl_ref_db,funneling_exponent,bias_mean_m[1],bias_sd_m to fit it alike level-reliability "
            "(repeatable; docs: fitting hypotheses, \"Why: intensity's freedom, switched off\").")

console = Console()


def _p(p: float) -> str:
    """A p-value for a table cell: ``< 0.0001`` or ``0.012``."""
    from ..analysis.report import format_p

    return format_p(p).removeprefix("p = ").removeprefix("p ")


def _point_errors(trials: Path, *, keep_aborted: bool, keep_dry_runs: bool, kind: str):
    """Mean error of point answers per method, mm, of a trials CSV with the point columns (None without them).

    The rows the analysis leaves out (other kinds of participant, aborted sessions, dry runs)
    are left out here too.
    """
    import pandas as pd

    from ..analysis import point_errors
    from ..analysis.trials import select_kind

    if not trials.is_file():
        return None
    try:
        raw = pd.read_csv(trials, dtype=str, keep_default_na=False, skipinitialspace=True, encoding="utf-8-sig")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
        return None
    if not {"response_x_mm", "response_y_mm"} <= set(raw.columns):
        return None
    raw = select_kind(raw, kind)[0]
    if not keep_aborted and "session_status" in raw.columns:
        raw = raw[raw["session_status"] != "aborted"]
    if not keep_dry_runs and "dry_run" in raw.columns:
        raw = raw[raw["dry_run"] != "1"]
    return point_errors(raw)


@command(
    "analyze",
    epilog=(
        "Example: vibrofocus analyze trials.csv --out report/  "
        "(then open report/report.html). Training rows are never analysed."
    ),
)
def analyze_command(
    trials: Path = typer.Argument(
        ...,
        help="Trials CSV (docs/file-formats.md, trials file): participant, study, phase, trial, method, target, response, rt_s; a BIDS folder written by vibrofocus export --bids; or a study database (SQLite).",
        show_default=False,
    ),
    out: Path = typer.Option(
        ..., "--out", "-o",
        help="Output folder for report.json, report.html and the PNG figures (created; its parent must exist).",
        show_default=False,
    ),
    exclude_invalid: bool = typer.Option(False, "--exclude-invalid", help="Exclude (and report) participants with "
                                                                           "invalid rows instead of refusing the file."),
    keep_aborted: bool = typer.Option(False, "--keep-aborted", help="Analyse the answers of aborted sessions too (left out and listed by default)."),
    keep_dry_runs: bool = typer.Option(False, "--keep-dry-runs", help="Analyse dry-run sessions too (no calibration, nothing played; left out and listed by default)."),
    simulated: bool = typer.Option(False, "--simulated", help="Analyse the simulated participants alone (answers from the perceptual model, not data) instead of the people on hardware."),
    rehearsals: bool = typer.Option(False, "--rehearsals", help="Analyse people's rehearsals on the simulated rig alone (they felt nothing) instead of the people on hardware."),
    alpha: float = typer.Option(0.05, "--alpha", help="Significance level for the results sentences, in (0, 1)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the paths written."),
    hypotheses: bool = typer.Option(
        False, "--hypotheses",
        help="Also fit every registered hypothesis of the simulated participants to the trials by maximum marginal "
             "likelihood, score each by leave-one-participant-out predictive log-likelihood (ELPD) and write "
             "hypotheses.json, its figure and a report section (model output; docs: fitting hypotheses)."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="With --hypotheses: Dask scheduler address (tcp://host:8786) for the folds; default "
                                  "a LocalCluster on this machine."),
    workers: int | None = typer.Option(None, "--workers", min=1, max=256,
                                       help="With --hypotheses: LocalCluster worker processes (default: CPUs)."),
    no_dask: bool = typer.Option(False, "--no-dask", help="With --hypotheses: fit in this process (same numbers)."),
    fix: list[str] = typer.Option([], "--fix", metavar="NAME:KEY[,KEY...]", help=FIX_HELP),
    draws: int = typer.Option(32, "--draws", min=1, max=100_000,
                              help="With --hypotheses: participants drawn from each hypothesis' population to "
                                   "integrate every participant's likelihood over (8 times as many, drawn apart, "
                                   "score the left-out participants)."),
    score_draws: int | None = typer.Option(
        None, "--score-draws", min=1, max=1_000_000,
        help="With --hypotheses: draws that score each left-out participant (default 8 x --draws). More draws cut "
             "the Monte Carlo error of the scores (docs: designing a study, \"How much of that is Monte Carlo "
             "error\"); a design's Study 1 trials cost about 1 ms per draw."),
) -> None:
    """Analyse localization studies 1 and 2 from a trials file.

    Study 1: Euclidean error (mm) per participant and condition; Shapiro-Wilk; two-way RM-ANOVA (location x method) with Mauchly and Greenhouse-Geisser; Bonferroni paired t-tests; localization ellipses.

    Study 2: number of selected locations; Friedman tests for location and method; pairwise Wilcoxon (Bonferroni); the same on trials whose selection contains the target.

    Participants missing a condition are excluded and listed, never dropped silently; so are
    aborted sessions and dry runs of a study database's export (--keep-aborted, --keep-dry-runs).

    One kind of participant per analysis: people on hardware by default; simulated participants with --simulated; people's rehearsals on the simulated rig with --rehearsals. The others are listed as left out.
    """  # noqa: E501
    with user_errors():
        from .._validation import check_in_range
        from ..analysis import report_trials_file
        from ..errors import ValidationError
        from ..simulation.fitting import trials_source

        check_in_range(alpha, "--alpha", 0.0, 1.0, inclusive=False)
        if simulated and rehearsals:
            raise ValidationError("--simulated and --rehearsals are two analyses: run one at a time")
        kind = "simulated" if simulated else "rehearsals" if rehearsals else "people"
        fit = _hypothesis_fit(draws, score_draws, fix, scheduler=scheduler, n_workers=workers,
                              local=no_dask) if hypotheses else None
        result, paths = report_trials_file(trials_source(trials), out, on_invalid="exclude" if exclude_invalid else "raise",
                                           keep_aborted=keep_aborted, keep_dry_runs=keep_dry_runs, alpha=alpha,
                                           hypotheses=fit, kind=kind)

    if quiet:
        for p in paths.values():
            console.print(str(p))
        return
    _print_summary(result, paths, trials, out, keep_aborted=keep_aborted, keep_dry_runs=keep_dry_runs, kind=kind)


def _print_summary(result, paths: dict, trials: Path, out: Path, *, keep_aborted: bool, keep_dry_runs: bool,
                   kind: str) -> None:
    """The analysis at the terminal: exclusions, notes, the studies' tables and the files written."""
    import pandas as pd

    console.print(f"[bold]vibrofocus analyze[/] {trials} ({result.n_trials} rows)")
    if result.simulated_participants:
        from ..analysis.report import _simulated

        console.print(f"[bold yellow]SIMULATED: {_simulated(result)['notice']}[/]")
    for row in result.exclusions.itertuples(index=False):
        where = "all studies" if row.study is None or row.study is pd.NA else f"study {int(row.study)}"
        console.print(f"[yellow]excluded[/] {row.participant} ({where}): {row.reason}")
    for w in result.warnings:
        console.print(f"[yellow]note[/] {w}")
    for reason in result.unavailable.values():
        console.print(f"[bold yellow]{reason}[/]")
    if result.stimulus_levels is not None:
        from ._levels import levels_table

        console.print(levels_table(result.stimulus_levels))
    s1 = result.study1
    if s1 is not None:
        n1 = len(s1.participants)
        if "anova" in s1.unavailable:
            console.print(f"[yellow]Study 1 RM-ANOVA (N = {n1}): not computed: {s1.unavailable['anova']}[/]")
        else:
            table = Table(title=f"Study 1: error (mm), RM-ANOVA, N = {n1}")
            for col in ("effect", "F", "ddof1", "ddof2", "p_unc", "eps", "p_gg", "Mauchly p"):
                table.add_column(col, justify="left" if col == "effect" else "right")
            for r in s1.anova.itertuples(index=False):
                mauchly = "n/a" if r.p_mauchly != r.p_mauchly else f"{r.p_mauchly:.3g}"
                table.add_row(
                    r.effect.replace(" * ", " × "), f"{r.F:.2f}", str(r.ddof1), str(r.ddof2),
                    _p(r.p_unc), f"{r.eps:.3f}", _p(r.p_gg), mauchly,
                )  # fmt: skip
            console.print(table)
        for key, name in (("posthoc", "post hoc t-tests"), ("shapiro", "Shapiro–Wilk")):
            if key in s1.unavailable:
                console.print(f"[yellow]Study 1 {name}: not computed: {s1.unavailable[key]}[/]")
        means = s1.errors.groupby("method")["error_mm"].mean()
        console.print("Study 1 mean error: " + ", ".join(f"{m} {means[m]:.2f} mm" for m in s1.methods))
    points = _point_errors(trials, keep_aborted=keep_aborted, keep_dry_runs=keep_dry_runs, kind=kind)
    if points is not None and len(points):
        console.print("Point answers, mean localization error (point to target): " + ", ".join(
            f"{r.method} {r.mean_error_mm:.2f} mm (n = {r.n})" for r in points.itertuples()))
    s2 = result.study2
    if s2 is not None:
        for label, part in (("all trials", s2.all_trials), ("contains target", s2.contains_target)):
            if part.wilcoxon_unavailable and part.wilcoxon_unavailable != part.unavailable:
                console.print(f"[yellow]Study 2 ({label}) Wilcoxon: not computed: {part.wilcoxon_unavailable}[/]")
            if part.friedman is None:
                console.print(f"[yellow]Study 2 Friedman ({label}): not computed: {part.unavailable}[/]")
                continue
            table = Table(title=f"Study 2: selected locations, Friedman ({label}), N = {len(part.participants)}")
            for col in ("factor", "chi2", "dof", "p", "Kendall W"):
                table.add_column(col, justify="left" if col == "factor" else "right")
            for factor, r in part.friedman.iterrows():
                table.add_row(factor, f"{r['chi2']:.2f}", str(int(r["dof"])), _p(r["p"]), f"{r['kendall_w']:.2f}")
            console.print(table)
    if "hypotheses_json" in paths:
        _print_hypotheses(paths["hypotheses_json"])
    figures = len([k for k in paths if k not in ("json", "html", "hypotheses_json")])
    written = f", {paths['hypotheses_json']}" if "hypotheses_json" in paths else ""
    console.print(f"wrote {paths['json']}, {paths['html']}{written} and {figures} figure(s) in {out}")


def _hypothesis_fit(draws: int, score_draws: int | None, fix: list[str], **cluster: Any) -> Any:
    """The hypotheses' fit of ``--hypotheses`` (``fit_trials`` with its settings), for the report."""
    from functools import partial

    from ..simulation import hypotheses_with_fixed
    from ..simulation.fitting import FitSettings, fit_trials

    return partial(fit_trials, hypotheses=hypotheses_with_fixed(fix) if fix else None,
                   settings=FitSettings(n_draws=draws, score_draws=score_draws), **cluster)


def _print_hypotheses(path: Path) -> None:
    """The hypotheses' fit (model output) from hypotheses.json."""
    import json

    fitted = json.loads(path.read_text(encoding="utf-8"))
    table = Table(title=f"Hypotheses fitted to the trials (MODEL OUTPUT), leave-one-participant-out ELPD, "
                        f"{fitted['elapsed_s']:.0f} s")
    for col in ("hypothesis", "ELPD", "SE", "parameters"):
        table.add_column(col, justify="left" if col in ("hypothesis", "parameters") else "right")
    for name, h in sorted(fitted["hypotheses"].items(), key=lambda kv: -kv[1]["elpd"]):
        params = ", ".join(f"{k} = {v:.4g}" for k, v in h["params"].items()) or "none free"
        table.add_row(name, f"{h['elpd']:.1f}", f"{h['se']:.1f}", params)
    console.print(table)
    if fitted.get("runner_up"):
        console.print(f"best: {fitted['chosen']}, {fitted['difference']:.1f} (SE {fitted['difference_se']:.1f}) "
                      f"above {fitted['runner_up']}")
