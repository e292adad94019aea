"""Calibration of the simulated forearm, checked against its true transfer, and designs
from the estimate played back on the arm."""

import numpy as np
import pytest

from vibrofocus.calibration import calibrate, transfer_error
from vibrofocus.rendering import InverseOperator, focus_metrics, render
from vibrofocus.signals import ricker


def median_relative_error(cal, rig):
    """Where the true response is within 40 dB of its peak: beyond that realistic skin
    damps it below the vibrometer's noise, and no method measures it."""
    truth = rig.transfer(rig.layout.points_xy, cal.freqs)
    band = (cal.freqs >= cal.band[0]) & (cal.freqs <= cal.band[1])
    return transfer_error(cal.H[band], truth[band])["median_relative_error"]


def play_clean(rig, drives, tries=5):
    """Play and record; repeat a recording spoiled by a vibrometer dropout."""
    for _ in range(tries):
        y = rig.play_and_record(drives, tail_s=0.0)
        if np.isfinite(y).all():
            return y
    raise AssertionError("every recording dropped out")


def test_default_method_is_within_5_percent_of_the_true_transfer(forearm_calibration):
    rig, cal = forearm_calibration
    err = median_relative_error(cal, rig)
    print(f"median relative error, mimo (8 takes of 2.5 s exponential sweeps, all actuators): {err:.2%}")
    assert err < 0.05


def test_paper_method_is_less_accurate_than_the_default(forearm_calibration):
    from vibrofocus.rigs import SimulatedForearm

    rig, cal = forearm_calibration
    paper_rig = SimulatedForearm(seed=0)
    paper = calibrate(paper_rig, participant_id="S00", method="paper")
    err_default, err_paper = median_relative_error(cal, rig), median_relative_error(paper, paper_rig)
    print(f"median relative error: mimo {err_default:.2%}, paper (one 2 s linear sweep) {err_paper:.2%}")
    assert err_default < err_paper < 0.10


def test_the_simulated_participant_passes_the_quality_checks(forearm_calibration):
    rig, cal = forearm_calibration
    q = cal.quality
    assert q.ok, q.lines()
    np.testing.assert_array_equal(q.polarity, [1, 1, 1, 1])
    # Every recording with NaN samples was counted as a dropout and left out.
    # mimo: recordings (takes, points, samples); a take serves every actuator.
    nan_takes = np.isnan(cal.recordings).any(axis=-1).sum(axis=0)  # (points,)
    np.testing.assert_array_equal(q.dropouts, np.repeat(nan_takes[:, None], 4, axis=1))
    assert np.all(q.repeats_used >= 8 - q.dropouts)
    # Coherent where the skin carries the vibration: near each actuator, over the band.
    near = np.linalg.norm(rig.layout.points_xy[:, None] - rig.layout.actuators_xy[None], axis=-1).argmin(axis=0)
    band = (cal.freqs >= 10) & (cal.freqs <= 1000)
    assert np.all(cal.coherence[band][:, near, np.arange(4)] > 0.9)


def test_designs_from_the_estimate_focus_like_designs_from_the_truth(forearm_calibration):
    rig, cal = forearm_calibration
    n = 4096
    H_est = cal.transfer_for(n)
    H_true = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(n, 1 / rig.fs))
    for location in rig.layout.location_numbers:
        fid = []
        for H in (H_est, H_true):
            r = render("inverse", H, cal.fs, cal.layout, location, limit_v=rig.limits.peak_v)
            y = play_clean(rig, r.drives)
            fid.append(focus_metrics(y, r.target_index, r.desired, rig.fs)["fidelity"])
        print(f"location {location}: fidelity from estimated H {fid[0]:.3f}, from true H {fid[1]:.3f}")
        assert fid[0] == pytest.approx(fid[1], abs=0.02)


def test_target_only_inverse_from_the_estimate_focuses_like_one_from_the_truth(forearm_calibration):
    # With realistic skin (about 190 Np/m at 250 Hz) no design reaches every location
    # with the whole tap: the high frequencies die within a few centimetres. What a
    # calibration must give is a design as good as the true transfer allows.
    rig, cal = forearm_calibration
    n = 4096
    H_est = cal.transfer_for(n)
    H_true = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(n, 1 / rig.fs))
    stimulus = 2e-6 * ricker(rig.fs, 1e-3, n / rig.fs, 0.5 * n / rig.fs)
    for location in rig.layout.location_numbers:
        target = location - 1
        fid = []
        for H in (H_est, H_true):
            op = InverseOperator(H, cal.fs, n_samples=n, control=[target], band=cal.band)
            drives = op.drives_for_point(target, stimulus)
            drives *= min(1.0, 0.95 * rig.limits.peak_v / np.abs(drives).max())  # fidelity ignores scale
            y = play_clean(rig, drives)
            fid.append(focus_metrics(y, target, op.band_limit(stimulus), rig.fs)["fidelity"])
        print(f"location {location}: target-only inverse fidelity from estimate {fid[0]:.3f}, truth {fid[1]:.3f}")
        assert fid[0] >= fid[1] - 0.03


def test_dead_and_reversed_actuators_on_the_simulated_arm_are_flagged():
    from dataclasses import replace

    from vibrofocus.rigs import SimulatedForearm

    from vibrofocus.skin import ForearmParameters

    class MiswiredForearm(SimulatedForearm):
        """The forearm with actuator A3's two wires swapped: its drive arrives negated."""

        def _play_and_record(self, drive, points_xy, n_tail):
            return super()._play_and_record(drive * np.array([[1.0], [1.0], [-1.0], [1.0]]), points_xy, n_tail)

    reversed_cal = calibrate(MiswiredForearm(seed=4), participant_id="S04", repeats=4, sweep_s=1.0)
    (issue,) = reversed_cal.quality.by_check("reversed_actuator")
    assert issue.actuator == 2 and "A3 is reversed" in issue.message
    assert reversed_cal.quality.by_check("dead_actuator") == []

    lay = SimulatedForearm(seed=4).layout
    params = ForearmParameters.draw(4, lay)
    weak = replace(params, gains=params.gains * np.array([1.0, 1e-3, 1.0, 1.0]))  # A2 barely driven
    dead_cal = calibrate(SimulatedForearm(seed=4, participant=weak), participant_id="S04", repeats=4, sweep_s=1.0)
    (issue,) = dead_cal.quality.by_check("dead_actuator")
    assert issue.actuator == 1 and "A2 looks dead" in issue.message
    assert dead_cal.quality.by_check("reversed_actuator") == []


def test_strap_forces_are_stored_with_the_calibration(forearm_calibration, tmp_path):
    from vibrofocus.calibration import load_calibration, save_calibration

    rig, cal = forearm_calibration
    assert cal.straps is not None
    np.testing.assert_allclose(cal.straps["forces_n"], rig.read_strap_forces(), rtol=1e-12)
    loaded = load_calibration(save_calibration(cal, tmp_path / "with_straps.nc"))
    assert loaded.straps == cal.straps
