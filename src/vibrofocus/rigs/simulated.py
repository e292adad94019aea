"""The simulated rig: :class:`SimulatedForearm`, the arm's physics played as a rig.

The physics (:class:`vibrofocus.skin.SimulatedArm`) knows nothing of rigs; this adapter
adds what a rig is: the safety layer of :class:`~.base.Rig`, and a vibrometer with noise
and dropouts.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from .._validation import check_band, check_positive
from ..defaults import BAND_HZ, FS_HZ
from ..errors import ValidationError
from ..layout import ArrayLayout
from ..skin.forearm import SimulatedArm
from ..skin.parameters import ForearmParameters
from .base import Rig
from .onset import SIMULATED_CLOCK, DeviceOnset
from .safety import SafetyLimits

__all__ = ["SimulatedForearm"]


class SimulatedForearm(SimulatedArm, Rig):
    """A simulated participant's forearm with the actuator array and a vibrometer: a rig.

    A thin adapter: the physics is :class:`vibrofocus.skin.SimulatedArm` (transfer,
    impulse responses, the response to a drive); this class adds the rig's safety layer
    and the vibrometer's noise and dropouts.

    Parameters
    ----------
    seed : int
        Participant seed: draws the participant (:meth:`ForearmParameters.draw`) and
        seeds the measurement noise. Same seed, same calls: identical results.
    layout : ArrayLayout, optional
        The array; default the reference setup (docs/method.md).
    fs : float
        Sample rate, Hz.
    limits : SafetyLimits, optional
        Drive limits of the safety layer.
    noise_m : float
        Vibrometer noise, m RMS within ``noise_band``. White Gaussian noise over the
        whole recording bandwidth, scaled so its in-band RMS is ``noise_m`` (its total
        RMS is larger by ``sqrt((fs/2) / bandwidth)``). Default 1 nm (docs/skin-model.md): an
        assumption of the right order. The OFV-505/5000 specification could not be
        checked; a related Polytec velocity decoder (PSV-500, DV-04) specifies a
        resolution of 0.1-1 µm/s between 10 Hz and 5 kHz, which is 0.16-1.6 nm of
        displacement at 100 Hz (``v / (2 pi f)``); on skin, less reflective than the
        specified tape, a vibrometer does worse. 0 turns noise off.
    dropout_rate : float
        Expected vibrometer dropouts per second of recording per point (speckle or
        signal loss of a laser vibrometer). Samples lost in a dropout are ``NaN`` in
        the recording, and :attr:`last_dropout_mask` marks them. Calibration must check
        for NaN and repeat the affected recording (or leave it out of its averages); it
        must never interpolate across a dropout. Default 0.005 /s (rare); 0 turns
        dropouts off.
    dropout_duration_s : (float, float)
        Range of dropout durations, s (uniform).
    participant, skin, geometry, n_images, ir_duration_s, latency_s
        The arm: as for :class:`vibrofocus.skin.SimulatedArm`.
    noise_band : (float, float)
        Band in which ``noise_m`` is specified, Hz.

    Attributes
    ----------
    participant : ForearmParameters
        This participant's parameters (read-only).
    geometry : ForearmGeometry
        Surface geometry (read-only).
    last_drive : ndarray or None
        The last drive played (after the safety layer's fades), shape
        (n_actuators, n_samples), V; None until something plays.
    n_played : int
        Number of drives played so far.
    samples_played : int
        The sample clock: samples played so far (drives, recording tails and loopback
        captures), over all plays. A play's onset on the device clock
        (:meth:`~vibrofocus.rigs.Rig.play`) is this count before it, divided by ``fs``.
    outputs_v : ndarray, shape (n_actuators,)
        Voltage now at each actuator; zero whenever the rig is idle.
    last_dropout_mask : ndarray of bool or None
        Dropout samples of the last recording, shape (n_points, n_samples).

    Notes
    -----
    The simulated vibrometer measures anywhere at once (``max_points_per_recording``
    is None); ``play_and_record(drive)`` without ``points_xy`` records at every point
    of the layout (locations then guards).
    """

    kind = "simulated"
    max_points_per_recording = None

    def __init__(
        self,
        seed: int = 0,
        layout: ArrayLayout | None = None,
        fs: float = FS_HZ,
        limits: SafetyLimits | None = None,
        noise_m: float = 1e-9,
        dropout_rate: float = 0.005,
        *,
        dropout_duration_s: tuple[float, float] = (1e-3, 10e-3),
        participant: ForearmParameters | None = None,
        skin: str | None = None,
        geometry: str = "cylinder",
        n_images: int = 2,
        ir_duration_s: float = 0.4096,
        latency_s: float = 0.0,
        noise_band: tuple[float, float] = BAND_HZ,
    ) -> None:
        Rig.__init__(self, layout=layout, fs=fs, limits=limits)
        SimulatedArm.__init__(self, seed, self.layout, self.fs, participant=participant, skin=skin, geometry=geometry,
                              n_images=n_images, ir_duration_s=ir_duration_s, latency_s=latency_s)
        self.noise_m = check_positive(noise_m, "noise_m", allow_zero=True)
        self.dropout_rate = check_positive(dropout_rate, "dropout_rate", allow_zero=True)
        lo, hi = (check_positive(v, "dropout_duration_s") for v in dropout_duration_s)
        if hi < lo:
            raise ValidationError(f"dropout_duration_s must be (shortest, longest), got {dropout_duration_s!r}")
        self.dropout_duration_s = (lo, hi)
        self.noise_band = check_band(noise_band, self.fs, "noise_band")
        self._rng = np.random.default_rng([self.seed, 0xD0])
        self.last_drive: np.ndarray | None = None
        self.n_played = 0
        self.samples_played = 0
        self._clock_lock = threading.Lock()  # the simulated rig may serve several threads at once
        self.outputs_v = np.zeros(self.layout.n_actuators)
        self.last_dropout_mask: np.ndarray | None = None

    # ------------------------------------------------------------------ Rig backend
    def read_strap_forces(self) -> np.ndarray:
        """Simulated strap force sensors, one per actuator strap, N.

        A model, not a measurement: a strap tightened to the 1 N target reads close to it
        where the actuator sits flat, and less where the arm narrows under it (partial
        contact), ``F = 1 N * (0.6 + 0.4 * contact)``, plus a seeded reading scatter of
        0.03 N. Used by ``vibrofocus straps`` and stored with each calibration, as the
        force-sensing resistors of a real rig are.

        Returns
        -------
        ndarray, shape (n_actuators,)
        """
        contact = np.asarray(self.participant.contact, dtype=float)
        scatter = np.random.default_rng([self.participant.seed or 0, 7919]).normal(0.0, 0.03, contact.shape)
        return 1.0 * (0.6 + 0.4 * contact) + scatter

    def _play(self, drive: np.ndarray) -> DeviceOnset:
        return self._output(drive, 0)

    def _output(self, drive: np.ndarray, n_after: int) -> DeviceOnset:
        """Put out a checked drive, then ``n_after`` samples of silence; return its onset."""
        # The sample clock advances by every sample this play puts out; the onset is
        # where it stood before.
        with self._clock_lock:
            start = self.samples_played
            self.samples_played += drive.shape[1] + n_after
            self.n_played += 1
        host = time.monotonic()
        self.last_drive = np.array(drive, copy=True)
        # The outputs hold the drive's last value until the safety layer zeroes them.
        self.outputs_v = self.last_drive[:, -1].copy()
        return DeviceOnset(host, start / self.fs, SIMULATED_CLOCK, latency_s=0.0)  # no output buffer

    def _play_and_record(self, drive: np.ndarray, points_xy: np.ndarray | None, n_tail: int) -> np.ndarray:
        self._output(drive, n_tail)
        return self._measure(self.respond(drive, points_xy, n_tail))

    def _play_and_capture(self, drive: np.ndarray, input_channel: int) -> tuple[np.ndarray, float]:
        # A loopback cable on an ideal sample clock: the strongest output comes back on
        # input 1 after the arm's modelled latency (latency_s), rounded to a sample.
        if input_channel != 1:
            raise ValidationError(f"the simulated rig has one loopback input, channel 1; got {input_channel}")
        lag, tail = int(round(self.latency_s * self.fs)), int(0.05 * self.fs)
        self._output(drive, lag + tail)
        strongest = drive[int(np.argmax(np.abs(drive).max(axis=1)))]
        return np.concatenate([np.zeros(lag), strongest, np.zeros(tail)]), self.fs

    def _measure(self, clean: np.ndarray) -> np.ndarray:
        """Add vibrometer noise and dropouts to a clean recording."""
        out = clean.copy()
        if self.noise_m > 0:
            lo, hi = self.noise_band
            white_rms = self.noise_m * np.sqrt((self.fs / 2) / (hi - lo))
            out += white_rms * self._rng.standard_normal(out.shape)
        mask = np.zeros(out.shape, dtype=bool)
        if self.dropout_rate > 0:
            duration = out.shape[1] / self.fs
            counts = self._rng.poisson(self.dropout_rate * duration, size=out.shape[0])
            for p in np.flatnonzero(counts):  # rare events: a loop over them is cheap
                for _ in range(counts[p]):
                    length = int(round(self._rng.uniform(*self.dropout_duration_s) * self.fs))
                    start = int(self._rng.integers(0, out.shape[1]))
                    mask[p, start:start + max(length, 1)] = True
            out[mask] = np.nan
        self.last_dropout_mask = mask
        return out

    def _zero_outputs(self) -> None:
        self.outputs_v = np.zeros(self.layout.n_actuators)

    def describe(self) -> dict:
        out = Rig.describe(self)
        model = self.describe_model()
        # The order of the former single class (the keys a calibration file stores).
        for key in ("seed", "skin", "participant", "geometry", "n_images"):
            out[key] = model.pop(key)
        out.update(noise_m=self.noise_m, dropout_rate=self.dropout_rate, **model)
        return out

    __repr__ = SimulatedArm.__repr__
