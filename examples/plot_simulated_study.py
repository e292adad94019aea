"""
A simulated study, end to end
=============================

Three simulated participants (a perceptual model, not data) are calibrated and run
Studies 1 and 2 into a SQLite study database; the trials are exported to the trials CSV
and analysed as ``vibrofocus analyze`` would, and the Study 1 localization figure is drawn
with the same code. With three participants the report says which tests are undefined.
"""

import tempfile
from pathlib import Path

import vibrofocus.analysis as va
from vibrofocus.participant_models import simulate_studies
from vibrofocus.studies import StudyStore

with tempfile.TemporaryDirectory() as tmp:
    db = Path(tmp) / "study.sqlite"
    simulate_studies(db, n_participants=3, seed=1)
    with StudyStore(db) as store:
        store.export_trials_csv(Path(tmp) / "trials.csv")
    trials = va.load_trials(Path(tmp) / "trials.csv")

result = va.analyze(trials)
for sentence in va.results_sentences(result):
    print(sentence)
fig = va.plot_localization(result.study1.positions, title="Study 1, 3 simulated participants (model, not data)")
