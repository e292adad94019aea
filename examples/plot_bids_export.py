"""
A study as a BIDS dataset, opened with pybids
=============================================

``vibrofocus export study.sqlite --bids bids/`` writes the answered trials as a BIDS
behavioural dataset: ``participants.tsv`` and, per participant and study session,
``sub-<id>/ses-<n>/beh/sub-<id>_ses-<n>_task-localization<1|2>_events.tsv`` with a JSON sidecar that
describes every column and records the rig, the calibration's hash, the skin preset and
whether the participant is simulated. pybids opens it like any other dataset. The
participant here is simulated: a perceptual model, not data.
"""

import tempfile
from pathlib import Path

import bids

from vibrofocus.participant_models import simulate_studies
from vibrofocus.studies import export_bids

with tempfile.TemporaryDirectory() as tmp:
    db = Path(tmp) / "study.sqlite"
    simulate_studies(db, n_participants=1, seed=3)
    counts = export_bids(db, Path(tmp) / "bids", metadata={"Authors": ["A. Researcher", "B. Researcher"],
                                                             "License": "CC0"})
    layout = bids.BIDSLayout(Path(tmp) / "bids")
    print(layout)
    print(f"exported {counts['events']} trials")
    events = layout.get(suffix="events", extension=".tsv", task="localization1")[0]
    meta = events.get_metadata()
    table = events.get_df()
    print(events.filename)
    print("simulated:", meta["Simulated"], "-", meta["SimulatedModel"])
    print("rig:", meta["Sessions"][0]["Rig"], " skin:", meta["Sessions"][0]["SkinPreset"],
          " calibration sha256:", meta["Sessions"][0]["CalibrationSHA256"][:16], "...")

print(table.head(8).to_string(index=False))
print(table[table["phase"] == "main"].groupby("method")["response_time"].mean().round(3))
