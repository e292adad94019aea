"""All actuators at once: Hadamard-signed sweeps, the MIMO H1 estimator, its verdicts and file."""

from pathlib import Path

import numpy as np
import pytest
import scipy.signal

from vibrofocus.calibration import (
    assess_quality,
    calibrate,
    hadamard_codes,
    load_calibration,
    mimo_h1,
    plan_calibration,
    save_calibration,
)
from vibrofocus.errors import CalibrationFileError, ValidationError

from .firrig import FIRRig

DATA = Path(__file__).parent / "data"


def _band(freqs):
    return (freqs >= 10.0) & (freqs <= 1000.0)


def _complex_normal(rng, shape):
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)


# ------------------------------------------------------------------ the estimator
def test_mimo_h1_recovers_a_known_fir_mimo_system_exactly_without_noise():
    # 3 inputs, 2 outputs, FIRs of 40 taps; 5 blocks of periodic white noise. In the
    # second period of a periodic input the output of lfilter is the circular
    # convolution, so the DFT relation Y = H X holds exactly with H = rfft(h, n).
    rng = np.random.default_rng(11)
    n, n_in, n_out, n_blocks = 256, 3, 2, 5
    h = rng.standard_normal((n_out, n_in, 40)) * np.exp(-np.arange(40) / 8.0)
    x = rng.standard_normal((n_blocks, n_in, n))
    y = np.zeros((n_blocks, n_out, n))
    for p in range(n_out):
        for a in range(n_in):
            y[:, p] += scipy.signal.lfilter(h[p, a], [1.0], np.tile(x[:, a], 2), axis=-1)[:, n:]
    est = mimo_h1(np.fft.rfft(x, axis=-1), np.fft.rfft(y, axis=-1))
    truth = np.moveaxis(np.fft.rfft(h, n, axis=-1), -1, 0)  # (F, P, A)
    np.testing.assert_allclose(est.H, truth, rtol=0, atol=1e-10 * np.abs(truth).max())
    np.testing.assert_allclose(est.multiple_coherence, 1.0, rtol=0, atol=1e-9)
    assert np.all(np.isfinite(est.condition_number)) and est.n_used.tolist() == [5, 5]


def test_mimo_h1_equals_a_weighted_least_squares_per_frequency(rng):
    # Noise and a dropped block at one output: the batched estimate is the least-squares
    # fit over the blocks kept, frequency by frequency (reference: numpy.linalg.lstsq).
    n_blocks, n_in, n_out, n_f = 9, 4, 3, 7
    X = _complex_normal(rng, (n_blocks, n_in, n_f))
    Y = _complex_normal(rng, (n_blocks, n_out, n_f))
    valid = np.ones((n_blocks, n_out), bool)
    valid[[2, 5], 1] = False
    Y[2, 1] = np.nan  # a dropout's garbage is ignored where the block is not kept
    est = mimo_h1(X, Y, valid)
    for p in range(n_out):
        keep = valid[:, p]
        for f in range(n_f):
            ref = np.linalg.lstsq(X[keep, :, f], Y[keep, p, f], rcond=None)[0]
            np.testing.assert_allclose(est.H[f, p], ref, rtol=1e-10)
    assert est.n_used.tolist() == [9, 7, 9]


def test_coherences_equal_the_analytic_values_with_planted_noise():
    # Independent unit-power inputs and output noise of known power N(f): the multiple
    # coherence is S / (S + N) with S = sum_a |H_a|^2, the partial coherence of input a
    # is |H_a|^2 / (|H_a|^2 + N). With 4000 blocks the estimates' spread is about 0.01.
    rng = np.random.default_rng(5)
    n_blocks, n_in, n_out = 4000, 3, 2
    noise_power = np.array([0.05, 0.3, 1.0, 3.0, 10.0])
    H = _complex_normal(rng, (noise_power.size, n_out, n_in))
    X = _complex_normal(rng, (n_blocks, n_in, noise_power.size))
    Y = np.einsum("fpa,raf->rpf", H, X) + np.sqrt(noise_power) * _complex_normal(rng, (n_blocks, n_out, noise_power.size))
    est = mimo_h1(X, Y)
    signal = (np.abs(H) ** 2).sum(axis=-1)
    np.testing.assert_allclose(est.multiple_coherence, signal / (signal + noise_power[:, None]), rtol=0, atol=0.03)
    own = np.abs(H) ** 2
    np.testing.assert_allclose(est.partial_coherence, own / (own + noise_power[:, None, None]), rtol=0, atol=0.03)
    assert est.input_correlation.max() < 0.1 and est.condition_number.max() < 1.2


def test_pure_noise_gives_the_stated_coherence_floors():
    # Documented floors: multiple coherence n_inputs / n_blocks, partial coherence
    # 1 / (n_blocks - n_inputs + 1); averaged over 4000 frequencies (spread < 0.003).
    rng = np.random.default_rng(8)
    n_blocks, n_in, n_f = 8, 4, 4000
    est = mimo_h1(_complex_normal(rng, (n_blocks, n_in, n_f)), _complex_normal(rng, (n_blocks, 1, n_f)))
    np.testing.assert_allclose(est.multiple_coherence.mean(), n_in / n_blocks, rtol=0, atol=0.01)
    np.testing.assert_allclose(est.partial_coherence.mean(), 1 / (n_blocks - n_in + 1), rtol=0, atol=0.01)
    # No more blocks than inputs: not assessable.
    few = mimo_h1(_complex_normal(rng, (4, n_in, 3)), _complex_normal(rng, (4, 1, 3)))
    assert np.isnan(few.multiple_coherence).all() and np.isnan(few.partial_coherence).all()


def test_mimo_h1_refuses_mismatched_inputs(rng):
    with pytest.raises(ValidationError, match="inputs"):
        mimo_h1(np.ones((3, 2, 5)), np.ones((4, 1, 5)))
    with pytest.raises(ValidationError, match="NaN"):
        mimo_h1(np.ones((3, 1, 1)), np.full((3, 1, 5), np.nan))


# ------------------------------------------------------------------ the excitations
@pytest.mark.parametrize("n_actuators, repeats", [(1, 2), (2, 2), (3, 4), (4, 4), (4, 8), (4, 12), (5, 8), (8, 16)])
def test_hadamard_codes_are_exactly_orthogonal(n_actuators, repeats):
    codes = hadamard_codes(n_actuators, repeats)
    assert codes.shape == (repeats, n_actuators) and set(np.unique(codes)) <= {-1, 1}
    np.testing.assert_array_equal(codes.T.astype(int) @ codes, repeats * np.eye(n_actuators, dtype=int))
    if repeats & -repeats > n_actuators:  # block larger than needed: every column balanced
        np.testing.assert_array_equal(codes.sum(axis=0), 0)


@pytest.mark.parametrize("n_actuators, repeats", [(4, 2), (4, 6), (3, 2), (5, 4), (5, 12)])
def test_hadamard_codes_refuse_takes_that_cannot_separate(n_actuators, repeats):
    with pytest.raises(ValidationError, match="multiple of"):
        hadamard_codes(n_actuators, repeats)


class _DriveLoggingRig(FIRRig):
    """The FIR rig keeping every drive it played (after the safety layer's fades)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.played = []

    def _play_and_record(self, drive, points_xy, n_tail):
        self.played.append(np.array(drive))
        return super()._play_and_record(drive, points_xy, n_tail)


def test_the_played_excitations_are_uncorrelated_to_rounding(layout, firs):
    # Stated level: the actuators' drives over the takes are uncorrelated to 1e-12, in
    # time (zero lag) and per frequency of the band.
    rig = _DriveLoggingRig(firs, layout)
    cal = calibrate(rig, participant_id="P", method="mimo", sweep_s=0.5, repeats=8)
    drives = np.stack(rig.played)  # (takes, actuators, samples)
    assert drives.shape[:2] == (8, 4) and np.all(np.abs(drives).max(axis=-1) > 4.0)  # everyone plays every take
    gram = np.einsum("rat,rbt->ab", drives, drives)
    corr = np.abs(gram) / np.sqrt(np.outer(np.diag(gram), np.diag(gram)))
    np.testing.assert_allclose(corr - np.eye(4), 0.0, rtol=0, atol=1e-12)
    spectra = np.fft.rfft(drives, axis=-1)
    freqs = np.fft.rfftfreq(drives.shape[-1], 1 / rig.fs)
    cross = np.einsum("raf,rbf->fab", spectra, spectra.conj())[_band(freqs)]
    power = np.einsum("faa->fa", cross).real
    coh = np.abs(cross) / np.sqrt(power[:, :, None] * power[:, None, :])
    np.testing.assert_allclose(coh - np.eye(4), 0.0, rtol=0, atol=1e-12)
    # What the calibration reports about its own inputs.
    np.testing.assert_allclose(cal.quality.input_correlation, 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cal.quality.input_condition, 1.0, rtol=1e-12)


# ------------------------------------------------------------------ calibrate(method="mimo")
def test_mimo_calibration_equals_h1_on_a_noise_free_rig(layout, firs):
    # The same sweep, linear estimates: in a noise-free linear medium the separation is
    # exact, so mimo gives h1's estimate (to the float32 rounding of the stored
    # recordings) in a quarter of the takes.
    h1_rig, mimo_rig = FIRRig(firs, layout), FIRRig(firs, layout)
    h1 = calibrate(h1_rig, participant_id="P", method="h1", sweep_s=0.5, repeats=4)
    mimo = calibrate(mimo_rig, participant_id="P", method="mimo", sweep_s=0.5, repeats=4)
    assert (h1_rig.n_recordings, mimo_rig.n_recordings) == (16, 4)
    np.testing.assert_allclose(mimo.recorded_s, 4 * 0.9) and np.testing.assert_allclose(h1.recorded_s, 16 * 0.9)
    scale = np.abs(h1.H).max(axis=0)
    np.testing.assert_allclose(mimo.H, h1.H, rtol=0, atol=1e-6 * scale.max())
    truth = mimo_rig.transfer(mimo.n_fft)
    b = _band(mimo.freqs)
    assert np.all(np.abs(mimo.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))
    assert mimo.method == "mimo" and mimo.recordings.shape == (4, 13, h1.recordings.shape[-1])
    np.testing.assert_array_equal(mimo.codes, hadamard_codes(4, 4))
    assert mimo.quality.ok and mimo.quality.issues == []


def test_mimo_snr_matches_h1_per_pair_and_noise_is_equal(layout, firs):
    # Noise of 0.1 µm: each pair's SNR read from the all-at-once takes is what the pair
    # alone gives (h1), and with the same sweep per actuator the error is alike.
    h1_rig = FIRRig(firs, layout, noise_m=1e-7, seed=4)
    mimo_rig = FIRRig(firs, layout, noise_m=1e-7, seed=5)
    h1 = calibrate(h1_rig, participant_id="P", method="h1", sweep_s=0.5, repeats=8)
    mimo = calibrate(mimo_rig, participant_id="P", method="mimo", sweep_s=0.5, repeats=8)
    np.testing.assert_allclose(mimo.quality.snr_db, h1.quality.snr_db, rtol=0, atol=1.5)
    truth = h1_rig.transfer(h1.n_fft)
    b = _band(h1.freqs)
    err_h1 = np.median(np.abs(h1.H[b] - truth[b]))
    err_mimo = np.median(np.abs(mimo.H[b] - truth[b]))
    np.testing.assert_allclose(err_mimo, err_h1, rtol=0.1)
    # Where the response is strong both coherences are near 1; the multiple coherence too.
    near = np.abs(truth[b]) > 0.3 * np.abs(truth[b]).max(axis=0)
    assert np.median(mimo.coherence[b][near]) > 0.99 and np.nanmedian(mimo.multiple_coherence[b]) > 0.9


class _LossyPointRig(FIRRig):
    """Point 4 (index 3) drops out in takes 1 to 6: the two takes left cannot separate four actuators."""

    def _play_and_record(self, drive, points_xy, n_tail):
        y = super()._play_and_record(drive, points_xy, n_tail)
        if 1 <= self.n_recordings <= 6:
            y[3, 100:150] = np.nan
        return y


def test_lost_takes_are_recorded_again_until_the_actuators_separate(layout, firs):
    rig = _LossyPointRig(firs, layout)
    cal = calibrate(rig, participant_id="P", method="mimo", sweep_s=0.5, repeats=8)
    assert 8 < rig.n_recordings <= 8 + 3
    q = cal.quality
    assert q.dropouts[3].tolist() == [6] * 4 and q.dropouts.sum() == 24
    assert np.all(q.repeats_used[3] == 8 - 6 + (rig.n_recordings - 8))
    assert np.all(q.input_condition[:, 3] <= 10.0) and np.all(q.input_condition[:, 2] == pytest.approx(1.0))
    assert q.by_check("ill_conditioned") == []
    truth = rig.transfer(cal.n_fft)
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 2e-3 * np.abs(truth[b]).max(axis=0))


def test_a_reversed_and_a_dead_actuator_are_flagged_with_mimo(layout, firs):
    h = firs.copy()
    h[:, 3] *= -1
    cal = calibrate(FIRRig(h, layout, noise_m=1e-11), participant_id="P", method="mimo", sweep_s=0.5, repeats=4)
    assert [i.check for i in cal.quality.issues] == ["reversed_actuator"] and cal.quality.issues[0].actuator == 3
    h = firs.copy()
    h[:, 1] *= 1e-4
    cal = calibrate(FIRRig(h, layout, noise_m=1e-11), participant_id="P", method="mimo", sweep_s=0.5, repeats=4)
    (dead,) = cal.quality.by_check("dead_actuator")
    assert dead.actuator == 1


def test_separation_verdicts_from_the_figures(layout, fir_calibration):
    cal = fir_calibration[1]
    n_f, n_p = cal.H.shape[:2]
    condition, correlation = np.ones((n_f, n_p)), np.zeros((n_f, n_p))
    condition[300, 2] = 50.0  # point 3 cannot be separated at one frequency in the band
    correlation[:, 5] = 0.7  # point 6: correlated inputs
    multiple = np.ones((n_f, n_p))
    multiple[(cal.freqs > 200) & (cal.freqs < 600), 7] = 0.2  # point 8: the actuators explain little mid-band
    multiple[cal.freqs > 700, 8] = 0.2  # point 9: only at the top of the band (damped skin): info
    q = cal.quality
    report = assess_quality(cal.H, cal.coherence, cal.freqs, cal.band, cal.layout, snr_db=q.snr_db,
                            noise_rms_m=q.noise_rms_m, clipped=q.clipped, repeats_used=q.repeats_used + 2,
                            dropouts=q.dropouts, drive_peak_v=5.0, peak_limit_v=10.0, multiple_coherence=multiple,
                            input_condition=condition, input_correlation=correlation)
    (ill,) = report.by_check("ill_conditioned")
    assert ill.point == 2 and ill.severity == "error" and "50" in ill.message and not report.ok
    (corr,) = report.by_check("input_correlation")
    assert corr.point == 5 and corr.severity == "warning" and "0.70" in corr.message
    (low,) = report.by_check("low_multiple_coherence")
    assert low.point == 7 and "pure noise gives 1" in low.message  # 4 actuators / 4 repeats
    assert "200-598 Hz" in low.message, low.message
    (top,) = report.by_check("multiple_coherence_limit")
    assert top.point == 8 and top.severity == "info" and "to 701 Hz" in top.message, top.message
    assert (report.verdicts()[2] == "not separable").all()


# ------------------------------------------------------------------ the plan
def test_the_plan_gives_the_real_duration_of_every_method(layout, firs):
    rig = FIRRig(firs, layout)
    spot = FIRRig(firs, layout, single_spot=True)
    cases = [
        (rig, "h1", 4 * 8, 2.4), (rig, "paper", 4, 2.4), (rig, "mimo", 8, 2.9),
        (spot, "h1", 13 * 4 * 8, 2.4), (spot, "mimo", 13 * 8, 2.9),
    ]
    for r, method, takes, take_s in cases:
        plan = plan_calibration(r, method=method)
        assert plan.takes == takes, method
        np.testing.assert_allclose(plan.duration_s, takes * take_s, rtol=1e-12)
    assert plan_calibration(spot, method="h1").describe().endswith(
        "= 16 min 38 s of sweeps, plus aiming the vibrometer 13 times")
    assert "8 takes of 2.9 s" in plan_calibration(rig).describe()  # mimo by default
    assert rig.n_recordings == 0 and spot.n_recordings == 0  # planning plays nothing
    with pytest.raises(ValidationError, match="multiple of 4"):
        plan_calibration(rig, method="mimo", repeats=6)


def test_calibrate_reports_the_plan_before_the_first_take(layout, firs):
    rig = FIRRig(firs, layout)
    calls = []

    def progress(done, total, message):
        calls.append((done, total, message, rig.n_recordings))

    calibrate(rig, participant_id="P", sweep_s=0.5, repeats=4, progress=progress)
    done, total, message, recorded = calls[0]
    assert (done, total, recorded) == (0, 4, 0)
    assert message == "mimo: 4 takes of 0.9 s (all 4 actuators at once, 4 Hadamard-coded repeats, every point " \
                      "in each take) = 3.6 s of sweeps"
    # then each take twice: as it starts (nothing recorded yet for it) and once recorded
    assert [c[0] for c in calls] == [0, 0, 1, 1, 2, 2, 3, 3, 4]
    assert [c[3] for c in calls] == [0, 0, 1, 1, 2, 2, 3, 3, 4]


# ------------------------------------------------------------------ the file
@pytest.fixture(scope="module")
def mimo_calibration(layout, firs):
    rig = FIRRig(firs, layout, noise_m=1e-10, dropout_prob=0.1, seed=9)
    return calibrate(rig, participant_id="M01", method="mimo", sweep_s=0.5, repeats=8)


def test_a_mimo_calibration_survives_the_round_trip(mimo_calibration, tmp_path):
    cal = mimo_calibration
    assert cal.quality.dropouts.sum() > 0  # dropouts raised the input correlation somewhere
    assert cal.quality.input_correlation.max() > 0.1
    back = load_calibration(save_calibration(cal, tmp_path / "M01.nc"))
    assert back.schema_version == 2 and back.method == "mimo"
    for name in ("H", "coherence", "multiple_coherence", "codes", "recordings", "drives"):
        np.testing.assert_array_equal(getattr(back, name), getattr(cal, name), err_msg=name)
    for name in ("input_condition", "input_correlation", "snr_db", "dropouts", "repeats_used"):
        np.testing.assert_array_equal(getattr(back.quality, name), getattr(cal.quality, name), err_msg=name)
    assert back.recorded_s == cal.recorded_s and back.quality.issues == cal.quality.issues
    assert back.quality.thresholds == cal.quality.thresholds


def test_a_mimo_file_without_its_codes_or_with_schema_1_is_refused(mimo_calibration, tmp_path):
    import xarray as xr

    path = save_calibration(mimo_calibration, tmp_path / "M01.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        ds = ds.load()
    ds.drop_vars("code").to_netcdf(tmp_path / "nocode.nc", engine="h5netcdf")
    with pytest.raises(CalibrationFileError, match="nocode.nc: lacks the variable.*code"):
        load_calibration(tmp_path / "nocode.nc")
    old = ds.copy()
    old.attrs["schema_version"] = np.int32(1)
    old.to_netcdf(tmp_path / "v1.nc", engine="h5netcdf")
    with pytest.raises(CalibrationFileError, match="mimo but schema version 1"):
        load_calibration(tmp_path / "v1.nc")
    bad = ds.copy()
    bad["code"] = bad["code"] * 2
    bad.to_netcdf(tmp_path / "badcode.nc", engine="h5netcdf")
    with pytest.raises(CalibrationFileError, match="code must hold"):
        load_calibration(tmp_path / "badcode.nc")


def test_a_schema_1_file_written_before_mimo_still_loads(layout, firs):
    cal = load_calibration(DATA / "schema1_h1.nc")  # see data/README.md
    assert cal.schema_version == 1 and cal.method == "h1" and cal.codes is None and cal.multiple_coherence is None
    assert np.isnan(cal.recorded_s) and cal.quality.input_condition is None
    assert cal.quality.thresholds.condition_max == 10.0  # not in the file: the default
    truth = FIRRig(firs, layout).transfer(cal.n_fft)[:, :1, :2]
    b = _band(cal.freqs)
    assert np.all(np.abs(cal.H[b] - truth[b]) <= 5e-3 * np.abs(truth[b]).max(axis=0))
