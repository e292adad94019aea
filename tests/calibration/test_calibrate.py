import numpy as np
import pytest

from vibrofocus import ArrayLayout
from vibrofocus.calibration import Calibration, calibrate
from vibrofocus.errors import SafetyError, ValidationError
from vibrofocus.rigs.safety import SafetyLimits

from .firrig import FIRRig


def _band(freqs, band=(10.0, 1000.0)):
    return (freqs >= band[0]) & (freqs <= band[1])


def test_noise_free_fir_rig_is_recovered(fir_calibration):
    rig, cal = fir_calibration
    assert isinstance(cal, Calibration)
    assert cal.H.shape == (cal.n_fft // 2 + 1, 13, 4) and cal.n_fft == 4096
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    # Exact up to the band-limited deconvolution, whose taper below 10 Hz rings longer
    # than the 4096-sample window: 2e-3 of each pair's largest gain at the band's low
    # edge, 1e-4 from 100 Hz up.
    scale = np.abs(truth[b]).max(axis=0)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * scale)
    upper = (cal.freqs >= 100) & (cal.freqs <= 1000)
    assert np.all(np.abs(cal.H[upper] - truth[upper]) <= 2e-4 * scale)
    np.testing.assert_allclose(cal.coherence[b], 1.0, atol=1e-6)
    assert cal.quality.ok and not cal.quality.issues


def test_transfer_for_other_window_lengths_matches_the_analytic_fir(fir_calibration):
    rig, cal = fir_calibration
    for n in (8192, 2048):
        H = cal.transfer_for(n)
        f = np.fft.rfftfreq(n, 1 / cal.fs)
        b = _band(f)
        truth = rig.transfer(n)
        assert H.shape == (n // 2 + 1, 13, 4)
        scale = np.abs(truth[b]).max(axis=0)
        assert np.all(np.abs(H[b] - truth[b]) <= 2e-3 * scale), n
        # Marked outside the band: tapered to exactly zero half an octave beyond the edges.
        assert np.all(H[(f < 7.0) | (f > 1415.0)] == 0)
        assert np.all(H[(f > 10.0) & (f < 1000.0)] != 0)


def test_transfer_for_refuses_odd_lengths(fir_calibration):
    with pytest.raises(ValidationError, match="even integer"):
        fir_calibration[1].transfer_for(1001)


def test_single_spot_vibrometer_prompts_for_each_point(layout, firs):
    rig = FIRRig(firs, layout, single_spot=True)
    asked = []

    def prompt(label, xy):
        asked.append(label)
        rig.aim(label, xy)  # the operator moves the spot there

    steps, messages = [], []
    cal = calibrate(rig, participant_id="P", method="h1", sweep_s=0.5, repeats=2, prompt=prompt,
                    progress=lambda done, total, msg: (steps.append((done, total)), messages.append(msg)))
    assert asked == list(layout.point_labels)
    # The plan first (0 done), then two calls per take: as it starts ("playing") and when done.
    assert steps[0] == (0, 104) and steps[-1] == (13 * 4 * 2, 13 * 4 * 2) and len(steps) == 2 * 13 * 4 * 2 + 1
    starts = [i for i, m in enumerate(messages) if m.endswith(": playing")]
    assert starts == list(range(1, len(steps), 2))
    assert all(steps[i] == steps[i - 1] and steps[i + 1][0] == steps[i][0] + 1 for i in starts)
    take_s = (0.1 + 0.5 + 0.3)  # silence, sweep, tail
    assert "104 takes" in messages[0] and f"{104 * take_s:.1f} s of sweeps" in messages[0], messages[0]
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


def test_single_spot_rig_without_prompt_is_refused_before_playing(layout, firs):
    rig = FIRRig(firs, layout, single_spot=True)
    with pytest.raises(ValidationError, match="prompt"):
        calibrate(rig, participant_id="P")
    assert rig.n_recordings == 0


def test_unsafe_sweep_is_refused_before_any_recording(layout, firs):
    rig = FIRRig(firs, layout)
    with pytest.raises(SafetyError, match="RMS"):
        calibrate(rig, participant_id="P", amplitude_v=8.0)  # 5.7 V RMS > 4 V
    rig = FIRRig(firs, layout)
    rig.limits = SafetyLimits(peak_v=2.0)
    with pytest.raises(SafetyError, match="peak"):
        calibrate(rig, participant_id="P")
    assert rig.n_recordings == 0


def test_dropouts_are_left_out_and_reported(layout, firs):
    rig = FIRRig(firs, layout, noise_m=1e-10, dropout_prob=0.2, seed=3)
    cal = calibrate(rig, participant_id="P", method="h1", sweep_s=0.5, repeats=3)
    q = cal.quality
    assert q.dropouts.sum() > 0
    assert np.all(q.repeats_used + q.dropouts >= 3)
    (issue,) = q.by_check("dropouts")
    assert f"{q.dropouts.sum()} recording(s)" in issue.message
    assert np.isnan(cal.recordings).any()  # kept raw, as recorded
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 1e-2 * np.abs(truth[b]).max(axis=0))


def test_paper_method_with_one_repeat_has_no_coherence(layout, firs):
    rig = FIRRig(firs, layout)
    cal = calibrate(rig, participant_id="P", method="paper", sweep_s=1.0)
    assert cal.sweep.kind == "linear" and cal.sweep.repeats == 1
    assert np.isnan(cal.coherence).all()
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


def test_subset_of_points_and_actuators(layout, firs):
    rig = FIRRig(firs, layout)
    cal = calibrate(rig, participant_id="P", method="h1", points=[4, 9, 0], actuators=[2, 1], sweep_s=0.5,
                    repeats=2)
    assert cal.layout.n_locations == 2 and cal.layout.n_guards == 1
    assert cal.layout.actuator_names == ("A2", "A3")
    np.testing.assert_allclose(cal.layout.points_xy, layout.points_xy[[0, 4, 9]])
    truth = rig.transfer(cal.n_fft)[:, [0, 4, 9]][:, :, [1, 2]]
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"participant_id": ""}, "participant_id"),
        ({"method": "mls"}, "method"),
        ({"points": [0, 13]}, "points"),
        ({"points": [0, 0]}, "twice"),
        ({"actuators": []}, "actuators"),
        ({"n_fft": 1000 + 1}, "n_fft"),
        ({"n_fft": 512}, "coarser"),
        ({"band": (10.0, 6000.0)}, "band"),
    ],
)
def test_bad_arguments_are_refused(layout, firs, kwargs, match):
    rig = FIRRig(firs, layout)
    args = {"participant_id": "P", **kwargs}
    with pytest.raises(ValidationError, match=match):
        calibrate(rig, **args)
    assert rig.n_recordings == 0


def test_rig_must_be_a_rig():
    with pytest.raises(ValidationError, match="Rig"):
        calibrate(object(), participant_id="P")


def test_other_layouts_work_unchanged(firs):
    # Three actuators in a row, five locations, no guards.
    lay = ArrayLayout(np.array([[-0.03, 0.0], [0.0, 0.0], [0.03, 0.0]]),
                      np.array([[x, 0.01] for x in (-0.02, -0.01, 0.0, 0.01, 0.02)]))
    from .firrig import analytic_firs

    rig = FIRRig(analytic_firs(lay, 10_000.0), lay)
    cal = calibrate(rig, participant_id="P", method="h1", sweep_s=0.5, repeats=2)
    assert cal.H.shape[1:] == (5, 3)
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


def test_samples_flagged_by_the_rig_count_as_dropouts(layout, firs):
    class FlaggingRig(FIRRig):
        """Flags a dropout without writing NaN (a vibrometer's signal-level flag)."""

        def _play_and_record(self, drive, points_xy, n_tail):
            y = super()._play_and_record(drive, points_xy, n_tail)
            self.last_dropout_mask = np.zeros(y.shape, bool)
            if self.n_recordings == 2:
                self.last_dropout_mask[3, 500:520] = True
                y[3, 500:520] = 1e-3  # garbage, not NaN
            return y

    cal = calibrate(FlaggingRig(firs, layout), participant_id="P", method="h1", sweep_s=0.5, repeats=2)
    assert cal.quality.dropouts[3, 0] == 1 and cal.quality.dropouts.sum() == 1
    assert np.isnan(cal.recordings[0, 1, 3, 500:520]).all()
    truth = FIRRig(firs, layout).transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


def test_clipping_reported_by_the_rig_is_a_verdict(layout, firs):
    class ReportingRig(FIRRig):
        """Its converter clipped during one take of point 7 (invisible in displacement)."""

        def _play_and_record(self, drive, points_xy, n_tail):
            y = super()._play_and_record(drive, points_xy, n_tail)
            self.last_clipped = np.arange(len(y)) == 6 if self.n_recordings == 5 else False
            return y

    cal = calibrate(ReportingRig(firs, layout), participant_id="P", method="h1", sweep_s=0.5, repeats=2)
    expected = np.zeros((13, 4), bool)
    expected[6, 2] = True  # take 5 = actuator A3 (index 2), first repeat
    np.testing.assert_array_equal(cal.quality.clipped, expected)
    (issue,) = cal.quality.by_check("clipping")
    assert "point 7 / A3" in issue.message and not cal.quality.ok
