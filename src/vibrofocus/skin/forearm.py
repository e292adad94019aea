"""The simulated forearm's physics (docs/skin-model.md); the rig over it is
:class:`vibrofocus.rigs.SimulatedForearm`.

Model, per actuator ``q`` and skin point ``p`` (NumPy's ``exp(+i omega t)`` convention):

``H_pq(f) = K g_q c_q E_q(f) (mu_1 / G(f)) sum_m Green(k(f), d_pqm, a_q)``

with ``K`` the drive sensitivity (so that 10 V of the base Ricker on one nominal
actuator gives 2 µm peak on the actuator, the paper's anchor; 6 mm away on the
``voigt-fit`` preset), ``g_q`` the actuator's gain, ``c_q`` its contact
(coupling), ``E_q`` the inertial-exciter resonance, ``G(f)`` the skin's complex shear
modulus (a causal viscoelastic law, :mod:`.viscoelastic`; ``mu_1`` = 1 kPa), ``Green`` the
finite-contact surface Green's function with the complex wavenumber ``k(f)`` that the
same law gives, and ``d_pqm`` the
surface path lengths on the tapered cylinder, the short way and ``m`` times around
(see :mod:`.parameters`, :mod:`.geometry`, :mod:`.propagation`).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from functools import lru_cache

import numpy as np
from scipy import fft as sp_fft

from .._docs import fill_doc
from .._validation import as_array, check_positive
from ..defaults import FS_HZ, N_SAMPLES, SIGMA_S
from ..errors import ValidationError
from ..layout import ArrayLayout
from .geometry import ForearmGeometry
from .parameters import ForearmParameters
from .precursor import precursor_spectrum
from .presets import DEFAULT_SKIN, skin_preset
from .propagation import _disc_factor, exciter_response, surface_green, wavenumber

__all__ = ["SimulatedArm", "drive_sensitivity"]

#: Peak displacement of one nominal actuator driven by a 10 V Ricker, at the preset's anchor
#: distance (on the actuator: de Vlam et al. 2023, sec. II.C and Fig. 4b).
_REFERENCE_PEAK_M = 2e-6
_REFERENCE_DRIVE_V = 10.0
# Impulse responses kept per point set by play_and_record (calibration aims at a few
# points at a time, so a small cache avoids recomputing the model for every repeat).
_IR_CACHE_SIZE = 32
# Playback responses shared by every arm of the process, keyed by what they are computed
# from (path lengths, frequency factors, sensitivity, grid): a participant simulated again
# (a second rig of the same seed, another run in the same process) reuses them. At most
# this many bytes of responses are kept (the 11 x 11 skin grid's are about 24 MB).
_SHARED_IR_BYTES = 256 * 2**20
_shared_ir: OrderedDict[bytes, tuple[np.ndarray, np.ndarray | None]] = OrderedDict()
_shared_ir_lock = threading.Lock()
# Playback responses sample the continuous-time response from a grid this many times
# finer (see SimulatedForearm.impulse_responses), with the Hankel function interpolated
# from a distance table of this relative step (about 1e-6 relative error).
_IR_OVERSAMPLING = 4
_IR_TABLE_STEP = 5e-3
# Length of the precursor (response before t = 0) that the layered presets take out of
# their transfer, s: it holds all but ~1e-8 of the precursor's energy (tests/skin).
_PRECURSOR_S = 0.05
# Unit of the modulus in the compliance factor (any constant: K absorbs it).
_MODULUS_UNIT_PA = 1e3


def _share_responses(key: bytes, value: tuple[np.ndarray, np.ndarray | None]) -> None:
    """Keep playback responses in the process's shared cache, the oldest out beyond its budget."""
    with _shared_ir_lock:
        _shared_ir[key] = value
        _shared_ir.move_to_end(key)
        total = sum(_nbytes(v) for v in _shared_ir.values())
        while total > _SHARED_IR_BYTES and len(_shared_ir) > 1:
            total -= _nbytes(_shared_ir.popitem(last=False)[1])


def _nbytes(value: tuple[np.ndarray, np.ndarray | None]) -> int:
    """Bytes of a cached pair of responses and precursor."""
    ir, pre = value
    return ir.nbytes + (0 if pre is None else pre.nbytes)


def _frequency_factors(freqs: np.ndarray, params: ForearmParameters) -> tuple[np.ndarray, ...]:
    """What the transfer needs that depends on frequency but not on the points.

    Returns the physics-convention wavenumber (n_freqs,), the contact-disc factor
    (n_freqs, 1, n_actuators) and the source term (exciter, gain, contact and the skin's
    compliance, n_freqs, n_actuators) for ``freqs`` > 0. The complex Bessel functions
    of the disc factor are the costly part, so playback caches these per rig.
    """
    k = wavenumber(freqs, params.law)
    radius = params.contact_radius_m * np.sqrt(params.contact)
    disc = _disc_factor(k[:, None, None] * radius[None, None, :])
    source = exciter_response(freqs, params.f0_hz, params.q) * (params.gains * params.contact)[None, :]
    # A stiffer medium moves less under the same force: displacement goes as 1 / G(f)
    # (the "tension" of the skin layer), which is causal and passive like G itself.
    compliance = _MODULUS_UNIT_PA / params.law.modulus(freqs)
    return k, disc, source * compliance[:, None]


def _unit_transfer(freqs: np.ndarray, distances: np.ndarray, params: ForearmParameters,
                   max_nepers: float = 40.0, table_step: float | None = None,
                   factors: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Transfer without the drive sensitivity K, shape (n_freqs, n_points, n_actuators).

    ``distances`` has shape (n_points, n_actuators, n_images); DC gives 0 (an inertial
    exciter exerts no static force). ``factors``: :func:`_frequency_factors` of the
    positive frequencies, if already computed.
    """
    f = np.asarray(freqs, dtype=float)
    out = np.zeros((f.size, distances.shape[0], distances.shape[1]), dtype=complex)
    pos = f > 0
    if not pos.any():
        return out
    k, disc, source = _frequency_factors(f[pos], params) if factors is None else factors
    radius = params.contact_radius_m * np.sqrt(params.contact)
    green = np.zeros((k.size, distances.shape[0], distances.shape[1]), dtype=complex)
    for m in range(distances.shape[2]):  # a handful of images; frequencies stay vectorized
        green += surface_green(k, distances[:, :, m], radius, max_nepers=max_nepers, disc_factor=disc,
                               table_step=table_step)
    out[pos] = green * source[:, None, :]
    return out


@lru_cache(maxsize=16)
def drive_sensitivity(fs: float = FS_HZ, sigma: float = SIGMA_S, skin: str = "voigt-fit") -> float:
    """Drive sensitivity ``K`` of the model, m/V per unit Green's function.

    Chosen so that a 10 V peak Ricker (spread ``sigma``) on one nominal, fully coupled
    actuator of the skin preset ``skin`` gives 2 µm peak displacement at the preset's
    anchor distance on a flat arm: on the actuator for the evidence presets, as the
    paper measured (about 2 µm on one exciter at the 10 V maximum, the reason for its
    0.002 mm target; de Vlam et al. 2023, sec. II.C, Fig. 4b); 6 mm from its centre for
    ``voigt-fit``, as the earlier model had it.
    """
    n = 4096
    preset = skin_preset(skin)
    params = ForearmParameters.nominal(1, skin=skin)
    freqs = np.fft.rfftfreq(n, 1 / fs)
    h = _unit_transfer(freqs, np.full((1, 1, 1), preset.anchor_distance_m), params)[:, 0, 0]
    t = np.arange(n) / fs - 0.1
    pulse = _REFERENCE_DRIVE_V * (1 - t**2 / sigma**2) * np.exp(-(t**2) / (2 * sigma**2))
    response = np.fft.irfft(np.fft.rfft(pulse) * h, n)
    return _REFERENCE_PEAK_M / float(np.abs(response).max())


@fill_doc
class SimulatedArm:
    """A simulated participant's forearm with the actuator array: the physics alone.

    The transfer of the skin from every actuator to any point (:meth:`transfer`), its
    impulse responses and the response to a drive played once from silence
    (:meth:`respond`). It knows nothing of rigs: :class:`vibrofocus.rigs.SimulatedForearm`
    is the rig over it (safety layer, vibrometer noise and dropouts).

    Parameters
    ----------
    seed : int
        Participant seed: draws the participant (:meth:`ForearmParameters.draw`). Same
        seed, same arm.
    layout : ArrayLayout, optional
        The array; default the reference setup (docs/method.md).
    %(fs)s
    participant : ForearmParameters, optional
        Explicit parameters instead of drawing them from ``seed`` (for controlled
        experiments, e.g. ``ForearmParameters.nominal(4, skin="nominal")``).
    skin : str, optional
        Skin preset (:data:`vibrofocus.skin.SKIN_PRESETS`: ``"nominal"``, ``"low"``,
        ``"high"``, ``"voigt-fit"``) around which ``seed`` draws the participant.
        Default: the participant's preset when one is given, else ``"nominal"``.
    geometry : {"cylinder", "plane"}
        ``"cylinder"`` (default): the tapered forearm, waves come back around it.
        ``"plane"``: an unbounded flat skin, for checks of the propagation law.
    n_images : int
        Turns around the arm summed in each direction (cylinder only).
    ir_duration_s : float
        Length of the impulse responses used for playback, s. Playback is the linear
        convolution of the drive with these responses; they are the inverse FFT of
        :meth:`transfer` computed over twice this length (so nothing wraps into the
        kept part) with the last 10 % faded out.
    latency_s : float
        Fixed delay between drive and recording, s, to model the converter, amplifier
        and vibrometer-decoder delays of a particular rig. Default 0: the ``voigt-fit``
        law is causal by construction (:mod:`.viscoelastic`) and the layered presets'
        transfer is the causal part of their surface mode (:mod:`.precursor`), so no
        delay is needed to hide a precursor; an impulse response holds less than 1e-6
        of its energy before ``t = 0``.
    """

    def __init__(
        self,
        seed: int = 0,
        layout: ArrayLayout | None = None,
        fs: float = FS_HZ,
        *,
        participant: ForearmParameters | None = None,
        skin: str | None = None,
        geometry: str = "cylinder",
        n_images: int = 2,
        ir_duration_s: float = 0.4096,
        latency_s: float = 0.0,
    ) -> None:
        self.layout = layout if layout is not None else ArrayLayout.reference()
        self.fs = check_positive(fs, "fs")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValidationError(f"seed must be a non-negative integer, got {seed!r}")
        self.seed = int(seed)
        if skin is not None:
            skin = skin_preset(skin).name
        if participant is None:
            participant = ForearmParameters.draw(self.seed, self.layout, skin=skin or DEFAULT_SKIN)
        elif not isinstance(participant, ForearmParameters):
            raise ValidationError(f"participant must be a ForearmParameters, got {type(participant).__name__}")
        elif skin is not None and skin != participant.skin:
            raise ValidationError(f"skin={skin!r} contradicts the participant's skin {participant.skin!r}")
        if participant.n_actuators != self.layout.n_actuators:
            raise ValidationError(
                f"participant describes {participant.n_actuators} actuators but the layout has "
                f"{self.layout.n_actuators}"
            )
        self._participant = participant
        self._geometry = ForearmGeometry.from_parameters(participant, kind=geometry, n_images=n_images)
        self.n_ir = int(round(check_positive(ir_duration_s, "ir_duration_s") * self.fs))
        if self.n_ir < 16:
            raise ValidationError(f"ir_duration_s must cover at least 16 samples, got {self.n_ir}")
        self.latency_s = check_positive(latency_s, "latency_s", allow_zero=True)
        self.sensitivity = drive_sensitivity(self.fs, skin=participant.skin)
        # points -> (playback impulse responses, precursor samples or None)
        self._ir_cache: OrderedDict[bytes, tuple[np.ndarray, np.ndarray | None]] = OrderedDict()
        self._ir_lock = threading.Lock()
        self._ir_factors: tuple[np.ndarray, ...] | None = None

    # ------------------------------------------------------------------ the model
    @property
    def skin(self) -> str:
        """Name of the skin preset this arm was drawn on (in every output made from it)."""
        return self._participant.skin

    @property
    def participant(self) -> ForearmParameters:
        """This participant's parameters (read-only: cached responses depend on them)."""
        return self._participant

    @property
    def geometry(self) -> ForearmGeometry:
        """The forearm's surface geometry (read-only)."""
        return self._geometry

    def transfer(self, points_xy: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """The true transfer from every actuator's voltage to displacement at points.

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)
            Skin points in the layout frame, m.
        freqs : ndarray, shape (n_freqs,)
            Frequencies, Hz, >= 0 (e.g. ``numpy.fft.rfftfreq(n, 1 / fs)``).

        Returns
        -------
        ndarray, complex, shape (n_freqs, n_points, n_actuators)
            m/V, NumPy's FFT sign convention (a delay is ``exp(-2j pi f tau)``).

        Notes
        -----
        On a layered preset the transfer is that of the response's causal part: the
        single surface mode's precursor (the response before ``t = 0``, see
        :mod:`.precursor`), computed on the playback grid, is subtracted, so the true H
        and playback agree and nothing arrives before the drive.
        """
        points = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        f = as_array(freqs, "freqs", ndim=1)
        if np.any(f < 0):
            raise ValidationError(f"freqs must be >= 0 Hz, got a minimum of {f.min():g} Hz")
        h = self._transfer(points, f)
        pre = self._responses(points)[1]
        if pre is not None:
            h -= precursor_spectrum(pre, _IR_OVERSAMPLING * self.fs, f)
            h[f == 0] = 0.0  # the exciter exerts no static force (the precursor's mean is ~1e-4 of |H|)
        return h

    def mode_transfer(self, points_xy: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """The surface mode's transfer, precursor included: :meth:`transfer` without its
        causal correction.

        On the homogeneous ``voigt-fit`` law it equals :meth:`transfer`; on a layered
        preset it differs by the precursor, about 0.1-0.4 % of ``|H|`` over 30-1000 Hz
        at the reference points. It needs no playback grid, so it is some 20 times
        faster: a model fit evaluates it many times (:func:`vibrofocus.calibration.fit_model`).

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2)
            Skin points in the layout frame, m.
        freqs : ndarray, shape (n_freqs,)
            Frequencies, Hz, >= 0.

        Returns
        -------
        ndarray, complex, shape (n_freqs, n_points, n_actuators)
            m/V, NumPy's FFT sign convention.
        """
        points = as_array(points_xy, "points_xy", ndim=2, shape=(None, 2))
        f = as_array(freqs, "freqs", ndim=1)
        if np.any(f < 0):
            raise ValidationError(f"freqs must be >= 0 Hz, got a minimum of {f.min():g} Hz")
        return self._transfer(points, f)

    def _transfer(self, points: np.ndarray, f: np.ndarray, max_nepers: float = 40.0,
                  table_step: float | None = None, factors: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
        d = self.geometry.path_lengths(points, self.layout.actuators_xy)
        delay = np.exp(-2j * np.pi * f * self.latency_s)[:, None, None]
        return (self.sensitivity * delay) * _unit_transfer(f, d, self.participant, max_nepers, table_step, factors)

    def impulse_responses(self, points_xy: np.ndarray) -> np.ndarray:
        """Impulse responses used for playback, shape (n_points, n_actuators, n_ir), m/V per sample.

        The responses are the continuous-time responses sampled at ``fs`` (impulse
        invariance): the model is evaluated on a grid ``_IR_OVERSAMPLING`` times
        finer in time (``rfftfreq(2 n_ir R, 1 / (R fs))``), transformed, and every
        ``R``-th sample kept. Truncating the spectrum at ``fs / 2`` instead would be an
        ideal low-pass, whose ringing puts up to 1e-4 of the energy of a response next
        to an actuator before ``t = 0``; sampled this way, the causal model keeps less
        than 1e-7 there. The first ``n_ir`` samples are kept and the last 10 % faded
        out with a half Hann window, so the responses are finite and playback is an
        exact linear convolution. In band their spectrum equals :meth:`transfer` up to
        the aliases ``H(f + m fs)``, which the skin's attenuation makes negligible
        except under the contact itself.
        """
        return self._responses(as_array(points_xy, "points_xy", ndim=2, shape=(None, 2)))[0]

    def _responses(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Playback impulse responses and, on a layered preset, the precursor samples
        (the last ``_PRECURSOR_S`` of the fine grid's circular response, shape
        (n_pre, n_points, n_actuators)); cached per point set, and shared with every arm
        of the process that computes the same ones (a second rig of the same participant)."""
        key = points.tobytes()
        with self._ir_lock:
            if key in self._ir_cache:
                self._ir_cache.move_to_end(key)
                return self._ir_cache[key]
        r = _IR_OVERSAMPLING
        n_fft = 2 * self.n_ir * r
        freqs = np.fft.rfftfreq(n_fft, 1 / (r * self.fs))
        with self._ir_lock:
            if self._ir_factors is None:  # the same grid for every point set
                self._ir_factors = _frequency_factors(freqs[1:], self.participant)
            factors = self._ir_factors
        shared_key = self._shared_key(points, factors)
        with _shared_ir_lock:
            found = _shared_ir.get(shared_key)
            if found is not None:
                _shared_ir.move_to_end(shared_key)
        if found is None:
            found = self._compute_responses(points, freqs, factors)
            _share_responses(shared_key, found)
        ir, pre = found
        with self._ir_lock:  # a web server may record from several threads
            self._ir_cache[key] = (ir, pre)
            if len(self._ir_cache) > _IR_CACHE_SIZE:
                self._ir_cache.popitem(last=False)
        return ir, pre

    def _shared_key(self, points: np.ndarray, factors: tuple[np.ndarray, ...]) -> bytes:
        """What the playback responses of ``points`` are computed from, hashed: two arms
        with equal keys have equal responses (the shared cache's key)."""
        d = self.geometry.path_lengths(points, self.layout.actuators_xy)
        radius = self.participant.contact_radius_m * np.sqrt(self.participant.contact)
        digest = hashlib.sha256(repr((d.shape, self.n_ir, self.fs, self.latency_s, self.sensitivity,
                                      self.participant.layered is None, _IR_OVERSAMPLING, _IR_TABLE_STEP,
                                      [a.shape for a in factors])).encode())
        for a in (d, np.asarray(radius, dtype=float), *factors):
            digest.update(np.ascontiguousarray(a).tobytes())
        return digest.digest()

    def _compute_responses(self, points: np.ndarray, freqs: np.ndarray,
                           factors: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray | None]:
        """Playback impulse responses and precursor of ``points`` (see :meth:`_responses`)."""
        r = _IR_OVERSAMPLING
        n_fft = 2 * self.n_ir * r
        h = self._transfer(points, freqs, table_step=_IR_TABLE_STEP, factors=factors)
        fine = np.fft.irfft(h, n_fft, axis=0)
        ir = r * fine[: r * self.n_ir: r]
        n_fade = max(self.n_ir // 10, 1)
        ir[-n_fade:] *= np.hanning(2 * n_fade)[n_fade:, None, None]
        ir = np.ascontiguousarray(np.moveaxis(ir, 0, -1))
        ir.setflags(write=False)
        pre = None
        if self.participant.layered is not None:
            pre = fine[-min(int(round(_PRECURSOR_S * r * self.fs)), n_fft // 4):].copy()
            pre.setflags(write=False)
        return ir, pre

    def response_length(self, points_xy: np.ndarray | None = None, tol: float = 1e-4) -> int:
        """Samples that hold all but ``tol`` of every playback impulse response's energy.

        :meth:`design_window` makes a design window from it.

        Parameters
        ----------
        points_xy : ndarray, shape (n_points, 2), optional
            Points, m; default the layout's points.
        tol : float
            Share of energy allowed past the returned length, in (0, 1).

        Returns
        -------
        int
            Samples at ``fs`` (at most ``n_ir``).
        """
        from .._validation import check_in_range

        tol = check_in_range(tol, "tol", 0.0, 1.0, inclusive=False)
        points = self.layout.points_xy if points_xy is None else as_array(points_xy, "points_xy", ndim=2,
                                                                         shape=(None, 2))
        energy = np.cumsum(self.impulse_responses(points) ** 2, axis=2)
        total = energy[..., -1:]
        done = np.all((energy >= (1 - tol) * total) | (total == 0), axis=(0, 1))
        return int(np.argmax(done)) + 1 if done.any() else self.n_ir

    def transfer_matrix(self, n_samples: int | None = None):
        """This arm's true transfer at its layout's points, as a
        :class:`~vibrofocus.rendering.TransferMatrix` (provenance: the seed and skin preset).

        Parameters
        ----------
        n_samples : int, optional
            Design window, samples; default :meth:`design_window`.

        Returns
        -------
        TransferMatrix
        """
        from ..rendering.transfer import TransferMatrix

        return TransferMatrix.from_model(self, self.layout, self.fs, n_samples)

    def design_window(self, minimum: int = N_SAMPLES, tol: float = 1e-5) -> int:
        """A design window that follows this arm's impulse-response length, samples.

        The tap sits mid-window: before it the inverse drive's pre-ringing, after it the
        medium's ring-down, each about as long as the responses
        (:meth:`response_length`). The window is four times that, rounded up to a power
        of two and at least ``minimum``. ``render`` and the demo use it when no window is
        given.

        Parameters
        ----------
        minimum : int
            Shortest window, samples.
        tol : float
            Share of each response's energy allowed past the ring-down length.
        """
        need = 4 * self.response_length(tol=tol)
        return int(max(minimum, 2 ** int(np.ceil(np.log2(need)))))

    def field(
        self,
        drive: np.ndarray,
        grid_xy: np.ndarray,
        times: np.ndarray | None = None,
        *,
        tail_s: float = 0.05,
        rtol: float = 1e-7,
        block: int = 512,
    ) -> np.ndarray:
        """Noise-free displacement over many points, for pictures and simulated people.

        Evaluates the model only at frequencies where the drive has energy (spectral
        magnitude above ``rtol`` times its peak), interpolates the Hankel function
        from a distance table (about 1e-6 relative error) and, for a few requested
        instants, sums the spectrum directly instead of transforming every sample;
        points are processed in blocks to bound memory.

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n_samples)
            Voltages, V. Not played: no safety check beyond validation.
        grid_xy : ndarray, shape (n_grid, 2)
            Points, m.
        times : ndarray, shape (n_times,), optional
            Instants, s, from the start of the drive (0 <= t). Default: every sample of
            the drive and ``tail_s`` after it.
        tail_s : float
            Extra time after the drive when ``times`` is None, s.
        rtol : float
            Frequencies where ``|drive spectrum|`` is below ``rtol`` times its maximum
            (over actuators) are left out, and so are wave paths attenuated below
            ``rtol / 100`` (``alpha d > ln(100 / rtol)``).
        block : int
            Points per block.

        Returns
        -------
        ndarray, shape (n_grid, n_times)
            Displacement, m; the same, up to the faded end of the impulse responses,
            as a noise-free :meth:`play_and_record` of the same (faded) drive.
        """
        d = as_array(drive, "drive", ndim=2, shape=(self.layout.n_actuators, None))
        grid = as_array(grid_xy, "grid_xy", ndim=2, shape=(None, 2))
        n = d.shape[1]
        if n == 0:
            raise ValidationError("drive holds no samples")
        n_tail = int(round(check_positive(tail_s, "tail_s", allow_zero=True) * self.fs))
        if times is None:
            t_idx = None
            n_out = n + n_tail
        else:
            t = as_array(times, "times", ndim=1)
            if np.any(t < 0):
                raise ValidationError(f"times must be >= 0 s, got a minimum of {t.min():g} s")
            t_idx = t
            n_out = int(np.ceil(t.max() * self.fs)) + 1 if t.size else 1
        n_fft = sp_fft.next_fast_len(max(n_out, n) + self.n_ir, real=True)
        spectrum = np.fft.rfft(d, n_fft, axis=1)
        freqs = np.fft.rfftfreq(n_fft, 1 / self.fs)
        mag = np.abs(spectrum).max(axis=0)
        keep = np.flatnonzero(mag > rtol * mag.max()) if mag.max() > 0 else np.zeros(0, int)
        n_times = n_out if t_idx is None else t_idx.size
        out = np.zeros((len(grid), n_times))
        if keep.size == 0:
            return out
        fk = freqs[keep]
        sk = spectrum[:, keep]
        max_nepers = float(np.log(100.0 / check_positive(rtol, "rtol")))
        # Weights of a real inverse DFT restricted to the kept bins (DC and Nyquist once).
        weight = np.full(keep.size, 2.0)
        weight[(keep == 0) | ((n_fft % 2 == 0) & (keep == n_fft // 2))] = 1.0
        if t_idx is not None:
            phasor = np.exp(2j * np.pi * fk[:, None] * t_idx[None, :]) * (weight / n_fft)[:, None]
        for start in range(0, len(grid), max(int(block), 1)):
            pts = grid[start:start + block]
            # A distance table for the Hankel function (about 1e-6 relative error) makes
            # dense grids cheaper; transfer() itself stays exact.
            h = self._transfer(pts, fk, max_nepers, table_step=5e-3)  # (n_keep, n_pts, n_act)
            u = np.einsum("fpq,qf->pf", h, sk)
            if t_idx is None:
                full = np.zeros((len(pts), n_fft // 2 + 1), dtype=complex)
                full[:, keep] = u
                out[start:start + len(pts)] = np.fft.irfft(full, n_fft, axis=1)[:, :n_out]
            else:
                out[start:start + len(pts)] = (u @ phasor).real
        return out

    # ------------------------------------------------------------------ playback
    def respond(self, drive: np.ndarray, points_xy: np.ndarray | None = None, n_tail: int = 0) -> np.ndarray:
        """Displacement at ``points_xy`` when ``drive`` plays once from silence, m.

        The linear convolution of the drive with the impulse responses, zero-padded:
        the response with its tail after the drive, never wrapped to the start.

        Parameters
        ----------
        drive : ndarray, shape (n_actuators, n)
            Drive, V.
        points_xy : ndarray, shape (n_points, 2), optional
            Points, m; default the layout's (locations then guards).
        n_tail : int
            Samples kept after the drive.

        Returns
        -------
        ndarray, shape (n_points, n + n_tail)
        """
        from scipy.signal import fftconvolve  # here: scipy.signal takes most of the arm's import time

        points = self.layout.points_xy if points_xy is None else points_xy
        ir = self.impulse_responses(points)  # (n_points, n_act, n_ir)
        n_out = drive.shape[1] + n_tail
        # Silent channels contribute nothing (calibration plays one actuator at a time).
        active = np.flatnonzero(np.any(drive != 0, axis=1))
        out = np.zeros((len(points), n_out))
        if active.size:
            # shape (n_points, n_active, n + n_ir - 1)
            conv = fftconvolve(ir[:, active], drive[None, active, :], axes=2)
            rec = conv.sum(axis=1)
            m = min(n_out, rec.shape[1])
            out[:, :m] = rec[:, :m]
        return out

    def describe_model(self) -> dict:
        """The arm's description: seed, skin preset, participant, geometry, responses."""
        return dict(seed=self.seed, skin=self.skin, participant=self.participant.to_dict(),
                    geometry=self.geometry.kind, n_images=self.geometry.n_images,
                    ir_duration_s=self.n_ir / self.fs, latency_s=self.latency_s)

    def __repr__(self) -> str:
        p = self.participant
        return (
            f"{type(self).__name__}(seed={self.seed}, skin={self.skin!r}, c(250 Hz)={p.c250_m_s:.2f} m/s, "
            f"alpha(250 Hz)={p.alpha250_np_m:.1f} Np/m, contact={np.round(p.contact, 2).tolist()}, "
            f"geometry={self.geometry.kind!r})"
        )
