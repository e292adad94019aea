"""fit_model: the skin model fitted to a calibration recovers the simulated participant's
parameters, predicts H where nothing was measured, and travels with the file."""

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus.calibration import FittedSkin, fit_model, load_calibration, save_calibration
from vibrofocus.calibration.fitmodel import parameter_names, true_parameters
from vibrofocus.errors import ValidationError
from vibrofocus.rendering import render
from vibrofocus.rigs import SimulatedForearm


@pytest.fixture(scope="module")
def fitted(forearm_calibration):
    rig, cal = forearm_calibration
    return fit_model(cal, law="homogeneous")


def _truth(rig, layout) -> np.ndarray:
    return np.array(list(true_parameters(rig.participant, layout.actuator_names).values()))


def test_noise_free_exact_transfer_gives_the_true_parameters(forearm_calibration):
    rig, cal = forearm_calibration
    exact = replace(cal, H=rig.transfer(cal.layout.points_xy, cal.freqs), coherence=np.ones(cal.H.shape))
    fit = fit_model(exact, law="homogeneous")
    assert_allclose(fit.values, _truth(rig, cal.layout), rtol=1e-6)
    assert np.all(fit.residual < 1e-6)


def test_noisy_calibration_recovers_the_parameters_within_their_uncertainty(forearm_calibration, fitted):
    rig, cal = forearm_calibration
    truth = _truth(rig, cal.layout)
    z = (fitted.values - truth) / fitted.std
    # 18 parameters: |z| < 4 for every one (a Gaussian exceeds 4 with probability 6e-5).
    assert np.all(np.abs(z) < 4), dict(zip(fitted.names, np.round(z, 2)))
    # and the uncertainty is small: the wave law within 0.1 %, every parameter within 1 %.
    assert np.all(fitted.std / fitted.values < 0.01)
    assert_allclose(fitted.values[:2], truth[:2], rtol=1e-3)
    assert 0.5 < fitted.info["chi2_per_dof"] < 3  # the weights describe the noise
    assert np.all(fitted.residual < 0.02)


def test_a_biased_truth_is_outside_the_stated_uncertainty(forearm_calibration, fitted):
    # The test above can fail: a 1 % wrong shear modulus is many standard errors off.
    rig, cal = forearm_calibration
    truth = _truth(rig, cal.layout)
    assert abs(fitted.values[0] - 1.01 * truth[0]) / fitted.std[0] > 10


def test_leave_one_point_out_predicts_the_held_out_point(forearm_calibration):
    # docs/method.md: held-out H error 0.01 % (median and largest, 3 participants x 9 points).
    rig, cal = forearm_calibration
    exact_arm = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0, skin="voigt-fit")
    p = 4  # location 5, the centre
    fit = fit_model(cal, law="homogeneous", points=np.delete(np.arange(cal.layout.n_points), p))
    assert p not in fit.info["points"]
    band = (cal.freqs >= 30) & (cal.freqs <= 1000)
    pt = cal.layout.points_xy[p:p + 1]
    truth = exact_arm.transfer(pt, cal.freqs[band])
    err = np.linalg.norm(fit.transfer(pt, cal.freqs[band]) - truth) / np.linalg.norm(truth)
    assert err < 1e-3
    # A model of another participant does much worse: the check can fail.
    other = SimulatedForearm(seed=5, noise_m=0.0, skin="voigt-fit").transfer(pt, cal.freqs[band])
    assert np.linalg.norm(other - truth) / np.linalg.norm(truth) > 10 * err


def test_a_tap_anywhere_from_the_fit_matches_one_from_the_true_h(forearm_calibration, fitted):
    rig, cal = forearm_calibration
    exact_arm = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0, skin="voigt-fit")
    target = (4e-3, -6e-3)  # between locations
    n = exact_arm.design_window()  # the arm's own window, for both (the fit alone would take 4096)
    r_fit = render("contrast", fitted, cal.fs, cal.layout, target_xy=target, n_samples=n)
    r_true = render("contrast", exact_arm, cal.fs, cal.layout, target_xy=target, n_samples=n)
    assert r_fit.location == cal.layout.n_locations + 1
    assert_allclose(r_fit.target_xy, target)
    assert r_fit.layout.n_locations == cal.layout.n_locations + 1
    rec_fit = exact_arm.play_and_record(r_fit.drives, r_fit.layout.points_xy, tail_s=0.0)
    rec_true = exact_arm.play_and_record(r_true.drives, r_true.layout.points_xy, tail_s=0.0)
    t = r_fit.target_index
    peak_true = np.abs(rec_true[t]).max()
    assert abs(np.abs(rec_fit[t]).max() / peak_true - 1) < 0.05
    corr = np.dot(rec_fit[t], rec_true[t]) / np.linalg.norm(rec_fit[t]) / np.linalg.norm(rec_true[t])
    assert corr > 0.99


def test_a_target_at_a_location_is_that_location(fitted, forearm_calibration):
    _, cal = forearm_calibration
    r = render("inverse", fitted, cal.fs, cal.layout, target_xy=cal.layout.locations_xy[4])
    r5 = render("inverse", fitted, cal.fs, cal.layout, 5)
    assert r.location == 5 and r.layout == cal.layout
    assert_allclose(r.drives, r5.drives)


def test_the_fit_travels_with_the_calibration_file(tmp_path, forearm_calibration, fitted):
    _, cal = forearm_calibration
    with_fit = replace(cal, fit=fitted)
    back = load_calibration(save_calibration(with_fit, tmp_path / "fit.nc"))
    assert isinstance(back.fit, FittedSkin)
    assert back.fit.names == fitted.names == parameter_names(cal.layout.actuator_names, "homogeneous")
    assert_allclose(back.fit.values, fitted.values, rtol=0)
    assert_allclose(back.fit.log_covariance, fitted.log_covariance, rtol=0)
    assert_allclose(back.fit.residual, fitted.residual, rtol=0)
    pts = np.array([[1e-3, 2e-3]])
    f = np.array([100.0, 250.0])
    assert_allclose(back.fit.transfer(pts, f), fitted.transfer(pts, f), rtol=1e-12)
    # A calibration with the fit in its file designs a tap anywhere by itself.
    r = render("inverse", back, cal.fs, cal.layout, target_xy=(1e-3, 2e-3))
    assert r.location == cal.layout.n_locations + 1
    # Without a fit, the file has none.
    assert load_calibration(save_calibration(cal, tmp_path / "plain.nc")).fit is None


def test_an_older_file_loads_without_a_fit():
    from pathlib import Path

    cal = load_calibration(Path(__file__).parent / "data" / "schema1_h1.nc")
    assert cal.fit is None


def test_bad_input_is_refused(forearm_calibration, fitted):
    rig, cal = forearm_calibration
    with pytest.raises(ValidationError, match="Calibration"):
        fit_model(cal.H)
    with pytest.raises(ValidationError, match="at least two"):
        fit_model(cal, points=[3])
    with pytest.raises(ValidationError, match="outside the calibrated band"):
        fit_model(cal, band=(5.0, 1000.0))
    nan = cal.H.copy()
    nan[10, 0, 0] = np.nan
    with pytest.raises(ValidationError, match="NaN"):
        fit_model(replace(cal, H=nan))
    lay = cal.layout
    with pytest.raises(ValidationError, match="not both"):
        render("inverse", fitted, cal.fs, lay, 5, target_xy=(0.0, 0.0))
    with pytest.raises(ValidationError, match="one of them"):
        render("inverse", fitted, cal.fs, lay)
    with pytest.raises(ValidationError, match="outside the model's skin"):
        render("inverse", fitted, cal.fs, lay, target_xy=(0.0, 0.2))
    with pytest.raises(ValidationError, match="outside the model's skin"):
        render("inverse", fitted, cal.fs, lay, target_xy=(0.2, 0.0))
    with pytest.raises(ValidationError, match="needs a model"):
        render("inverse", cal.transfer_for(4096), cal.fs, lay, target_xy=(0.0, 0.0))
    with pytest.raises(ValidationError, match="fit_model"):
        render("inverse", cal, cal.fs, lay, target_xy=(0.0, 0.0))
    with pytest.raises(ValidationError, match="outside the modelled skin"):
        fitted.transfer(np.array([[0.0, 0.3]]), np.array([100.0]))


def test_the_standard_error_of_the_fitted_h_is_the_size_of_its_error(forearm_calibration, fitted):
    # Off the grid, the fit's H misses the true H by about its propagated standard error.
    exact_arm = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0, skin="voigt-fit")
    pts, f = np.array([[4e-3, -6e-3], [-12e-3, 3e-3]]), np.linspace(50.0, 500.0, 46)
    std = fitted.transfer_std(pts, f)
    assert std.shape == (46, 2, 4) and np.all(std > 0)
    err = np.abs(fitted.transfer(pts, f) - exact_arm.transfer(pts, f))
    ratio = np.sqrt(np.sum(err ** 2) / np.sum(std ** 2))
    assert 0.3 < ratio < 3, ratio
    with pytest.raises(ValidationError, match="outside the modelled skin"):
        fitted.transfer_std(np.array([[0.0, 0.3]]), f)


def test_a_design_from_the_fit_knows_its_uncertainty(forearm_calibration, fitted):
    from vibrofocus.rendering import Minimax, TransferMatrix

    _, cal = forearm_calibration
    tm = TransferMatrix.from_model(fitted, cal.layout, cal.fs, 4096)
    # The model's own H where the design's drives reach (half an octave past the band's
    # top, 1000 Hz), and its standard error there: the robust minimax bounds its quiet
    # peaks over it.
    f = tm.freqs
    reach = (f >= 10.0) & (f <= 1000.0 * 2 ** 0.5)
    assert_allclose(tm.H[reach][::40], fitted.transfer(cal.layout.points_xy, f[reach][::40]), rtol=1e-12)
    assert np.all(tm.H[f > 2000.0] == 0)
    relative = np.sqrt(np.sum(tm.h_std[reach] ** 2) / np.sum(np.abs(tm.H[reach]) ** 2))
    assert 1e-6 < relative < 1e-2, relative
    assert np.all(tm.h_std[f > 2000.0] == 0)
    assert_allclose(Minimax(robust=2.0).h_radius(tm), 2 * tm.h_std)
    assert Minimax(robust=None).h_radius(tm) is None
    assert TransferMatrix.from_model(SimulatedForearm(seed=0, noise_m=0.0), cal.layout, cal.fs, 4096).h_std is None


def test_a_fit_that_misses_gets_a_verdict_and_render_warns(forearm_calibration, fitted):
    import warnings

    _, cal = forearm_calibration
    assert fitted.verdict is None  # the model's family: residuals at the noise level
    res = fitted.residual.copy()
    res[2] = 0.3
    poor = replace(fitted, residual=res)
    assert "misses the measured H by up to 30.0% (point 3; 1 point(s) over 5%)" in poor.verdict
    with pytest.warns(UserWarning, match="designing from a fitted skin model that does not describe the skin"):
        render("inverse", poor, cal.fs, cal.layout, target_xy=(4e-3, -6e-3))
    with pytest.warns(UserWarning, match="does not describe the skin"):
        render("inverse", replace(cal, fit=poor), cal.fs, cal.layout, target_xy=(4e-3, -6e-3))
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*does not describe the skin")
        render("inverse", fitted, cal.fs, cal.layout, target_xy=(4e-3, -6e-3))
        # A measured calibration is designed from its measurement: its fit is not used.
        render("inverse", replace(cal, fit=poor), cal.fs, cal.layout, 5)
