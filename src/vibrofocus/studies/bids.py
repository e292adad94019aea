"""Export the studies as a BIDS behavioural dataset (``vibrofocus export --bids DIR``).

Builds the plain records of :mod:`vibrofocus.io.bids` from a study database (with the
onsets, rigs, calibration hashes and skin presets it stores) or from a trials CSV (which
stores no times: onsets are ``n/a``), and writes them.
"""

from __future__ import annotations

import os
from collections import defaultdict
from datetime import datetime
from pathlib import Path
from typing import Any

from ..errors import StudyError
from ..io.bids import BIDS_VERSION, EVENT_COLUMN_DESCRIPTIONS, TASKS, bids_label, write_bids_dataset
from ..io.responses import format_response
from ..io.trials_csv import read_trials_csv

__all__ = ["export_bids"]


def _participant_columns(model_label: str) -> dict[str, dict[str, Any]]:
    """participants.json: each column of participants.tsv described."""
    return {
        "participant_id": {"Description": "BIDS participant label: the study id's letters and digits."},
        "source_id": {"Description": "The participant's id in the study database or trials file."},
        "simulated": {"Description": "Whether the answers come from vibrofocus's perceptual model, not from a person.",
                      "Levels": {"true": f"simulated ({model_label})", "false": "a person"}},
    }


def _onsets(store: Any, session_id: int) -> dict[int, datetime]:
    """Wall-clock time of each trial's last stimulus onset (a trial presented again keeps its last)."""
    return {int(e.payload["trial_index"]): datetime.fromisoformat(e.created_at)
            for e in store.events(session_id, kind="stimulus_onset")}


def _from_database(db: Path) -> tuple[list[dict[str, Any]], dict[str, bool], dict[tuple[str, int], list[dict]]]:
    from .storage import StudyStore

    with StudyStore(db, create=False) as store:
        rows = store.trial_rows()
        simulated = {p.participant_id: bool(p.simulated) for p in store.participants()}
        onsets: dict[int, dict[int, datetime]] = {}
        sessions: dict[tuple[str, int], list[dict]] = defaultdict(list)
        for info in store.sessions():
            onsets[info.session_id] = _onsets(store, info.session_id)
            cal = store.calibration(info.calibration_id) if info.calibration_id is not None else None
            sessions[(info.participant_id, info.study)].append({
                "Session": info.session_id, "Status": info.status,
                "Rig": info.config.get("rig", "simulated" if simulated.get(info.participant_id) else None),
                "SkinPreset": info.config.get("skin"),
                "LevelRule": info.design.levels,
                "CalibrationSHA256": None if cal is None else cal.sha256,
                "CalibrationFile": None if cal is None else Path(cal.path).name,
                "SoftwareVersion": info.software_version,
            })
    for row in rows:
        row["onset_time"] = onsets.get(row["session_id"], {}).get(row["trial_index"])
    return rows, simulated, sessions


def _from_trials_csv(path: Path) -> tuple[list[dict[str, Any]], dict[str, bool], dict[tuple[str, int], list[dict]]]:
    rows = read_trials_csv(path)
    simulated: dict[str, bool] = {}
    for row in rows:
        simulated[row["participant"]] = simulated.get(row["participant"], False) or bool(row.get("simulated"))
        row["onset_time"] = None
    return rows, simulated, {}


def _is_database(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(16) == b"SQLite format 3\x00"
    except OSError as exc:
        raise StudyError(f"cannot read {path}: {exc.strerror or exc}") from exc


def export_bids(source: str | os.PathLike, out_dir: str | os.PathLike, *, force: bool = False) -> dict[str, Any]:
    """Write a study database or a trials CSV as a BIDS behavioural dataset, or add it to one.

    One ``sub-<label>/beh/sub-<label>_task-localization<study>_events.tsv`` per participant
    and study, one row per answered trial (both phases), with its JSON sidecar; see
    :mod:`vibrofocus.io.bids` for the layout and the columns. Into an existing dataset
    (EEG, MRI, another study's export) only files vibrofocus wrote are replaced and the
    participants files are merged (:mod:`vibrofocus.io.bids_merge`); nothing is deleted.

    Parameters
    ----------
    source : path-like
        A study database (SQLite) or a trials CSV (docs/file-formats.md, trials file).
    out_dir : path-like
        The dataset folder; its parent must exist. A new one is built beside it and put
        in place as a whole; a symbolic link to a folder is written through.
    force : bool
        Replace files in the way: at a path the export writes, but not written by
        vibrofocus (or edited since). Without it they are refused and nothing changes.

    Returns
    -------
    dict
        ``participants`` and ``events`` (rows written; one per answered trial),
        ``merged`` and ``kept`` (see :func:`vibrofocus.io.write_bids_dataset`).

    Raises
    ------
    StudyError
        An unreadable source, a source inside ``out_dir``, or two participant ids with
        the same BIDS label.
    ValidationError
        A participant id that cannot be a BIDS label (no ASCII letter or digit, a
        control character).
    OutputError
        The folder cannot be written, or holds a file in the way (not ``force``).
    """
    from .. import __version__
    # The label of the model that answers for simulated participants (the simulation floor
    # sits above the studies: imported here, where a sidecar names it).
    from ..simulation.perception import MODEL_LABEL

    source = Path(source)
    if source.resolve().is_relative_to(Path(out_dir).resolve()):
        raise StudyError(f"the BIDS folder {out_dir} would replace its input {source}: write the dataset elsewhere")
    if not source.is_file():
        raise StudyError(f"{source} is not a study database or a trials CSV file")
    from ..rigs.onset import CLOCKS

    from_db = _is_database(source)
    rows, simulated, sessions = _from_database(source) if from_db else _from_trials_csv(source)
    # Every clock the data names is a level: a lab's own, registered when it was recorded
    # but not in this process, is described as such.
    own = {c for r in rows if isinstance(c := r.get("onset_clock"), str) and c} - set(CLOCKS)
    levels = {**CLOCKS, **dict.fromkeys(sorted(own), "a lab's own device clock (vibrofocus.rigs.register_clock)")}
    clock_column = {**EVENT_COLUMN_DESCRIPTIONS["device_clock"], "Levels": levels}
    labels: dict[str, str] = {}
    for pid in simulated:
        label = bids_label(pid)
        clash = [other for other, lab in labels.items() if lab == label]
        if clash:
            raise StudyError(f"participants {clash[0]!r} and {pid!r} would both be sub-{label} in BIDS")
        labels[pid] = label
    grouped: dict[tuple[str, int], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        grouped[(row["participant"], int(row["study"]))].append(row)
    runs = []
    for (pid, study), trials in grouped.items():
        starts = [t["onset_time"] for t in trials if t["onset_time"] is not None]
        first = min(starts) if starts else None
        events = [{
            "onset": None if t["onset_time"] is None else (t["onset_time"] - first).total_seconds(),
            "duration": None, "trial_type": f"{t['method']}_loc{int(t['target'])}", "method": t["method"],
            "target": int(t["target"]),
            "response": t["response"] if isinstance(t["response"], str) else format_response(t["response"]),
            "response_time": float(t["rt_s"]), "phase": t["phase"], "trial": int(t["trial"]),
            "session_id": t.get("session"), "session_status": t.get("session_status"),
            "dry_run": None if t.get("dry_run") is None else int(bool(t["dry_run"])),
            "device_onset": t.get("onset_device_s"), "device_clock": t.get("onset_clock"),
            "levels": t.get("levels") or None, "drive_peak_v": t.get("drive_peak_v"),
            "target_peak_um": t.get("target_peak_um"),
        } for t in trials]
        sim = simulated.get(pid, False)
        runs.append({"label": labels[pid], "study": study, "events": events, "sidecar": {
            "device_clock": clock_column,
            "SourceId": pid, "Study": study, "Simulated": sim,
            # The rows' own label (model and hypothesis) where the source names it.
            "SimulatedModel": next((t["model"] for t in trials if t.get("model")), MODEL_LABEL) if sim else None,
            "Source": "study database" if from_db else "trials CSV", "SourceFile": source.name,
            "Sessions": sessions.get((pid, study), []),
        }})
    # The README speaks for the whole dataset: simulated participants of an earlier
    # export into it count too.
    any_sim = any(simulated.values()) or _dataset_has_simulated(Path(out_dir))
    description = {
        "Name": "vibrofocus localization studies", "BIDSVersion": BIDS_VERSION,
        "DatasetType": "raw",
        "GeneratedBy": [{"Name": "vibrofocus", "Version": __version__,
                         "Description": "vibrofocus export --bids: localization studies with focused vibrotactile "
                                        "stimuli (Study 1: one location per trial; Study 2: several)."}],
    }
    # One README for every export into the dataset: each events sidecar names its source file.
    readme = (f"Localization studies run with vibrofocus {__version__} (vibrofocus export --bids; each events "
              "sidecar names its source file).\n"
              f"Tasks: {', '.join(TASKS.values())} (Study 1: one location per trial; Study 2: one or more).\n")
    if any_sim:
        readme += (f"\nSIMULATED: participants marked simulated=true in participants.tsv are {MODEL_LABEL}. "
                   "Their answers come from a perceptual model, not from people; statistics that include them are "
                   "not evidence about perception.\n")
    participants = [{"participant_id": f"sub-{labels[pid]}", "source_id": pid,
                     "simulated": "true" if simulated[pid] else "false"} for pid in simulated]
    return write_bids_dataset(out_dir, description=description, readme=readme, participants=participants,
                              participant_columns=_participant_columns(MODEL_LABEL), runs=runs,
                              source=str(source.resolve()), force=force)


def _dataset_has_simulated(root: Path) -> bool:
    """Whether an existing dataset's participants.tsv marks someone ``simulated`` (``true``)."""
    import csv

    try:
        with open(root / "participants.tsv", newline="", encoding="utf-8") as fh:
            return any(row.get("simulated") == "true" for row in csv.DictReader(fh, delimiter="\t"))
    except (OSError, UnicodeDecodeError, csv.Error):
        return False
