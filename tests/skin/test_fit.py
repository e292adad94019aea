"""Tests of the wave-law fit and of the nominal law against the published forearm data."""

import numpy as np
import pandas as pd
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.skin.fit import fit_wave_law, load_forearm_data, points_from_published_fits
from vibrofocus.skin.parameters import NOMINAL_LAW
from vibrofocus.skin.viscoelastic import ViscoelasticLaw

# The largest residual that docs/skin-model.md and parameters.NOMINAL_LAW state.
STATED_MAX_RESIDUAL_PCT = 1.0


def test_data_file_names_its_sources_and_only_forearm_points_are_fitted():
    data = load_forearm_data()
    assert {"quantity", "value", "source_key", "where", "how_read", "use"} <= set(data.columns)
    assert data["where"].str.len().min() > 10  # every number says where it stands
    used = data[data["use"].astype(bool)]
    assert len(used) >= 1 and used["body_site"].str.contains("forearm").all()


def test_points_derived_from_the_voigt_fit_match_the_measured_speed():
    # Independent of the code under test: the closed-form Voigt shear speed with
    # Zhang et al. 2011's mu1, mu2, 1000 kg/m^3 and the Rayleigh factor 0.9553 at 200 Hz,
    # against their measured 3.25 m/s at 200 Hz (the one measured point).
    mu, eta, rho, w = 7860.0, 5.03, 1000.0, 2 * np.pi * 200
    mag = np.hypot(mu, w * eta)
    c_surface = 0.9553 * np.sqrt(2 * mag**2 / (rho * (mu + mag)))
    np.testing.assert_allclose(c_surface, 3.25, rtol=0.015)
    derived = points_from_published_fits(load_forearm_data())
    at200 = derived[(derived["frequency_hz"] == 200) & (derived["quantity"] == "phase_speed_m_s")]
    np.testing.assert_allclose(at200["value"].to_numpy(), [c_surface], rtol=1e-9)
    assert (derived["how_read"] == "derived from the published Voigt fit").all()
    assert (derived["spread"] > 0).all()


def test_fit_reproduces_the_published_points_within_the_stated_residual():
    fit = fit_wave_law()
    assert fit.max_abs_residual_pct <= STATED_MAX_RESIDUAL_PCT
    assert len(fit.points) >= 10


def test_nominal_law_is_the_fit_rounded():
    fit = fit_wave_law()
    np.testing.assert_allclose(NOMINAL_LAW.mu0_pa, fit.law.mu0_pa, rtol=5e-3)
    np.testing.assert_allclose(NOMINAL_LAW.eta_pa_sn, fit.law.eta_pa_sn, rtol=5e-3)
    np.testing.assert_allclose(NOMINAL_LAW.order, fit.law.order, atol=2e-3)
    # ... and so reproduces the points within the stated residual too.
    f = fit.points["frequency_hz"].to_numpy(float)
    for quantity, of in (("phase_speed_m_s", NOMINAL_LAW.phase_speed), ("attenuation_np_m", NOMINAL_LAW.attenuation)):
        sel = fit.points["quantity"].to_numpy() == quantity
        resid = 100 * (of(f[sel]) / fit.points["value"].to_numpy(float)[sel] - 1)
        assert np.abs(resid).max() <= STATED_MAX_RESIDUAL_PCT + 0.5


def test_fitter_recovers_a_known_fractional_law(rng):
    truth = ViscoelasticLaw(mu0_pa=4e3, eta_pa_sn=60.0, order=0.55)
    f = np.geomspace(50, 800, 9)
    noise = 1 + 0.01 * rng.standard_normal((2, f.size))
    rows = [dict(quantity=q, frequency_hz=fi, value=v, spread=0.01 * v, use=True)
            for q, vals in (("phase_speed_m_s", truth.phase_speed(f) * noise[0]),
                            ("attenuation_np_m", truth.attenuation(f) * noise[1]))
            for fi, v in zip(f, vals)]
    fit = fit_wave_law(pd.DataFrame(rows), density_kg_m3=truth.density_kg_m3)
    np.testing.assert_allclose(fit.law.order, truth.order, atol=4 * fit.relative_std["order"] + 0.01)
    np.testing.assert_allclose(np.log(fit.law.mu0_pa / truth.mu0_pa), 0, atol=4 * fit.relative_std["mu0_pa"] + 0.02)
    assert fit.max_abs_residual_pct < 4.0


def test_too_few_points_are_refused():
    rows = pd.DataFrame([dict(quantity="phase_speed_m_s", frequency_hz=200.0, value=3.0, spread=np.nan, use=True)])
    with pytest.raises(ValidationError, match="at least 3"):
        fit_wave_law(rows)
