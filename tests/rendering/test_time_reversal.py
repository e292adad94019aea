"""time_reversal_drives: H^H U, the time-reversed impulse responses."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus.errors import ValidationError
from vibrofocus.rendering import band_taper, time_reversal_drives

from ._media import FS, delay_gain_medium


def test_pure_delays_are_reversed_in_time():
    # Path gains g_q and delays d_q to the one point: conj(H) advances the target by d_q.
    n = 512  # bin spacing 19.5 Hz
    H = delay_gain_medium(n, FS, np.array([[7, 30]]), np.array([[2.0, -0.5]]))
    target = np.zeros((1, n))
    target[0, 250] = 1.0
    drives = time_reversal_drives(H, target, FS, band=(10.0, 5000.0), taper_octaves=0.0)
    # Band (10, 5000) Hz with a brick wall keeps every bin except DC: remove the mean.
    expected = np.stack([2.0 * np.roll(target[0], -7), -0.5 * np.roll(target[0], -30)])
    expected -= expected.mean(axis=1, keepdims=True)
    assert_allclose(drives, expected, atol=1e-12)


def test_normalized_to_max_drive_and_focuses_in_phase(rng):
    n = 1024
    H = delay_gain_medium(n, FS, rng.uniform(0, 50, (3, 4)), rng.uniform(0.5, 1.5, (3, 4)))
    target = np.zeros((3, n))
    target[1, 600] = 1.0
    drives = time_reversal_drives(H, target, FS, max_drive=7.0)
    assert_allclose(np.abs(drives).max(), 7.0, rtol=1e-12)
    spectra = np.fft.rfft(drives, axis=-1).T
    response = np.fft.irfft(np.einsum("fpq,fq->pf", H, spectra), n, axis=-1)
    # Every path arrives in phase at the target at the target's time.
    assert np.argmax(np.abs(response[1])) == 600
    taper = band_taper(np.fft.rfftfreq(n, 1 / FS), (10.0, 1000.0))
    unscaled = np.fft.irfft(np.conj(H[:, 1, :]).T * taper * np.fft.rfft(target[1]), n, axis=-1)
    assert_allclose(drives, unscaled * 7.0 / np.abs(unscaled).max(), atol=1e-12)


def test_bad_input():
    n = 256
    H = delay_gain_medium(n, FS, np.array([[1, 2]]), np.array([[1.0, 1.0]]))
    with pytest.raises(ValidationError, match="targets has 2 rows but H has 1 points"):
        time_reversal_drives(H, np.zeros((2, n)), FS)
    with pytest.raises(ValidationError, match="silent drives"):
        time_reversal_drives(H, np.zeros((1, n)), FS, max_drive=1.0)
    with pytest.raises(ValidationError, match="n // 2 \\+ 1"):
        time_reversal_drives(H, np.zeros((1, n + 2)), FS)
