"""A refusal by a limit over time names a wait that is then kept; one that no wait lifts says so."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.defaults import FS_HZ
from vibrofocus.errors import CoolingError, SafetyError
from vibrofocus.rigs.devices import StoppedError
from vibrofocus.rigs.safety import EnergyBudget, SafetyLimits, play_paced
from vibrofocus.rigs.simulated import SimulatedForearm

FS = FS_HZ
LIMITS = SafetyLimits(sustained_rms_v=1.0, sustained_window_s=10.0)


def _tone(level_v: float, seconds: float, n: int = 4) -> np.ndarray:
    t = np.arange(int(seconds * FS)) / FS
    return np.tile(level_v * np.sqrt(2) * np.sin(2 * np.pi * 100 * t), (n, 1))


def test_a_drive_that_alone_breaks_the_sustained_limit_is_told_no_wait_helps():
    budget = EnergyBudget(LIMITS, 4, FS)
    with pytest.raises(SafetyError, match="no wait will ever admit it") as info:
        budget.admit(_tone(1.5, 8.0), 0.0)  # 1.5 V RMS for 8 s: 1.34 V RMS over 10 s from silence
    assert not isinstance(info.value, CoolingError)
    assert "wait 10" not in str(info.value)


def test_a_drive_refused_with_the_plays_before_it_names_a_wait_that_admits_it():
    budget = EnergyBudget(LIMITS, 4, FS)
    budget.admit(_tone(1.3, 5.0), 0.0)
    with pytest.raises(CoolingError) as info:
        budget.admit(_tone(1.3, 5.0), 5.0)
    budget.admit(_tone(1.3, 5.0), 5.0 + info.value.wait_s)


class _VirtualClockArm(SimulatedForearm):
    now = 0.0

    def _clock(self) -> float:
        return self.now


def test_play_paced_waits_the_named_time_and_then_plays():
    rig = _VirtualClockArm(seed=1, fs=FS)
    rig.limits = LIMITS
    waits = []

    def sleep(seconds: float) -> None:
        rig.now += seconds

    play_paced(rig, _tone(1.3, 5.0), sleep=sleep)
    play_paced(rig, _tone(1.3, 5.0), lambda wait_s, why: waits.append((wait_s, why)), sleep=sleep)
    assert rig.n_played == 2
    assert len(waits) == 1 and waits[0][0] > 0 and "sustained_rms_v" in waits[0][1]
    assert rig.now == pytest.approx(waits[0][0], abs=0.06)


def test_a_stop_during_the_wait_ends_the_play():
    rig = _VirtualClockArm(seed=1, fs=FS)
    rig.limits = LIMITS
    play_paced(rig, _tone(1.3, 5.0), sleep=lambda s: None)

    def sleep(seconds: float) -> None:
        rig.now += seconds
        rig.stop()

    with pytest.raises(StoppedError):
        play_paced(rig, _tone(1.3, 5.0), sleep=sleep)
    assert rig.n_played == 1
