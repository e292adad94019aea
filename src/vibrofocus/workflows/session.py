"""Plan a session and run it: the steps every front-end shares (docs/method.md, "Studies").

:func:`plan_session` renders every stimulus before the trial list is stored, so a design
that cannot fit the participant is refused when the session is planned, never mid-study;
:func:`run_session` runs the one study loop (:meth:`~vibrofocus.studies.StudyEngine.run`)
with the front-end's responder. :func:`run_study_at_terminal` is ``vibrofocus study run``:
a real participant's next session, planned or resumed, answered at the keypad.
"""

from __future__ import annotations

import contextlib
import secrets
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ContextManager

from .progress import Progress, QuietProgress

__all__ = ["plan_session", "run_session", "first_unfinished_block", "run_study_at_terminal"]


def plan_session(
    store: Any,
    participant_id: str,
    study: int,
    *,
    seed: int,
    calibration_id: int | None = None,
    config: Mapping[str, Any] | None = None,
    renderer: Any = None,
    rig: Any = None,
    reuse: str | None = None,
    store_lock: ContextManager | None = None,
) -> tuple[int, bool]:
    """Render every stimulus of a session's design, then store the session and its trial list.

    Parameters
    ----------
    store : StudyStore
        The study database.
    participant_id : str
        A registered participant.
    study : {1, 2}
        The study.
    seed : int
        Seed of the trial order.
    calibration_id : int, optional
        The registered calibration the stimuli are rendered from (None: a dry run).
    config : mapping, optional
        The session's settings (:meth:`~vibrofocus.studies.StudyStore.create_session`).
    renderer : CalibrationRenderer, optional
        Renders the stimuli; its ``prepare`` runs first (None: nothing to render, as
        for a dry run or a session resumed with its own design).
    rig : Rig, optional
        The rig whose limits the stimuli must meet.
    reuse : {None, "open", "latest"}
        None: always a new session (the web app plans sessions side by side);
        otherwise :meth:`~vibrofocus.studies.StudyStore.open_session`'s rule.
    store_lock : context manager, optional
        Held around the store's call (the web app's database lock), not the rendering.

    Returns
    -------
    (int, bool)
        The session id, and whether it was created now.
    """
    from ..studies.protocol import StudyDesign

    if renderer is not None:
        design = StudyDesign.from_config(study, dict(config or {}))
        renderer.prepare(design.methods, design.locations, **({} if rig is None else {"rig": rig}))
    with store_lock if store_lock is not None else contextlib.nullcontext():
        if reuse is None:
            return store.create_session(participant_id, study, seed=seed, calibration_id=calibration_id,
                                        config=config), True
        return store.open_session(participant_id, study, seed=seed, calibration_id=calibration_id, config=config,
                                  reuse=reuse)


def run_session(engine: Any, responder: Any, *, pace_s: float = 0.0, progress: Progress | None = None) -> Any:
    """Run a session's remaining trials through the one study loop.

    Parameters
    ----------
    engine : StudyEngine
        The session's engine (the front-end builds it: its cue, dry run, who cues).
    responder : Responder
        Who answers: the keypad, the web page, a simulated participant.
    pace_s : float
        Wait after each answer, s.
    progress : Progress, optional
        One step per committed answer.

    Returns
    -------
    RunSummary
        :meth:`~vibrofocus.studies.StudyEngine.run`'s summary.
    """
    if progress is None:
        return engine.run(responder, pace_s=pace_s)
    total = engine.store.session(engine.session_id).n_trials

    def answered(trial: Any, receipt: Any) -> None:
        progress.step(trial.trial_index + 1, total, f"trial {trial.trial_index + 1}")

    return engine.run(responder, pace_s=pace_s, progress=answered)


def first_unfinished_block(db: Path | Any, participant_id: str, protocol: Any) -> int:
    """The index of the participant's first unfinished block of a protocol (read only).

    A block is finished when its latest session of ``protocol`` is; the terminal's
    ``study run`` and the web app's planning both pick blocks by this rule.

    Parameters
    ----------
    db : Path or StudyStore
        The study database (a missing file: no block is finished), or an open store.
    participant_id : str
        The participant.
    protocol : StudyProtocol
        The protocol whose blocks run in order.

    Returns
    -------
    int

    Raises
    ------
    StudyError
        Every block is finished.
    """
    from ..errors import StudyError
    from ..studies import StudyStore

    if not isinstance(db, (str, os.PathLike)):
        done = _finished_blocks(db, participant_id, protocol.name)
    elif Path(db).is_file():
        with StudyStore(db, create=False) as store:
            done = _finished_blocks(store, participant_id, protocol.name)
    else:
        done = set()
    todo = [b.index for b in protocol.blocks if b.index not in done]
    if not todo:
        where = f" in {db}" if isinstance(db, (str, os.PathLike)) else ""
        raise StudyError(f"{participant_id} has finished every block of the protocol {protocol.name!r}{where}")
    return todo[0]


def _finished_blocks(store: Any, participant_id: str, protocol_name: str) -> set[int]:
    from ..studies.storage import session_protocol

    done: set[int] = set()
    if not any(p.participant_id == participant_id for p in store.participants()):
        return done
    for s in store.sessions(participant_id):
        name, b = session_protocol(s.study, s.config)
        if name == protocol_name and s.finished:
            done.add(b)
        elif name == protocol_name:
            done.discard(b)
    return done


def run_study_at_terminal(
    participant: str,
    *,
    db: Path,
    calibration: Path,
    rig: str,
    rig_config: Path | None,
    study: int | None,
    seed: int | None,
    levels: str,
    protocol: Path | None,
    cue: Callable[[Any], Any],
    responder: Callable[[int], Any],
    lsl: bool = False,
    lsl_source: Callable[[int], str | None] = lambda study: None,
    lsl_wait_s: float = 0.0,
    progress: Progress | None = None,
) -> Any:
    """Plan (or resume) a real participant's session and run it with the front-end's responder.

    Parameters
    ----------
    participant : str
        The participant's id.
    db : Path
        The study database (created if missing).
    calibration : Path
        The participant's calibration file.
    rig : str
        The rig kind (:func:`~vibrofocus.rigs.make_rig`).
    rig_config : Path, optional
        The hardware rig's config file.
    study : {1, 2}, optional
        The paper's study (not with ``protocol``).
    seed : int, optional
        Seed of a new session's trial order (default random, stored).
    levels : str
        Level rule of a new session (a resumed session keeps its own).
    protocol : Path, optional
        A protocol file: its first unfinished block runs.
    cue : callable
        ``cue(rig)`` returns the cue before each stimulus (None: no cue).
    responder : callable
        ``responder(n_trials)`` returns who answers.
    lsl : bool
        Send LSL markers.
    lsl_source : callable
        ``lsl_source(study)`` returns the LSL source id (checked before the rig is made).
    lsl_wait_s : float
        Wait up to this long for an LSL consumer, s.
    progress : Progress, optional
        Notes: the LSL outlet, a new or resumed session.

    Returns
    -------
    RunSummary

    Raises
    ------
    KeyboardInterrupt
        After pausing the session (every answer so far is saved).
    StudyError
        Nobody answers (the session is paused), or a bad protocol, study, calibration.
    """
    from .._validation import shorten
    from ..calibration import load_calibration
    from ..errors import StudyError
    from ..rigs import make_rig
    from ..studies import StudyStore
    from ..studies.engine import StudyEngine, calibration_renderer
    from ..studies.markers import lsl_markers
    from ..studies.protocol import StudyDesign
    from ..studies.storage import session_protocol
    from ..studies.terminal import InputEnded

    progress = progress if progress is not None else QuietProgress()
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
    source_id = lsl_source(study)  # a bad id: refused before the rig is made
    cal = load_calibration(calibration)
    if getattr(cal, "participant_id", participant) != participant:
        raise StudyError(
            f"calibration {calibration} belongs to participant {cal.participant_id!r}, not {shorten(participant)}"
        )
    block_index = 0
    threshold_db = None
    if the_protocol is not None:
        # The participant's first unfinished block (read before anything is written).
        block_index = first_unfinished_block(db, participant, the_protocol)
        study = the_protocol.blocks[block_index].study
        assert study is not None
        # Every stimulus of the block rendered and its level checked before anything is written.
        from ..studies.engine import check_drive_levels

        if the_protocol.blocks[block_index].level_unit == "dB SL":  # on the threshold block's result
            with StudyStore(db, create=False) as store:
                threshold_db = the_protocol.participant_threshold(store, participant, block_index)
        design0 = the_protocol.design(block_index, threshold_db)
        check_drive_levels(calibration_renderer(cal, levels=design0.levels), design0,
                           where=the_protocol.level_where(block_index))
    # The rig first: a rig that cannot be made (no config, no device) leaves the
    # database as it was, with no participant or session planned for nothing.
    the_rig = make_rig(rig, config=rig_config, layout=cal.layout)
    with lsl_markers(lsl, source_id=source_id, wait_s=lsl_wait_s) as outlet, the_rig, StudyStore(db) as store:
        if outlet is not None:
            progress.note(f"LSL markers: outlet vibrofocus-markers (type Markers, source id {outlet.source_id})")
        store.add_participant(participant, simulated=False)
        cid = store.add_calibration(participant, calibration)
        config: dict = {"rig": rig, "levels": levels}
        if the_protocol is not None:
            config = {"rig": rig, **the_protocol.session_config(block_index, threshold_db)}
        design = StudyDesign.from_config(study, config)
        renderer = None
        mine = (the_protocol.name if the_protocol is not None else f"paper-study{study}", block_index)
        if not any(not s.finished for s in store.sessions(participant, study=study)
                   if session_protocol(s.study, s.config) == mine):
            # A new session: every stimulus is rendered before it is planned, so one
            # that cannot fit this calibration is refused now, never mid-study.
            renderer = calibration_renderer(cal, levels=design.levels)
        # Check and create in one transaction: two `study run`s at once get one session.
        sid, created = plan_session(
            store, participant, study, seed=secrets.randbelow(2**31) if seed is None else seed,
            calibration_id=cid, config=config, renderer=renderer, rig=the_rig, reuse="open",
        )
        info = store.session(sid)
        if not created:
            renderer = None  # the session's own level rule, from its stored design
            if info.calibration_id != cid:
                raise StudyError(
                    f"session {info.session_id} of {participant} (study {study}) was started with calibration "
                    f"{info.calibration_id} ({store.calibration(info.calibration_id).path}); resume it with that file"
                )
            progress.note(f"resuming session {sid}: {info.n_answered} of {info.n_trials} trials answered")
        else:
            progress.note(f"new session {sid} for {participant}, study {study} ({design.levels} levels)"
                          + ("" if the_protocol is None else
                             f", protocol {the_protocol.name} block {block_index + 1} of {len(the_protocol.blocks)}"))
        engine = StudyEngine(store, sid, the_rig, cal, cue=cue(the_rig), renderer=renderer)
        try:
            summary = run_session(engine, responder(store.session(sid).n_trials),
                                  pace_s=float(info.config.get("pace_s", 0.0) or 0.0))
        except KeyboardInterrupt:
            store.set_status(sid, "paused")
            raise
        except InputEnded as exc:
            # Nobody is answering (stdin closed or redirected): pause, never abort.
            progress.note("", input_ended=True)  # end the prompt's line
            store.set_status(sid, "paused")
            info = store.session(sid)
            raise StudyError(f"{exc}: session {sid} is paused with {info.n_answered} of {info.n_trials} trials "
                             "answered; run the same command at a terminal to resume") from None
        progress.note(f"session {sid}: {summary.status}, {summary.n_answered} of {summary.n_trials} trials answered")
        return summary
