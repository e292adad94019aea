"""Calibrating fewer points: which points a subset measures, the plan, the predicted rows
of H, their verdicts and their mark in the file."""

import numpy as np
import pytest
import xarray as xr
from numpy.testing import assert_array_equal

from vibrofocus import ArrayLayout
from vibrofocus.calibration import calibrate, load_calibration, plan_calibration, save_calibration
from vibrofocus.calibration.plan import subset_points
from vibrofocus.demo.trust import tap_band
from vibrofocus.errors import CalibrationFileError, ValidationError
from vibrofocus.rigs import SimulatedForearm

from ._netcdf import rewrite_netcdf


def _labels(layout, idx):
    return [layout.point_labels[i] for i in idx]


def test_the_subset_spreads_over_the_array():
    lay = ArrayLayout.reference()
    # Location 5 is nearest the centre; the guards are farthest from it and from each
    # other; then the edge locations (10 mm from location 5, 14 mm from the guards)
    # before the corners (5 mm from a guard).
    assert _labels(lay, subset_points(lay, 5)) == ["5", "G1", "G2", "G3", "G4"]
    assert _labels(lay, subset_points(lay, 9)) == ["2", "4", "5", "6", "8", "G1", "G2", "G3", "G4"]
    assert_array_equal(subset_points(lay, 13), np.arange(13))
    seven = subset_points(lay, 7)
    assert set(subset_points(lay, 5)) < set(seven) < set(subset_points(lay, 9))  # nested: K grows by adding
    for bad in (1, 14, 2.5, True):
        with pytest.raises(ValidationError, match="points to measure"):
            subset_points(lay, bad)


def test_the_plan_says_what_is_measured_predicted_and_saved():
    rig = SimulatedForearm(seed=1)
    full, plan = plan_calibration(rig), plan_calibration(rig, measure=7)
    assert plan.predicted_indices == (0, 2, 5, 6, 7, 8)
    assert plan.point_indices == (1, 3, 4, 9, 10, 11, 12)
    assert "measures 7 of 13 points and predicts the other 6" in plan.describe()
    assert full.predicted_indices == () and "predicts" not in full.describe()
    # The simulated rig records every point in each take: nothing saved there.
    assert plan.positions == full.positions == 1 and plan.positions_saved == 0 and plan.seconds_saved == 0


def test_on_a_single_spot_rig_each_predicted_point_saves_an_aim(monkeypatch):
    rig = SimulatedForearm(seed=1)
    monkeypatch.setattr(type(rig), "max_points_per_recording", 1, raising=False)
    full, plan = plan_calibration(rig), plan_calibration(rig, measure=5)
    assert (full.positions, plan.positions, plan.positions_saved) == (13, 5, 8)
    assert plan.seconds_saved == pytest.approx(8 * full.takes_per_position * full.settings.take_s)
    assert "8 aiming(s)" in plan.describe()


def test_bad_subsets_are_refused_before_anything_plays():
    rig = SimulatedForearm(seed=1)
    with pytest.raises(ValidationError, match="not both"):
        calibrate(rig, participant_id="S", points=[0, 1, 2], measure=2)
    with pytest.raises(ValidationError, match="points to measure"):
        calibrate(rig, participant_id="S", measure=14)
    with pytest.raises(ValidationError, match="at least 2"):
        calibrate(rig, participant_id="S", measure=[4])
    with pytest.raises(ValidationError, match="law"):
        calibrate(rig, participant_id="S", measure=5, fit_law="voigt")


@pytest.fixture(scope="module")
def subset():
    """Participant 1 on the nominal skin, 5 of 13 points measured (noise and dropouts on)."""
    return calibrate(SimulatedForearm(seed=1), participant_id="S01", measure=5)


@pytest.mark.slow
def test_the_predicted_rows_match_the_true_arm(subset):
    lay = subset.layout
    assert lay == ArrayLayout.reference() and subset.H.shape[1] == 13
    assert _labels(lay, np.flatnonzero(subset.measured)) == ["5", "G1", "G2", "G3", "G4"]
    assert_array_equal(subset.predicted_points, [0, 1, 2, 3, 5, 6, 7, 8])
    assert subset.fit is not None and subset.fit.law == "layered"
    assert subset.fit.info["points"] == list(np.flatnonzero(subset.measured))
    arm = SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)
    lo, hi = tap_band()
    band = (subset.freqs >= lo) & (subset.freqs <= hi)
    truth = arm.transfer(lay.points_xy, subset.freqs[band])
    err = np.linalg.norm(subset.H[band] - truth, axis=(0, 2)) / np.linalg.norm(truth, axis=(0, 2))
    # Predicted rows: the model family is the arm's, so within 1 % (about 0.02 % here);
    # measured rows carry the vibrometer noise (about 0.2-0.4 %).
    assert np.all(err[subset.predicted_points] < 0.01), err
    assert np.all(err[subset.measured] < 0.02), err
    # No figure of a recording where nothing was recorded.
    assert np.isnan(subset.coherence[:, subset.predicted_points]).all()
    assert np.isnan(subset.recordings[:, subset.predicted_points]).all()
    assert np.isfinite(subset.coherence[band][:, subset.measured]).all()


@pytest.mark.slow
def test_the_verdicts_name_the_predicted_points(subset):
    q = subset.quality
    predicted = q.by_check("predicted")
    assert [i.point for i in predicted] == list(subset.predicted_points)
    assert all(i.severity == "info" for i in predicted)
    assert q.ok and not q.by_check("fit_residual")  # the model fits: no warning
    verdicts = q.verdicts()
    assert (verdicts[subset.predicted_points] == "predicted").all()
    assert not np.char.find(verdicts[subset.measured].astype(str), "predicted").max() >= 0
    lines = q.lines()
    assert sum("not measured" in line for line in lines) == 1  # one line for all of them
    assert "point(s) 1, 2, 3, 4, 6, 7, 8, 9 were not measured" in " ".join(lines)


@pytest.mark.slow
def test_a_poor_fit_is_a_warning(subset):
    from dataclasses import replace

    from vibrofocus.calibration.quality import QualityThresholds, assess_quality

    q = subset.quality
    residual = subset.fit.residual.copy()
    kw = dict(snr_db=q.snr_db, noise_rms_m=q.noise_rms_m, clipped=q.clipped, repeats_used=q.repeats_used,
              dropouts=q.dropouts, drive_peak_v=1.0, peak_limit_v=10.0, measured=subset.measured)
    strict = assess_quality(subset.H, subset.coherence, subset.freqs, subset.band, subset.layout,
                            thresholds=replace(QualityThresholds(), fit_residual_max=np.nanmin(residual) / 2),
                            fit_residual=residual, **kw)
    flagged = [i.point for i in strict.by_check("fit_residual")]
    assert flagged == list(np.flatnonzero(subset.measured)) and strict.by_check("fit_residual")[0].severity == "warning"


@pytest.mark.slow
def test_the_file_says_which_rows_are_measured(subset, tmp_path):
    path = save_calibration(subset, tmp_path / "S01.nc")
    with xr.open_dataset(path, engine="h5netcdf") as ds:  # what any netCDF reader sees
        assert_array_equal(ds["point_measured"].values, subset.measured.astype(int))
        assert ds["point_measured"].attrs["flag_meanings"] == "predicted measured"
        assert "fit_value" in ds.variables
    back = load_calibration(path)
    assert_array_equal(back.measured, subset.measured)
    assert_array_equal(back.H, subset.H)
    assert back.quality.by_check("predicted") == subset.quality.by_check("predicted")


def test_a_full_calibration_file_marks_every_row_measured(fir_calibration, fir_calibration_file, tmp_path):
    _, cal = fir_calibration
    assert cal.measured is None and cal.measured_points.all() and cal.predicted_points.size == 0
    path = fir_calibration_file  # save_calibration(cal, ...), made once
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert (ds["point_measured"].values == 1).all()
    assert load_calibration(path).measured is None
    # A file from before the variable loads as every row measured.
    old = rewrite_netcdf(path, tmp_path / "old.nc", lambda ds: ds.drop_vars("point_measured"))
    assert load_calibration(old).measured is None


@pytest.mark.parametrize("values, match", [
    ([1] * 12 + [2], "0 .predicted. or 1"),
    ([0] * 13, "no point as measured"),
    ([1] * 12 + [0], "no fitted skin model"),
])
def test_a_hostile_point_measured_is_refused(fir_calibration_file, tmp_path, values, match):
    bad = rewrite_netcdf(fir_calibration_file, tmp_path / "bad.nc",
                   lambda ds: ds.assign(point_measured=("point", np.asarray(values, np.int8))))
    with pytest.raises(CalibrationFileError, match=match):
        load_calibration(bad)


@pytest.mark.parametrize("fixed, match", [
    ({"law": "bogus"}, "law"),
    ({"law": "layered", "skin": "bogus"}, "skin"),
    ({"law": "layered", "reference_hz": -1.0}, "reference_hz"),
])
def test_a_fitted_model_with_unusable_settings_is_refused_when_built(fixed, match):
    # What a stored fit with edited settings gives: refused at load, not at the first prediction.
    from vibrofocus.calibration import FittedSkin
    from vibrofocus.calibration.fitmodel import _nominal_law_values

    lay = ArrayLayout.reference()
    n = 4 + 4 * lay.n_actuators
    values = np.concatenate([_nominal_law_values("layered"), np.ones(4), np.full(4, 3e-3), np.full(4, 500.0),
                             np.ones(4)])
    with pytest.raises(ValidationError, match=match):
        FittedSkin(layout=lay, fs=10_000.0, band=(10.0, 1000.0), values=values, log_covariance=np.eye(n),
                   residual=np.zeros(lay.n_points), fixed=fixed)
    fine = FittedSkin(layout=lay, fs=10_000.0, band=(10.0, 1000.0), values=values, log_covariance=np.eye(n),
                      residual=np.full(lay.n_points, np.nan), fixed={"law": "layered"})
    assert fine.law == "layered" and fine.participant.layered is not None


@pytest.mark.slow
def test_a_single_spot_rig_is_aimed_at_the_measured_points_by_their_own_labels(monkeypatch):
    # The prompts and the progress name the layout's points (location 5, G1..G4), not a
    # renumbered subset.
    rig = SimulatedForearm(seed=2)
    monkeypatch.setattr(type(rig), "max_points_per_recording", 1, raising=False)
    prompts, messages = [], []
    cal = calibrate(rig, participant_id="S02", measure=5, repeats=4, sweep_s=0.5,
                    prompt=lambda label, xy: prompts.append((label, tuple(np.round(xy, 6)))),
                    progress=lambda done, total, message: messages.append(message))
    lay = rig.layout
    assert [p[0] for p in prompts] == ["5", "G1", "G2", "G3", "G4"]
    assert [p[1] for p in prompts] == [tuple(np.round(lay.points_xy[i], 6)) for i in (4, 9, 10, 11, 12)]
    assert "aiming the vibrometer 5 times" in messages[0] and "8 aiming(s)" in messages[0]
    assert any("point G3" in m for m in messages) and not any("point 6," in m or m.endswith("point 6") for m in messages)
    assert_array_equal(np.flatnonzero(cal.measured), [4, 9, 10, 11, 12])


@pytest.mark.slow
def test_robust_minimax_takes_the_fits_standard_error_at_the_predicted_points(subset):
    """The points the fit predicted have no coherence, so the robust design took no
    uncertainty there; it takes the fit's standard error (``FittedSkin.transfer_std``),
    and the coherence's radius at the measured points as before."""
    from vibrofocus.rendering import Minimax, coherence_radius

    tm = subset.transfer_matrix()
    radius = Minimax().h_radius(tm)
    pred, measured = subset.predicted_points, subset.measured
    assert np.all(np.max(radius[:, pred], axis=0) > 0)
    live = np.abs(tm.H[:, pred[0], 0]) > 0
    std = subset.fit.transfer_std(subset.layout.points_xy[pred[:1]], tm.freqs[live])[:, 0]
    taper = np.abs(tm.H[live, pred[0]]) / np.abs(subset.fit.transfer(subset.layout.points_xy[pred[:1]],
                                                                      tm.freqs[live])[:, 0])
    np.testing.assert_allclose(radius[live, pred[0]], std * taper, rtol=1e-6)
    averages = int(tm.provenance.get("averages", 1))
    np.testing.assert_allclose(radius[:, measured],
                               coherence_radius(tm.H, tm.coherence, averages=averages)[:, measured], rtol=1e-12)
