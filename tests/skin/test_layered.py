"""The layered skin law and the named presets of the simulated forearm."""

import numpy as np
import pytest
from scipy import optimize

from vibrofocus import ArrayLayout, SimulatedForearm, ricker
from vibrofocus.errors import ValidationError
from vibrofocus.skin import (
    DEFAULT_SKIN,
    LAYERED_NOMINAL,
    NOMINAL_LAW,
    SKIN_PRESETS,
    ForearmParameters,
    LayeredLaw,
    skin_preset,
)

RHO, XI = 1100.0, 0.9553
LOSSLESS = LayeredLaw(top_shear_pa=50e3, substrate_shear_pa=4e3, top_depth_m=0.5e-3, loss_tangent=0.0,
                      density_kg_m3=RHO, rayleigh_factor=XI)


def test_limits_are_the_substrate_and_top_layer_rayleigh_speeds():
    c_sub, c_top = LOSSLESS.rayleigh_speeds()
    np.testing.assert_allclose([c_sub, c_top], XI * np.sqrt(np.array([4e3, 50e3]) / RHO), rtol=1e-12)
    # k h = 2 pi f h / c: far below 1 at 0.1 Hz, far above at 1 MHz.
    np.testing.assert_allclose(LOSSLESS.phase_speed(np.array([0.1])), c_sub, rtol=1e-3)
    np.testing.assert_allclose(LOSSLESS.phase_speed(np.array([1e6])), c_top, rtol=1e-3)
    speed = LOSSLESS.phase_speed(np.geomspace(1, 1e5, 50))
    assert np.all(np.diff(speed) > -1e-12)  # rises monotonically between the limits (to round-off)
    np.testing.assert_array_equal(LOSSLESS.attenuation(np.array([10.0, 500.0])), 0.0)


def test_elastic_dispersion_matches_an_independent_root_finder():
    freqs = np.array([20.0, 150.0, 600.0, 3000.0])
    mine = LOSSLESS.wavenumber(freqs).real

    def relation(k, omega):
        mu = 4e3 + 46e3 * (1 - np.exp(-k * 0.5e-3))
        return k * k * XI**2 * mu - RHO * omega**2

    ref = [optimize.brentq(relation, 1e-6, 1e7, args=(2 * np.pi * f,), xtol=1e-12, rtol=1e-13) for f in freqs]
    np.testing.assert_allclose(mine, ref, rtol=1e-9)


def test_one_layer_with_loss_is_the_closed_form_spring_pot():
    law = LayeredLaw(top_shear_pa=9e3, substrate_shear_pa=9e3, top_depth_m=1e-3, loss_tangent=0.3,
                     reference_hz=200.0, density_kg_m3=RHO, rayleigh_factor=XI)
    f = np.array([50.0, 200.0, 800.0])
    n = 2 * np.arctan(0.3) / np.pi
    # Physics convention: modulus 9 kPa (-i f / 200 Hz)^n.
    modulus = 9e3 * (-1j * f / 200.0) ** n
    expected = 2 * np.pi * f * np.sqrt(RHO / (XI**2 * modulus))
    np.testing.assert_allclose(law.wavenumber(f), expected, rtol=1e-10)
    np.testing.assert_allclose(law.modulus(f).imag / law.modulus(f).real, 0.3, rtol=1e-9)


def test_group_speed_is_the_derivative_of_the_wavenumber():
    f = np.array([80.0, 250.0, 900.0])
    df = 1e-3
    dk = (LAYERED_NOMINAL.wavenumber(f + df).real - LAYERED_NOMINAL.wavenumber(f - df).real) / (2 * df)
    np.testing.assert_allclose(LAYERED_NOMINAL.group_speed(f), 1 / (dk / (2 * np.pi)), rtol=1e-5)


def test_layered_law_refuses_a_soft_top_and_bad_values():
    with pytest.raises(ValidationError, match="top_shear_pa"):
        LayeredLaw(top_shear_pa=1e3, substrate_shear_pa=5e3, top_depth_m=1e-3, loss_tangent=0.1)
    with pytest.raises(ValidationError, match="loss_tangent"):
        LayeredLaw(top_shear_pa=9e3, substrate_shear_pa=5e3, top_depth_m=1e-3, loss_tangent=-0.1)


def test_presets_reproduce_their_evidence():
    assert set(SKIN_PRESETS) == {"nominal", "low", "high", "voigt-fit"} and DEFAULT_SKIN == "nominal"
    nominal = skin_preset("nominal").law
    # Zhang et al. 2011: 3.25 +/- 0.19 m/s at 200 Hz on the forearm.
    np.testing.assert_allclose(nominal.phase_speed(np.array([200.0])), 3.25, atol=0.01)
    # Manfredi et al. 2012: plateau near 7 m/s (the top layer's Rayleigh speed).
    np.testing.assert_allclose(nominal.rayleigh_speeds()[1], 7.0, rtol=1e-9)
    # Feng et al. 2022: hypodermis E about 15 kPa -> shear 5 kPa.
    np.testing.assert_allclose(nominal.substrate_shear_pa, 5e3, rtol=1e-12)
    tangents = {name: SKIN_PRESETS[name].law.loss_tangent for name in ("low", "nominal", "high")}
    np.testing.assert_allclose(list(tangents.values()), [0.07, 0.14, 0.42], rtol=1e-12)
    alpha = {name: SKIN_PRESETS[name].law.attenuation(np.array([250.0]))[0] for name in tangents}
    assert alpha["low"] < alpha["nominal"] < alpha["high"] < 0.6 * NOMINAL_LAW.attenuation(np.array([250.0]))[0]
    assert SKIN_PRESETS["voigt-fit"].law is None
    with pytest.raises(ValidationError, match="skin must be one of"):
        skin_preset("Nominal")


@pytest.mark.parametrize("skin", ["nominal", "low", "high"])
def test_ten_volts_give_about_two_micrometres_on_the_actuator(skin):
    rig = SimulatedForearm(participant=ForearmParameters.nominal(4, skin=skin), noise_m=0.0, dropout_rate=0.0,
                           geometry="plane")
    drive = np.zeros((4, 2000))
    drive[1] = ricker(rig.fs, duration=0.2, t0=0.02, amplitude=10.0)
    peak = np.abs(rig.play_and_record(drive, rig.layout.actuators_xy[1:2])).max()
    np.testing.assert_allclose(peak, 2e-6, rtol=0.05)  # the paper's anchor; the issue allows 1.4-2.8 µm


def test_reference_guards_lie_outside_the_exciter_toward_the_centre():
    lay = ArrayLayout.reference()
    d = np.linalg.norm(lay.guards_xy - lay.actuators_xy, axis=1)
    np.testing.assert_allclose(d, 9e-3, rtol=1e-12)
    assert np.all(d > 7e-3)  # outside the 14 mm footprint
    assert np.all(np.linalg.norm(lay.guards_xy, axis=1) < np.linalg.norm(lay.actuators_xy, axis=1))


def test_a_seed_draws_the_same_person_on_every_skin():
    lay = ArrayLayout.reference()
    people = {skin: ForearmParameters.draw(7, lay, skin=skin) for skin in SKIN_PRESETS}
    for p in people.values():
        np.testing.assert_array_equal(p.contact, people["voigt-fit"].contact)
        np.testing.assert_array_equal(p.gains, people["voigt-fit"].gains)
    base = SKIN_PRESETS["nominal"].law
    drawn = people["nominal"].layered
    assert people["nominal"].skin == "nominal" and people["voigt-fit"].layered is None
    assert abs(drawn.loss_tangent / base.loss_tangent - 1) <= 0.25
    assert abs(drawn.top_shear_pa / base.top_shear_pa - 1) <= 0.237
    assert people["nominal"].to_dict()["layered"]["kind"] == "layered"


@pytest.mark.parametrize("skin", list(SKIN_PRESETS))
def test_render_on_a_model_picks_a_window_its_responses_fit_in(skin):
    from vibrofocus.rendering import render

    arm = SimulatedForearm(seed=1, skin=skin, noise_m=0.0, dropout_rate=0.0)
    n = arm.design_window()
    assert n >= 4 * arm.response_length(tol=1e-5) and n & (n - 1) == 0
    for loc in (2, 4, 5):  # at a fixed 4096 samples, 2 of 54 designs on nominal arms 0-1 were refused
        r = render("inverse", arm, arm.fs, arm.layout, loc)
        assert r.n_samples == n and r.wraparound_fraction < 1e-3


def test_mode_transfer_is_the_transfer_before_its_causal_correction():
    # What fit_model iterates on: equal to transfer on the homogeneous law (no precursor
    # to take out); on a layered skin the precursor's 0.1-0.4 % of |H|, not more.
    f = np.linspace(30.0, 1000.0, 40)
    voigt = SimulatedForearm(seed=0, skin="voigt-fit", noise_m=0.0)
    pts = voigt.layout.points_xy
    np.testing.assert_allclose(voigt.mode_transfer(pts, f), voigt.transfer(pts, f), rtol=1e-12, atol=0)
    arm = SimulatedForearm(seed=0, noise_m=0.0)
    mode, causal = arm.mode_transfer(pts, f), arm.transfer(pts, f)
    rel = np.linalg.norm(mode - causal, axis=(0, 2)) / np.linalg.norm(causal, axis=(0, 2))
    assert np.all(rel < 0.01) and np.all(rel > 1e-5), rel
    with pytest.raises(ValidationError, match="freqs"):
        arm.mode_transfer(pts, -f)
