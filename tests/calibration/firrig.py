"""A small linear test rig: drives are convolved (linearly) with known FIR responses.

Not a mock: it is a real linear, time-invariant medium whose transfer matrix is known in
closed form, ``H_true = rfft(h, n)`` for any ``n >= fir_length``, so estimates can be
compared with an exact answer.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from vibrofocus import ArrayLayout
from vibrofocus.rigs.base import Rig


def analytic_firs(layout: ArrayLayout, fs: float, length: int = 1024) -> np.ndarray:
    """Impulse responses ``h[p, a, k]`` (m/V per sample): a damped 300 Hz resonance,
    delayed by the travel time at 5 m/s and attenuated with distance (e-folding 30 mm)."""
    r = np.linalg.norm(layout.points_xy[:, None, :] - layout.actuators_xy[None, :, :], axis=-1)
    delay = r / 5.0 * fs  # samples, fractional
    k = np.arange(length)
    t = (k[None, None, :] - delay[..., None]) / fs
    gain = 1e-7 * np.exp(-r / 0.03)[..., None]
    h = np.where(t >= 0, gain * np.exp(-t / 4e-3) * np.sin(2 * np.pi * 300 * t), 0.0)
    return h


class FIRRig(Rig):
    """Linear FIR medium with optional sensor noise, dropouts, clipping and aiming.

    Parameters
    ----------
    h : ndarray, shape (n_points, n_actuators, length)
        Impulse responses to ``layout.points_xy``, m/V per sample.
    noise_m : float
        White Gaussian sensor noise, RMS, m.
    dropout_prob : float
        Chance that a recording of a point holds a burst of NaN samples.
    sensor_range_m : float, optional
        Recordings are clipped at +-this.
    single_spot : bool
        Behave as a single-spot vibrometer aimed with :meth:`aim`.
    """

    kind = "fir-test"

    def __init__(self, h, layout=None, fs=10_000.0, *, noise_m=0.0, dropout_prob=0.0, sensor_range_m=None,
                 single_spot=False, seed=0):
        super().__init__(layout=layout, fs=fs)
        self.h = np.asarray(h, float)
        self.noise_m = noise_m
        self.dropout_prob = dropout_prob
        self.sensor_range_m = sensor_range_m
        self.max_points_per_recording = 1 if single_spot else None
        self.rng = np.random.default_rng(seed)
        self.aimed = None
        self.n_recordings = 0

    def aim(self, point_label: str, point_xy: np.ndarray) -> None:
        """The operator's side of ``prompt``: point the spot at a labelled point."""
        self.aimed = self.layout.point_labels.index(point_label)
        np.testing.assert_allclose(point_xy, self.layout.points_xy[self.aimed])

    def transfer(self, n: int) -> np.ndarray:
        """Exact H on rfftfreq(n, 1/fs), shape (n//2+1, n_points, n_actuators)."""
        return np.moveaxis(np.fft.rfft(self.h, n, axis=-1), -1, 0)

    def _play(self, drive):
        pass

    def _zero_outputs(self):
        pass

    def _play_and_record(self, drive, points_xy, n_tail):
        self.n_recordings += 1
        if self.max_points_per_recording == 1:
            idx = np.array([self.aimed])
        else:
            idx = np.arange(self.layout.n_points)
        n_out = drive.shape[1] + n_tail
        n = scipy.fft.next_fast_len(n_out + self.h.shape[-1])
        # Linear convolution, summed over actuators.
        spec = np.einsum("pak,ak->pk", np.fft.rfft(self.h[idx], n, axis=-1), np.fft.rfft(drive, n, axis=-1))
        y = np.fft.irfft(spec, n, axis=-1)[:, :n_out]
        y = y + self.noise_m * self.rng.standard_normal(y.shape)
        if self.sensor_range_m is not None:
            y = np.clip(y, -self.sensor_range_m, self.sensor_range_m)
        drop = self.rng.random(len(idx)) < self.dropout_prob
        for i in np.flatnonzero(drop):
            start = self.rng.integers(0, n_out - 50)
            y[i, start:start + 50] = np.nan
        return y
