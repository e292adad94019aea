"""Sweeps: instantaneous frequency, inverses, deconvolution of a known medium."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose
from scipy.signal import fftconvolve, hilbert

from vibrofocus.errors import ValidationError
from vibrofocus.signals import (
    apply_fades,
    exponential_sweep,
    exponential_sweep_inverse,
    linear_sweep,
    spectral_inverse,
)

FS = 10_000.0


def zero_crossing_frequency(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous frequency from successive zero crossings (linearly interpolated):
    half a period between two crossings. Returns (times, frequencies)."""
    k = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:]))
    crossings = (k + x[k] / (x[k] - x[k + 1])) / fs
    return (crossings[1:] + crossings[:-1]) / 2, 0.5 / np.diff(crossings)


@settings(max_examples=12, deadline=None, derandomize=True)
@given(kind=st.sampled_from(["linear", "exponential"]), f1=st.floats(5, 100), ratio=st.floats(3, 40),
       duration=st.floats(0.5, 2.0))
def test_instantaneous_frequency_follows_the_law_and_rises(kind, f1, ratio, duration):
    f2 = min(f1 * ratio, 0.1 * FS)  # >= 10 samples per cycle keeps the crossing estimate sharp
    sweep = (linear_sweep if kind == "linear" else exponential_sweep)(FS, f1, f2, duration, fade_s=0.0)
    t, inst = zero_crossing_frequency(sweep, FS)
    expected = f1 + (f2 - f1) * t / duration if kind == "linear" else f1 * (f2 / f1) ** (t / duration)
    assert_allclose(inst, expected, rtol=1e-2)
    # Rising: frequency over consecutive blocks of 10 half periods (averages out the
    # interpolation jitter of single crossings).
    blocks = 0.5 * 10 / np.diff(np.cumsum(0.5 / inst)[::10])
    assert np.all(np.diff(blocks) > 0)


def test_analytic_signal_agrees_in_mid_sweep():
    sweep = exponential_sweep(FS, 20.0, 1000.0, 1.0, fade_s=0.0)
    inst = np.diff(np.unwrap(np.angle(hilbert(sweep)))) * FS / (2 * np.pi)
    t = (np.arange(inst.size) + 0.5) / FS
    core = (t > 0.2) & (t < 0.8)
    assert_allclose(inst[core], 20.0 * 50.0 ** t[core], rtol=0.02)


def test_fades_and_amplitude():
    sweep = exponential_sweep(FS, 10, 1000, 1.0, amplitude=0.5, fade_s=0.01)
    assert sweep[0] == 0.0 and abs(sweep[-1]) < 1e-3
    assert_allclose(np.abs(sweep).max(), 0.5, rtol=1e-3)
    x = np.ones((2, 1000))
    faded = apply_fades(x, FS, 0.01, 0.02)
    assert_allclose(faded[:, 50], 0.5, rtol=1e-12)  # half-way through a 100-sample fade-in
    assert_allclose(faded[:, 1000 - 101], 0.5, rtol=1e-12)  # half-way through a 200-sample fade-out (mirror)
    assert_allclose(faded[:, ::-1][:, :200], apply_fades(x, FS, 0.02)[:, :200], rtol=1e-12)
    assert np.all(faded[:, 100:800] == 1.0) and np.all(x == 1.0)


def test_exponential_inverse_gives_flat_band_limited_impulse():
    f1, f2, duration = 10.0, 1000.0, 2.0
    sweep = exponential_sweep(FS, f1, f2, duration)
    inverse = exponential_sweep_inverse(FS, f1, f2, duration)
    impulse = fftconvolve(sweep, inverse)
    n = sweep.size
    assert abs(np.argmax(np.abs(impulse)) - (n - 1)) <= 1  # the impulse sits at the sweep length
    freqs = np.fft.rfftfreq(impulse.size, 1 / FS)
    gain_db = 20 * np.log10(np.abs(np.fft.rfft(impulse)))
    # Flat around unit gain away from the band edges (near the low edge the sweep's
    # onset leaves the usual Fresnel ripple of about 1 dB).
    inner = (freqs > 4 * f1) & (freqs < f2 / 2)
    assert np.abs(gain_db[inner]).max() < 0.5
    assert gain_db[freqs > 2 * f2].max() < -20  # and band-limited


@pytest.mark.parametrize("sweep_fn", [linear_sweep, exponential_sweep])
def test_spectral_inverse_recovers_a_known_fir(rng, sweep_fn):
    sweep = sweep_fn(FS, 10.0, 1000.0, 1.0)
    h = rng.standard_normal(64) * np.exp(-np.arange(64) / 10)
    recording = fftconvolve(sweep, h)  # what a rig records, with its tail
    n_fft = 2 ** int(np.ceil(np.log2(recording.size)))
    inv = spectral_inverse(sweep, FS, n_fft, (10.0, 1000.0))
    estimate = np.fft.rfft(recording, n_fft) * inv
    freqs = np.fft.rfftfreq(n_fft, 1 / FS)
    inner = (freqs > 30) & (freqs < 800)
    assert_allclose(estimate[inner], np.fft.rfft(h, n_fft)[inner], rtol=1e-3, atol=1e-4 * np.abs(np.fft.rfft(h)).max())
    assert np.abs(estimate[freqs > 1500]).max() == 0.0  # beyond the taper


def test_spectral_inverse_is_band_limited_unit_response():
    sweep = linear_sweep(FS, 10.0, 1000.0, 1.0)
    n_fft = 16384
    product = np.fft.rfft(sweep, n_fft) * spectral_inverse(sweep, FS, n_fft, (10.0, 1000.0), regularization=1e-9)
    freqs = np.fft.rfftfreq(n_fft, 1 / FS)
    inner = (freqs > 30) & (freqs < 900)
    assert_allclose(product[inner], 1.0, rtol=1e-4)


def test_bad_input():
    with pytest.raises(ValidationError, match=r"\(f_start, f_stop\) must satisfy"):
        linear_sweep(FS, 10, 6000)
    with pytest.raises(ValidationError, match="duration must be > 0"):
        exponential_sweep(FS, duration=0)
    with pytest.raises(ValidationError, match="n_fft=100 must be an integer >= the excitation length 10000"):
        spectral_inverse(linear_sweep(FS), FS, 100, (10, 1000))
    with pytest.raises(ValidationError, match="band must satisfy"):
        spectral_inverse(linear_sweep(FS), FS, 16384, (10, 6000))
    with pytest.raises(ValidationError, match="excitation contains"):
        spectral_inverse(np.full(10, np.nan), FS, 16, (10, 1000))


def test_fades_bad_input():
    with pytest.raises(ValidationError, match="fade_in_s must be >= 0"):
        apply_fades(np.ones(10), FS, -0.1)
    with pytest.raises(ValidationError, match="signal contains"):
        apply_fades(np.array([np.inf]), FS, 0.1)
