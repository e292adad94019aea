"""A small linear test rig: drives are convolved (linearly) with known FIR responses.

Not a mock: it is a real linear, time-invariant medium whose transfer matrix is known in
closed form, ``H_true = rfft(h, n)`` for any ``n >= fir_length``, so estimates can be
compared with an exact answer.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import scipy.signal

from vibrofocus import ArrayLayout
from vibrofocus.rigs.base import Rig


def analytic_firs(layout: ArrayLayout, fs: float, length: int = 1024) -> np.ndarray:
    """Impulse responses ``h[p, a, k]`` (m/V per sample), exactly ``length`` long.

    Each is the impulse response of a 2nd-order Butterworth band-pass (60-600 Hz: like
    an inertial exciter on skin, no static response), delayed by the travel time at
    5 m/s (whole samples) and attenuated with distance (e-folding length 30 mm).
    """
    r = np.linalg.norm(layout.points_xy[:, None, :] - layout.actuators_xy[None, :, :], axis=-1)
    delay = np.round(r / 5.0 * fs).astype(int)
    b, a = scipy.signal.butter(2, (60.0, 600.0), btype="bandpass", fs=fs)
    impulse = np.zeros(length)
    impulse[0] = 1.0
    base = scipy.signal.lfilter(b, a, impulse)
    h = np.zeros(r.shape + (length,))
    for (p, q), d in np.ndenumerate(delay):  # a few dozen pairs: building the fixture only
        h[p, q, d:] = 1e-6 * np.exp(-r[p, q] / 0.03) * base[: length - d]
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
        elif points_xy is None:
            idx = np.arange(self.layout.n_points)
        else:  # a medium known only at the layout's points
            d = np.linalg.norm(points_xy[:, None, :] - self.layout.points_xy[None], axis=-1)
            idx = d.argmin(axis=1)
            assert np.all(d.min(axis=1) < 1e-12), "the FIR rig knows only the layout's points"

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
