"""inverse_filter and InverseOperator against analytic media and independent references."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose
from scipy.signal import fftconvolve

from vibrofocus.rendering import InverseOperator, inverse_filter
from vibrofocus.errors import CausalityError, DriveLimitError, ValidationError
from vibrofocus.rendering import DriveScaledWarning, WraparoundCheck, band_taper
from vibrofocus.rendering.inverse import scale_to_peak
from vibrofocus.signals import ricker

from ._media import FS, delay_gain_medium, fir_medium, random_fir_taps

BAND = (10.0, 1000.0)


def band_limited(x: np.ndarray, fs: float = FS, band=BAND) -> np.ndarray:
    n = x.shape[-1]
    return np.fft.irfft(np.fft.rfft(x, axis=-1) * band_taper(np.fft.rfftfreq(n, 1 / fs), band), n, axis=-1)


def respond(H: np.ndarray, drives: np.ndarray) -> np.ndarray:
    """Circular response irfft(H rfft(drives)), written independently of the package."""
    n = drives.shape[1]
    return np.fft.irfft(np.einsum("fpq,qf->pf", H, np.fft.rfft(drives, axis=-1)), n, axis=-1)


def naive_pinv_design(H, targets, fs=FS, band=BAND, rcond=None):
    """The reference: numpy.linalg.pinv at each frequency in a Python loop."""
    n = targets.shape[1]
    taper = band_taper(np.fft.rfftfreq(n, 1 / fs), band)
    U = np.fft.rfft(targets, axis=-1).T
    S = np.zeros((H.shape[0], H.shape[2]), complex)
    for k in range(H.shape[0]):
        pinv = np.linalg.pinv(H[k]) if rcond is None else np.linalg.pinv(H[k], rcond=rcond)
        S[k] = taper[k] * pinv @ U[k]
    return np.fft.irfft(S, n, axis=0).T


def random_medium(rng, n, n_points, n_actuators, length=32):
    return fir_medium(n, random_fir_taps(rng, n_points, n_actuators, length))


# ---------------------------------------------------------------- analytic media
def test_pure_delay_single_path_is_shift_and_gain():
    n, delay, gain = 2048, 37, 2.5e-6
    H = delay_gain_medium(n, FS, np.array([[delay]]), np.array([[gain]]))
    target = ricker(FS, duration=n / FS)[None] * 2e-6
    drives = inverse_filter(H, target, FS)
    # Undo a delay of `delay` samples and a gain: the band-limited target, earlier.
    assert_allclose(drives[0], np.roll(band_limited(target[0]), -delay) / gain, atol=1e-9 * np.abs(drives).max())


def test_pure_delay_diagonal_medium_each_actuator_serves_its_point():
    n = 1024
    delays = np.array([[5, 0], [0, 11]])
    gains = np.array([[2.0, 0.0], [0.0, 0.5]])
    H = delay_gain_medium(n, FS, delays, gains)
    targets = np.stack([ricker(FS, duration=n / FS), -ricker(FS, 2e-3, duration=n / FS)])
    drives = inverse_filter(H, targets, FS)
    expected = np.stack([np.roll(band_limited(targets[0]), -5) / 2.0, np.roll(band_limited(targets[1]), -11) / 0.5])
    assert_allclose(drives, expected, atol=1e-12)


@pytest.mark.parametrize("n_act", [2, 4])
def test_square_well_conditioned_medium_reproduces_targets_in_band(rng, n_act):
    n = 1024
    H = random_medium(rng, n, n_act, n_act)
    targets = rng.standard_normal((n_act, n))
    drives = inverse_filter(H, targets, FS, check_wraparound=False)
    assert_allclose(respond(H, drives), band_limited(targets), atol=1e-10 * np.abs(targets).max())


def test_linear_convolution_through_fir_medium_reproduces_target(rng):
    n, length = 2048, 48
    taps = random_fir_taps(rng, 3, 3, length)
    H = fir_medium(n, taps)
    targets = np.zeros((3, n))
    targets[1] = ricker(FS, duration=n / FS) * 2e-6  # t0 in the middle of the window
    drives = inverse_filter(H, targets, FS)
    # Play the drives once from silence: zero-padded linear convolution, no wrap-around.
    played = np.zeros((3, n + length - 1))
    for p in range(3):
        for q in range(3):
            played[p] += fftconvolve(drives[q], taps[p, q])
    assert_allclose(played[:, :n], band_limited(targets), atol=1e-3 * 2e-6)
    assert np.abs(played[:, n:]).max() < 1e-3 * 2e-6


def test_wraparound_check_fires_when_window_too_short():
    # A 300-sample delay and a target 100 samples into the window: the drive would have to
    # start 200 samples before the window, so the circular design wraps it to the end.
    n = 1024
    H = delay_gain_medium(n, FS, np.array([[300]]), np.array([[1.0]]))
    target = ricker(FS, 1e-3, duration=n / FS, t0=100 / FS)[None]
    with pytest.raises(CausalityError, match="too short"):
        inverse_filter(H, target, FS)
    # The same target late enough in the window passes.
    late = ricker(FS, 1e-3, duration=n / FS, t0=600 / FS)[None]
    inverse_filter(H, late, FS)


def test_a_kept_wraparound_check_gives_the_one_shot_verdict(rng):
    n = 1024
    H = delay_gain_medium(n, FS, np.array([[300]]), np.array([[1.0]]))
    kept = WraparoundCheck(H)
    early = ricker(FS, 1e-3, duration=n / FS, t0=100 / FS)[None]
    with pytest.raises(CausalityError, match="too short"):
        inverse_filter(H, early, FS, wraparound=kept)
    # Through a richer medium, several designs reuse the kept spectra: same drives and
    # the fraction of the one-shot check (which transforms every path again).
    H = random_medium(rng, n, 5, 3)
    kept = WraparoundCheck(H)
    for t0 in (0.3, 0.5, 0.7):
        targets = np.zeros((5, n))
        targets[1] = ricker(FS, 1e-3, duration=n / FS, t0=t0 * n / FS)
        once, report = inverse_filter(H, targets, FS, full_output=True)
        again, kept_report = inverse_filter(H, targets, FS, wraparound=kept, full_output=True)
        assert_allclose(again, once, rtol=0, atol=0)
        assert_allclose(kept_report.wraparound_fraction, report.wraparound_fraction, rtol=1e-4, atol=1e-12)
    assert kept._padded is not None  # built once, kept


def test_a_wraparound_check_of_another_medium_is_refused(rng):
    n = 256
    H = random_medium(rng, n, 3, 2)
    targets = rng.standard_normal((3, n))
    other = H.copy()
    other[10] *= 2
    with pytest.raises(ValidationError, match="another transfer matrix"):
        inverse_filter(H, targets, FS, wraparound=WraparoundCheck(other))
    with pytest.raises(ValidationError, match="another transfer matrix"):
        inverse_filter(H[:-1], targets[:, :-2], FS, wraparound=WraparoundCheck(H))
    with pytest.raises(ValidationError, match="must be a WraparoundCheck"):
        inverse_filter(H, targets, FS, wraparound=H)
    # An equal copy is the same medium.
    inverse_filter(H, targets, FS, wraparound=WraparoundCheck(H.copy()), check_wraparound=False)
    # The same array changed in place after the check was built is not.
    kept = WraparoundCheck(H)
    inverse_filter(H, targets, FS, wraparound=kept, check_wraparound=False)  # compared all the same
    H[20, 1, 0] *= 1.001
    with pytest.raises(ValidationError, match="changed in place"):
        inverse_filter(H, targets, FS, wraparound=kept, check_wraparound=False)
    H[20, 2, 1] = np.nan
    with pytest.raises(ValidationError, match="NaN|finite"):
        inverse_filter(H, targets, FS, wraparound=kept, check_wraparound=False)


def test_wraparound_can_warn_instead():
    n = 1024
    H = delay_gain_medium(n, FS, np.array([[300]]), np.array([[1.0]]))
    target = ricker(FS, 1e-3, duration=n / FS, t0=100 / FS)[None]
    with pytest.warns(UserWarning, match="too short"):
        inverse_filter(H, target, FS, check_wraparound="warn")


# ---------------------------------------------------------------- independent references
@pytest.mark.parametrize("shape", [(13, 4), (5, 4), (4, 4), (3, 4)])
def test_matches_naive_pinv_loop(rng, shape):
    n = 512
    H = random_medium(rng, n, *shape)
    # Make some frequencies ill conditioned / rank deficient to exercise the SVD route.
    H[40, :, 1] = H[40, :, 0]
    H[41, :, 1] = H[41, :, 0] * (1 + 1e-7)
    targets = rng.standard_normal((shape[0], n))
    drives = inverse_filter(H, targets, FS, check_wraparound=False)
    assert_allclose(drives, naive_pinv_design(H, targets), rtol=0, atol=1e-9 * np.abs(drives).max())


def test_tikhonov_matches_regularized_normal_equations(rng):
    n, lam = 512, 0.05
    H = random_medium(rng, n, 6, 4)
    targets = rng.standard_normal((6, n))
    drives = inverse_filter(H, targets, FS, regularization="tikhonov", reg_param=lam, check_wraparound=False)
    # (H^H H + (lam s_max)^2 I) S = H^H U, solved per frequency by numpy.linalg.solve.
    s_max = np.linalg.svd(H, compute_uv=False)[:, 0]
    Hh = np.conj(np.swapaxes(H, 1, 2))
    lhs = Hh @ H + (lam * s_max)[:, None, None] ** 2 * np.eye(4)
    rhs = Hh @ np.fft.rfft(targets, axis=-1).T[:, :, None]
    taper = band_taper(np.fft.rfftfreq(n, 1 / FS), BAND)
    S = np.linalg.solve(lhs, rhs)[:, :, 0] * taper[:, None]
    assert_allclose(drives, np.fft.irfft(S, n, axis=0).T, atol=1e-10 * np.abs(drives).max())


def test_tsvd_matches_pinv_with_rcond(rng):
    n = 512
    H = random_medium(rng, n, 6, 4)
    H[:, :, 3] = H[:, :, 2] + 0.05 * H[:, :, 3]  # a weak direction at every frequency
    targets = rng.standard_normal((6, n))
    drives = inverse_filter(H, targets, FS, regularization="tsvd", reg_param=0.1, check_wraparound=False)
    expected = naive_pinv_design(H, targets, rcond=0.1)
    assert_allclose(drives, expected, atol=1e-9 * np.abs(expected).max())
    plain = inverse_filter(H, targets, FS, check_wraparound=False)
    assert np.linalg.norm(drives) < 0.5 * np.linalg.norm(plain)  # the weak direction was dropped


# ---------------------------------------------------------------- properties
@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), a=st.floats(-3, 3), b=st.floats(-3, 3))
def test_linear_in_target(seed, a, b):
    rng = np.random.default_rng(seed)
    n = 256
    H = random_medium(rng, n, 5, 3, length=16)
    t1, t2 = rng.standard_normal((2, 5, n))
    d1, d2, d12 = (inverse_filter(H, t, FS, check_wraparound=False) for t in (t1, t2, a * t1 + b * t2))
    assert_allclose(d12, a * d1 + b * d2, atol=1e-10 * (abs(a) + abs(b) + 1) * max(np.abs(d1).max(), np.abs(d2).max()))


@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), lam_small=st.floats(1e-4, 0.3), factor=st.floats(1.01, 20))
def test_regularization_never_raises_drive_norm(seed, lam_small, factor):
    rng = np.random.default_rng(seed)
    n = 256
    H = random_medium(rng, n, 6, 4, length=16)
    targets = rng.standard_normal((6, n))
    norm = lambda **kw: np.linalg.norm(inverse_filter(H, targets, FS, check_wraparound=False, **kw))  # noqa: E731
    plain = norm()
    weak = norm(regularization="tikhonov", reg_param=lam_small)
    strong = norm(regularization="tikhonov", reg_param=lam_small * factor)
    assert weak <= plain * (1 + 1e-12)
    assert strong <= weak * (1 + 1e-12)
    cut_weak = norm(regularization="tsvd", reg_param=min(lam_small, 1.0))
    cut_strong = norm(regularization="tsvd", reg_param=min(lam_small * factor, 1.0))
    assert cut_strong <= cut_weak * (1 + 1e-12) <= plain * (1 + 1e-12) ** 2


# ---------------------------------------------------------------- operator
def test_operator_gives_same_drives_as_inverse_filter(rng):
    n = 1024
    H = random_medium(rng, n, 9, 4)
    targets = rng.standard_normal((9, n))
    for reg, param in ((None, None), ("tikhonov", 0.02), ("tsvd", 0.05)):
        op = InverseOperator(H, FS, regularization=reg, reg_param=param)
        expected = inverse_filter(H, targets, FS, regularization=reg, reg_param=param, check_wraparound=False)
        assert_allclose(op.drives(targets), expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


def test_operator_retarget_one_point_equals_full_design(rng):
    n = 1024
    H = random_medium(rng, n, 7, 4)
    control = [2, 5, 6, 0]
    op = InverseOperator(H, FS, control=control)
    waveform = ricker(FS, duration=n / FS)
    targets = np.zeros((4, n))
    targets[1] = waveform  # control[1] is point 5
    assert_allclose(op.drives_for_point(5, waveform), op.drives(targets), rtol=1e-10, atol=1e-14)
    expected = inverse_filter(H[:, control], targets, FS, check_wraparound=False)
    assert_allclose(op.drives_for_point(5, waveform), expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    with pytest.raises(ValidationError, match="not one of the operator's control points"):
        op.drives_for_point(1, waveform)


def test_operator_predicts_at_every_point(rng):
    n = 512
    H = random_medium(rng, n, 6, 3)
    op = InverseOperator(H, FS, control=[0, 1, 2])
    drives = rng.standard_normal((3, n))
    assert_allclose(op.predict(drives), respond(H, drives), rtol=1e-10, atol=1e-12)
    assert op.predict(drives).shape == (6, n)


# ---------------------------------------------------------------- drive limit
def test_drive_limit_refuse_and_scale(rng):
    n = 512
    H = random_medium(rng, n, 3, 3)
    targets = rng.standard_normal((3, n))
    free = inverse_filter(H, targets, FS, check_wraparound=False)
    limit = 0.5 * np.abs(free).max()
    with pytest.raises(DriveLimitError, match="max_drive"):
        inverse_filter(H, targets, FS, max_drive=limit, check_wraparound=False)
    scaled, report = inverse_filter(H, targets, FS, max_drive=limit, on_limit="scale", check_wraparound=False,
                                    full_output=True)
    assert_allclose(np.abs(scaled).max(), limit, rtol=1e-12)
    assert_allclose(report.scale, 0.5, rtol=1e-12)
    assert_allclose(scaled, 0.5 * free, rtol=1e-12, atol=1e-15)
    peak_row = np.unravel_index(np.argmax(np.abs(targets)), targets.shape)[0]
    assert_allclose(report.reached_peak, np.abs(respond(H, scaled)[peak_row]).max(), rtol=1e-10)
    with pytest.warns(DriveScaledWarning, match="scaled by 0.5"):
        inverse_filter(H, targets, FS, max_drive=limit, on_limit="scale", check_wraparound=False)
    within = inverse_filter(H, targets, FS, max_drive=2 * limit, check_wraparound=False)
    assert_allclose(within, free, rtol=0, atol=0)



def test_scaled_drives_never_read_over_the_limit():
    # drives * (limit / peak) rounds one ulp over the limit for some arrays (about 1 in 60
    # of these); a drive scaled to the limit must peak at the limit, not just over it.
    rng = np.random.default_rng(2026)
    naive_over = 0
    for _ in range(500):
        drives = rng.standard_normal((4, 64)) * rng.uniform(0.1, 100.0)
        limit = float(rng.uniform(0.5, 20.0))
        naive_over += np.abs(drives * (limit / np.abs(drives).max())).max() > limit
        scaled = scale_to_peak(drives, limit)
        assert np.abs(scaled).max() <= limit
        assert_allclose(np.abs(scaled).max(), limit, rtol=1e-15)
        assert_allclose(scaled, drives * (limit / np.abs(drives).max()), rtol=1e-15, atol=0)
    assert naive_over > 0  # the case this guards against occurs in the sample

# ------------------------------- bad input (docs/method.md, "Bad input, full disks and interrupts")
@pytest.fixture
def small_case(rng):
    n = 256
    return random_medium(rng, n, 3, 2, length=8), rng.standard_normal((3, n))


def test_rejects_wrong_frequency_count(small_case):
    H, targets = small_case
    with pytest.raises(ValidationError, match=r"n // 2 \+ 1 = 129"):
        inverse_filter(H[:-1], targets, FS)


def test_rejects_wrong_point_count(small_case):
    H, targets = small_case
    with pytest.raises(ValidationError, match="targets has 2 rows but H has 3 points"):
        inverse_filter(H, targets[:2], FS)


def test_rejects_wrong_dimensions(small_case):
    H, targets = small_case
    with pytest.raises(ValidationError, match="H must have 3 dimension"):
        inverse_filter(H[:, 0], targets, FS)
    with pytest.raises(ValidationError, match="targets must have 2 dimension"):
        inverse_filter(H, targets[0], FS)
    with pytest.raises(ValidationError, match="targets must be real"):
        inverse_filter(H, targets + 0j, FS)


@pytest.mark.parametrize("where", ["H", "targets"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_rejects_non_finite(small_case, where, bad):
    H, targets = (a.copy() for a in small_case)
    (H if where == "H" else targets)[(1, 1, 1) if where == "H" else (1, 1)] = bad
    with pytest.raises(ValidationError, match=rf"{where} contains 1 non-finite"):
        inverse_filter(H, targets, FS)


@pytest.mark.parametrize("band", [(0.0, 1000.0), (10.0, 6000.0), (500.0, 100.0), (-5.0, 100.0), (10.0,)])
def test_rejects_band_outside_nyquist(small_case, band):
    H, targets = small_case
    with pytest.raises(ValidationError, match="band"):
        inverse_filter(H, targets, FS, band=band)


def test_rejects_all_zero_and_empty_transfer(small_case):
    H, targets = small_case
    with pytest.raises(ValidationError, match="H is all zero"):
        inverse_filter(np.zeros_like(H), targets, FS)
    with pytest.raises(ValidationError, match="H is empty"):
        inverse_filter(np.zeros((129, 3, 0), complex), targets, FS)


def test_rejects_transfer_zero_inside_band(small_case):
    H, targets = small_case
    H = H.copy()
    H[10] = 0  # 10 * 10 kHz / 256 = 390.625 Hz
    with pytest.raises(ValidationError, match=r"H is zero at 1 frequency inside band.*390.625 Hz"):
        inverse_filter(H, targets, FS)


def test_rejects_bad_options(small_case):
    H, targets = small_case
    with pytest.raises(ValidationError, match="regularization must be one of"):
        inverse_filter(H, targets, FS, regularization="ridge")
    with pytest.raises(ValidationError, match="reg_param"):
        inverse_filter(H, targets, FS, reg_param=0.1)
    with pytest.raises(ValidationError, match="reg_param must be > 0"):
        inverse_filter(H, targets, FS, regularization="tikhonov", reg_param=-1)
    with pytest.raises(ValidationError, match="on_limit must be one of"):
        inverse_filter(H, targets, FS, on_limit="clip")
    with pytest.raises(ValidationError, match="max_drive must be > 0"):
        inverse_filter(H, targets, FS, max_drive=0)
    with pytest.raises(ValidationError, match="fs must be > 0"):
        inverse_filter(H, targets, -1.0)


def test_odd_window_length(rng):
    n = 1023  # n // 2 + 1 = 512 bins, the same count as n = 1022
    H = random_medium(rng, n, 3, 3)
    targets = rng.standard_normal((3, n))
    drives = inverse_filter(H, targets, FS, check_wraparound=False)
    assert drives.shape == (3, n)
    assert_allclose(respond(H, drives), band_limited(targets), atol=1e-10 * np.abs(targets).max())
    op = InverseOperator(H, FS, n_samples=n)
    assert_allclose(op.drives(targets), drives, rtol=1e-10, atol=1e-12 * np.abs(drives).max())
    with pytest.raises(ValidationError, match="n_samples implies n = 1000"):
        InverseOperator(H, FS, n_samples=1000)


def test_operator_bad_control(rng):
    H = random_medium(rng, 256, 4, 2, length=8)
    with pytest.raises(ValidationError, match="control holds indices outside the 4 points"):
        InverseOperator(H, FS, control=[0, 4])
    with pytest.raises(ValidationError, match="control holds repeated point indices"):
        InverseOperator(H, FS, control=[1, 1])
    op = InverseOperator(H, FS, control=[0, 2])
    with pytest.raises(ValidationError, match=r"targets must have shape \(2, 256\)"):
        op.drives(np.zeros((4, 256)))


def test_weighted_operator_matches_weighted_pinv(rng):
    n = 512
    H = random_medium(rng, n, 5, 3)
    weights = np.array([1.0, 0.2, 0.2, 3.0, 0.5])
    targets = rng.standard_normal((5, n))
    op = InverseOperator(H, FS, weights=weights)
    # (W H)^+ W U per frequency, by the naive loop on the weighted problem.
    expected = naive_pinv_design(H * weights[None, :, None], targets * weights[:, None])
    assert_allclose(op.drives(targets), expected, atol=1e-9 * np.abs(expected).max())
    with pytest.raises(ValidationError, match="weights must all be > 0"):
        InverseOperator(H, FS, weights=[1, 1, 0, 1, 1])
    with pytest.raises(ValidationError, match=r"weights must have shape \(5,\)"):
        InverseOperator(H, FS, weights=[1, 1])


@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), n_points=st.integers(1, 7), n_actuators=st.integers(1, 5),
       regularization=st.sampled_from([None, "tikhonov", "tsvd"]), shift=st.integers(-100, 100))
def test_operator_equals_design_and_designs_are_shift_covariant(seed, n_points, n_actuators, regularization, shift):
    rng = np.random.default_rng(seed)
    n = 256
    H = random_medium(rng, n, n_points, n_actuators, length=12)
    targets = rng.standard_normal((n_points, n))
    kw = dict(regularization=regularization, reg_param=None if regularization is None else 0.05)
    drives = inverse_filter(H, targets, FS, check_wraparound=False, **kw)
    op = InverseOperator(H, FS, **kw)
    assert_allclose(op.drives(targets), drives, rtol=1e-10, atol=1e-12 * np.abs(drives).max())
    # A linear time-invariant design: delaying the targets (circularly) delays the drives.
    shifted = inverse_filter(H, np.roll(targets, shift, axis=1), FS, check_wraparound=False, **kw)
    assert_allclose(shifted, np.roll(drives, shift, axis=1), atol=1e-10 * np.abs(drives).max())
