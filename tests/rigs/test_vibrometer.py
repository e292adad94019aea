"""Vibrometer decoder volts -> displacement, against analytic signals."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.rigs import Vibrometer

FS = 10_000.0


def test_velocity_of_a_sine_integrates_to_its_displacement():
    t = np.arange(30_000) / FS
    f, amp = 100.0, 2e-6  # 2 µm at 100 Hz
    velocity = amp * 2 * np.pi * f * np.cos(2 * np.pi * f * t)  # m/s
    vib = Vibrometer("velocity", 0.005)  # 5 mm/s/V
    x = vib.to_displacement(velocity / 0.005, FS)
    inner = slice(5000, -5000)  # away from the high-pass ringing at the abrupt ends
    np.testing.assert_allclose(x[inner], amp * np.sin(2 * np.pi * f * t[inner]), atol=1e-3 * amp)


def test_velocity_integration_is_flat_and_zero_phase_in_the_band(rng):
    # Displacement band-limited to 10-1000 Hz; its derivative in the frequency domain is
    # the decoder output; integration must give it back (a 4th-order 3 Hz high-pass).
    n = 8192
    freqs = np.fft.rfftfreq(n, 1 / FS)
    spec = (rng.standard_normal(freqs.size) + 1j * rng.standard_normal(freqs.size)) * ((freqs >= 10) & (freqs <= 1000))
    x = np.fft.irfft(spec, n)
    x = np.concatenate([np.zeros(n), x * np.hanning(n), np.zeros(n)]) * 1e-6  # starts and ends at rest
    v = np.gradient(x, 1 / FS)
    got = Vibrometer("velocity", 1.0, highpass_hz=3.0).to_displacement(v, FS)
    # np.gradient is a central difference: its gain sin(wT)/(wT) falls below 1 toward
    # 1 kHz (0.3 % at 200 Hz); compare in 10-200 Hz.
    def band(y):
        f = np.fft.rfftfreq(y.size, 1 / FS)
        return np.fft.irfft(np.fft.rfft(y) * ((f >= 10) & (f <= 200)), y.size)

    np.testing.assert_allclose(band(got), band(x), atol=1e-2 * np.abs(band(x)).max())


def test_offset_does_not_become_a_ramp():
    t = np.arange(30_000) / FS
    volts = 0.2 + 0.01 * np.sin(2 * np.pi * 50 * t)  # a 0.2 V decoder offset
    x = Vibrometer("velocity", 0.005).to_displacement(volts, FS)
    expected_amp = 0.01 * 0.005 / (2 * np.pi * 50)
    assert np.abs(x[3000:-3000]).max() < 1.05 * expected_amp  # integrated plainly: 0.2*0.005*3 s = 3 mm


def test_displacement_decoder_scales_and_removes_dc():
    t = np.arange(30_000) / FS
    volts = 1.0 + 0.5 * np.sin(2 * np.pi * 200 * t)
    x = Vibrometer("displacement", 1e-6).to_displacement(volts, FS)
    # The zero-phase 3 Hz high-pass rings for a few hundred ms around the abrupt ends.
    inner = slice(5000, -5000)
    np.testing.assert_allclose(x[inner], 0.5e-6 * np.sin(2 * np.pi * 200 * t[inner]), atol=1e-9)
    raw = Vibrometer("displacement", 1e-6, highpass_hz=None).to_displacement(volts, FS)
    np.testing.assert_allclose(raw, volts * 1e-6)


def test_shapes_and_bad_input():
    vib = Vibrometer("velocity", 0.005)
    assert vib.to_displacement(np.zeros((3, 100)), FS).shape == (3, 100)
    with pytest.raises(ValidationError, match="decoder must be one of"):
        Vibrometer("acceleration", 1.0)
    with pytest.raises(ValidationError, match="sensitivity must be > 0"):
        Vibrometer("velocity", 0.0)
    with pytest.raises(ValidationError, match="volts contains 1 non-finite"):
        vib.to_displacement(np.array([0.0, np.nan]), FS)
    assert vib.describe()["sensitivity_unit"] == "(m/s)/V"
