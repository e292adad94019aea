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
        None, "--calibration-dir", help="Where calibration files go (default: <db>.calibrations/ beside the database)."
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
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
        from rich.table import Table

        from ..studies.markers import lsl_markers
        from ..simulation.participants import MODEL_NOTICE
        from ..simulation.simulate import simulate_studies, summarize_simulation

        from .._atomic import TRIALS_CSV, allow_overwrite, check_writable, output_error, protect
        from ..io.calibration_nc import estimate_calibration_bytes
        from ..layout import ArrayLayout

        allow_overwrite(force)
        from ..studies.protocol import level_options

        the_protocol = None
        if protocol is not None:  # a bad file: one error line before anything is created
            from ..errors import StudyError
            from ..studies.protocol_files import load_protocol

            if methods is not None or levels is not None:
                raise StudyError("--protocol names the methods and levels of its blocks: leave out --methods and "
                                 "--levels")
            the_protocol = load_protocol(protocol)
            the_protocol.check_runnable()
            protect(protocol, "protocol file")
            from ..simulation.simulate import check_protocol_levels

            check_protocol_levels(the_protocol, seed, skin)  # a level over the drive limit: before anything
        if levels is not None:
            level_options(levels, 10.0)  # a bad rule: one error line before anything is created
        from ..simulation.hypotheses import hypothesis as find_hypothesis

        chosen_h = find_hypothesis(hypothesis)  # an unknown name: one error line, nothing created
        chosen = None
        if methods is not None:  # checked now, before anything is created
            from ..studies.protocol import StudyDesign

            chosen = StudyDesign(methods=tuple(m.strip() for m in methods.split(",") if m.strip())).methods
        source_id = lsl_source(lsl, lsl_source_id, db)  # a bad id: one error line before anything is created
        if lsl:  # no pylsl: one error line before anything is created
            from ..io.lsl import import_pylsl

            import_pylsl()
        if trials_csv is not None and not trials_csv.parent.is_dir():
            # Checked first: the simulation takes minutes and the file is written last.
            from ..errors import ValidationError

            raise ValidationError(f"--trials-csv {trials_csv}: the folder {trials_csv.parent} does not exist")
        # Every output place is checked before the first calibration: a read-only folder,
        # a full disk or a trials file named like the database is reported now, not after
        # minutes of simulation (and nothing is created for a refused run).
        check_writable(db, what="study database")
        protect(db, "study database")
        held = 0
        if db.exists():
            from ..simulation.simulate import SIMULATED_PREFIX
            from ..studies import StudyStore

            # A foreign file is refused now; an open store protects the calibrations it lists.
            with StudyStore(db, create=False) as store:
                held = len({s.participant_id for s in store.sessions()
                            if s.participant_id.startswith(SIMULATED_PREFIX) and s.config.get("simulation_seed") is not None})
        if participants is None:
            participants = held or 3
        elif participants > held > 0:
            typer.echo(f"adding simulated participant(s) sim-{held + 1:03d} to sim-{participants:03d}: the database held "
                       f"{held}", err=True)
        if trials_csv is not None:
            check_writable(trials_csv, what="trials file", kind=TRIALS_CSV)
        cal_dir = calibration_dir if calibration_dir is not None else db.with_name(db.name + ".calibrations")
        created = not cal_dir.exists()
        try:
            cal_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise output_error(exc, cal_dir, "calibration folder") from exc
        lay = ArrayLayout.reference()
        try:
            check_writable(cal_dir / "calibration.nc", what="calibration",
                           expected_bytes=participants * estimate_calibration_bytes(lay.n_points, lay.n_actuators,
                                                                                    8, 30_000, 4096))
        except BaseException:
            if created:
                cal_dir.rmdir()
            raise
        console = Console(stderr=True)
        console.print(f"[yellow]{MODEL_NOTICE} Hypothesis: {chosen_h.label()}.[/]")
        if the_protocol is not None:
            console.print(f"protocol {the_protocol.name} ({len(the_protocol.blocks)} block(s)) from {protocol}",
                          markup=False)
        if source_id is not None:
            console.print(f"LSL markers: outlet vibrofocus-markers (type Markers, source id {source_id})", markup=False)
        with lsl_markers(lsl, source_id=source_id, wait_s=lsl_wait), Progress(
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            console=console, disable=quiet, transient=False,
        ) as bar:
            task = bar.add_task("trials", total=None)

            def progress(what: str, done: int, total: int) -> None:
                bar.update(task, description=what, completed=done, total=total)

            result = simulate_studies(
                db, n_participants=participants, seed=seed, pace_s=pace,
                calibration_dir=calibration_dir, progress=progress, skin=skin, methods=chosen, levels=levels,
                hypothesis=chosen_h.name, protocol=the_protocol,
            )
        summary = summarize_simulation(db)
        table = Table(title=f"Simulated participants on the {skin} skin ({chosen_h.label()}): main trials")
        for col in ("study", "method", "trials", "mean error (mm)", "correct (%)", "locations selected"):
            table.add_column(col, justify="right" if col != "method" else "left")
        for row in summary:
            table.add_row(
                str(row["study"]), row["method"], str(row["n"]), f"{row['mean_error_mm']:.1f}",
                f"{100 * row['correct']:.0f}", f"{row['mean_n_selected']:.2f}",
            )
        Console().print(table)
        import pandas as pd

        from ..analysis.levels import stimulus_levels
        from ..studies import StudyStore
        from ._levels import levels_table

        with StudyStore(db) as store:
            levels = stimulus_levels(pd.DataFrame(store.trial_rows()))
        if levels is not None:
            Console().print(levels_table(levels, title="Stimuli played (main trials, median over participants)"))
        held_now = result["n_participants"]
        console.print(
            f"{result['n_answered']} answers stored in {db} ({result['n_new']} new this run) for {held_now} "
            f"simulated participant(s)"
            + (f" ({participants} in this run)." if held_now != participants else ".")
        )
        if trials_csv is not None:
            from ..studies import StudyStore

            with StudyStore(db) as store:
                n = store.export_trials_csv(trials_csv)
            console.print(f"wrote {n} trials to {trials_csv}")
        console.print(f"[yellow]{MODEL_NOTICE} Hypothesis: {chosen_h.label()}.[/]")
