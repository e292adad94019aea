"""The Ricker base stimulus and its printed (non-zero-mean) form."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose

from vibrofocus import ricker
from vibrofocus.defaults import N_SAMPLES
from vibrofocus.errors import ValidationError

FS = 10_000.0


def test_defaults_place_unit_peak_mid_window():
    s = ricker(FS)
    assert s.shape == (N_SAMPLES,)
    assert np.argmax(s) == N_SAMPLES // 2
    assert_allclose(s.max(), 1.0, rtol=1e-15)


def test_formula_at_known_times():
    sigma, t0 = 1e-3, 0.01
    s = ricker(FS, sigma, duration=0.02, t0=t0, amplitude=2.0)
    t = np.arange(200) / FS
    # tau = sigma: the zero crossing; tau = sqrt(3) sigma: the side-lobe minimum -2 exp(-3/2).
    assert_allclose(s[int(round((t0 + sigma) * FS))], 0.0, atol=1e-12)
    tau = t - t0
    side = np.argmin(s)
    assert_allclose(abs(tau[side]), np.sqrt(3) * sigma, atol=1 / FS)
    assert_allclose(s.min(), -4 * np.exp(-1.5), rtol=2e-3)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(sigma=st.floats(2e-4, 5e-3), fraction=st.floats(0.3, 0.7))
def test_zero_mean_and_printed_mean(sigma, fraction):
    duration = 0.5
    t0 = fraction * duration
    s = ricker(FS, sigma, duration, t0)
    # Sum over samples approximates fs times the integral (zero) to sampling accuracy.
    assert abs(s.sum()) / FS < 1e-9 * sigma
    printed = ricker(FS, sigma, duration, t0, form="printed")
    # Its integral is sigma sqrt(pi) / 2, i.e. a sample sum of fs sigma sqrt(pi) / 2.
    assert_allclose(printed.sum(), FS * sigma * np.sqrt(np.pi) / 2, rtol=1e-6)


def test_spectral_peak_near_225_hz():
    n = 2**16
    s = ricker(FS, 1e-3, n / FS)
    freqs = np.fft.rfftfreq(n, 1 / FS)
    peak = freqs[np.argmax(np.abs(np.fft.rfft(s)))]
    assert_allclose(peak, 1 / (np.sqrt(2) * np.pi * 1e-3), atol=FS / n)


def test_bad_input():
    with pytest.raises(ValidationError, match="fs must be > 0"):
        ricker(0)
    with pytest.raises(ValidationError, match="sigma must be > 0"):
        ricker(FS, sigma=-1e-3)
    with pytest.raises(ValidationError, match="t0 must lie in"):
        ricker(FS, duration=0.1, t0=0.2)
    with pytest.raises(ValidationError, match="form must be one of"):
        ricker(FS, form="mexican")
    with pytest.raises(ValidationError, match="duration must be > 0"):
        ricker(FS, duration=np.nan)
    with pytest.raises(ValidationError, match="shorter than one sample"):
        ricker(FS, duration=1e-5)
