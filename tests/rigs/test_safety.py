"""The safety layer, exercised through the simulated forearm: a refused drive never
reaches the actuators."""

import numpy as np
import pytest

from vibrofocus import SafetyLimits, SimulatedForearm
from vibrofocus.errors import SafetyError
from vibrofocus.rigs.safety import check_drive

FS = 10_000.0


@pytest.fixture
def rig() -> SimulatedForearm:
    return SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0,
                            limits=SafetyLimits(peak_v=10.0, rms_v=4.0, max_duration_s=1.0))


def _bad_drives():
    ok = np.zeros((4, 1000))
    over = ok.copy()
    over[2, 500] = 10.5
    nan = ok.copy()
    nan[1, 10] = np.nan
    inf = ok.copy()
    inf[0, 0] = np.inf
    loud = np.full((4, 1000), 5.0)  # 5 V RMS on every channel, peak within limit
    return {
        "over the peak limit": (over, "channel 3 reaches 10.5 V"),  # numbered from 1
        "NaN": (nan, "first on channel 2 at sample 10"),
        "Inf": (inf, "NaN/Inf"),
        "over the RMS limit": (loud, "RMS"),
        "too long": (np.zeros((4, 10_001)), "longer than the limit"),
        "wrong channel count": (np.zeros((3, 100)), "n_actuators=4"),
        "empty": (np.zeros((4, 0)), "no samples"),
        "complex": (np.zeros((4, 10), complex), "real"),
    }


@pytest.mark.parametrize("case", list(_bad_drives()))
@pytest.mark.parametrize("how", ["play", "play_and_record"])
def test_bad_drive_is_refused_before_anything_plays(rig, case, how):
    drive, words = _bad_drives()[case]
    with pytest.raises(SafetyError, match=words):
        getattr(rig, how)(drive)
    assert rig.n_played == 0 and rig.last_drive is None
    np.testing.assert_array_equal(rig.outputs_v, 0.0)


def test_a_drive_at_the_limit_plays_faded(rig):
    t = np.arange(2000) / FS
    drive = np.tile(np.where(np.abs(t - 0.1) < 0.005, 10.0, 0.0) * np.sin(2 * np.pi * 200 * t), (4, 1))
    drive[:, :3] = 1.0  # a step at the start, which the fade must remove
    rig.play(drive)
    assert rig.n_played == 1
    played = rig.last_drive
    assert played[:, 0].max() == 0.0  # fade-in starts from zero
    assert np.all(np.abs(played) <= np.abs(drive) + 1e-15)  # fades never amplify
    np.testing.assert_array_equal(played[:, 100:-100], drive[:, 100:-100])  # the middle is untouched


def test_check_drive_returns_what_plays(rig):
    drive = np.random.default_rng(3).uniform(-1, 1, (4, 800))
    expected = check_drive(drive, FS, 4, rig.limits)
    rig.play(drive)
    np.testing.assert_array_equal(rig.last_drive, expected)
