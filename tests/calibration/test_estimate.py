import numpy as np
import pytest
import scipy.signal

from vibrofocus.calibration.estimate import (
    estimate_repeats,
    h1_average,
    noise_and_snr,
    resize_impulse_response,
)
from vibrofocus.signals import exponential_sweep

FS = 10_000.0


def test_resize_lengthens_without_changing_the_response(rng):
    h = np.zeros(512)
    h[:300] = rng.standard_normal(300)  # causal
    h[-20:] = rng.standard_normal(20)  # acausal (negative times)
    longer = resize_impulse_response(h, 2048)
    # Same samples at the same (circular) times: the zero-padded DFT interpolates.
    np.testing.assert_array_equal(longer[:300], h[:300])
    np.testing.assert_array_equal(longer[-20:], h[-20:])
    assert np.count_nonzero(longer) == 320
    np.testing.assert_allclose(np.fft.rfft(longer)[::4], np.fft.rfft(h), rtol=1e-12, atol=1e-12)


def test_resize_shortens_with_a_fade_and_back_is_lossless_where_it_fits(rng):
    h = np.zeros(4096)
    h[:200] = rng.standard_normal(200)
    short = resize_impulse_response(h, 1024)
    np.testing.assert_array_equal(short[:200], h[:200])  # well before the fade
    np.testing.assert_array_equal(resize_impulse_response(short, 4096), h)


def test_linear_deconvolution_recovers_a_known_fir(rng):
    # A band-pass FIR (no static response, like an exciter on skin) plus a random,
    # decaying component; a 1 s sweep recorded with the FIR's full tail: linear
    # convolution.
    b, a = scipy.signal.butter(2, (40.0, 800.0), btype="bandpass", fs=FS)
    h = scipy.signal.lfilter(b, a, rng.standard_normal(1500) * np.exp(-np.arange(1500) / 200))
    x = np.concatenate([np.zeros(500), exponential_sweep(FS, 5.0, 2000.0, 1.0, amplitude=2.0)])
    y = np.convolve(x, h)[None, :]
    H, valid = estimate_repeats(y, x, FS, (5.0, 2000.0), 4096)
    f = np.fft.rfftfreq(4096, 1 / FS)
    band = (f >= 10) & (f <= 1000)
    truth = np.fft.rfft(h, 4096)
    assert valid.all()
    np.testing.assert_allclose(H[0, band], truth[band], rtol=0, atol=1e-3 * np.abs(truth[band]).max())


def test_dropouts_are_flagged_and_zeroed(rng):
    x = exponential_sweep(FS, 5.0, 2000.0, 0.5)
    y = np.tile(np.convolve(x, [0.0, 1.0, 0.5]), (3, 1))
    y[1, 100:130] = np.nan
    H, valid = estimate_repeats(y, x, FS, (5.0, 2000.0), 1024)
    np.testing.assert_array_equal(valid, [True, False, True])
    assert np.all(H[1] == 0) and np.isfinite(H).all()


def test_h1_average_and_coherence_of_identical_and_of_noise_repeats(rng):
    signal = rng.standard_normal(200) + 1j * rng.standard_normal(200)
    same = np.tile(signal, (4, 1))
    H, coh, n = h1_average(same, np.ones(4, bool))
    np.testing.assert_allclose(H, signal, rtol=1e-12)
    np.testing.assert_allclose(coh, 1.0, rtol=1e-12)
    # Independent noise: coherence is |mean|^2 / mean|.|^2, expected 1/R.
    r = 8
    noise = rng.standard_normal((r, 20000)) + 1j * rng.standard_normal((r, 20000))
    _, coh, _ = h1_average(noise, np.ones(r, bool))
    assert np.mean(coh) == pytest.approx(1 / r, rel=0.05)


def test_h1_average_leaves_out_invalid_repeats_and_marks_single_repeats(rng):
    H_r = rng.standard_normal((3, 2, 10)) + 0j
    valid = np.array([[True, True], [False, True], [True, False]])
    H, coh, n = h1_average(H_r, valid)
    np.testing.assert_allclose(H[0], (H_r[0, 0] + H_r[2, 0]) / 2, rtol=1e-12)
    np.testing.assert_allclose(H[1], (H_r[0, 1] + H_r[1, 1]) / 2, rtol=1e-12)
    np.testing.assert_array_equal(n, [2, 2])
    _, coh1, _ = h1_average(H_r[:1], valid[:1])
    assert np.isnan(coh1).all()


def test_snr_from_the_pre_sweep_silence(rng):
    n_pre, n = 1000, 5000
    t = np.arange(n) / FS
    tone = np.where(np.arange(n) >= n_pre, 1e-6 * np.sin(2 * np.pi * 200 * t), 0.0)
    noise_rms = 1e-8
    y = tone[None, None, :] + noise_rms * rng.standard_normal((4, 1, n))
    noise, snr = noise_and_snr(y, np.ones((4, 1), bool), n_pre, FS, (10.0, 1000.0))
    # White noise over 0-5 kHz: the 10-1000 Hz share of its power is 990/5000.
    assert noise[0] == pytest.approx(noise_rms * np.sqrt(990 / 5000), rel=0.1)
    expected = 10 * np.log10((1e-6**2 / 2) / (noise_rms**2 * 990 / 5000))
    assert snr[0] == pytest.approx(expected, abs=0.5)


def test_an_integrated_velocity_recording_keeps_its_silence_silent():
    # A noise-free take read through a velocity decoder: integrated over the whole take,
    # the displacement drifts linearly in the silence before the sweep. That drift is not
    # noise: the SNR of a perfect loopback must stay far above any verdict's threshold.
    from vibrofocus.calibration.estimate import noise_and_snr
    from vibrofocus.rigs import Vibrometer
    from vibrofocus.signals.sweeps import exponential_sweep

    fs, n_pre = 10_000.0, 1000
    sweep = exponential_sweep(fs, 7.0, 1400.0, 1.0, amplitude=1.0, fade_s=0.01)
    velocity_volts = np.concatenate([np.zeros(n_pre), sweep, np.zeros(3000)])
    displacement = Vibrometer("velocity", 0.005, highpass_hz=None).to_displacement(velocity_volts, fs)
    _, snr_db = noise_and_snr(displacement[None, None, :], np.ones((1, 1), bool), n_pre, fs, (10.0, 1000.0))
    assert snr_db[0] > 100.0
