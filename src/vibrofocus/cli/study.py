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
    trial); session, session_status, dry_run (its session); onset_host_s,
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
        import secrets

        from rich.console import Console

        from ..calibration import load_calibration
        from ..errors import StudyError
        from ..rigs import make_rig
        from ..studies import StudyStore
        from ..studies.engine import StudyEngine, calibration_renderer, headphone_beep, terminal_beep
        from ..studies.protocol import StudyDesign
        from ..studies.markers import lsl_markers
        from ..studies.terminal import InputEnded, TerminalResponder
        from .._validation import shorten

        console = Console()
        the_protocol = None
        if protocol is not None:  # a bad file: one error line before anything is made or written
            from .._atomic import protect
            from ..studies.protocol_files import load_protocol

            if study is not None or levels != "paper":
                raise StudyError("--protocol names the study and levels of its blocks: leave out --study and --levels")
            the_protocol = load_protocol(protocol)
            the_protocol.check_runnable()
            for b in the_protocol.blocks:  # the terminal's keypad names locations; a point needs a picture
                if b.response == "point":
                    raise StudyError(f"{the_protocol.where(f'blocks[{b.index}].response')}: point answers are given on "
                                     "the web participant page (vibrofocus serve); the terminal's keypad answers "
                                     "locations only")
            protect(protocol, "protocol file")
            study = the_protocol.blocks[0].study
        elif study is None:
            raise StudyError("give --study 1 or 2 (the paper's studies), or --protocol FILE")
        assert study is not None
        check_rig_options(rig, rig_config)
        source_id = lsl_source(lsl, lsl_source_id, db, study)  # a bad id: refused before the rig is made
        cal = load_calibration(calibration)
        if getattr(cal, "participant_id", participant) != participant:
            raise StudyError(
                f"calibration {calibration} belongs to participant {cal.participant_id!r}, not {shorten(participant)}"
            )
        block_index = 0
        if the_protocol is not None:
            # The participant's first unfinished block (read before anything is written).
            from ..studies.storage import session_protocol

            done: set[int] = set()
            if db.is_file():
                with StudyStore(db, create=False) as store:
                    if any(p.participant_id == participant for p in store.participants()):
                        for s in store.sessions(participant):
                            name, b = session_protocol(s.study, s.config)
                            if name == the_protocol.name and s.finished:
                                done.add(b)
                            elif name == the_protocol.name:
                                done.discard(b)
            todo = [b.index for b in the_protocol.blocks if b.index not in done]
            if not todo:
                raise StudyError(f"{participant} has finished every block of the protocol {the_protocol.name!r} in "
                                 f"{db}")
            block_index = todo[0]
            study = the_protocol.blocks[block_index].study
            assert study is not None
            # Every stimulus of the block rendered and its level checked before anything is written.
            from ..studies.engine import check_drive_levels

            threshold_db = None
            if the_protocol.blocks[block_index].level_unit == "dB SL":  # on the threshold block's result
                with StudyStore(db, create=False) as store:
                    threshold_db = the_protocol.participant_threshold(store, participant, block_index)
            design0 = the_protocol.design(block_index, threshold_db)
            check_drive_levels(calibration_renderer(cal, levels=design0.levels), design0,
                               where=the_protocol.level_where(block_index))
        # The rig first: a rig that cannot be made (no config, no device) leaves the
        # database as it was, with no participant or session planned for nothing.
        the_rig = make_rig(rig, config=rig_config, layout=cal.layout)
        with lsl_markers(lsl, source_id=source_id, wait_s=lsl_wait) as outlet, the_rig, StudyStore(db) as store:
            if outlet is not None:
                console.print(f"LSL markers: outlet vibrofocus-markers (type Markers, source id {outlet.source_id})",
                              markup=False)
            store.add_participant(participant, simulated=False)
            cid = store.add_calibration(participant, calibration)
            config: dict = {"rig": rig, "levels": levels}
            if the_protocol is not None:
                config = {"rig": rig, **the_protocol.session_config(block_index, threshold_db)}
            design = StudyDesign.from_config(study, config)
            renderer = None
            from ..studies.storage import session_protocol

            mine = (the_protocol.name if the_protocol is not None else f"paper-study{study}", block_index)
            if not any(not s.finished for s in store.sessions(participant, study=study)
                       if session_protocol(s.study, s.config) == mine):
                # A new session: every stimulus is rendered before it is planned, so one
                # that cannot fit this calibration is refused now, never mid-study.
                renderer = calibration_renderer(cal, levels=design.levels)
                renderer.prepare(design.methods, design.locations, rig=the_rig)
            # Check and create in one transaction: two `study run`s at once get one session.
            sid, created = store.open_session(
                participant, study, seed=secrets.randbelow(2**31) if seed is None else seed,
                calibration_id=cid, config=config, reuse="open",
            )
            info = store.session(sid)
            if not created:
                renderer = None  # the session's own level rule, from its stored design
                if info.calibration_id != cid:
                    raise StudyError(
                        f"session {info.session_id} of {participant} (study {study}) was started with calibration "
                        f"{info.calibration_id} ({store.calibration(info.calibration_id).path}); resume it with that file"
                    )
                console.print(f"resuming session {sid}: {info.n_answered} of {info.n_trials} trials answered")
            else:
                console.print(f"new session {sid} for {participant}, study {study} ({design.levels} levels)"
                              + ("" if the_protocol is None else
                                 f", protocol {the_protocol.name} block {block_index + 1} of {len(the_protocol.blocks)}"))
            if not beep:
                cue = None
            elif beep_device is not None:
                cue = headphone_beep(beep_device, rig=the_rig)
            else:
                cue = terminal_beep
            engine = StudyEngine(store, sid, the_rig, cal, cue=cue, renderer=renderer)
            responder = TerminalResponder(console=console, n_trials=store.session(sid).n_trials)
            try:
                summary = engine.run(responder, pace_s=float(info.config.get("pace_s", 0.0) or 0.0))
            except KeyboardInterrupt:
                store.set_status(sid, "paused")
                console.print("\ninterrupted: every answer so far is saved; run the same command to resume")
                raise typer.Exit(code=130) from None
            except InputEnded as exc:
                # Nobody is answering (stdin closed or redirected): pause, never abort.
                console.print()  # end the prompt's line
                store.set_status(sid, "paused")
                info = store.session(sid)
                raise StudyError(f"{exc}: session {sid} is paused with {info.n_answered} of {info.n_trials} trials "
                                 "answered; run the same command at a terminal to resume") from None
            console.print(
                f"session {sid}: {summary.status}, {summary.n_answered} of {summary.n_trials} trials answered"
            )
