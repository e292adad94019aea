"""Whole simulated studies: calibrate simulated participants and run both studies.

Everything is derived from one seed, and everything decided is stored first (the
participant, the calibration file and its hash, the sessions with their plans), so
running again on the same database resumes exactly where a killed run stopped.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .._db_files import calibrations_dir, make_private_dir
from ..defaults import STUDY_METHODS
from ..errors import AnswerRefused, CalibrationFileError, StudyError
from ..studies.protocol import DEFAULT_LEVELS
from ..io.responses import parse_response_text
from .perception import STUDY_SKIN
from ..studies.storage import StudyStore

__all__ = ["participant_seeds", "simulate_studies", "check_protocol_levels", "summarize_simulation", "SIMULATED_PREFIX"]

#: Ids of simulated participants: ``sim-001``, ``sim-002``, ...
SIMULATED_PREFIX = "sim-"

ProgressFn = Callable[[str, int, int], None]


def participant_seeds(seed: int, k: int) -> tuple[int, int, int]:
    """Seeds of simulated participant ``k`` (1-based) of a simulation seeded with ``seed``.

    Parameters
    ----------
    seed : int
        Seed of the simulation.
    k : int
        Participant number, 1-based.

    Returns
    -------
    (participant_seed, study1_seed, study2_seed) : tuple of int
        The participant seed drives the simulated forearm and the perceptual model; the
        study seeds the trial orders. Independent streams of ``numpy.random.SeedSequence``.
    """
    state = np.random.SeedSequence([int(seed), int(k)]).generate_state(3, dtype=np.uint32)
    return int(state[0]), int(state[1]), int(state[2])


def _calibration_for(store: StudyStore, pid: str, rig: Any, cal_dir: Path) -> tuple[int, Any]:
    """The participant's registered calibration, or a new one (file written before it is registered)."""
    from ..calibration import calibrate, load_calibration, save_calibration
    from ..calibration.replacing import reserve_free_name

    for rec in reversed(store.calibrations(pid)):
        try:
            return rec.calibration_id, load_calibration(store.verify_calibration(rec.calibration_id))
        except (StudyError, CalibrationFileError):
            continue  # file gone, changed or unreadable: calibrate again rather than trust it
    cal = calibrate(rig, participant_id=pid)
    cal_dir.mkdir(parents=True, exist_ok=True)
    # Never over a file already there: it may be another database's registered
    # calibration (a shared --calibration-dir). The name is reserved exclusively, so a
    # process simulating at the same time takes another one (sim-001.1.nc).
    final = reserve_free_name(cal_dir / f"{pid}.nc")
    try:
        save_calibration(cal, final, keep_previous=False)  # atomic, over the empty reservation
    except BaseException:
        final.unlink(missing_ok=True)
        raise
    return store.add_calibration(pid, final), cal


def simulate_studies(
    db: str | os.PathLike,
    *,
    n_participants: int,
    seed: int = 0,
    pace_s: float | None = None,
    calibration_dir: str | os.PathLike | None = None,
    studies: tuple[int, ...] = (1, 2),
    config: dict[str, Any] | None = None,
    progress: ProgressFn | None = None,
    skin: str = STUDY_SKIN,
    methods: tuple[str, ...] | None = None,
    levels: str | None = None,
    hypothesis: str | None = None,
    protocol: Any = None,
) -> dict[str, int]:
    """Calibrate ``n_participants`` simulated participants and run the studies into ``db``.

    Parameters
    ----------
    db : path-like
        Study database; created if missing, resumed if it holds an unfinished simulation
        with the same ``seed``.
    n_participants : int
        Participants ``sim-001`` ... ``sim-NNN``.
    seed : int
        Seed of the simulation (see :func:`participant_seeds`).
    pace_s : float, optional
        Wait after each answer, s; default the protocol block's pacing (0 for the paper's).
    calibration_dir : path-like, optional
        Where calibration files are written; default ``<db stem>-files/calibrations`` beside it
        (:func:`vibrofocus._db_files.calibrations_dir`).
    studies : tuple of int
        Which studies to run, in order.
    config : dict, optional
        Extra session config (design keys such as ``repetitions`` or ``levels`` change the
        design; ``levels`` default the paper's, :data:`~vibrofocus.studies.DEFAULT_LEVELS`).
    skin : str
        Skin preset of the participants' forearms (default :data:`STUDY_SKIN`,
        ``nominal``, the skin the perceptual model was fitted on; another preset changes the
        stimuli under a model not fitted to them). Stored in each session's config.
    progress : callable, optional
        ``progress(description, n_answered, n_total)`` after each answer.
    methods : tuple of str, optional
        Registered rendering methods the studies compare (default the paper's funneling,
        inverse and combination); a resumed database must have been started with the same
        (in any order: the stored order is kept).
    levels : {"paper", "equal-peak"}, optional
        The level rule of the stimuli (:func:`~vibrofocus.studies.protocol.level_options`;
        default the paper's, or ``config["levels"]``); a resumed database must have been
        started with the same.
    hypothesis : str, optional
        How the simulated participants read the felt field
        (:mod:`vibrofocus.simulation.hypotheses`; default the default hypothesis, with its fitted parameters), stored with
        each session (name and version); a resumed database must have been started with
        the same.
    protocol : StudyProtocol, optional
        A study protocol (:func:`~vibrofocus.studies.protocol_files.load_protocol`): each
        participant runs its blocks in order, one session each, with the protocol's name
        stored in each session. Default: the paper's two protocols (``studies``, of
        ``paper-study1`` and ``paper-study2``). Not with ``methods`` or ``levels`` (name
        them in the file); a database holds one protocol's sessions (or the paper's).

    Returns
    -------
    dict
        ``n_answered`` (all answers in the simulated sessions of the database),
        ``n_total`` (their planned trials), ``n_new`` (answers added by this call) and
        ``n_participants`` (the simulated participants those sessions belong to, which
        may be more than ``n_participants``).

    Notes
    -----
    The answers come from :class:`SimulatedParticipant`, a perceptual model, not data.
    """
    from ..rigs import make_rig
    from ..skin import skin_preset
    from ..studies.engine import StudyEngine, calibration_renderer, check_drive_levels
    from ..studies.protocol import StudyDesign
    from .participants import SimulatedParticipant

    def renderer_for(parts: dict[str, Any], levels: str) -> Any:
        """The participant's renderer of a level rule (its stimuli rendered once, cached)."""
        if levels not in parts["renderer"]:
            parts["renderer"][levels] = calibration_renderer(parts["cal"][1], levels=levels)
        return parts["renderer"][levels]

    skin = skin_preset(skin).name

    if isinstance(n_participants, bool) or not isinstance(n_participants, (int, np.integer)) or n_participants < 1:
        raise StudyError(f"n_participants must be an integer >= 1, got {n_participants!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise StudyError(f"seed must be a non-negative integer, got {seed!r}")
    if pace_s is not None and (not np.isfinite(pace_s) or pace_s < 0):
        raise StudyError(f"pace must be >= 0 s, got {pace_s!r}")
    if methods is not None:  # checked (registered, each once) by the study design
        from ..studies.protocol import StudyDesign

        methods = StudyDesign(methods=tuple(methods)).methods
        config = {**(config or {}), "methods": list(methods)}
    if levels is not None:
        from ..studies.protocol import level_options

        level_options(levels, 1.0)  # checked: one of the rules
        config = {**(config or {}), "levels": levels}
    from ..studies.storage import session_protocol

    if protocol is not None:
        if methods is not None or levels is not None:
            raise StudyError("a protocol names its blocks' methods and levels: give them in the protocol file, not "
                             "as methods or levels")
        protocol.check_runnable()  # what the engine cannot run yet: refused before anything is written
        # A block in dB SL: its config (level) per participant, from their threshold (below).
        runs = [(b.study, protocol.session_config(b.index, 0.0 if b.level_unit == "dB SL" else None), protocol.name,
                 b.index, b.pacing_s) for b in protocol.blocks]
    else:
        from ..studies.protocol_files import paper_protocol_name, shipped_protocol

        runs = [(study, {}, paper_protocol_name(study), 0, shipped_protocol(paper_protocol_name(study)).blocks[0].pacing_s)
                for study in studies]
    asked_protocols = {run[2] for run in runs}
    asked_methods = tuple((config or {}).get("methods") or STUDY_METHODS)
    asked_levels = str((config or {}).get("levels", DEFAULT_LEVELS))
    from .hypotheses import hypothesis as find_hypothesis

    chosen = find_hypothesis(hypothesis)
    db = Path(db)
    cal_dir = Path(calibration_dir) if calibration_dir is not None else calibrations_dir(db)
    if calibration_dir is None:
        make_private_dir(cal_dir, db)  # 0700, never through a link (docs/security.md)
    with StudyStore(db) as store:
        per_participant = sum(StudyDesign.from_config(run[0], {**(config or {}), **run[1]}).n_trials for run in runs)
        n_new = 0
        answered = 0
        for k in range(1, n_participants + 1):
            pid = f"{SIMULATED_PREFIX}{k:03d}"
            pseed = participant_seeds(seed, k)[0]
            # Session seeds: stream 1 + i of the participant's seed sequence for the i-th
            # block (the paper's Study 1 and Study 2: streams 1 and 2, as before protocols).
            streams = np.random.SeedSequence([int(seed), int(k)]).generate_state(1 + max(2, len(runs)), dtype=np.uint32)
            store.add_participant(pid, simulated=True)
            for info in store.sessions(pid):
                if info.config.get("simulation_seed") != seed:
                    raise StudyError(
                        f"{db} holds participant {pid} from a simulation with seed "
                        f"{info.config.get('simulation_seed')!r}, not {seed}; use that seed or another database"
                    )
                if info.config.get("skin", STUDY_SKIN) != skin:
                    raise StudyError(
                        f"{db} holds participant {pid} simulated on the {info.config.get('skin', STUDY_SKIN)!r} skin, "
                        f"not {skin!r}; use that skin or another database"
                    )
                stored_protocol = session_protocol(info.study, info.config)[0]
                if stored_protocol not in asked_protocols:
                    raise StudyError(
                        f"{db} holds participant {pid} simulated with the protocol {stored_protocol!r}, not "
                        f"{', '.join(sorted(asked_protocols))}; use that protocol or another database"
                    )
                stored = tuple(info.config.get("methods") or STUDY_METHODS)
                if protocol is not None:
                    stored = asked_methods  # each block names its own; compared per block below
                if stored != asked_methods and sorted(stored) == sorted(asked_methods):
                    # The same methods in another order: the same study. The stored order
                    # is kept, so every participant's plan is drawn from the same design.
                    asked_methods = stored
                    config = {**(config or {}), "methods": list(stored)}
                if stored != asked_methods:
                    raise StudyError(
                        f"{db} holds participant {pid} simulated with the methods {', '.join(stored)}, not "
                        f"{', '.join(asked_methods)}; use those methods or another database"
                    )
                if protocol is None and info.design.levels != asked_levels:
                    raise StudyError(
                        f"{db} holds participant {pid} simulated at {info.design.levels!r} levels, not "
                        f"{asked_levels!r}; use those levels or another database"
                    )
                stored_h = info.config.get("hypothesis", "v3-centroid")  # before hypotheses were stored: v3
                stored_v = info.config.get("hypothesis_version", chosen.version)
                if stored_h != chosen.name or stored_v != chosen.version:
                    raise StudyError(
                        f"{db} holds participant {pid} simulated under the hypothesis {stored_h!r} v{stored_v}, not "
                        f"{chosen.name!r} v{chosen.version}; use that hypothesis or another database"
                    )
                # The stored seed wins over the derivation: the participant stays who it was.
                pseed = int(info.config.get("participant_seed", pseed))
            # Built lazily, once per participant and shared by both studies: the rig, the
            # perceptual model (its grid transfer) and the rendered drives per condition.
            shared: dict[str, Any] = {}

            def participant_parts(cid: int | None, _pid: str = pid, _pseed: int = pseed) -> dict[str, Any]:
                if "rig" not in shared:
                    shared["rig"] = make_rig("simulated", seed=_pseed, skin=skin)
                if cid is None:
                    cid, cal = _calibration_for(store, _pid, shared["rig"], cal_dir)
                    shared["cal"] = (cid, cal)
                if shared.get("cal", (None,))[0] != cid:
                    from ..calibration import load_calibration

                    shared["cal"] = (cid, load_calibration(store.verify_calibration(cid)))
                    shared.pop("renderer", None)
                if "renderer" not in shared:
                    shared["renderer"] = {}  # one per level rule (both studies share one normally)
                if "participant" not in shared:
                    shared["participant"] = SimulatedParticipant(shared["rig"], _pseed, hypothesis=chosen)
                return shared

            for run_index, (study, block_config, pname, block_index, block_pace) in enumerate(runs):
                if protocol is not None and protocol.blocks[block_index].level_unit == "dB SL":
                    block_config = protocol.session_config(
                        block_index, protocol.participant_threshold(store, pid, block_index))
                existing = [s for s in store.sessions(pid, study=study)
                            if session_protocol(s.study, s.config) == (pname, block_index)]
                if protocol is not None and existing:
                    planned = StudyDesign.from_config(study, {**(config or {}), **block_config})
                    if existing[-1].design != planned:
                        raise StudyError(
                            f"{db} holds participant {pid}'s block {block_index} of the protocol {pname!r} planned with "
                            f"another design ({existing[-1].design}); use the protocol file it was planned from or "
                            "another database")
                if existing and existing[-1].finished:
                    answered += existing[-1].n_answered
                    continue
                if existing:
                    info = existing[-1]
                    if info.calibration_id is None:
                        raise StudyError(f"session {info.session_id} of {pid} has no calibration to render from")
                    parts = participant_parts(info.calibration_id)
                    sid = info.session_id
                else:
                    parts = participant_parts(shared["cal"][0] if "cal" in shared else None)
                    session_config = dict(config or {})
                    session_config.update(block_config)
                    session_config.update(simulated=True, simulation_seed=int(seed), participant_seed=pseed, skin=skin,
                                          hypothesis=chosen.name, hypothesis_version=chosen.version,
                                          model=chosen.label())
                    # Every stimulus is rendered (and a design that cannot fit this arm, or the
                    # rig's limits, made again or refused) before the session is planned.
                    design = StudyDesign.from_config(study, session_config)
                    if design.point:  # the picture a point is answered on: this arm's layout
                        session_config["layout"] = parts["cal"][1].layout.to_dict()
                    renderer_for(parts, design.levels).prepare(design.methods, design.locations, rig=parts["rig"])
                    check_drive_levels(renderer_for(parts, design.levels), design,
                                       where=None if protocol is None else protocol.level_where(block_index))
                    # Check and create in one transaction: another process simulating into
                    # the same database may have created this session since the check above.
                    stream = int(streams[study if protocol is None else 1 + run_index])
                    sid, created = store.open_session(
                        pid, study, seed=_block_seed(protocol, block_index, stream), calibration_id=parts["cal"][0],
                        config=session_config, reuse="latest",
                    )
                    if not created:
                        info = store.session(sid)
                        if info.finished:
                            answered += info.n_answered
                            continue
                        if info.calibration_id != parts["cal"][0]:
                            parts = participant_parts(info.calibration_id)
                info = store.session(sid)
                answered += info.n_answered
                # Later participants have no sessions yet: each runs the same blocks.
                total_est = per_participant * n_participants
                label = f"{pid} study {study}"

                def on_answer(trial: Any, receipt: Any, _label: str = label, _total: int = total_est) -> None:
                    nonlocal answered, n_new
                    answered += 1
                    n_new += 1
                    if progress is not None:
                        progress(_label, answered, _total)

                if progress is not None:
                    progress(label, answered, total_est)
                engine = StudyEngine(store, sid, parts["rig"], renderer=renderer_for(parts, info.design.levels))
                try:
                    engine.run(parts["participant"], pace_s=block_pace if pace_s is None else pace_s,
                               progress=on_answer)
                except AnswerRefused as exc:
                    if exc.reason not in ("answered", "not_current"):
                        raise
                    # Another process runs this session (its answers came first): stop
                    # rather than answer the participant's trials twice.
                    raise StudyError(
                        f"another process is running session {sid} of {pid} (study {study}) in {db}: a trial this "
                        f"run presented was answered by it meanwhile ({exc}). Every answer is stored once; run the "
                        "command again when the other one has finished"
                    ) from None
        answered = total = 0
        people = set()
        for info in store.sessions():
            if info.config.get("simulation_seed") is not None:
                answered += info.n_answered
                total += info.n_trials
                people.add(info.participant_id)
        return {"n_answered": answered, "n_total": total, "n_new": n_new, "n_participants": len(people)}


def check_protocol_levels(protocol: Any, seed: int, skin: str = STUDY_SKIN) -> None:
    """Refuse, before anything is written, a block level over the drive limit on the first
    simulated participant's arm.

    Only a level above 0 dB re its rule can exceed the limit; for a protocol with one, the
    first participant's arm is calibrated in memory and every stimulus of those blocks
    rendered (``simulate-study`` calls this before it creates anything). A later
    participant's arm needing more is refused by :func:`simulate_studies` when its session
    is planned, before its first trial.

    Parameters
    ----------
    protocol : StudyProtocol
        The protocol to check.
    seed : int
        Seed of the simulation (:func:`participant_seeds`).
    skin : str
        Skin preset of the simulated forearms.

    Raises
    ------
    StudyError
        A block's level needs more than the drive limit, naming the file's line and field.
    """
    # A block in dB SL is checked when it is planned, on the participant's own threshold.
    loud = [b for b in protocol.blocks if b.level_unit == "dB"
            and (b.levels[0] > 0 if b.response != "detection" else (b.max_db or 0.0) > 0)]
    if not loud:
        return
    from ..calibration import calibrate
    from ..rigs import make_rig
    from ..studies.engine import calibration_renderer, check_drive_levels

    with make_rig("simulated", seed=participant_seeds(seed, 1)[0], skin=skin) as rig:
        cal = calibrate(rig, participant_id=f"{SIMULATED_PREFIX}001")
    renderers: dict[str, Any] = {}
    for b in loud:
        design = protocol.design(b.index)
        renderer = renderers.setdefault(design.levels, calibration_renderer(cal, levels=design.levels))
        check_drive_levels(renderer, design, where=protocol.level_where(b.index))


def _block_seed(protocol: Any, index: int, stream: int) -> int:
    """The seed of a session of block ``index``: the block's own seed, else its stream's."""
    return stream if protocol is None else protocol.blocks[index].session_seed(stream)


def summarize_simulation(db: str | os.PathLike) -> list[dict[str, Any]]:
    """Per study and method, over main trials: mean localization error, share correct and
    mean number of selected locations.

    The error of a trial is the distance, mm, from the target to the answered location
    (Study 2: to the centroid of the selected locations), on the reference layout's
    location coordinates stored in each participant's calibration layout (reference
    layout assumed when unavailable).

    Parameters
    ----------
    db : path-like
        Study database.

    Returns
    -------
    list of dict
        One per (study, method).
    """
    from ..layout import ArrayLayout

    locations = ArrayLayout.reference().locations_xy * 1e3
    with StudyStore(db) as store:
        rows = [r for r in store.trial_rows() if r["phase"] == "main"]
    out: list[dict[str, Any]] = []
    keys = sorted({(r["study"], r["method"]) for r in rows})
    for study, method in keys:
        sel = [r for r in rows if r["study"] == study and r["method"] == method]
        errs, correct, counts = [], [], []
        for r in sel:
            resp = list(parse_response_text(r["response"]))
            perceived = locations[np.asarray(resp) - 1].mean(axis=0)
            errs.append(float(np.linalg.norm(perceived - locations[r["target"] - 1])))
            correct.append(r["target"] in resp if study == 2 else resp == [r["target"]])
            counts.append(len(resp))
        out.append({
            "study": study, "method": method, "n": len(sel), "mean_error_mm": float(np.mean(errs)),
            "correct": float(np.mean(correct)), "mean_n_selected": float(np.mean(counts)),
        })
    return out
