"""Export the studies as a BIDS behavioural dataset (``vibrofocus export --bids DIR``).

Builds the plain records of :mod:`vibrofocus.io.bids` from a study database (with the
onsets, rigs, calibration hashes and skin presets it stores) or from a trials CSV (with
the onsets it has: ``onset_host_s``), one events file per participant, study and
session, and writes them.
"""

from __future__ import annotations

import os
import re
from collections import defaultdict
from collections.abc import Mapping
from datetime import datetime
from pathlib import Path
from typing import Any

from ..errors import StudyError, ValidationError
from ..io.bids import (BIDS_VERSION, EVENT_COLUMN_DESCRIPTIONS, METADATA_KEYS, TASK_INFO, TASKS,
                       THRESHOLD_COLUMN_DESCRIPTIONS, THRESHOLD_TASK, THRESHOLD_TASK_INFO, bids_label,
                       check_bids_metadata, levels_from_data, read_bids_metadata, write_bids_dataset)
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
    from .storage import StudyStore, session_protocol

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
                **_protocol_keys(info),
            })
        block = {info.session_id: session_protocol(info.study, info.config)[1] for info in store.sessions()}
    for row in rows:  # with their level and allowed answers (StudyStore.trial_rows)
        row["onset_time"] = onsets.get(row["session_id"], {}).get(row["trial_index"])
        row["block"] = block.get(row["session_id"])
    return rows, simulated, sessions


def _protocol_keys(info: Any) -> dict[str, Any]:
    """A session's protocol, block and levels, as the events sidecar's ``Sessions`` names them."""
    from .storage import session_protocol

    protocol, block = session_protocol(info.study, info.config)
    keys = {"Protocol": protocol, "Block": block, "BlockName": info.config.get("block_name"),
            "LevelUnit": info.config.get("level_unit", "dB"), "LevelDb": info.design.level_db}
    if info.config.get("level_unit") == "dB SL":
        keys.update(LevelSlDb=info.config.get("level_sl_db"), ThresholdDb=info.config.get("threshold_db"))
    if info.design.staircase is not None:
        keys["Staircase"] = info.design.staircase.to_dict()
    return keys


def _threshold_runs(db: Path, labels: dict[str, str], sessions: dict[tuple[str, int], list[dict]],
                    institution: dict[str, Any]) -> list[dict[str, Any]]:
    """The threshold blocks' trials (:meth:`StudyStore.threshold_rows`): one ``task-threshold`` run per session."""
    from .storage import StudyStore

    with StudyStore(db, create=False) as store:
        rows = store.threshold_rows()
        walls = {sid: _onsets(store, sid) for sid in {r["session"] for r in rows}}
        infos = {sid: store.session(sid) for sid in walls}
    grouped: dict[int, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        grouped[int(r["session"])].append(r)
    runs = []
    for sid, trials in grouped.items():
        info = infos[sid]
        index = [t["trial"] - 1 + (info.design.n_training if t["phase"] == "main" else 0) for t in trials]
        stamps = [walls[sid].get(i) for i in index]
        first = min((w for w in stamps if w is not None), default=None)
        events = [{
            "onset": None if w is None or first is None else (w - first).total_seconds(), "duration": None,
            "trial_type": f"detection_{t['method']}_loc{int(t['target'])}", "method": t["method"],
            "target": int(t["target"]), "response": int(t["felt"]), "response_time": float(t["rt_s"]),
            "phase": t["phase"], "trial": int(t["trial"]), "session_status": info.status,
            "dry_run": int(info.calibration_id is None), "levels": t["levels"], "level_db": t["level_db"],
            "drive_peak_v": t["drive_peak_v"], "reversal": t["reversal"], "threshold_db": t["threshold_db"],
            "protocol": t["protocol"], "block": t["block"],
        } for t, w in zip(trials, stamps, strict=True)]
        pid = info.participant_id
        runs.append({"label": labels[pid], "study": info.study, "session": sid, "task": THRESHOLD_TASK,
                     "events": events, "sidecar": {
                         **THRESHOLD_TASK_INFO, **institution, "SourceId": pid,
                         "onset": {**THRESHOLD_COLUMN_DESCRIPTIONS["onset"], "Description": _ONSET_NOTE["wall"]},
                         "Sessions": [s for s in sessions.get((pid, info.study), []) if s["Session"] == sid]}})
    return runs


def _from_trials_csv(path: Path) -> tuple[list[dict[str, Any]], dict[str, bool], dict[tuple[str, int], list[dict]]]:
    rows = read_trials_csv(path)
    simulated: dict[str, bool] = {}
    for row in rows:
        simulated[row["participant"]] = simulated.get(row["participant"], False) or bool(row.get("simulated"))
        row["onset_time"] = None  # a CSV has no wall clock; its onset_host_s, where it has one, is used
    return rows, simulated, {}


def _is_database(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(16) == b"SQLite format 3\x00"
    except OSError as exc:
        raise StudyError(f"cannot read {path}: {exc.strerror or exc}") from exc


def _method_levels(methods: list[Any]) -> dict[str, str]:
    """``method``'s Levels: every method of the data, a lab's own described by its class."""
    from ..rendering.registry import available_methods, method_class

    known = dict(EVENT_COLUMN_DESCRIPTIONS["method"]["Levels"])
    registered = set(available_methods())
    for name in ({str(m) for m in methods if m is not None} - set(known)) & registered:
        doc = (method_class(name).__doc__ or "").strip().splitlines()
        known[name] = f"a lab's own rendering method: {doc[0].strip()}" if doc and doc[0].strip() else \
            "a lab's own rendering method (vibrofocus.rendering.register_method)"
    return levels_from_data(methods, known, "a rendering method not registered in the exporting process (a "
                                            "lab's own, vibrofocus.rendering.register_method)")


def _onsets_s(trials: list[dict[str, Any]]) -> tuple[list[float | None], str | None]:
    """Each trial's onset from the first of the file, s, and which clock gave it.

    The host's monotonic onset (``onset_host_s``, what response times count from) where
    the source has it; else the wall clock of the stored ``stimulus_onset`` event (a
    database older than the monotonic onsets); else None (n/a).
    """
    host = [t.get("onset_host_s") for t in trials]
    if any(h is not None for h in host):
        first = min(h for h in host if h is not None)
        return [None if h is None else float(h) - first for h in host], "host"
    walls = [t.get("onset_time") for t in trials]
    if any(w is not None for w in walls):
        first_wall = min(w for w in walls if w is not None)
        return [None if w is None else (w - first_wall).total_seconds() for w in walls], "wall"
    return [None] * len(trials), None


_ONSET_NOTE = {
    "host": None,  # the column's own description
    "wall": "Time of the stimulus onset from the first stimulus onset of this file's session, from the UTC wall "
            "clock of the stored stimulus_onset event (the database holds no monotonic onset): within some ms.",
    None: "n/a: the source stores no onset times.",
}


def _allowed_cell(allowed: Any) -> str | None:
    """The ``allowed`` cell: the text of a database's row, the locations of a trials CSV's (None: n/a)."""
    if allowed is None or isinstance(allowed, str):
        return allowed or None
    return format_response(allowed)


def _session_key(row: dict[str, Any]) -> int | None:
    session = row.get("session")
    return int(session) if session not in (None, "", 0, "0") else None


def export_bids(source: str | os.PathLike, out_dir: str | os.PathLike, *, force: bool = False,
                metadata: dict[str, Any] | None = None,
                session_labels: Mapping[int, str] | None = None) -> dict[str, Any]:
    """Write a study database or a trials CSV as a BIDS behavioural dataset, or add it to one.

    One ``sub-<label>/ses-<session>/beh/sub-<label>_ses-<session>_task-localization<study>_events.tsv``
    per participant, study and session (no ``ses-`` for a source without sessions), one
    row per answered trial (both phases), with its JSON sidecar; see
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
    metadata : dict, optional
        BIDS metadata (:data:`vibrofocus.io.bids.METADATA_KEYS`): ``Authors``,
        ``License``, ``Funding``, ... for ``dataset_description.json``, and
        ``InstitutionName``, ``InstitutionAddress``, ``InstitutionalDepartmentName`` for
        every events sidecar. What the dataset at ``out_dir`` already holds of these is
        kept unless given here, so a re-export never drops it.
    session_labels : mapping of int to str, optional
        The ``ses-`` label of a study session (database id -> label), to file the
        behaviour beside the lab's own sessions (``{3: "01"}``: session 3 is
        ``ses-01``); a session not named keeps its id. Labels are BIDS labels (ASCII
        letters and digits); two sessions of one participant and study may not share one.

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
        control character), or metadata of an unknown key or the wrong type.
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
    given = check_bids_metadata(metadata)
    # What the dataset holds already (an earlier export's Authors, License, institution)
    # stays unless given anew.
    meta = {**read_bids_metadata(out_dir), **given}
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
    relabel = _check_session_labels(session_labels)
    grouped: dict[tuple[str, int, int | None], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        grouped[(row["participant"], int(row["study"]), _session_key(row))].append(row)
    named: dict[tuple[str, int, str], int] = {}
    for pid, study, session in grouped:
        if session is not None and session in relabel:
            other = named.setdefault((pid, study, relabel[session]), session)
            if other != session:
                raise ValidationError(f"sessions {other} and {session} of participant {pid!r}, study {study}, would "
                                      f"both be ses-{relabel[session]}: give each its own label")
    institution = {k: v for k, v in meta.items() if METADATA_KEYS[k][0] == "events"}
    runs = []
    for (pid, study, session), trials in grouped.items():
        onsets, clock = _onsets_s(trials)
        events = [{
            "onset": onset, "duration": None, "trial_type": f"{t['method']}_loc{int(t['target'])}",
            "method": t["method"], "target": int(t["target"]),
            "response": t["response"] if isinstance(t["response"], str) else format_response(t["response"]),
            "response_time": float(t["rt_s"]), "phase": t["phase"], "trial": int(t["trial"]),
            "session_status": t.get("session_status"),
            "dry_run": None if t.get("dry_run") is None else int(bool(t["dry_run"])),
            "device_onset": t.get("onset_device_s"), "device_clock": t.get("onset_clock"),
            "levels": t.get("levels") or None, "drive_peak_v": t.get("drive_peak_v"),
            "target_peak_um": t.get("target_peak_um"), "protocol": t.get("protocol"), "block": t.get("block"),
            "level_db": t.get("level_db"), "allowed": _allowed_cell(t.get("allowed")),
            "response_x_mm": t.get("response_x_mm"),
            "response_y_mm": t.get("response_y_mm"), "xrun_represented": t.get("xrun_represented"),
        } for t, onset in zip(trials, onsets, strict=True)]
        sim = simulated.get(pid, False)
        infos = [s for s in sessions.get((pid, study), []) if session is None or s["Session"] == session]
        columns: dict[str, Any] = {
            "method": {**EVENT_COLUMN_DESCRIPTIONS["method"], "Levels": _method_levels([e["method"] for e in events])},
            "device_clock": clock_column,
        }
        rules = levels_from_data([e["levels"] for e in events], EVENT_COLUMN_DESCRIPTIONS["levels"]["Levels"],
                                 "a level rule of the session's protocol")
        if rules:  # else every cell is n/a: the known rules stay described
            columns["levels"] = {**EVENT_COLUMN_DESCRIPTIONS["levels"], "Levels": rules}
        if _ONSET_NOTE[clock]:
            columns["onset"] = {**EVENT_COLUMN_DESCRIPTIONS["onset"], "Description": _ONSET_NOTE[clock]}
        versions = sorted({str(i["SoftwareVersion"]) for i in infos if i.get("SoftwareVersion")})
        runs.append({"label": labels[pid], "study": study, "session": relabel.get(session, session) if session
                     is not None else None, "events": events, "sidecar": {
            **columns, **TASK_INFO[study],
            # The software that presented the stimuli: the recording's vibrofocus.
            "StimulusPresentation": {"SoftwareName": "vibrofocus",
                                     "SoftwareVersion": ", ".join(versions) if versions else __version__},
            **institution,
            "SourceId": pid, "Study": study, "Simulated": sim,
            # The rows' own label (model and hypothesis) where the source names it.
            "SimulatedModel": next((t["model"] for t in trials if t.get("model")), MODEL_LABEL) if sim else None,
            "Source": "study database" if from_db else "trials CSV", "SourceFile": source.name,
            "Sessions": infos,
        }})
    if from_db:
        runs += [{**run, "session": relabel.get(run["session"], run["session"])}
                 for run in _threshold_runs(source, labels, sessions, institution)]
    # The README speaks for the whole dataset: simulated participants of an earlier
    # export into it count too.
    any_sim = any(simulated.values()) or _dataset_has_simulated(Path(out_dir))
    description = {
        "Name": meta.get("Name", "vibrofocus localization studies"), "BIDSVersion": BIDS_VERSION,
        "DatasetType": "raw",
        **{k: v for k, v in meta.items() if METADATA_KEYS[k][0] == "dataset_description.json" and k != "Name"},
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


def _check_session_labels(session_labels: Mapping[int, str] | None) -> dict[int, str]:
    """``session_labels`` checked: database ids to BIDS labels (ASCII letters and digits)."""
    out: dict[int, str] = {}
    for key, label in (session_labels or {}).items():
        if isinstance(key, bool) or not isinstance(key, int) or key < 1:
            raise ValidationError(f"a session label names a study session by its database id (1, 2, ...), got "
                                  f"{key!r}")
        if not isinstance(label, str) or not re.fullmatch(r"[0-9A-Za-z]+", label):
            raise ValidationError(f"ses- label {label!r} of session {key}: BIDS labels are ASCII letters and digits "
                                  "only (e.g. 01)")
        out[key] = label
    return out
