"""response_timing: arrival, energy group delay and ring-down read from H, against pure
delays and decaying echoes whose times are known."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.rendering import response_timing
from vibrofocus.rendering.timing import DEFAULT_SUPPORT_S

FS, N, BAND = 2000.0, 2048, (20.0, 400.0)


def delays_medium(delays_s):
    """H of pure delays, shape (N // 2 + 1, n_points, n_actuators), from delays (n_points, n_actuators), s."""
    f = np.fft.rfftfreq(N, 1 / FS)[:, None, None]
    return np.exp(-2j * np.pi * f * np.asarray(delays_s)[None])


def test_pure_delays_arrive_and_ring_down_around_their_delay():
    tau = np.array([[0.010, 0.030], [0.050, 0.120]])
    t = response_timing(delays_medium(tau), FS, band=BAND)
    # The band-limited pulse is symmetric about the delay: half its energy at the delay, its
    # first 1 % a little before; its last 1e-4 is in the taper's low skirt (14 Hz), 0.1 s on.
    np.testing.assert_allclose(t.centre_s, tau, atol=1 / FS)
    assert np.all(t.arrival_s < tau) and np.all(t.arrival_s > tau - 0.01)
    assert np.all(t.ringdown_s > tau) and np.all(t.ringdown_s < tau + 0.15)
    # The same pulse every time: every time moves with the delay (the earliest pulse's far
    # skirt, before -0.128 s, wraps to the window's end: a few ms on its ring-down).
    np.testing.assert_allclose(t.arrival_s - tau, t.arrival_s[0, 0] - tau[0, 0], atol=1 / FS)
    np.testing.assert_allclose(t.ringdown_s - tau, t.ringdown_s[1, 1] - tau[1, 1], atol=4e-3)
    assert t.fs == FS and t.n_samples == N and t.arrival_s.shape == (2, 2)


def test_an_echo_rings_down_late():
    tau = np.full((1, 1), 0.010)
    H = delays_medium(tau) + 0.1 * delays_medium(tau + 0.3)  # 1 % of the energy 0.3 s later
    t = response_timing(H, FS, band=BAND)
    assert 0.30 < t.ringdown_s[0, 0] < 0.33
    assert t.centre_s[0, 0] == pytest.approx(0.010, abs=1 / FS)
    assert t.window() == 4096  # four times 0.31 s at 2 kHz, to a power of two
    assert t.window(minimum=8192) == 8192


def test_support_is_twice_the_latest_arrival_at_the_target_and_never_below_the_reference():
    tau = np.array([[0.040, 0.060], [0.001, 0.002]])
    t = response_timing(delays_medium(tau), FS, band=BAND)
    pre, post = t.support_s(0)
    assert pre == pytest.approx(2 * t.arrival_s[0].max(), abs=5e-4) and post == DEFAULT_SUPPORT_S[1]
    assert t.support_s(1) == DEFAULT_SUPPORT_S  # waves that arrive within 5 ms: the reference setup's


def test_a_silent_response_and_bad_shares():
    H = delays_medium(np.full((1, 2), 0.02))
    H[:, 0, 1] = 0
    t = response_timing(H, FS, band=BAND)
    assert t.arrival_s[0, 1] == 0 and t.ringdown_s[0, 1] == 0
    with pytest.raises(ValidationError, match="onset"):
        response_timing(H, FS, band=BAND, onset=0.7)
    with pytest.raises(ValidationError, match="tol"):
        response_timing(H, FS, band=BAND, tol=0)
