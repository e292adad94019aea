"""Simulate a study: check every output first, calibrate simulated participants, run their
sessions, summarize, export (docs/simulated-participants.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .progress import Progress, QuietProgress

__all__ = ["SimulationOutcome", "simulate_study"]


@dataclass(frozen=True)
class SimulationOutcome:
    """What :func:`simulate_study` stored and wrote.

    Attributes
    ----------
    counts : dict
        :func:`~vibrofocus.simulation.simulate_studies`' counts (``n_answered``,
        ``n_total``, ``n_new``, ``n_participants``).
    participants : int
        The participants of this run.
    hypothesis : Hypothesis
        The hypothesis the simulated participants answered under.
    summary : list of dict
        :func:`~vibrofocus.simulation.simulate.summarize_simulation` of the database.
    levels : DataFrame or None
        The stimuli played (:func:`~vibrofocus.analysis.levels.stimulus_levels`).
    n_exported : int or None
        The rows of the trials file written, None without one.
    """

    counts: dict[str, int]
    participants: int
    hypothesis: Any
    summary: list[dict[str, Any]]
    levels: Any = None
    n_exported: int | None = None


def simulate_study(
    db: Path,
    *,
    participants: int | None = None,
    seed: int = 0,
    pace_s: float | None = None,
    trials_csv: Path | None = None,
    calibration_dir: Path | None = None,
    skin: str = "nominal",
    methods: str | None = None,
    hypothesis: str | None = None,
    levels: str | None = None,
    protocol: Path | None = None,
    lsl_source_id: str | None = None,
    lsl_wait_s: float = 0.0,
    progress: Progress | None = None,
) -> SimulationOutcome:
    """Calibrate simulated participants and run their studies into a study database.

    Every input and every output place is checked before the first calibration (a bad
    protocol, level rule, hypothesis or method; a read-only folder, a full disk, a trials
    file named like the database), so a refused run creates nothing. Then
    :func:`~vibrofocus.simulation.simulate_studies` runs (an unfinished database is
    resumed), and the trials file is written last.

    Parameters
    ----------
    db : Path
        Study database (SQLite).
    participants : int, optional
        Simulated participants; default 3 for a new database, else the number it holds.
    seed : int
        Seed of the whole simulation.
    pace_s : float, optional
        Wait after each answer, s (default the protocol's pacing).
    trials_csv : Path, optional
        Also write the trials file here.
    calibration_dir : Path, optional
        Where calibration files go (default ``<db stem>-files/calibrations/``, made 0700;
        those of a database made before, in ``<db>.calibrations/``, stay there).
    skin : str
        Skin preset of the simulated forearms.
    methods : str, optional
        Rendering methods, comma separated (default the paper's).
    hypothesis : str, optional
        The simulated participants' hypothesis (default the best fitted one).
    levels : str, optional
        Level rule of the stimuli (default the paper's).
    protocol : Path, optional
        A study protocol file (not with ``methods`` or ``levels``).
    lsl_source_id : str, optional
        Send LSL markers with this source id (None: no markers).
    lsl_wait_s : float
        Wait up to this long for an LSL consumer, s.
    progress : Progress, optional
        Notes (the model's notice, the protocol, the LSL outlet), a step per answer, and
        ``note("summary", summary=..., levels=...)`` once the studies are run.

    Returns
    -------
    SimulationOutcome
    """
    from .._atomic import TRIALS_CSV, check_writable, output_error, protect
    from ..errors import StudyError, ValidationError
    from ..io.calibration_nc import estimate_calibration_bytes
    from ..layout import ArrayLayout
    from ..simulation.participants import MODEL_NOTICE
    from ..simulation.simulate import simulate_studies, summarize_simulation
    from ..studies.markers import lsl_markers
    from ..studies.protocol import level_options

    progress = progress if progress is not None else QuietProgress()
    the_protocol = None
    if protocol is not None:  # a bad file: one error line before anything is created
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
    if lsl_source_id is not None:  # no pylsl: one error line before anything is created
        from ..io.lsl import import_pylsl

        import_pylsl()
    if trials_csv is not None and not trials_csv.parent.is_dir():
        # Checked first: the simulation takes minutes and the file is written last.
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
        progress.note(f"adding simulated participant(s) sim-{held + 1:03d} to sim-{participants:03d}: the database held "
                      f"{held}", plain=True)
    if trials_csv is not None:
        check_writable(trials_csv, what="trials file", kind=TRIALS_CSV)
    from .._db_files import calibrations_dir, files_dir, former_calibrations_dir, make_private_dir

    cal_dir = calibration_dir if calibration_dir is not None else calibrations_dir(db)
    made = [d for d in (files_dir(db), cal_dir) if (calibration_dir is None or d == cal_dir) and not d.exists()]
    if calibration_dir is None:
        make_private_dir(cal_dir, db)  # never through a link (docs/security.md)
        former = former_calibrations_dir(db)
        if former is not None:
            progress.note(f"calibrations made before stay in {former}/ (read from there); new ones go to "
                          f"{cal_dir}/", plain=True)
    else:
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
        for folder in reversed(made):
            folder.rmdir()
        raise
    progress.note(f"{MODEL_NOTICE} Hypothesis: {chosen_h.label()}.", notice=True)
    if the_protocol is not None:
        progress.note(f"protocol {the_protocol.name} ({len(the_protocol.blocks)} block(s)) from {protocol}")
    if lsl_source_id is not None:
        progress.note(f"LSL markers: outlet vibrofocus-markers (type Markers, source id {lsl_source_id})")
    with lsl_markers(lsl_source_id is not None, source_id=lsl_source_id, wait_s=lsl_wait_s):
        result = simulate_studies(
            db, n_participants=participants, seed=seed, pace_s=pace_s,
            calibration_dir=calibration_dir, progress=lambda what, done, total: progress.step(done, total, what),
            skin=skin, methods=chosen, levels=levels, hypothesis=chosen_h.name, protocol=the_protocol,
        )
    summary = summarize_simulation(db)
    import pandas as pd

    from ..analysis.levels import stimulus_levels
    from ..studies import StudyStore

    with StudyStore(db) as store:
        played = stimulus_levels(pd.DataFrame(store.trial_rows()))
    progress.note("summary", summary=summary, levels=played, hypothesis=chosen_h)
    held_now = result["n_participants"]
    progress.note(
        f"{result['n_answered']} answers stored in {db} ({result['n_new']} new this run) for {held_now} "
        f"simulated participant(s)"
        + (f" ({participants} in this run)." if held_now != participants else ".")
    )
    n = None
    if trials_csv is not None:
        with StudyStore(db) as store:
            n = store.export_trials_csv(trials_csv)
        progress.note(f"wrote {n} trials to {trials_csv}")
    progress.note(f"{MODEL_NOTICE} Hypothesis: {chosen_h.label()}.", notice=True)
    return SimulationOutcome(result, participants, chosen_h, summary, played, n)
