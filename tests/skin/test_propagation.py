"""Tests of the skin model's building blocks against independent references."""

import numpy as np
import pytest
from scipy import integrate, special

from vibrofocus.skin import exciter_response, surface_green, wavenumber
from vibrofocus.skin.parameters import NOMINAL_LAW


def _k(f):
    return wavenumber(np.atleast_1d(f), NOMINAL_LAW)


def _disc_average_reference(k, d, a):
    """Area average of the point-source Green's function over a disc, by quadrature.

    Physics convention; valid for a field point outside the disc (smooth integrand).
    """
    xs, ws = np.polynomial.legendre.leggauss(60)
    r = 0.5 * a * (xs + 1)
    wr = 0.5 * a * ws
    th = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    R, TH = np.meshgrid(r, th, indexing="ij")
    dist = np.sqrt(d**2 + R**2 - 2 * d * R * np.cos(TH))
    vals = 0.25j * special.hankel1(0, k * dist)
    return (vals * R * wr[:, None]).sum() * (2 * np.pi / th.size) / (np.pi * a**2)


@pytest.mark.parametrize("f, d", [(50.0, 0.004), (250.0, 0.01), (800.0, 0.02)])
def test_disc_source_outside_matches_quadrature(f, d):
    a = 3e-3
    k = _k(f)
    got = surface_green(k, np.array([[d]]), np.array([a]))[0, 0, 0]
    ref = np.conj(_disc_average_reference(k[0], d, a))
    np.testing.assert_allclose(got, ref, rtol=1e-6)


@pytest.mark.parametrize("f", [20.0, 250.0, 900.0])
def test_disc_source_centre_matches_radial_integral(f):
    # At the centre the disc average is (2/a^2) int_0^a r (i/4) H0(k r) dr, a 1-D
    # integral with an integrable log singularity, evaluated here by adaptive quadrature.
    a = 3e-3
    k = _k(f)[0]

    def part(fun):
        integrand = lambda r: fun(r * 0.25j * special.hankel1(0, k * r))  # noqa: E731
        return integrate.quad(integrand, 0, a, limit=400, epsabs=0, epsrel=1e-11)[0]

    ref = (2 / a**2) * (part(np.real) + 1j * part(np.imag))
    got = surface_green(np.array([k]), np.array([[0.0]]), np.array([a]))[0, 0, 0]
    np.testing.assert_allclose(got, np.conj(ref), rtol=1e-6)


def test_disc_source_is_continuous_at_the_rim():
    a = 3e-3
    k = _k(np.array([30.0, 250.0, 1000.0]))
    d = np.array([[a * (1 - 1e-9), a * (1 + 1e-9)]])
    g = surface_green(k, d.T, np.array([a]))  # shape (3, 2, 1)
    np.testing.assert_allclose(g[:, 0, 0], g[:, 1, 0], rtol=1e-6)


def test_far_field_is_cylindrical_spreading_times_attenuation():
    f = np.array([250.0])
    k = _k(f)[0]
    d1, d2 = 0.05, 0.1
    g = surface_green(np.array([k]), np.array([[d1], [d2]]), np.array([3e-3]))[0, :, 0]
    ratio = abs(g[1] / g[0])
    expected = np.sqrt(d1 / d2) * np.exp(-k.imag * (d2 - d1))
    np.testing.assert_allclose(ratio, expected, rtol=0.01)
    # NumPy convention: the farther point lags, i.e. its phase is smaller by k_r (d2 - d1).
    lag = -np.angle(g[1] / g[0])
    expected_lag = np.mod(k.real * (d2 - d1) + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(lag, expected_lag, atol=0.02)


def test_exciter_resonance_shape():
    f0, q = 500.0, 1.0
    f = np.array([5.0, f0, 50_000.0])
    e = exciter_response(f, np.array([f0]), np.array([q]))[:, 0]
    np.testing.assert_allclose(abs(e[0]), (5.0 / f0) ** 2, rtol=1e-3)  # mass-controlled low end
    np.testing.assert_allclose(abs(e[1]), q, rtol=1e-12)  # |E(f0)| = Q
    np.testing.assert_allclose(abs(e[2]), 1.0, rtol=1e-3)  # flat far above resonance


def test_exciter_response_is_the_causal_analog_high_pass():
    # scipy.signal.freqs evaluates b(s)/a(s) at s = j omega, the same sign convention as
    # NumPy's FFT; the system s^2 / (s^2 + s w0/Q + w0^2) has its poles in the left half
    # plane, so it is causal, and the model must match it.
    from scipy import signal

    f0, q = 470.0, 0.9
    w0 = 2 * np.pi * f0
    f = np.linspace(1.0, 3000.0, 500)
    _, ref = signal.freqs([1.0, 0.0, 0.0], [1.0, w0 / q, w0**2], worN=2 * np.pi * f)
    got = exciter_response(f, np.array([f0]), np.array([q]))[:, 0]
    np.testing.assert_allclose(got, ref, rtol=1e-10)
    assert np.all(np.roots([1.0, w0 / q, w0**2]).real < 0)


def test_distance_table_matches_exact_evaluation(rng):
    k = wavenumber(np.linspace(5, 1500, 120), NOMINAL_LAW)
    d = rng.uniform(0.0, 0.3, (300, 3))  # some paths inside the 3 mm contact too
    a = np.array([3e-3, 2e-3, 3e-3])
    exact = surface_green(k, d, a)
    table = surface_green(k, d, a, table_step=5e-3)
    np.testing.assert_allclose(table, exact, rtol=0, atol=1e-5 * np.abs(exact).max())
    big = np.abs(exact) > 1e-3 * np.abs(exact).max()
    np.testing.assert_allclose(table[big], exact[big], rtol=1e-5)


def test_distance_table_evaluates_only_the_nodes_it_uses(rng):
    # The table's nodes next to some path only (the complex Hankel function is the costly
    # part): every value is the one the whole table gives (to rounding: the in-place
    # arithmetic may round the last bit otherwise).
    from vibrofocus.skin.propagation import _hankel0_scaled, _tabulated_hankel0

    k = wavenumber(np.linspace(5, 1500, 50), NOMINAL_LAW)
    d = np.concatenate([[3e-3, 0.2], rng.uniform(3e-3, 0.2, 40)])  # fewer paths than nodes
    step = 5e-3
    ratio = np.log1p(step)
    n_nodes = int(np.ceil(np.log(d.max() / d.min()) / ratio)) + 2
    table = _hankel0_scaled(k[:, None] * (d.min() * np.exp(ratio * np.arange(n_nodes)))[None, :])
    u = np.log(d / d.min()) / ratio
    i = np.clip(np.floor(u).astype(int), 0, n_nodes - 2)
    whole = (table[:, i] * (1 - (u - i)) + table[:, i + 1] * (u - i)) * np.exp(1j * k[:, None] * d[None, :])
    np.testing.assert_allclose(_tabulated_hankel0(k, d, step), whole, rtol=1e-14, atol=0)


def test_scaled_hankel_series_matches_scipy_to_1e_14(rng):
    # The playback tables' H0(z) exp(-iz): Hankel's series from |z| = 30 (14 terms, 8 from
    # |z| = 100), scipy's AMOS below; the two agree to about 1e-15 relative.
    from vibrofocus.skin.propagation import _hankel0_scaled

    size = 10 ** rng.uniform(-1, 4, 20_000)
    z = size * np.exp(1j * rng.uniform(0, np.pi / 2, size.size))  # Re k > 0, Im k >= 0
    z = np.concatenate([z, [30.0, 30.0 + 1e-9j, 100.0, 29.999, 99.999j]])
    ref = special.hankel1e(0, z)
    np.testing.assert_allclose(_hankel0_scaled(z), ref, rtol=1e-14, atol=0)
