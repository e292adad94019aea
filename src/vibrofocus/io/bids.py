"""BIDS behavioural datasets: the localization studies as ``beh`` events files.

Layout written by :func:`write_bids_dataset` (BIDS 1.10, the ``beh`` datatype)::

    DIR/dataset_description.json       Name, BIDSVersion, DatasetType, GeneratedBy (vibrofocus, version)
    DIR/README                         what the dataset is; that simulated participants are a model
    DIR/participants.tsv, .json        participant_id (sub-<label>), source_id, simulated
    DIR/sub-<label>/beh/sub-<label>_task-localization<1|2>_events.tsv
    DIR/sub-<label>/beh/sub-<label>_task-localization<1|2>_events.json

The events file has one row per answered trial with the columns :data:`EVENT_COLUMNS`;
its JSON sidecar describes every column (units, levels) and records where the trials
came from (rig, calibration hash, skin preset, simulated or not). This module writes and
reads plain records (dicts and lists); the study side builds them
(:mod:`vibrofocus.studies.bids`). :func:`read_bids_trials_table` turns a dataset back into
the trials table the analysis reads.
"""

from __future__ import annotations

import csv
import io as _io
import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .._validation import shorten
from ..errors import ValidationError
from .jsonsafe import json_safe

__all__ = ["BIDS_VERSION", "EVENT_COLUMNS", "EVENT_COLUMN_DESCRIPTIONS", "TASKS", "bids_label", "events_name",
           "write_bids_dataset", "read_bids_trials_table"]

#: The BIDS version the dataset follows.
BIDS_VERSION = "1.10.0"
#: Task label per study.
TASKS = {1: "localization1", 2: "localization2"}
#: Columns of every events file, in order: BIDS's ``onset`` and ``duration`` first, then
#: the trial (``trial_type``, ``method``, ``target``, ``response``, ``response_time``,
#: ``phase``), then where it sits in the study (``trial``, ``session_id``,
#: ``session_status``, ``dry_run``; not ``session``, which is a BIDS entity), then the
#: stimulus onset on the rig's own clock (``device_onset``, ``device_clock``), then the
#: stimulus played (``levels``, ``drive_peak_v``, ``target_peak_um``); a dataset written
#: before those existed is read without them.
EVENT_COLUMNS = ("onset", "duration", "trial_type", "method", "target", "response", "response_time", "phase",
                 "trial", "session_id", "session_status", "dry_run", "device_onset", "device_clock",
                 "levels", "drive_peak_v", "target_peak_um")
#: The columns :func:`read_bids_trials_table` needs (every events file has had them).
_REQUIRED_COLUMNS = EVENT_COLUMNS[:12]
#: The sidecar's description of each column of :data:`EVENT_COLUMNS` (BIDS "column
#: description": LongName, Description, Units, Levels).
EVENT_COLUMN_DESCRIPTIONS: dict[str, dict[str, Any]] = {
    "onset": {"LongName": "stimulus onset",
              "Description": "Time of the stimulus onset from the first stimulus onset of this participant's study: "
                             "when the stimulus_onset event was stored (UTC wall clock, microseconds), just before the "
                             "drive went to the rig. n/a when the source (a trials CSV) records no times.",
              "Units": "s"},
    "duration": {"LongName": "stimulus duration",
                 "Description": "n/a: the trials record no drive length; the tap itself lasts a few ms.",
                 "Units": "s"},
    "trial_type": {"LongName": "condition",
                   "Description": "The condition: method and target location, '<method>_loc<target>'."},
    "method": {"LongName": "rendering method",
               "Description": "How the drive was designed.",
               "Levels": {"funneling": "amplitude panning between actuators",
                          "inverse": "spatio-temporal inverse filter from the calibration",
                          "combination": "inverse filter reproducing funneling's field at the target",
                          "time_reversal": "time-reversed transfer functions",
                          "contrast": "acoustic contrast control",
                          "constrained": "peak-contrast design with a fidelity constraint"}},
    "target": {"LongName": "target location",
               "Description": "The location (1-9 on the reference layout) the stimulus was focused at."},
    "response": {"LongName": "chosen locations",
                 "Description": "Locations the participant chose, ascending, separated by spaces "
                                "(Study 1: one; Study 2: one or more)."},
    "response_time": {"LongName": "response time",
                      "Description": "From the stimulus onset to the answer.", "Units": "s"},
    "phase": {"LongName": "phase", "Description": "Part of the study.",
              "Levels": {"training": "practice trials, not analysed", "main": "the trials analysed"}},
    "trial": {"LongName": "trial number", "Description": "1-based trial number within the phase."},
    "session_id": {"LongName": "study session", "Description": "Id of the session in the study database (0: none)."},
    "session_status": {"LongName": "session status",
                       "Description": "The session's status when exported.",
                       "Levels": {"planned": "not started", "running": "in progress", "paused": "paused",
                                  "aborted": "ended early (left out of the analysis by default)",
                                  "completed": "all trials answered"}},
    "dry_run": {"LongName": "dry run",
                "Description": "Whether the session ran without a calibration (nothing was played).",
                "Levels": {"0": "stimuli were played", "1": "dry run: nothing was played"}},
    "device_onset": {"LongName": "stimulus onset on the device clock",
                     "Description": "The drive's first sample on the rig's own clock (device_clock says which), as "
                                    "the rig reported it; n/a for a dry run, a rig without a device clock, or a "
                                    "source that stored none.",
                     "Units": "s"},
    "device_clock": {"LongName": "device clock",
                     "Description": "The clock device_onset is on."},
    "levels": {"LongName": "level rule",
               "Description": "How the stimuli's levels were set (the session's protocol).",
               "Levels": {"paper": "each method at the source paper's level: funneling by eq. 3 with A at the drive "
                                   "limit, the inverse filter asking 2 um at the target, the combination funneling's "
                                   "displacement there, each scaled down only over the drive limit",
                          "equal-peak": "every method scaled to the drive limit"}},
    "drive_peak_v": {"LongName": "peak drive",
                     "Description": "Largest absolute drive over the actuators of the stimulus played; n/a where "
                                    "none was stored (a dry run, an older database, a trials CSV without it).",
                     "Units": "V"},
    "target_peak_um": {"LongName": "predicted peak at the target",
                       "Description": "Peak displacement at the target predicted from the participant's calibration; "
                                      "n/a where none was stored.",
                       "Units": "um"},
}
_LABEL = re.compile(r"[^A-Za-z0-9]")
_NA = "n/a"


def bids_label(participant_id: str) -> str:
    """The BIDS label of a participant id: its ASCII letters and digits (``P-01`` -> ``P01``).

    BIDS labels are alphanumeric ASCII only (``[0-9a-zA-Z]+``, BIDS 1.10, "Entities"):
    other characters, letters of other scripts included, are dropped.

    Raises
    ------
    ValidationError
        The id holds a control character (tab, newline, ...), or has no ASCII letter
        or digit (``'李'``): BIDS cannot name such a subject.
    """
    text = str(participant_id)
    if not text.isprintable():
        raise ValidationError(f"participant id {shorten(text)} holds a control character (tab, newline, ...); "
                              "rename the participant")
    label = _LABEL.sub("", text)
    if not label:
        raise ValidationError(f"participant id {shorten(text)} has no ASCII letter or digit: BIDS subject labels "
                              "allow only A-Z, a-z and 0-9, so this participant cannot be a BIDS subject; give "
                              "the participant an id with some of those")
    return label


def events_name(label: str, study: int) -> str:
    """``sub-<label>_task-localization<study>_events`` (without suffix)."""
    return f"sub-{label}_task-{TASKS[study]}_events"


def _tsv(columns: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    buf = _io.StringIO()
    writer = csv.writer(buf, delimiter="\t", lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_NA if row.get(c) is None else _cell(row[c]) for c in columns])
    return buf.getvalue()


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return _NA if value != value else repr(value)  # NaN -> n/a; repr keeps every digit
    return str(value)


def _json(value: Any) -> str:
    return json.dumps(json_safe(value), indent=2, sort_keys=False) + "\n"


def write_bids_dataset(
    out_dir: str | os.PathLike,
    *,
    description: Mapping[str, Any],
    readme: str,
    participants: Sequence[Mapping[str, Any]],
    participant_columns: Mapping[str, Mapping[str, Any]],
    runs: Sequence[Mapping[str, Any]],
    source: str | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Write a BIDS behavioural dataset, or add it to an existing one without touching anything else.

    A new folder is built beside ``out_dir`` and put in place at once
    (:func:`vibrofocus._atomic.atomic_directory`). Into an existing folder (a lab's
    dataset with EEG or MRI, an earlier export, another study's) the files are merged
    by :func:`vibrofocus.io.bids_merge.merge_into_dataset`: only files vibrofocus wrote
    (listed with their SHA-256 in ``.vibrofocus-bids.json``) are replaced;
    ``participants.tsv`` and ``participants.json`` are merged, keeping the lab's columns
    and rows; ``dataset_description.json`` and ``README`` are written only where
    missing or vibrofocus's own; nothing is deleted. A folder given as a symbolic link
    is written through (the link stays).

    Parameters
    ----------
    out_dir : path-like
        The dataset folder; its parent must exist.
    description : mapping
        ``dataset_description.json`` (Name, BIDSVersion, GeneratedBy, ...).
    readme : str
        The README's text.
    participants : sequence of mapping
        One row of ``participants.tsv`` per participant, keys as ``participant_columns``
        (the first is ``participant_id``, ``sub-<label>``).
    participant_columns : mapping
        Column name -> its description (``participants.json``), in column order.
    runs : sequence of mapping
        One per participant and study: ``label`` (str), ``study`` (1 or 2), ``events``
        (rows keyed by :data:`EVENT_COLUMNS`; None or NaN is written ``n/a``) and
        ``sidecar`` (extra keys of the events JSON besides the column descriptions).
    source : str, optional
        Where the data comes from (the source file's resolved path), recorded in the
        manifest: an events file is replaced only by an export of the same source (the
        same label from another study is a file in the way).
    force : bool
        Replace files at the paths the export writes that vibrofocus did not write (or
        that were edited since, or another source's); without it such a file is refused
        and nothing changes.

    Returns
    -------
    dict
        ``participants`` and ``events`` (rows written), ``merged`` (True when added to
        an existing folder) and ``kept`` (the dataset's own ``dataset_description.json``
        or ``README``, left as they were).

    Raises
    ------
    ValidationError
        A run names a study other than 1 or 2, or two runs the same file.
    OutputError
        The folder cannot be written, or holds a file in the way (not ``force``).
    """
    from .._atomic import atomic_directory, write_text
    from .._atomic_folders import resolve_folder_link
    from .bids_merge import merge_into_dataset, text_sha256, write_manifest

    files: dict[str, str] = {}
    for run in runs:
        if run["study"] not in TASKS:
            raise ValidationError(f"a BIDS run must be of study 1 or 2, got {run['study']!r}")
        name = events_name(run["label"], run["study"])
        folder = f"sub-{run['label']}/beh"
        if f"{folder}/{name}.tsv" in files:
            raise ValidationError(f"two runs would both write {name}.tsv")
        sidecar = {"TaskName": TASKS[run["study"]], **EVENT_COLUMN_DESCRIPTIONS, **run["sidecar"]}
        files[f"{folder}/{name}.tsv"] = _tsv(EVENT_COLUMNS, run["events"])
        files[f"{folder}/{name}.json"] = _json(sidecar)
    n_events = sum(len(run["events"]) for run in runs)
    shared = {"dataset_description.json": _json(description), "README": readme}
    columns = list(participant_columns)
    rows = [{c: _NA if p.get(c) is None else _cell(p[c]) for c in columns} for p in participants]
    out = resolve_folder_link(out_dir, what="BIDS dataset")
    counts: dict[str, Any] = {"participants": len(participants), "events": n_events}
    if out.exists():
        kept = merge_into_dataset(out, files=files, shared=shared, participant_columns=participant_columns,
                                  participant_rows=rows, participants_tsv=_tsv(columns, participants),
                                  participants_json=_json(participant_columns), source=source, force=force)
        return {**counts, "merged": True, "kept": kept}
    with atomic_directory(out, what="BIDS dataset") as build:
        texts = {**shared, "participants.tsv": _tsv(columns, participants),
                 "participants.json": _json(participant_columns), **files}
        for rel, text in texts.items():
            (build / rel).parent.mkdir(parents=True, exist_ok=True)
            write_text(build / rel, text, what="BIDS file")
        write_manifest(build, {rel: text_sha256(text) for rel, text in texts.items()},
                       {rel: source for rel in files} if source is not None else None)
    return {**counts, "merged": False, "kept": []}


def _read_tsv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh, delimiter="\t"))


def read_bids_trials_table(root: str | os.PathLike):
    """Read a dataset written by :func:`write_bids_dataset` as the trials table the analysis reads.

    Parameters
    ----------
    root : path-like
        The dataset folder (with ``dataset_description.json`` and ``participants.tsv``).

    Returns
    -------
    DataFrame
        Every value a str, with the trials-file columns (``participant``: the
        ``source_id``, ``study``, ``phase``, ``trial``, ``method``, ``target``,
        ``response``, ``rt_s``), the session columns (``session``, ``session_status``,
        ``dry_run``), ``simulated`` (``1``/``0``), the stimulus columns (``levels``,
        ``drive_peak_v``, ``target_peak_um``) and, for a simulated participant, ``model``
        (the sidecar's ``SimulatedModel``) where the events files have them, and ``line``
        (row number over all events files, from 2), as
        :func:`~vibrofocus.io.trials_csv.read_trials_table` gives.

    Raises
    ------
    ValidationError
        Not a BIDS dataset, no events file, or an events file without a column of
        :data:`EVENT_COLUMNS`.
    """
    import pandas as pd

    from .._atomic import protect

    root = Path(root)
    if not (root / "dataset_description.json").is_file() or not (root / "participants.tsv").is_file():
        raise ValidationError(f"{root} is not a BIDS dataset: it needs dataset_description.json and participants.tsv")
    try:
        people = {r["participant_id"]: r for r in _read_tsv(root / "participants.tsv")}
    except (OSError, KeyError, csv.Error, UnicodeDecodeError) as exc:
        raise ValidationError(f"cannot read {root / 'participants.tsv'}: {exc}") from exc
    rows: list[dict[str, str]] = []
    files = sorted(root.glob("sub-*/beh/sub-*_task-localization*_events.tsv"))
    if not files:
        raise ValidationError(f"the BIDS dataset {root} has no sub-*/beh/*_task-localization*_events.tsv")
    for path in files:
        protect(path, "BIDS events file")
        sub = path.parent.parent.name
        study = path.name.split("_task-localization", 1)[1].split("_", 1)[0]
        person = people.get(sub, {})
        try:
            events = _read_tsv(path)
        except (OSError, csv.Error, UnicodeDecodeError) as exc:
            raise ValidationError(f"cannot read the events file {path}: {exc}") from exc
        if events and set(_REQUIRED_COLUMNS) - set(events[0]):
            missing = sorted(set(_REQUIRED_COLUMNS) - set(events[0]))
            raise ValidationError(f"the events file {path} lacks the column(s) {', '.join(missing)}")
        model = None
        if person.get("simulated") == "true":  # the sidecar names the model that answered
            try:
                model = json.loads(path.with_suffix(".json").read_text(encoding="utf-8")).get("SimulatedModel")
            except (OSError, ValueError, AttributeError):
                model = None
        for ev in events:
            stimulus = {c: ("" if ev[c] == _NA else ev[c]) for c in ("levels", "drive_peak_v", "target_peak_um")
                        if c in ev}
            if model:
                stimulus["model"] = str(model)
            rows.append({
                "participant": person.get("source_id") or sub.removeprefix("sub-"), "study": study,
                "phase": ev["phase"], "trial": ev["trial"], "method": ev["method"], "target": ev["target"],
                "response": ev["response"], "rt_s": ev["response_time"],
                "session": "0" if ev["session_id"] == _NA else ev["session_id"],
                "session_status": "completed" if ev["session_status"] == _NA else ev["session_status"],
                "dry_run": "0" if ev["dry_run"] == _NA else ev["dry_run"],
                "simulated": "1" if person.get("simulated") == "true" else "0",
                **stimulus,
            })
    table = pd.DataFrame(rows, dtype=str).fillna("")  # a column some events files lack: empty cells
    table["line"] = range(2, len(table) + 2)
    return table
