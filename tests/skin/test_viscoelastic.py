"""Tests of the causal viscoelastic wave law against closed forms and its own calculus."""

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.skin.viscoelastic import ViscoelasticLaw

FREQS = np.array([20.0, 100.0, 250.0, 400.0, 1000.0, 3000.0])


def test_voigt_limit_matches_the_closed_form_speed_and_attenuation():
    # Kelvin-Voigt (n = 1): the textbook closed forms for a shear wave with
    # G = mu + i omega eta (e.g. as used by Zhang et al. 2011 for skin).
    mu, eta, rho = 4e3, 1.5, 1050.0
    law = ViscoelasticLaw(mu0_pa=mu, eta_pa_sn=eta, order=1.0, density_kg_m3=rho, rayleigh_factor=1.0)
    w = 2 * np.pi * FREQS
    mag = np.sqrt(mu**2 + (w * eta) ** 2)
    c = np.sqrt(2 * mag**2 / (rho * (mu + mag)))
    alpha = np.sqrt(rho * w**2 * (mag - mu) / (2 * mag**2))
    np.testing.assert_allclose(law.phase_speed(FREQS), c, rtol=1e-12)
    np.testing.assert_allclose(law.attenuation(FREQS), alpha, rtol=1e-12)


def test_rayleigh_factor_scales_the_speed_and_the_wavenumber():
    a = ViscoelasticLaw(mu0_pa=4e3, eta_pa_sn=50.0, order=0.6, rayleigh_factor=1.0)
    b = ViscoelasticLaw(mu0_pa=4e3, eta_pa_sn=50.0, order=0.6, rayleigh_factor=0.9)
    np.testing.assert_allclose(b.phase_speed(FREQS), 0.9 * a.phase_speed(FREQS), rtol=1e-12)
    np.testing.assert_allclose(b.attenuation(FREQS), a.attenuation(FREQS) / 0.9, rtol=1e-12)


def test_modulus_limits_and_positive_loss():
    law = ViscoelasticLaw(mu0_pa=3e3, eta_pa_sn=80.0, order=0.5, mu_inf_pa=6e4)
    g = law.modulus(np.array([1e-6, 1e12]))
    np.testing.assert_allclose(g.real, [3e3, 6e4], rtol=1e-3)
    wide = np.geomspace(1.0, 1e5, 200)
    assert np.all(law.modulus(wide).imag > 0)  # a passive material dissipates
    assert np.all(law.attenuation(wide) > 0)
    np.testing.assert_allclose(law.phase_speed(np.array([1e12]))[0], law.plateau_speed(), rtol=1e-3)


def test_fractional_power_law_at_high_frequency():
    # Where the spring-pot dominates, G ~ eta (i omega)^n: phase angle n pi / 2, so
    # alpha / Re k = tan(n pi / 4) and c ~ f^(n / 2).
    n = 0.6
    law = ViscoelasticLaw(mu0_pa=1e-3, eta_pa_sn=100.0, order=n)
    k = law.wavenumber(np.array([500.0, 2000.0]))
    np.testing.assert_allclose(k.imag / k.real, np.tan(n * np.pi / 4), rtol=1e-6)
    c = law.phase_speed(np.array([500.0, 2000.0]))
    np.testing.assert_allclose(c[1] / c[0], 4 ** (n / 2), rtol=1e-6)


def test_group_speed_is_the_derivative_of_the_dispersion_relation():
    law = ViscoelasticLaw(mu0_pa=5e3, eta_pa_sn=120.0, order=0.65, mu_inf_pa=1e5)
    f = FREQS
    h = 1e-4 * f
    dk = (law.wavenumber(f + h).real - law.wavenumber(f - h).real) / (2 * np.pi * 2 * h)
    np.testing.assert_allclose(law.group_speed(f), 1 / dk, rtol=1e-6)


def _precursor_energy(k_phys, fs: float, n: int, distance_m: float) -> float:
    """Share of the energy of a plane wave's impulse response that comes before t = 0.

    ``k_phys`` maps frequencies (Hz) to the physics-convention wavenumber; the NumPy
    propagator over ``distance_m`` is ``exp(-i conj(k) r)``. The response is band-limited
    by a causal low-pass (four real poles at fs / 40), so that truncating the spectrum at
    Nyquist adds no ringing of its own: energy at negative times can only come from a
    non-causal wavenumber.
    """
    f = np.fft.rfftfreq(n, 1 / fs)
    k = np.zeros(f.size, complex)
    k[1:] = k_phys(f[1:])
    smooth = (1 + 1j * f / (fs / 40)) ** -4
    ir = np.fft.irfft(np.exp(-1j * np.conj(k) * distance_m) * smooth, n)
    e = ir**2
    return float(e[n // 2:].sum() / e.sum())


def test_wave_law_is_causal_and_a_non_kramers_kronig_pair_is_not():
    fs, n = 80_000.0, 2**16
    law = ViscoelasticLaw(mu0_pa=5e3, eta_pa_sn=120.0, order=0.65)
    for r in (1e-3, 5e-3, 20e-3):
        assert _precursor_energy(law.wavenumber, fs, n, r) < 1e-9

    # The first version's laws, chosen independently (c ~ f^0.3, alpha ~ f), are not a
    # causal pair: the same measurement finds a precursor.
    def power_laws(f):
        return 2 * np.pi * f / (3.5 * (f / 250) ** 0.3) + 1j * 60.0 * f / 250

    assert _precursor_energy(power_laws, fs, n, 5e-3) > 1e-4


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(mu0_pa=-1.0, eta_pa_sn=1.0, order=0.5), "mu0_pa"),
        (dict(mu0_pa=1.0, eta_pa_sn=1.0, order=1.5), "order"),
        (dict(mu0_pa=1.0, eta_pa_sn=1.0, order=0.0), "order"),
        (dict(mu0_pa=1e3, eta_pa_sn=1.0, order=0.5, mu_inf_pa=10.0), "mu_inf_pa"),
        (dict(mu0_pa=1e3, eta_pa_sn=1.0, order=0.5, rayleigh_factor=1.2), "rayleigh_factor"),
    ],
)
def test_bad_parameters_are_refused(kwargs, match):
    with pytest.raises(ValidationError, match=match):
        ViscoelasticLaw(**kwargs)
