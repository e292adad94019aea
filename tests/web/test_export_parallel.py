"""Parallel trial exports from the web app never return another participant's rows."""

from __future__ import annotations

import csv
import io
from concurrent.futures import ThreadPoolExecutor

from fastapi.testclient import TestClient

from vibrofocus.studies import StudyStore
from vibrofocus.web.app import create_app

TOKEN = "e" * 32
PEOPLE = {"sim-001": (2, 4), "sim-002": (6, 8, 2), "sim-003": (4,), "sim-004": (8, 6, 4, 2)}


def _database(path):
    with StudyStore(path) as store:
        for pid, locations in PEOPLE.items():
            store.add_participant(pid)
            sid = store.create_session(pid, 1, seed=1, config={"repetitions": 1, "n_training": 0,
                                                               "methods": ["inverse"], "locations": list(locations)})
            for trial in store.planned_trials(sid):
                store.record_answer(sid, trial.trial_index, trial.target, 0.5, answer_id=f"{pid}-{trial.trial_index}")
    return path


def test_a_hundred_rounds_of_parallel_exports_never_mix_participants(tmp_path):
    app = create_app(_database(tmp_path / "s.sqlite"), token=TOKEN, allowed_hosts=("testserver",), resume=False)
    headers = {"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}
    with TestClient(app, headers=headers) as client, ThreadPoolExecutor(len(PEOPLE)) as pool:
        def export(pid):
            r = client.get("/api/export/trials.csv", params={"participant_id": pid})
            return pid, r.status_code, r.headers.get("content-disposition"), list(csv.DictReader(io.StringIO(r.text)))

        wrong = []
        for _ in range(100):
            for pid, status, disposition, rows in pool.map(export, PEOPLE):
                assert status == 200 and 'filename="trials.csv"' in disposition
                if sorted(int(r["target"]) for r in rows) != sorted(PEOPLE[pid]) or {r["participant"] for r in rows} != {pid}:
                    wrong.append((pid, [(r["participant"], r["target"]) for r in rows]))
    assert wrong == []
    # Nothing of the participants' data stays on disk after it was served.
    assert list((tmp_path / "s-files" / "exports").iterdir()) == []
