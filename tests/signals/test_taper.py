"""band_taper: unit pass band, raised-cosine roll-off over the given octaves, zero beyond."""

import numpy as np
from numpy.testing import assert_allclose

from vibrofocus.signals import band_taper


def test_pass_band_roll_off_and_stop_band():
    freqs = np.array([0.0, 5.0, 10.0 / np.sqrt(2) ** 0.5, 10.0, 500.0, 1000.0, 1000.0 * 2**0.25, 1500.0, 5000.0])
    w = band_taper(freqs, (10.0, 1000.0), taper_octaves=0.5)
    # A quarter octave outside an edge is half-way down the half-octave raised cosine.
    assert_allclose(w, [0, 0, 0.5, 1, 1, 1, 0.5, 0, 0], atol=1e-12)


def test_monotone_roll_off_and_brick_wall():
    freqs = np.linspace(0, 5000, 10001)
    w = band_taper(freqs, (100.0, 1000.0), 1.0)
    below, above = freqs < 100, freqs > 1000
    assert np.all(np.diff(w[below]) >= 0) and np.all(np.diff(w[above]) <= 0)
    assert np.all((w >= 0) & (w <= 1))
    brick = band_taper(freqs, (100.0, 1000.0), 0.0)
    assert_allclose(brick, ((freqs >= 100) & (freqs <= 1000)).astype(float))


def test_dc_is_zero_without_warnings():
    # pyproject turns RuntimeWarnings from vibrofocus into errors: log2(0) must be silent.
    assert band_taper(np.array([0.0]), (10.0, 1000.0))[0] == 0.0


def test_bad_input():
    import pytest

    from vibrofocus.errors import ValidationError

    with pytest.raises(ValidationError, match="band must satisfy 0 < low < high"):
        band_taper(np.arange(10.0), (100.0, 10.0))
    with pytest.raises(ValidationError, match="band must be a pair"):
        band_taper(np.arange(10.0), 100.0)
    with pytest.raises(ValidationError, match="taper_octaves must be >= 0"):
        band_taper(np.arange(10.0), (1.0, 5.0), -1)
    with pytest.raises(ValidationError, match="freqs contains"):
        band_taper(np.array([np.nan]), (1.0, 5.0))
