"""Tests of the simulated forearm rig: physics recovered from its recordings, linearity,
reproducibility and playback."""

import numpy as np
import pytest
from scipy import optimize, signal

from vibrofocus import ArrayLayout, SimulatedForearm, ricker
from vibrofocus.errors import ValidationError
from vibrofocus.skin import ForearmParameters

FS = 10_000.0


def _quiet(**kwargs) -> SimulatedForearm:
    """A noise-free, dropout-free forearm."""
    kwargs.setdefault("seed", 0)
    return SimulatedForearm(noise_m=0.0, dropout_rate=0.0, **kwargs)


def _single_actuator_drive(n_act: int, q: int, duration: float = 0.2, t0: float = 0.02, amp: float = 10.0,
                           sigma: float = 0.5e-3):
    pulse = ricker(FS, sigma=sigma, duration=duration, t0=t0, amplitude=amp)
    drive = np.zeros((n_act, pulse.size))
    drive[q] = pulse
    return drive


def _speed_and_attenuation(rig, src, direction, d1, d2, freqs, q=0):
    """Phase speed (m/s) and attenuation (Np/m) recovered from two recordings."""
    drive = _single_actuator_drive(rig.layout.n_actuators, q, duration=0.8)
    pts = np.array([src + d1 * direction, src + d2 * direction])
    rec = rig.play_and_record(drive, pts, tail_s=0.0)
    spec = np.fft.rfft(rec, axis=1)
    f = np.fft.rfftfreq(rec.shape[1], 1 / FS)
    # From the first bin above DC (phase there is a fraction of a radian, so unwrapping
    # upward from it counts the whole turns) to well above the band.
    use = (f > 0) & (f < 1500)
    f, ratio = f[use], spec[1, use] / spec[0, use]
    # NumPy convention: the farther point lags by k_r (d2 - d1) radians.
    phase = -np.unwrap(np.angle(ratio))
    k_r = np.interp(freqs, f, phase) / (d2 - d1)
    speed = 2 * np.pi * np.asarray(freqs) / k_r
    mag = np.interp(freqs, f, np.abs(ratio))
    alpha = -np.log(mag * np.sqrt(d2 / d1)) / (d2 - d1)  # undo cylindrical spreading
    return speed, alpha


def test_flat_arm_recovers_the_speed_and_attenuation_of_a_voigt_law():
    # Kelvin-Voigt (order 1) has closed forms independent of the code under test.
    mu, eta, rho = 6e3, 1.2, 1100.0
    params = ForearmParameters.nominal(4, shear_modulus_pa=mu, spring_pot_pa_sn=eta, fractional_order=1.0,
                                       density_kg_m3=rho, rayleigh_factor=1.0)
    rig = _quiet(participant=params, geometry="plane")
    src = rig.layout.actuators_xy[2]
    freqs = np.array([100.0, 250.0, 500.0])
    speed, alpha = _speed_and_attenuation(rig, src, np.array([0.0, -1.0]), 0.02, 0.04, freqs, q=2)
    w = 2 * np.pi * freqs
    mag = np.sqrt(mu**2 + (w * eta) ** 2)
    np.testing.assert_allclose(speed, np.sqrt(2 * mag**2 / (rho * (mu + mag))), rtol=0.05)
    np.testing.assert_allclose(alpha, np.sqrt(rho * w**2 * (mag - mu) / (2 * mag**2)), rtol=0.05)


def test_default_participant_speed_is_plausible_and_dispersive():
    rig = _quiet()
    src = rig.layout.actuators_xy[2]  # elbow side, toward the elbow: far from any image
    freqs = np.array([100.0, 250.0, 500.0])
    speed, alpha = _speed_and_attenuation(rig, src, np.array([0.0, -1.0]), 0.02, 0.04, freqs, q=2)
    p = rig.participant
    assert 2.0 <= speed[1] <= 8.0
    assert speed[0] < speed[1] < speed[2]  # low frequencies travel slower
    np.testing.assert_allclose(speed, p.phase_speed(freqs), rtol=0.05)
    # The layered arm loses little; at 100 Hz (k r about 4) the far-field spreading
    # correction of the estimate is off by a few Np/m, hence the absolute tolerance.
    np.testing.assert_allclose(alpha, p.attenuation(freqs), rtol=0.05, atol=5.0)


@pytest.mark.parametrize(("skin", "low_db", "high_db"), [("voigt-fit", 30.0, 45.0), ("nominal", 10.0, 25.0)])
def test_peak_loss_from_6_to_35_mm(skin, low_db, high_db):
    # Cylindrical spreading alone gives 10 log10(35 / 6) = 7.7 dB. The homogeneous Voigt
    # fit adds 190 Np/m at 250 Hz (30-45 dB in all); the layered arm's loss tangent of
    # 0.14 adds about 28 Np/m (some 15 dB in all), so the tap is still there 4 cm away as
    # Shah et al. 2019 (Appl. Sci. 9:4329) found above 150 Hz.
    rig = _quiet(skin=skin)
    src = rig.layout.actuators_xy[2]
    drive = _single_actuator_drive(4, 2, amp=10.0, sigma=1e-3)  # the base stimulus
    down = np.array([0.0, -1.0])
    rec = rig.play_and_record(drive, np.array([src + 6e-3 * down, src + 35e-3 * down]))
    peaks = np.abs(rec).max(axis=1)
    loss_db = 20 * np.log10(peaks[0] / peaks[1])
    assert low_db <= loss_db <= high_db


def test_ten_volts_give_about_two_micrometres_next_to_a_nominal_actuator():
    rig = _quiet(participant=ForearmParameters.nominal(4))
    src = rig.layout.actuators_xy[3]
    drive = np.zeros((4, 2000))
    drive[3] = ricker(FS, duration=0.2, t0=0.02, amplitude=10.0)
    rec = rig.play_and_record(drive, src[None] + [[0.0, -6e-3]])
    np.testing.assert_allclose(np.abs(rec).max(), 2e-6, rtol=0.05)


def test_superposition_holds_to_numerical_precision(rng):
    rig = _quiet(seed=4)
    n = 1500
    sos = signal.butter(4, [20, 900], btype="band", fs=FS, output="sos")
    d1, d2 = (signal.sosfilt(sos, rng.standard_normal((4, n))) for _ in range(2))
    d1, d2 = (np.pad(d / np.abs(d).max(), ((0, 0), (50, 50))) for d in (d1, d2))
    a, b = 2.5, -1.5
    pts = rng.uniform(-0.04, 0.04, (5, 2))
    r1 = rig.play_and_record(d1, pts)
    r2 = rig.play_and_record(d2, pts)
    r12 = rig.play_and_record(a * d1 + b * d2, pts)
    np.testing.assert_allclose(r12, a * r1 + b * r2, rtol=0, atol=1e-10 * np.abs(r12).max())


def test_time_invariance_holds_to_numerical_precision():
    rig = _quiet(seed=2)
    shift = 137
    base = _single_actuator_drive(4, 1, duration=0.1)
    base[0] = -0.5 * base[1]
    early = np.pad(base, ((0, 0), (0, shift)))
    late = np.pad(base, ((0, 0), (shift, 0)))
    r_early = rig.play_and_record(early)
    r_late = rig.play_and_record(late)
    np.testing.assert_allclose(r_late[:, shift:], r_early[:, :-shift], rtol=0, atol=1e-12 * np.abs(r_early).max())
    np.testing.assert_allclose(r_late[:, :shift], 0.0, atol=1e-12 * np.abs(r_early).max())


def test_reciprocity_between_identical_actuators_on_the_tapered_arm():
    a, b = np.array([-0.01, 0.03]), np.array([0.025, -0.02])
    layout = ArrayLayout(np.array([a, b]), np.array([a, b]))
    rig = _quiet(layout=layout, participant=ForearmParameters.nominal(2))
    f = np.linspace(10, 1000, 200)
    h = rig.transfer(np.array([a, b]), f)
    np.testing.assert_allclose(h[:, 1, 0], h[:, 0, 1], rtol=1e-10)  # source A at B == source B at A
    # With unequal contact the symmetry is broken: the test can tell.
    p = ForearmParameters(contact=[1.0, 0.5], gains=[1.0, 1.0], f0_hz=[500.0, 500.0], q=[1.0, 1.0])
    h2 = _quiet(layout=layout, participant=p).transfer(np.array([a, b]), f)
    assert np.max(np.abs(h2[:, 1, 0] - h2[:, 0, 1])) > 0.1 * np.max(np.abs(h2[:, 1, 0]))


def test_far_side_of_the_arm_hears_later_than_a_near_point_at_the_same_chord():
    layout = ArrayLayout(np.array([[0.0, 0.0]]), np.array([[0.0, 0.01]]))
    rig = _quiet(layout=layout, participant=ForearmParameters.nominal(1))
    geo = rig.geometry
    far = np.array([float(geo.circumference(0.0)) / 2, 0.0])  # opposite side of the arm
    chord = np.linalg.norm(np.diff(geo.to_3d(np.array([[0.0, 0.0], far])), axis=0))

    def chord_minus(y):
        return np.linalg.norm(np.diff(geo.to_3d(np.array([[0.0, 0.0], [0.0, y]])), axis=0)) - chord

    near = np.array([0.0, optimize.brentq(chord_minus, 0.01, 0.12)])
    drive = _single_actuator_drive(1, 0, duration=0.2)
    rec = rig.play_and_record(drive, np.array([near, far]))
    envelope = np.abs(signal.hilbert(rec, axis=1))
    t_near, t_far = envelope.argmax(axis=1) / FS
    assert t_far > t_near + 5e-3  # the far side is reached over the surface, not through the arm


def test_same_seed_reproduces_everything_and_seeds_differ():
    drive = _single_actuator_drive(4, 0, duration=0.3)
    a = SimulatedForearm(seed=11, dropout_rate=20.0).play_and_record(drive)
    b = SimulatedForearm(seed=11, dropout_rate=20.0).play_and_record(drive)
    np.testing.assert_array_equal(a, b)  # noise and dropouts included (NaN compares equal here)
    c = SimulatedForearm(seed=12, dropout_rate=20.0).play_and_record(drive)
    assert not np.allclose(np.nan_to_num(a), np.nan_to_num(c))


def test_playback_is_linear_not_circular():
    rig = _quiet(participant=ForearmParameters.nominal(4))
    # 10 ms drive; the point is 90 mm away, so the wave (about 7 m/s group speed)
    # arrives after the drive has ended.
    drive = _single_actuator_drive(4, 0, duration=0.01, t0=0.004)
    pt = rig.layout.actuators_xy[0][None] + [[0.0, -0.09]]
    rec = rig.play_and_record(drive, pt, tail_s=0.15)[0]
    n = drive.shape[1]
    assert np.abs(rec[:n]).max() < 0.05 * np.abs(rec).max()  # nothing wrapped to the start
    # Independent reference: direct (non-FFT) linear convolution with the rig's responses.
    ir = rig.impulse_responses(pt)[0]
    ref = sum(np.convolve(rig.last_drive[q], ir[q]) for q in range(4))[: rec.size]
    np.testing.assert_allclose(rec, ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_impulse_responses_agree_with_the_transfer():
    rig = _quiet(seed=5)
    pts = rig.layout.points_xy[:3]
    ir = rig.impulse_responses(pts)
    f = np.fft.rfftfreq(rig.n_ir, 1 / FS)
    h = rig.transfer(pts, f)
    band = (f > 10) & (f < 1000)
    err = np.abs(np.moveaxis(np.fft.rfft(ir, axis=2), 2, 0) - h)[band]
    assert err.max() < 0.02 * np.abs(h[band]).max()


def test_field_matches_noise_free_recordings_and_instants():
    rig = _quiet(seed=6)
    drive = _single_actuator_drive(4, 0, duration=0.1)
    drive[3] = -0.7 * np.roll(drive[0], 40)
    pts = rig.layout.points_xy
    rec = rig.play_and_record(drive, pts, tail_s=0.05)
    full = rig.field(rig.last_drive, pts, tail_s=0.05)
    assert full.shape == rec.shape
    # Playback samples the continuous response (impulse invariance); the field truncates
    # the spectrum at Nyquist. They differ by the aliases above Nyquist, small at >= 6 mm
    # (on the low-loss layered arm some 0.25 % of the peak, from the guard 9 mm away).
    np.testing.assert_allclose(full, rec, rtol=0, atol=5e-3 * np.abs(rec).max())
    idx = np.array([0, 100, 321, 999])
    some = rig.field(rig.last_drive, pts, times=idx / FS)
    np.testing.assert_allclose(some, full[:, idx], rtol=0, atol=1e-9 * np.abs(full).max())


def test_noise_has_the_documented_in_band_rms():
    rig = SimulatedForearm(seed=1, noise_m=1e-9, dropout_rate=0.0)
    rec = rig.play_and_record(np.zeros((4, 40_000)), np.zeros((1, 2)), tail_s=0.0)[0]
    sos = signal.butter(8, [10, 1000], btype="band", fs=FS, output="sos")
    in_band = signal.sosfiltfilt(sos, rec)[2000:-2000]
    np.testing.assert_allclose(np.sqrt(np.mean(in_band**2)), 1e-9, rtol=0.1)


def test_dropouts_are_nan_and_flagged():
    rig = SimulatedForearm(seed=3, dropout_rate=5.0)
    rec = rig.play_and_record(np.zeros((4, 10_000)))
    assert np.isnan(rec).any()
    np.testing.assert_array_equal(np.isnan(rec), rig.last_dropout_mask)
    clean = SimulatedForearm(seed=3, dropout_rate=0.0).play_and_record(np.zeros((4, 10_000)))
    assert not np.isnan(clean).any()


def test_transfer_shape_dc_and_bad_input():
    rig = _quiet()
    h = rig.transfer(rig.layout.points_xy, np.array([0.0, 100.0, 250.0]))
    assert h.shape == (3, 13, 4) and h.dtype == complex
    np.testing.assert_array_equal(h[0], 0)  # an inertial exciter exerts no static force
    with pytest.raises(ValidationError, match="freqs"):
        rig.transfer(rig.layout.points_xy, [-1.0, 10.0])
    with pytest.raises(ValidationError, match="points_xy"):
        rig.transfer(np.zeros((3, 3)), [10.0])
    with pytest.raises(ValidationError, match="drive"):
        rig.field(np.zeros((3, 10)), np.zeros((1, 2)))
    with pytest.raises(ValidationError, match="participant"):
        SimulatedForearm(participant=ForearmParameters.nominal(2))
    with pytest.raises(ValidationError, match="noise_m"):
        SimulatedForearm(noise_m=-1.0)


def test_waves_come_back_around_the_arm_at_low_frequencies_only():
    params = ForearmParameters.nominal(4)
    cyl = _quiet(participant=params)
    flat = _quiet(participant=params, geometry="plane")
    point = cyl.layout.actuators_xy[0][None] + [[0.03, 0.0]]
    f = np.array([12.0, 500.0])
    h_cyl = cyl.transfer(point, f)[:, 0, 0]
    h_flat = flat.transfer(point, f)[:, 0, 0]
    # At 500 Hz the way round (> 0.15 m) costs exp(-alpha(500 Hz) * 0.15 m), below 1e-6.
    assert params.attenuation([500.0])[0] * 0.15 > np.log(1e6)
    np.testing.assert_allclose(h_cyl[1], h_flat[1], rtol=1e-6)
    # At 12 Hz (a few Np/m) the wave that went round the arm adds a sizeable contribution.
    assert abs(h_cyl[0] - h_flat[0]) > 0.1 * abs(h_flat[0])


def test_simulated_strap_forces_follow_contact_and_the_seed():
    from vibrofocus.rigs.force import check_straps

    rig = SimulatedForearm(seed=4)
    forces = rig.read_strap_forces()
    assert forces.shape == (rig.layout.n_actuators,)
    np.testing.assert_array_equal(forces, SimulatedForearm(seed=4).read_strap_forces())
    assert not np.array_equal(forces, SimulatedForearm(seed=5).read_strap_forces())
    # F = 1 N (0.6 + 0.4 contact) within the 0.03 N scatter (4 SD)
    expected = 0.6 + 0.4 * np.asarray(rig.participant.contact)
    np.testing.assert_allclose(forces, expected, atol=0.12)
    reading = check_straps(rig)
    assert reading.simulated and reading.target_n == 1.0


def _energy_before_zero(rig, points, oversampling=4, n=2**15, precursor_s=0.05):
    """Share of each impulse response's energy in the ``precursor_s`` before t = 0.

    Independent of the rig's own playback responses: the true transfer on a grid
    ``oversampling`` times finer than the rig's rate, so that the spectrum's truncation at
    Nyquist rings too little to matter, over a window (3.3 s) long enough that the slowly
    decaying low-frequency tail wraps around into negative times at below 1e-9.
    Returns shape (n_points, n_actuators).
    """
    m = n * oversampling
    h = rig.transfer(points, np.fft.rfftfreq(m, 1 / (oversampling * rig.fs)))
    e = np.fft.irfft(h, m, axis=0) ** 2
    k = int(precursor_s * oversampling * rig.fs)
    return e[m - k:].sum(axis=0) / e.sum(axis=0)


@pytest.mark.parametrize(("skin", "seed"), [("voigt-fit", 0), ("voigt-fit", 3), ("nominal", 0), ("low", 3),
                                          ("high", 3)])
def test_impulse_responses_are_causal_with_no_latency(skin, seed):
    rig = _quiet(seed=seed, skin=skin)
    assert rig.latency_s == 0.0
    a = rig.layout.actuators_xy
    # every layout point, under each actuator's centre and 1 mm, 3 mm and 6 mm from it
    pts = np.concatenate([rig.layout.points_xy, a, a + [1e-3, 0.0], a + [3e-3, 0.0], a + [0.0, 6e-3]])
    assert _energy_before_zero(rig, pts).max() < 1e-6


def test_layered_transfer_is_the_causal_part_of_the_single_mode():
    # One surface mode whose speed rises with frequency at low loss has a precursor
    # (Kramers-Kronig); the layered presets subtract it (skin/precursor.py). Without the
    # subtraction the share before t = 0 is large under the actuator; with it, nil; and
    # what is taken out is small in the band.
    rig = _quiet(skin="nominal")
    a = rig.layout.actuators_xy[:1]
    f = np.fft.rfftfreq(4096, 1 / FS)
    corrected = rig.transfer(a, f)
    single_mode = rig._transfer(a, f)
    band = (f >= 10) & (f <= 1000)
    change = np.abs(corrected - single_mode)[band].max() / np.abs(single_mode[band]).max()
    assert 1e-5 < change < 0.05
    ir_mode = np.fft.irfft(single_mode, 4096, axis=0)[:, 0, 0] ** 2
    assert ir_mode[-400:].sum() / ir_mode.sum() > 1e-4  # the uncorrected mode is acausal


def test_field_and_transfer_use_one_skin():
    rig = _quiet(skin="high")
    assert rig.skin == "high" and rig.describe()["skin"] == "high" and "high" in repr(rig)
    with pytest.raises(ValidationError, match="contradicts"):
        SimulatedForearm(participant=ForearmParameters.nominal(4), skin="nominal")
    with pytest.raises(ValidationError, match="skin must be one of"):
        SimulatedForearm(skin="firm")


def test_arrival_times_follow_the_group_speed():
    rig = _quiet(participant=ForearmParameters.nominal(4), geometry="plane")
    f_c = 250.0
    t = np.arange(int(0.4 * FS)) / FS
    burst = 10.0 * np.exp(-0.5 * ((t - 0.1) / 0.02) ** 2) * np.sin(2 * np.pi * f_c * (t - 0.1))
    drive = np.zeros((4, t.size))
    drive[2] = burst
    src = rig.layout.actuators_xy[2]
    d1, d2 = 0.02, 0.05
    rec = rig.play_and_record(drive, src + np.array([[0.0, -d1], [0.0, -d2]]), tail_s=0.0)
    envelope = np.abs(signal.hilbert(rec, axis=1))
    # the envelope's centroid is robust to its flat top
    t_arrival = (envelope**2 @ t) / (envelope**2).sum(axis=1)
    delay = t_arrival[1] - t_arrival[0]
    expected = (d2 - d1) / rig.participant.group_speed(np.array([f_c]))[0]
    np.testing.assert_allclose(delay, expected, rtol=0.05)
    # and it is not the phase speed, which differs by more than the tolerance here
    assert abs((d2 - d1) / rig.participant.phase_speed(np.array([f_c]))[0] - expected) > 0.1 * expected


def test_skin_under_a_contact_is_passive():
    # Driving-point compliance of the skin (no exciter): a passive medium absorbs power,
    # which in NumPy's convention means Im(u / F) <= 0 at every frequency.
    layout = ArrayLayout(np.array([[0.0, 0.0]]), np.array([[0.0, 0.0]]))
    params = ForearmParameters.nominal(1)
    rig = _quiet(layout=layout, participant=params, geometry="plane")
    f = np.geomspace(5.0, 5000.0, 300)
    from vibrofocus.skin.propagation import exciter_response

    # The power a uniform pressure on the contact disc puts in is set by the disc's
    # average displacement: midpoint quadrature over rings (the plane under a centred
    # contact is axisymmetric, so one point per ring, on a slant, stands for its ring).
    a = params.contact_radius_m
    r = (np.arange(40) + 0.5) * a / 40
    pts = r[:, None] * np.array([[np.cos(0.3), np.sin(0.3)]])
    weights = r / r.sum()
    h = rig.transfer(pts, f)[:, :, 0] @ weights
    skin = h / exciter_response(f, params.f0_hz, params.q)[:, 0]
    assert np.all(skin.imag < 0)
    # An active term would show: flipping the sign of the loss would break it.
    assert not np.all(np.conj(skin).imag < 0)


def test_a_second_arm_of_the_same_participant_reuses_its_playback_responses(monkeypatch):
    # Playback responses are shared in the process, keyed by what they are computed from:
    # a second rig of the same seed computes none, another seed or latency does.
    from vibrofocus.skin import forearm

    pts = ArrayLayout.reference().points_xy[:2]
    first = _quiet(seed=5).impulse_responses(pts)
    computed = []
    real = forearm.SimulatedArm._compute_responses
    monkeypatch.setattr(forearm.SimulatedArm, "_compute_responses",
                        lambda self, *a: computed.append(self.seed) or real(self, *a))
    assert _quiet(seed=5).impulse_responses(pts) is first
    assert computed == []
    other = _quiet(seed=6).impulse_responses(pts)
    late = _quiet(seed=5, latency_s=1e-3).impulse_responses(pts)
    assert computed == [6, 5]
    assert not np.allclose(other, first, rtol=1e-3, atol=0) and not np.allclose(late, first, rtol=1e-3, atol=0)
    monkeypatch.setattr(forearm, "_shared_ir", type(forearm._shared_ir)())  # an empty cache
    np.testing.assert_array_equal(_quiet(seed=5).impulse_responses(pts), first)
    assert computed == [6, 5, 5]
