import numpy as np

from vibrofocus.calibration import calibrate, detect_clipping

from .firrig import FIRRig

QUICK = {"sweep_s": 0.5, "repeats": 3, "method": "h1"}


def _checks(cal):
    return {i.check for i in cal.quality.issues}


def test_a_clean_rig_gets_no_verdict(layout, firs):
    cal = calibrate(FIRRig(firs, layout, noise_m=1e-11, seed=1), participant_id="P", **QUICK)
    assert cal.quality.issues == []
    assert (cal.quality.verdicts() == "ok").all()
    np.testing.assert_array_equal(cal.quality.polarity, [1, 1, 1, 1])


def test_reversed_actuator_is_flagged(layout, firs):
    h = firs.copy()
    h[:, 1] *= -1  # A2 wired the wrong way round
    cal = calibrate(FIRRig(h, layout, noise_m=1e-11), participant_id="P", **QUICK)
    (issue,) = cal.quality.by_check("reversed_actuator")
    assert issue.actuator == 1 and issue.severity == "error"
    assert "A2 is reversed" in issue.message and "G2" in issue.message
    np.testing.assert_array_equal(cal.quality.polarity, [1, -1, 1, 1])
    assert not cal.quality.ok
    assert all("reversed" in v for v in cal.quality.verdicts()[:, 1])


def test_dead_actuator_is_flagged_and_not_called_reversed(layout, firs):
    h = firs.copy()
    h[:, 2] *= -1e-4  # A3 barely connected (and its sign meaningless)
    cal = calibrate(FIRRig(h, layout, noise_m=1e-11), participant_id="P", **QUICK)
    (issue,) = cal.quality.by_check("dead_actuator")
    assert issue.actuator == 2 and "A3 looks dead" in issue.message
    assert cal.quality.by_check("reversed_actuator") == []
    assert cal.quality.polarity[2] == 0


def test_one_connected_actuator_is_not_called_dead(layout, firs):
    # A loopback bench: only A1 reaches the input, the others are unconnected (zero).
    h = np.zeros_like(firs)
    h[:, 0] = firs[:, 0]
    cal = calibrate(FIRRig(h, layout, noise_m=1e-11), participant_id="P", **QUICK)
    dead = cal.quality.by_check("dead_actuator")
    assert sorted(i.actuator for i in dead) == [1, 2, 3]
    assert all("relative to the strongest actuator (A1)" in i.message for i in dead)


def test_point_that_barely_moves_is_flagged(layout, firs):
    h = firs.copy()
    h[4] *= 1e-3  # the vibrometer misses point 5
    cal = calibrate(FIRRig(h, layout, noise_m=1e-12), participant_id="P", **QUICK)
    (issue,) = cal.quality.by_check("still_point")
    assert issue.point == 4 and "point 5" in issue.message and "barely moves" in issue.message


def test_clipping_at_the_sensor_range_is_flagged(layout, firs):
    clean = calibrate(FIRRig(firs, layout), participant_id="P", **QUICK)
    clean_peak = np.abs(clean.recordings).max(axis=(1, 3)).T  # (P, A)
    sensor_range = np.sqrt(clean_peak.min() * clean_peak.max())  # between far and near
    rig = FIRRig(firs, layout, sensor_range_m=sensor_range)
    cal = calibrate(rig, participant_id="P", **QUICK)
    assert cal.quality.by_check("clipping") and not cal.quality.ok
    # Exactly the pairs whose clean response exceeds the range.
    np.testing.assert_array_equal(cal.quality.clipped, clean_peak >= sensor_range)
    assert 0 < cal.quality.clipped.sum() < cal.quality.clipped.size


def test_flat_top_is_detected_without_a_known_range(rng):
    t = np.arange(2000) / 1e4
    y = np.sin(2 * np.pi * 50 * t) + 1e-3 * rng.standard_normal(2000)
    assert not detect_clipping(y)
    assert detect_clipping(np.clip(y, -0.9, 0.9))


def test_low_snr_and_low_coherence_are_flagged(layout, firs):
    # In-band noise (0.18 µm RMS) near the far responses (0.26 µm RMS), below the near
    # ones (1.4 µm RMS): the far pairs lose SNR and, at the band edges, coherence.
    cal = calibrate(FIRRig(firs, layout, noise_m=4e-7, seed=2), participant_id="P", method="h1", sweep_s=0.5,
                    repeats=4)
    q = cal.quality
    assert q.by_check("low_snr") and q.by_check("low_coherence")
    far = np.unravel_index(np.argmin(q.band_gain), q.band_gain.shape)
    near = np.unravel_index(np.argmax(q.band_gain), q.band_gain.shape)
    assert q.snr_db[far] < 10 < q.snr_db[near]
    assert q.low_coherence_share[far] > 0.1 > q.low_coherence_share[near]
    assert "coherence below 0.5" in q.by_check("low_coherence")[0].message


def test_drive_at_the_limit_is_flagged(layout, firs):
    from vibrofocus.rigs.safety import SafetyLimits

    rig = FIRRig(firs, layout)
    rig.limits = SafetyLimits(peak_v=5.0)
    cal = calibrate(rig, participant_id="P", amplitude_v=5.0, **QUICK)
    assert "drive_at_limit" in _checks(cal)


def test_summary_table_has_a_row_per_point(fir_calibration):
    from rich.console import Console

    _, cal = fir_calibration
    console = Console(record=True, width=200)
    console.print(cal.summary_table())
    text = console.export_text()
    assert all(f"\n│ {label} " in text or f"\n┃ {label} " in text for label in ("1", "9", "G4"))
    assert "A4" in text and "ok" in text
