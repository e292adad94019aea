"""``vibrofocus simulate-study``: simulated participants through both studies."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import SEED_MAX, force_option, lsl_option, lsl_source, lsl_source_id_option, lsl_wait_option
from ._command import command


@command("simulate-study")
def simulate_study(
    participants: int | None = typer.Option(
        None, "--participants", "-n", min=1, max=1000, show_default=False,
        help="Number of simulated participants (sim-001 ...); default 3 for a new database, and for an existing "
             "one the number it holds (a larger number adds participants, and says so)."),
    seed: int = typer.Option(0, "--seed", min=0, max=SEED_MAX,
                             help="Seed of the whole simulation (participants, trial orders, answers)."),
    db: Path = typer.Option(..., "--db", help="Study database (SQLite); an unfinished one is resumed."),
    pace: float | None = typer.Option(None, "--pace", min=0.0, max=60.0, show_default=False,
                                      help="Wait this long after each answer, s (default the protocol's pacing: 0 "
                                           "for the paper's studies)."),
    trials_csv: Path | None = typer.Option(
        None, "--trials-csv", help="Also write the trials file here (never over the database or a calibration)."
    ),
    calibration_dir: Path | None = typer.Option(
        None, "--calibration-dir", help="Where calibration files go (default: <db stem>-files/calibrations/ beside the database)."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    force: bool = force_option(),
    skin: str = typer.Option("nominal", "--skin",
                             help="Skin preset of the simulated forearms: nominal (the skin the perceptual model "
                                  "was fitted on) | low | high | voigt-fit."),
    lsl: bool = lsl_option(),
    lsl_source_id: str | None = lsl_source_id_option(),
    lsl_wait: float = lsl_wait_option(),
    methods: str | None = typer.Option(
        None, "--methods",
        help="Rendering methods the studies compare, comma separated: any registered ones, such as minimax "
             "(default the paper's funneling, inverse, combination).",
    ),
    hypothesis: str | None = typer.Option(
        None, "--hypothesis",
        help="How the simulated participants read the felt field: v3-centroid (the energy centroid of the whole "
             "felt field) | grid-peak (where it felt most intense inside the grid area) | level-reliability (weak "
             "taps localized less reliably). Default: the hypothesis whose fit holds best on held-out seeds; see "
             "docs/simulated-participants.md, Hypotheses. Stored with each session.",
    ),
    levels: str | None = typer.Option(
        None, "--levels", show_default=False,
        help="Level rule of the stimuli (default paper): paper (funneling by eq. 3 at A = 10 V, the inverse filter asking 2 um, the "
             "combination funneling's displacement, each scaled down only over 10 V) | equal-peak (every method at "
             "10 V). Stored with each session; a resumed database keeps its own.",
    ),
    protocol: Path | None = typer.Option(
        None, "--protocol",
        help="A study protocol file (TOML; docs/protocols.md): each participant runs its blocks in order, and its "
             "name is stored with each session and exported. Default: the paper's Study 1 and Study 2 "
             "(paper-study1, paper-study2). Not with --methods or --levels (the file names them).",
    ),
) -> None:
    """Calibrate N simulated participants and run Study 1 and Study 2 with each.

    Answers come from a documented perceptual MODEL of the simulated skin field, not from
    people. Running the same command again on an unfinished database resumes it: the same
    participants and plans, from the first unanswered trial.
    """
    with user_errors():
        from rich.console import Console

        from .._atomic import allow_overwrite
        from .. import workflows

        allow_overwrite(force)
        source_id = lsl_source(lsl, lsl_source_id, db)  # a bad id: one error line before anything is created
        with SimulationProgress(Console(stderr=True), quiet=quiet, skin=skin) as shown:
            workflows.simulate_study(db, participants=participants, seed=seed, pace_s=pace, trials_csv=trials_csv,
                calibration_dir=calibration_dir, skin=skin, methods=methods, hypothesis=hypothesis, levels=levels,
                protocol=protocol, lsl_source_id=source_id, lsl_wait_s=lsl_wait, progress=shown)


class SimulationProgress:
    """The simulation workflow's :class:`~vibrofocus.workflows.Progress` at the terminal: its
    lines on stderr, a bar of the trials, and the summary tables on stdout."""

    def __init__(self, console, *, quiet: bool, skin: str):
        self.console, self.quiet, self.skin = console, quiet, skin
        self.bar = self.task = None

    def __enter__(self) -> "SimulationProgress":
        return self

    def __exit__(self, *exc) -> None:
        self._close()

    def _close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None

    def step(self, done: int, total: int, message: str) -> None:
        if self.bar is None:
            from ._progress import progress_bar

            self.bar = progress_bar(self.console, disable=self.quiet)
            self.bar.start()
            self.task = self.bar.add_task("trials", total=None)
        self.bar.update(self.task, description=message, completed=done, total=total)

    def note(self, message: str, **details) -> None:
        if details.get("plain"):
            typer.echo(message, err=True)
        elif details.get("notice"):
            self.console.print(f"[yellow]{message}[/]")
        elif "summary" in details:
            self._close()
            self._tables(details["summary"], details["levels"], details["hypothesis"])
        else:
            self.console.print(message, markup=False)

    def _tables(self, summary, levels, chosen_h) -> None:
        from rich.console import Console
        from rich.table import Table

        from ._levels import levels_table

        table = Table(title=f"Simulated participants on the {self.skin} skin ({chosen_h.label()}): main trials")
        for col in ("study", "method", "trials", "mean error (mm)", "correct (%)", "locations selected"):
            table.add_column(col, justify="right" if col != "method" else "left")
        for row in summary:
            table.add_row(
                str(row["study"]), row["method"], str(row["n"]), f"{row['mean_error_mm']:.1f}",
                f"{100 * row['correct']:.0f}", f"{row['mean_n_selected']:.2f}",
            )
        Console().print(table)
        if levels is not None:
            Console().print(levels_table(levels, title="Stimuli played (main trials, median over participants)"))

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False
