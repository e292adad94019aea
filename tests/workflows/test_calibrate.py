"""The calibration workflow (vibrofocus.workflows.calibrate_participant) on the simulated forearm."""

from __future__ import annotations

import threading

import pytest

from vibrofocus.rigs.simulated import SimulatedForearm
from vibrofocus.studies.storage import StudyStore
from vibrofocus.workflows import CalibrationOutcome, Progress, QuietProgress, WorkflowCancelled, calibrate_participant

#: A short measurement: one linear sweep per actuator (the paper's method).
QUICK = dict(method="paper", sweep_s=0.3)


class Recorder(QuietProgress):
    """Records what the workflow reports, in order; cancels at the ``cancel_at``-th step."""

    def __init__(self, cancel_at: int | None = None):
        self.events: list[tuple] = []
        self.cancel_at = cancel_at

    def step(self, done, total, message):
        self.events.append(("step", done, total))

    def note(self, message, **details):
        self.events.append(("note", message))

    def judged(self, result):
        self.events.append(("judged",))

    def cancelled(self):
        steps = sum(e[0] == "step" for e in self.events)
        return self.cancel_at is not None and steps >= self.cancel_at


def test_the_recorder_and_the_quiet_progress_are_progresses():
    assert isinstance(Recorder(), Progress) and isinstance(QuietProgress(), Progress)


def test_a_calibration_is_planned_recorded_judged_saved_and_registered_in_that_order(tmp_path):
    out = tmp_path / "P01.nc"
    progress = Recorder()
    saving = []

    def before_saving():
        saving.append(out.exists())
        progress.events.append(("before_saving",))

    with StudyStore(tmp_path / "s.sqlite") as store:
        store.add_participant("P01")
        lock = threading.RLock()
        done = calibrate_participant(SimulatedForearm(seed=3), "P01", out, progress=progress,
                                     before_saving=before_saving, store=store, store_lock=lock, **QUICK)
        registered = [c.calibration_id for c in store.calibrations("P01")]
    assert isinstance(done, CalibrationOutcome)
    assert done.path == out and out.is_file() and done.kept is None and done.figure is None
    assert registered == [done.calibration_id] and done.calibration_id is not None
    assert saving == [False], "the hook runs once, before the file is written"
    kinds = [e[0] for e in progress.events]
    notes = [e[1] for e in progress.events if e[0] == "note"]
    assert notes[0].startswith("strap forces: ") and notes[1].startswith("plan: paper"), notes
    assert kinds[:2] == ["note", "note"], "the straps and the plan are shown before the first sweep"
    last_step = max(i for i, k in enumerate(kinds) if k == "step")
    assert kinds[last_step + 1:] == ["judged", "before_saving", "note"], progress.events
    assert progress.events[-1] == ("note", f"wrote {out}")


def test_a_cancel_during_the_recordings_saves_nothing_and_skips_the_saving_hook(tmp_path):
    out = tmp_path / "P01.nc"
    hooked = []
    progress = Recorder(cancel_at=2)
    with pytest.raises(WorkflowCancelled):
        calibrate_participant(SimulatedForearm(seed=3), "P01", out, progress=progress,
                              before_saving=lambda: hooked.append(True), **QUICK)
    assert [e[0] for e in progress.events].count("step") == 2, "the recordings stop at the step that saw the cancel"
    assert "judged" not in [e[0] for e in progress.events]
    assert hooked == [] and not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_a_hook_that_refuses_saves_nothing(tmp_path):
    # The web job's point of no return raises when the job was cancelled just before it.
    out = tmp_path / "P01.nc"

    class Refused(Exception):
        pass

    def refuse():
        raise Refused

    with pytest.raises(Refused):
        calibrate_participant(SimulatedForearm(seed=3), "P01", out, before_saving=refuse, **QUICK)
    assert not out.exists()
