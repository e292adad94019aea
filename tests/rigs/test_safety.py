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
    loud = np.full((4, 10_000), 5.0)  # 5 V RMS over 1 s on every channel, peak within limit
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


# ---------------------------------------------------------------- RMS over a sliding window
def _sine(peak_v, seconds, f=200.0):
    t = np.arange(int(round(seconds * FS))) / FS
    return peak_v * np.sin(2 * np.pi * f * t)


def test_zero_padding_cannot_dilute_the_rms_limit():
    # 10 V peak for 5 s, then 25 s of zeros: 2.89 V RMS over the whole drive, 7.07 V over any 1 s of the sine.
    d = np.tile(np.concatenate([_sine(10.0, 5.0), np.zeros(int(25 * FS))]), (4, 1))
    assert np.sqrt(np.mean(d**2)) < 4.0
    with pytest.raises(SafetyError, match=r"channel 1 reaches 7.071 V RMS over 1 s, over the limit of 4 V RMS"):
        check_drive(d, FS, 4, SafetyLimits())


@pytest.mark.parametrize("seconds, refused", [(0.3, False), (0.33, True), (5.0, True)])
def test_a_short_burst_counts_over_the_whole_window(seconds, refused):
    # 10 V peak sine: 50 V^2 per s; over a 1 s window, 4 V RMS is 16 V^2 s, so at most 0.32 s of it.
    d = np.tile(_sine(10.0, seconds), (4, 1))
    if refused:
        with pytest.raises(SafetyError, match="V RMS"):
            check_drive(d, FS, 4, SafetyLimits())
    else:
        check_drive(d, FS, 4, SafetyLimits())


def test_windowed_rms_against_a_direct_loop(rng):
    x = rng.standard_normal((2, 500))
    from vibrofocus.rigs.safety import windowed_rms

    n = 64
    direct = [max(np.sqrt(np.sum(ch[i:i + n] ** 2) / n) for i in range(500 - n + 1)) for ch in x]
    np.testing.assert_allclose(windowed_rms(x**2, n), direct, rtol=1e-12)
    np.testing.assert_allclose(windowed_rms(x[:, :10] ** 2, n), np.sqrt(np.sum(x[:, :10] ** 2, axis=1) / n),
                               rtol=1e-12)


def test_back_to_back_plays_share_one_budget(rig):
    # 0.3 s of a 10 V sine passes alone (15 V^2 s); a second one right after would make 30 V^2 s in 1 s.
    burst = np.tile(_sine(10.0, 0.3), (4, 1))
    rig.limits = SafetyLimits(peak_v=10.0, rms_v=4.0, max_duration_s=1.0)
    rig.play(burst)
    with pytest.raises(SafetyError, match="together with the plays before it.*wait"):
        rig.play(burst)
    assert rig.n_played == 1


def test_the_budget_recovers_after_the_window():
    from vibrofocus.rigs.safety import EnergyBudget

    burst = np.tile(_sine(10.0, 0.3), (4, 1))
    budget = EnergyBudget(SafetyLimits(), 4, FS)
    budget.admit(burst, start_s=100.0)
    with pytest.raises(SafetyError):
        budget.admit(burst, start_s=100.5)  # 0.2 s after the first ended
    budget.admit(burst, start_s=101.3)  # 1 s after the first ended: a fresh window
    with pytest.raises(SafetyError):
        budget.admit(burst, start_s=101.3)  # overlapping plays count as back to back


@pytest.mark.parametrize("field, value, words", [
    ("peak_v", 25.0, "hard ceiling of 20"), ("rms_v", 5.7, "hard ceiling of 5.66"),
    ("sustained_rms_v", 4.01, "hard ceiling of 4"),
    ("max_duration_s", 61.0, "hard ceiling of 60"), ("fade_s", 0.0, r"fade_s must lie in \[0.0001, 0.05\]"),
    ("fade_s", 100.0, "fade_s must lie in"), ("peak_v", float("inf"), "peak_v must be > 0 and finite"),
])
def test_limits_have_hard_ceilings_and_a_minimum_fade(field, value, words):
    from vibrofocus.errors import ValidationError

    with pytest.raises(ValidationError, match=words):
        SafetyLimits(**{field: value})


def test_a_value_just_over_the_limit_never_reads_as_the_limit():
    d = np.zeros((4, 100))
    d[0, 50] = 10.0 + 1e-6
    with pytest.raises(SafetyError, match=r"reaches 10.000001 V peak, over the limit of 10 V"):
        check_drive(d, FS, 4, SafetyLimits())


def test_the_short_ceiling_is_twice_the_assumed_rating_in_power():
    from vibrofocus.rigs.safety import ASSUMED_COIL_OHMS, ASSUMED_RATED_POWER_W, RMS_V_CEILING, SUSTAINED_RMS_V_CEILING

    np.testing.assert_allclose(RMS_V_CEILING**2 / ASSUMED_COIL_OHMS, 2 * ASSUMED_RATED_POWER_W, rtol=1e-12)
    np.testing.assert_allclose(SUSTAINED_RMS_V_CEILING**2 / ASSUMED_COIL_OHMS, ASSUMED_RATED_POWER_W, rtol=1e-12)


def test_a_duty_cycle_over_the_sustained_limit_is_refused_after_about_one_window():
    from vibrofocus.rigs.safety import EnergyBudget

    limits = SafetyLimits(rms_v=4.0, sustained_rms_v=2.5, sustained_window_s=60.0)
    burst = np.tile(_sine(3.0 * np.sqrt(2), 0.5), (4, 1))  # 3 V RMS for 0.5 s
    budget = EnergyBudget(limits, 4, FS)
    t, admitted = 0.0, 0
    with pytest.raises(SafetyError, match=r"over 60 s, over the limit of 2.5 V RMS \(sustained_rms_v\)"):
        while admitted < 1000:
            budget.admit(burst, start_s=t)
            admitted += 1
            t += 0.6  # 0.5 s on, 0.1 s off: over 60 s, 3 * sqrt(0.5 / 0.6) = 2.74 V RMS
    # Refused once the 60 s window holds more than (2.5 / 3)^2 * 60 = 41.7 s of the burst: about
    # 83 plays of 0.5 s; the 10 ms bins may refuse slightly earlier, never later.
    assert 80 <= admitted <= 84


@pytest.mark.parametrize("n", [1, 2])
def test_a_drive_too_short_for_its_fades_is_refused(n):
    with pytest.raises(SafetyError, match="cannot hold its fades"):
        check_drive(np.full((4, n), 1.0), FS, 4, SafetyLimits())


def test_at_a_low_rate_the_fade_is_at_least_one_sample():
    # 0.1 ms at 2 kHz is 0.2 samples: it must not round to no fade at all.
    out = check_drive(np.full((4, 50), 1.0), 2000.0, 4, SafetyLimits(fade_s=1e-4))
    np.testing.assert_array_equal(out[:, 0], 0.0)
    np.testing.assert_array_equal(out[:, -1], 0.0)


@pytest.mark.parametrize("drive, words", [
    (np.full((4, int(30 * FS)), 3.9), "DC"),  # 30 s of 3.9 V DC: under every voltage limit
    (np.tile(3.9 * np.sin(2 * np.pi * 2.0 * np.arange(int(5 * FS)) / FS), (4, 1)), "below 10 Hz"),
])
def test_dc_and_slow_drives_are_refused(drive, words):
    with pytest.raises(SafetyError, match=words):
        check_drive(drive, FS, 4, SafetyLimits(max_duration_s=30.0))


def test_the_calibration_sweeps_pass_the_slow_content_check():
    from vibrofocus.calibration.excitation import default_settings, make_excitation

    for method in ("mimo", "h1", "paper"):
        for band in ((10.0, 1000.0), (5.0, 1000.0)):
            sweep = np.atleast_2d(make_excitation(default_settings(method, FS, band)))
            check_drive(np.tile(sweep[:1], (4, 1)), FS, 4, SafetyLimits())


def test_a_play_that_began_late_moves_the_budgets_end_later():
    """delay_last: the plays after it are placed against where it played, not where it was admitted."""
    from vibrofocus.rigs.safety import EnergyBudget

    fs = 1000.0
    half_second = np.tile(5.0 * np.sqrt(2) * np.sin(2 * np.pi * 50 * np.arange(500) / fs), (1, 1))  # 5 V RMS
    # Two of them 0.4 s apart hold 25 * 0.6 V^2 over the worst 1 s: 3.87 V RMS, under 4 V.
    on_time = EnergyBudget(SafetyLimits(), 1, fs)
    on_time.admit(half_second, 0.0)
    on_time.admit(half_second, 0.9)
    # The first began 0.1 s later than admitted: the second, at the same time, is 0.3 s after it
    # (25 * 0.7 V^2: 4.18 V RMS), refused.
    late = EnergyBudget(SafetyLimits(), 1, fs)
    late.admit(half_second, 0.0)
    late.delay_last(0.1)
    with pytest.raises(SafetyError, match="together with the plays before it"):
        late.admit(half_second, 0.9)
