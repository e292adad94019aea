"""combination_target: funneling predicted through H at the target."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import ricker
from vibrofocus.errors import ValidationError
from vibrofocus.rendering import band_taper, combination_target

from ._media import FS, delay_gain_medium


def test_pure_delay_paths_sum_shifted_scaled_stimuli():
    n = 2048
    delays = np.array([[10, 25, 40]])
    gains = np.array([[1.0, 0.5, 2.0]])
    H = delay_gain_medium(n, FS, delays, gains)
    amplitudes = np.array([3.0, 4.0, 0.0])
    stimulus = ricker(FS, 1e-3, n / FS)
    expected = 3.0 * 1.0 * np.roll(stimulus, 10) + 4.0 * 0.5 * np.roll(stimulus, 25)
    assert_allclose(combination_target(H, 0, amplitudes, stimulus, FS, band=None), expected, atol=1e-12)
    taper = band_taper(np.fft.rfftfreq(n, 1 / FS), (10.0, 1000.0))
    limited = np.fft.irfft(np.fft.rfft(expected) * taper, n)
    assert_allclose(combination_target(H, 0, amplitudes, stimulus, FS), limited, atol=1e-12)


def test_zero_funneling_at_target_is_refused():
    n = 256
    H = delay_gain_medium(n, FS, np.array([[1, 2], [3, 4]]), np.array([[1.0, 0.0], [1.0, 1.0]]))
    with pytest.raises(ValidationError, match="funneling predicts no displacement at point 0"):
        combination_target(H, 0, np.array([0.0, 5.0]), ricker(FS, 1e-3, n / FS), FS)


def test_bad_input():
    n = 256
    H = delay_gain_medium(n, FS, np.array([[1, 2]]), np.array([[1.0, 1.0]]))
    stimulus = ricker(FS, 1e-3, n / FS)
    with pytest.raises(ValidationError, match="target_index=1 is outside the 1 points of H"):
        combination_target(H, 1, [1.0, 1.0], stimulus, FS)
    with pytest.raises(ValidationError, match=r"gains must have shape \(2,\)"):
        combination_target(H, 0, [1.0], stimulus, FS)
    with pytest.raises(ValidationError, match="stimulus"):
        combination_target(H, 0, [1.0, 1.0], stimulus[:100], FS)
