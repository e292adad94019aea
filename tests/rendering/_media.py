"""Analytic media for the rendering tests: every transfer matrix here is known exactly."""

import numpy as np


FS = 10_000.0


def delay_gain_medium(n: int, fs: float, delays: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """H_pq(f) = g_pq exp(-2 pi i f tau_pq): each path a pure delay (samples) and gain."""
    freqs = np.fft.rfftfreq(n, 1 / fs)
    return np.asarray(gains)[None] * np.exp(-2j * np.pi * freqs[:, None, None] * np.asarray(delays)[None] / fs)


def fir_medium(n: int, taps: np.ndarray) -> np.ndarray:
    """H on rfftfreq(n) of FIR paths ``taps`` (n_points, n_actuators, L), L <= n."""
    return np.moveaxis(np.fft.rfft(taps, n, axis=-1), -1, 0)


def random_fir_taps(rng: np.random.Generator, n_points: int, n_actuators: int, length: int) -> np.ndarray:
    """Decaying random FIR paths with a strong direct term on the 'diagonal' so that a
    square medium is well conditioned and its inverse decays quickly."""
    decay = np.exp(-np.arange(length) / (length / 5))
    taps = 0.3 * rng.standard_normal((n_points, n_actuators, length)) * decay
    for k in range(min(n_points, n_actuators)):
        taps[k, k, 2] += 2.0
    return taps




def layout_medium(layout, n: int, fs: float, speed_m_s: float = 10.0, latency_s: float = 2e-3) -> np.ndarray:
    """Distance-dependent delay and 1/(1 + r/1 cm) gain from every actuator to every point
    of ``layout`` (m/V), rows in ``layout.points_xy`` order."""
    r = np.linalg.norm(layout.points_xy[:, None, :] - layout.actuators_xy[None], axis=-1)
    delays = (latency_s + r / speed_m_s) * fs
    return delay_gain_medium(n, fs, delays, 1e-6 / (1 + r / 0.01))
