"""The cached wrap-around check (odd bins of the 2n-point spectra) against the former
playback by linear convolution at every point, and the fast plain pseudo-inverse route
against numpy.linalg.pinv per frequency."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus.errors import CausalityError, ValidationError
from vibrofocus.rendering import InverseOperator, WraparoundCheck, check_wraparound, inverse_filter, wraparound_fraction
from vibrofocus.rendering._pinv import SpectralPinv
from vibrofocus.rendering.causality import _playback_wraparound_fraction
from vibrofocus.signals import ricker

from ._media import FS, delay_gain_medium, fir_medium, random_fir_taps


def random_medium(rng, n, n_points, n_actuators, longest=0.9):
    delays = rng.uniform(0, longest * n, (n_points, n_actuators))
    return delay_gain_medium(n, FS, delays, rng.uniform(0.5, 2, (n_points, n_actuators)))


def tap_drives(rng, n, n_actuators, centre):
    t = np.arange(n)
    return rng.standard_normal((n_actuators, 1)) * np.exp(-(((t - centre) / (0.02 * n)) ** 2))


@pytest.mark.parametrize("n", [256, 255, 1024])
@pytest.mark.parametrize("centre", [0.2, 0.5, 0.97])
def test_equals_playback_on_causal_and_wrapped_designs(rng, n, centre):
    H = random_medium(rng, n, 7, 3, longest=0.4)
    drives = tap_drives(rng, n, 3, centre * n)
    expected = _playback_wraparound_fraction(drives, H)
    one_shot = wraparound_fraction(drives, H)
    check = WraparoundCheck(H, n)
    check.odd_spectra  # cached route, with its skipped bins
    assert_allclose([one_shot, check.fraction(drives), check.fraction(drives)], expected, rtol=1e-4, atol=1e-9)


def test_design_spectra_route_equals_playback(rng):
    n = 1024
    H = fir_medium(n, random_fir_taps(rng, 9, 4, 60))
    targets = np.zeros((9, n))
    for centre, wrapped in ((0.5, False), (0.995, True)):
        targets[0] = ricker(FS, duration=n / FS, t0=centre * n / FS)
        drives = inverse_filter(H, targets, FS, check_wraparound=False)
        spectra = np.fft.rfft(drives, axis=-1).T
        spectra[np.abs(spectra) < 1e-13 * np.abs(spectra).max()] = 0
        expected = _playback_wraparound_fraction(drives, H)
        check = WraparoundCheck(H)
        assert_allclose(check.fraction(drives, spectra), expected, rtol=1e-4, atol=1e-9)
        check.odd_spectra
        assert_allclose(check.fraction(drives, spectra), expected, rtol=1e-4, atol=1e-9)
        assert (expected > 1e-3) == wrapped


@pytest.mark.parametrize("factor, raises", [(0.9, False), (1.1, True)])
def test_verdict_at_the_edge_of_the_tolerance(rng, factor, raises):
    n = 512
    H = random_medium(rng, n, 5, 2, longest=0.3)
    drives = tap_drives(rng, n, 2, 0.75 * n)
    fraction = _playback_wraparound_fraction(drives, H)
    assert 1e-3 < fraction < 0.5
    tol = fraction / factor
    operator = InverseOperator(H, FS)
    for run in (lambda: check_wraparound(drives, H, tol=tol), lambda: operator.check_wraparound(drives, tol=tol),
                lambda: operator.check_wraparound(drives, tol=tol)):
        if raises:
            with pytest.raises(CausalityError):
                run()
        else:
            assert run() == pytest.approx(fraction, rel=1e-4)


def test_verdict_plays_every_bin_where_the_skipped_bins_could_change_it(rng, monkeypatch):
    import vibrofocus.rendering.causality as causality

    n = 512
    H = random_medium(rng, n, 5, 2, longest=0.3)
    drives = tap_drives(rng, n, 2, 0.75 * n)
    exact = _playback_wraparound_fraction(drives, H)
    for share in ("_SKIP_SHARE", "_CORE_SHARE"):  # leave out bins that move the share
        monkeypatch.setattr(causality, share, 0.05)
    check = WraparoundCheck(H, n)
    rough = check.fraction(drives)
    assert abs(rough - exact) > 1e-3 * exact
    tol = 0.5 * (rough + exact)  # the bins kept and all the bins give opposite verdicts
    if exact > tol:
        with pytest.raises(CausalityError):
            check.check(drives, tol=tol)
    else:
        assert check.check(drives, tol=tol) == pytest.approx(exact, rel=1e-4)
    far = 0.5 * min(rough, exact)  # far from both: the bins kept decide
    with pytest.raises(CausalityError):
        check.check(drives, tol=far)


def test_inverse_filter_verdict_equals_playback(rng):
    n = 1024
    H = fir_medium(n, random_fir_taps(rng, 6, 3, 40))
    targets = np.zeros((6, n))
    targets[0] = ricker(FS, duration=n / FS, t0=0.985 * n / FS)
    drives = inverse_filter(H, targets, FS, check_wraparound=False)
    fraction = _playback_wraparound_fraction(drives, H)
    assert fraction > 1e-5
    for factor, raises in ((0.9, False), (1.1, True)):
        if raises:
            with pytest.raises(CausalityError):
                inverse_filter(H, targets, FS, wraparound_tol=fraction / factor)
        else:
            _, report = inverse_filter(H, targets, FS, wraparound_tol=fraction / factor, full_output=True)
            assert report.wraparound_fraction == pytest.approx(fraction, rel=1e-4)


def singular_stack(rng, n_freqs, n_rows, n_cols):
    H = rng.standard_normal((n_freqs, n_rows, n_cols)) + 1j * rng.standard_normal((n_freqs, n_rows, n_cols))
    H[1, :, 0] = 0  # a dead actuator: exactly singular (tall)
    H[2, 0, :] = 0  # a dead point: exactly singular (wide)
    if n_cols > 2:
        H[3, :, 1] = H[3, :, 2]  # two identical actuators
    H[4] = 0  # nothing moves
    for f, factor in ((5, 1e-9), (6, 3e-3), (7, 1e-2)):  # ill-conditioned, near the threshold, fine
        u, s, vh = np.linalg.svd(H[f], full_matrices=False)
        s[-1] *= factor
        H[f] = (u * s) @ vh
    H[8] *= 1e-100  # tiny but its Gram matrix does not underflow
    return H


@pytest.mark.parametrize("shape", [(13, 4), (4, 13), (33, 32), (5, 5), (1, 3), (3, 1)])
def test_plain_route_equals_pinv_per_frequency(rng, shape):
    H = singular_stack(rng, 12, *shape)
    factors = SpectralPinv.factorize(H)
    assert factors.inverse is not None  # the eigenvalue-free route
    matrix = factors.matrix()
    rhs = rng.standard_normal((12, shape[0])) + 1j * rng.standard_normal((12, shape[0]))
    applied = factors.apply(rhs)
    rows = np.array([0, shape[0] - 1]) if shape[0] > 1 else np.array([0])
    few = np.zeros_like(rhs)
    few[:, rows] = rhs[:, rows]
    applied_rows = factors.apply(rhs[:, rows], rows)
    for f in range(12):
        expected = np.linalg.pinv(H[f])
        scale = max(np.abs(expected).max(), 1e-300)
        assert_allclose(matrix[f], expected, rtol=0, atol=1e-9 * scale)
        assert_allclose(applied[f], expected @ rhs[f], rtol=0, atol=1e-9 * scale * np.abs(rhs[f]).max())
        assert_allclose(applied_rows[f], expected @ few[f], rtol=0, atol=1e-9 * scale * np.abs(rhs[f]).max())
    assert_allclose(factors.singular_values, np.linalg.svd(H, compute_uv=False), rtol=0,
                    atol=1e-12 * np.abs(H).max())
    assert 4 in np.flatnonzero(factors.zero_freqs)
    assert 5 in factors.svd_freqs or min(shape) == 1
    if shape in ((13, 4), (4, 13)):  # well-conditioned random frequencies take the Gram route
        assert 7 in factors.gram_freqs and 8 in factors.gram_freqs


@pytest.mark.parametrize("regularization", ["tikhonov", "tsvd"])
def test_regularized_routes_keep_the_eigenvalues(rng, regularization):
    H = singular_stack(rng, 12, 9, 4)
    factors = SpectralPinv.factorize(H, regularization, 1e-2)
    assert factors.inverse is None and factors._singular_values is not None
    s = np.linalg.svd(H, compute_uv=False)
    u, _, vh = np.linalg.svd(H, full_matrices=False)
    for f in range(12):
        if s[f, 0] == 0:
            continue
        if regularization == "tikhonov":
            g = s[f] / (s[f] ** 2 + (1e-2 * s[f, 0]) ** 2)
        else:
            g = np.where(s[f] >= 1e-2 * s[f, 0], 1 / np.where(s[f] > 0, s[f], 1), 0.0)
        expected = (np.conj(vh[f]).T * g) @ np.conj(u[f]).T
        assert_allclose(factors.matrix()[f], expected, rtol=0, atol=1e-9 * np.abs(expected).max())


def test_operator_singular_values_on_demand(rng):
    H = random_medium(rng, 256, 6, 3)
    operator = InverseOperator(H, FS)
    s = operator.singular_values
    active = operator.taper > 0
    assert_allclose(s[active], np.linalg.svd(H[active], compute_uv=False), rtol=1e-10)
    assert np.all(s[~active] == 0)


def test_a_check_of_an_array_changed_in_place_refuses_to_build_its_spectra(rng):
    n = 256
    H = random_medium(rng, n, 4, 2, longest=0.3)
    check = WraparoundCheck(H)
    assert check.matches(H) and check.matches(H.copy())
    assert check.matches(np.asfortranarray(H))  # a strided copy: same values, no copy made
    H[5, 0, 0] += 1e-3 * np.abs(H).max()
    assert not check.matches(H)
    with pytest.raises(ValidationError, match="changed in place"):
        check.padded_spectra
