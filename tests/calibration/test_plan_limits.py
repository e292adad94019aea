"""A calibration's plan is checked against the rig's limits over time before the first sweep."""

from __future__ import annotations

import types

import pytest

from vibrofocus.calibration import calibrate, plan_calibration
from vibrofocus.calibration import plan as plan_module
from vibrofocus.calibration import recording
from vibrofocus.errors import SafetyError, ValidationError
from vibrofocus.rigs.safety import SafetyLimits, plan_levels
from vibrofocus.rigs.simulated import SimulatedForearm


class _VirtualClockArm(SimulatedForearm):
    """A simulated arm whose energy budget runs on a clock that only the pauses advance."""

    now = 0.0

    def _clock(self) -> float:
        return self.now


def _arm(**limits) -> SimulatedForearm:
    rig = _VirtualClockArm(seed=3)
    rig.limits = SafetyLimits(**limits)
    return rig


def test_a_plan_over_the_sustained_limit_gets_the_shortest_pause_that_fits():
    rig = _arm(sustained_rms_v=2.0)  # the default 5 V sweeps: 2.04 V RMS over 60 s back to back
    plan = plan_calibration(rig)
    assert plan.pause_s > 0
    assert "--amplitude-v 4.9 needs no pause" in plan.describe()
    drives = plan_module._take_drives(plan, rig.layout.n_actuators)
    assert plan_levels(drives, rig.fs, rig.limits, pause_s=plan.pause_s).fits
    assert not plan_levels(drives, rig.fs, rig.limits, pause_s=plan.pause_s - 0.1).fits
    assert plan_calibration(rig, amplitude_v=4.9).pause_s == 0


def test_a_plan_no_pause_can_fix_is_refused_with_the_amplitude_that_fits():
    rig = _arm(rms_v=3.0)  # a 5 V sweep holds 3.5 V RMS over 1 s by itself
    with pytest.raises(SafetyError, match=r"nothing was played: .*over rms_v = 3 V.*--amplitude-v (\d\.\d+)") as info:
        plan_calibration(rig)
    amplitude = float(info.value.args[0].rsplit(" ", 1)[1])
    assert 4.0 < amplitude < 5.0
    assert plan_calibration(rig, amplitude_v=amplitude).pause_s == 0


def test_the_calibration_pauses_between_sweeps_instead_of_failing_midway(monkeypatch):
    rig = _arm(sustained_rms_v=2.0, sustained_window_s=10.0)
    slept = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        rig.now += seconds

    monkeypatch.setattr(recording, "time", types.SimpleNamespace(sleep=sleep))
    # Without the pauses the third take is refused: 4.1 V RMS... over the sustained window.
    cal = calibrate(rig, participant_id="P01", repeats=4, sweep_s=1.0)
    assert cal.H.shape[1:] == (rig.layout.n_points, rig.layout.n_actuators)
    assert sum(slept) > 0


class _RetakingArm(_VirtualClockArm):
    """Takes its third recording again at once, as the audio rig does after lost samples."""

    calls = 0

    def _play_and_record(self, drive, points_xy, n_tail):
        self.calls += 1
        if self.calls == 3:
            self._admit(drive, "recording")  # the take again: admitted again, with no pause
        return super()._play_and_record(drive, points_xy, n_tail)


def test_a_take_refused_after_a_retake_waits_for_the_actuators_to_cool(monkeypatch):
    rig = _RetakingArm(seed=3)
    rig.limits = SafetyLimits(sustained_rms_v=2.0, sustained_window_s=10.0)
    told = []
    monkeypatch.setattr(recording, "time", types.SimpleNamespace(sleep=lambda s: setattr(rig, "now", rig.now + s)))
    calibrate(rig, participant_id="P01", repeats=4, sweep_s=1.0, progress=lambda d, t, m: told.append(m))
    # Four takes, and the third tried once more after its wait.
    assert rig.calls == 5 and any(m.startswith("pausing") for m in told)


def test_a_shown_plan_is_used_as_it_is_and_one_for_other_arguments_is_refused(monkeypatch):
    rig = _arm(sustained_rms_v=2.0, sustained_window_s=10.0)
    shown = plan_calibration(rig, repeats=4, sweep_s=1.0)
    assert shown.pause_s > 0
    searched = []
    from vibrofocus.rigs import safety

    monkeypatch.setattr(safety, "plan_levels", lambda *a, **k: searched.append(a) or plan_levels(*a, **k))
    monkeypatch.setattr(recording, "time", types.SimpleNamespace(sleep=lambda s: setattr(rig, "now", rig.now + s)))
    calibrate(rig, participant_id="P01", repeats=4, sweep_s=1.0, plan=shown)
    assert searched == []  # the pause search ran once, for the plan shown
    with pytest.raises(ValidationError, match="plan must be the CalibrationPlan that plan_calibration gives"):
        calibrate(rig, participant_id="P01", repeats=8, sweep_s=1.0, plan=shown)
