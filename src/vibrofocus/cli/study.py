"""``vibrofocus study``: run a participant from the terminal, export the trials file."""

from __future__ import annotations

from pathlib import Path

import typer

from ._errors import user_errors
from ._options import (RIG_CONFIG_HELP, SEED_MAX, check_rig_options, force_option, lsl_option, lsl_source,
                       lsl_source_id_option, lsl_wait_option)
from ._command import command

study_app = typer.Typer(
    name="study", help="Localization studies: run a participant at the terminal, export trials.",
    no_args_is_help=True,
)
#: Sub-apps this module adds to the root app (registered by :mod:`.commands`).
SUB_APPS = {"study": study_app}


@study_app.command("export")
def export(
    db: Path = typer.Option(..., "--db", help="Study database."),
    out: Path = typer.Option(..., "--out", help="Trials CSV to write (columns above; docs/file-formats.md, trials file)."),
    participant: str | None = typer.Option(None, "--participant", help="Only this participant."),
    force: bool = force_option(),
) -> None:
    """Write every answered trial as a trials CSV, one row per answer.

    Columns: participant, study, phase, trial, method, target, response, rt_s (the
    trial); session, session_status, dry_run, rig (its session); onset_host_s,
    onset_device_s, onset_clock (the stimulus onset); and simulated, last, when some
    participant is simulated. For a BIDS dataset use: vibrofocus export DB --bids DIR.
    """
    with user_errors():
        from .._atomic import allow_overwrite
        from ..errors import StudyError
        from ..studies import StudyStore

        allow_overwrite(force)
        if not db.is_file():
            raise StudyError(f"no study database at {db}")
        with StudyStore(db, create=False) as store:
            n = store.export_trials_csv(out, participant_id=participant)
        typer.echo(f"wrote {n} trials to {out}")


@study_app.command("run")
def run(
    participant: str = typer.Option(..., "--participant", help="Participant id (letters, digits, _ . -)."),
    study: int | None = typer.Option(None, "--study", min=1, max=2, show_default=False,
                                     help="1: one location per trial; 2: several (the paper's; not with --protocol)."),
    db: Path = typer.Option(..., "--db", help="Study database; an unfinished session of this participant and study is resumed."),
    calibration: Path = typer.Option(..., "--calibration", help="The participant's calibration file (netCDF)."),
    rig: str = typer.Option("simulated", "--rig", help="simulated | audio | nidaq"),
    rig_config: Path | None = typer.Option(None, "--rig-config", help=RIG_CONFIG_HELP),
    seed: int | None = typer.Option(None, "--seed", min=0, max=SEED_MAX,
                                    help="Seed of the trial order (default: random, stored)."),
    beep: bool = typer.Option(True, "--beep/--no-beep", help="Cue before each stimulus (the terminal bell unless --beep-device)."),
    beep_device: str | None = typer.Option(
        None, "--beep-device",
        help="Play the cue as a tone on this audio output (the participant's headphones; see `vibrofocus devices`). "
        "The rig's own actuator interface is refused.",
    ),
    lsl: bool = lsl_option(),
    lsl_source_id: str | None = lsl_source_id_option(),
    lsl_wait: float = lsl_wait_option(),
    levels: str = typer.Option(
        "paper", "--levels",
        help="Level rule of a new session's stimuli: paper (funneling by eq. 3 at A = the drive limit, the inverse "
        "filter asking 2 um, the combination funneling's displacement, each scaled down only over the limit) | "
        "equal-peak (every method at the drive limit). A resumed session keeps its own.",
    ),
    protocol: Path | None = typer.Option(
        None, "--protocol",
        help="A study protocol file (TOML; docs/protocols.md) in place of --study: runs the participant's first "
             "unfinished block of it (one session per block; run again for the next). Its name is stored with the "
             "session and exported. Not with --study or --levels.",
    ),
) -> None:
    """Run a real participant: each trial beeps, plays the stimulus, then waits for the
    answer on the keypad — digits then Enter (Study 2: several digits, e.g. ``45``);
    ``p`` then Enter pauses, ``q`` then Enter aborts. Each answer is committed to the
    database before the next trial; running the command again resumes."""
    with user_errors():
        from rich.console import Console

        from ..studies.engine import headphone_beep, terminal_beep
        from ..studies.terminal import TerminalResponder
        from ..workflows import run_study_at_terminal

        console = Console()
        check_rig_options(rig, rig_config)

        def cue(the_rig):
            if not beep:
                return None
            return headphone_beep(beep_device, rig=the_rig) if beep_device is not None else terminal_beep

        try:
            run_study_at_terminal(
                participant, db=db, calibration=calibration, rig=rig, rig_config=rig_config, study=study, seed=seed,
                levels=levels, protocol=protocol, cue=cue,
                responder=lambda n_trials: TerminalResponder(console=console, n_trials=n_trials),
                lsl=lsl, lsl_source=lambda s: lsl_source(lsl, lsl_source_id, db, s), lsl_wait_s=lsl_wait,
                progress=_Lines(console))
        except KeyboardInterrupt:
            console.print("\ninterrupted: every answer so far is saved; run the same command to resume")
            raise typer.Exit(code=130) from None


class _Lines:
    """The session workflow's :class:`~vibrofocus.workflows.Progress` at the terminal: its lines."""

    def __init__(self, console):
        self.console = console

    def step(self, done: int, total: int, message: str) -> None:
        pass

    def note(self, message: str, **details) -> None:
        if details.get("input_ended"):
            self.console.print()  # end the prompt's line
        elif message.startswith("LSL markers"):
            self.console.print(message, markup=False)
        else:
            self.console.print(message)

    def judged(self, result) -> None:
        pass

    def cancelled(self) -> bool:
        return False
