"""render(): every method on analytic media, drive limits, causality and bad input."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import ArrayLayout, Design, render, ricker
from vibrofocus.errors import CausalityError, DriveLimitError, ValidationError
from vibrofocus.rendering import band_taper, funneling_gains

from ._media import FS, layout_medium

N = 4096
REF = ArrayLayout.reference()
# The reference array with three guards: target + guards is a square 4 x 4 system, so the
# inverse designs meet their targets exactly and the prediction can be checked analytically.
SQUARE = ArrayLayout(REF.actuators_xy, REF.locations_xy, REF.guards_xy[:3], spacing_xy=REF.spacing_xy)


def band_limited(x):
    return np.fft.irfft(np.fft.rfft(x) * band_taper(np.fft.rfftfreq(len(x), 1 / FS), (10.0, 1000.0)), len(x))


def respond(H, drives):
    return np.fft.irfft(np.einsum("fpq,qf->pf", H, np.fft.rfft(drives, axis=-1)), drives.shape[1], axis=-1)


@pytest.fixture(scope="module")
def H_square():
    return layout_medium(SQUARE, N, FS)


@pytest.fixture(scope="module")
def H_ref():
    return layout_medium(REF, N, FS)


@pytest.mark.parametrize("location", [1, 5, 9])
def test_inverse_meets_target_and_silences_guards(H_square, location):
    r = render("inverse", H_square, FS, SQUARE, location, limit_v=1e3, scale_to_limit=False)
    assert isinstance(r, Design)
    ideal = band_limited(2e-6 * ricker(FS, 1e-3, N / FS))
    assert_allclose(r.desired, ideal, atol=1e-15)
    assert_allclose(r.predicted, respond(H_square, r.drives), atol=1e-15)
    assert_allclose(r.predicted[location - 1], ideal, atol=1e-6 * 2e-6)
    assert np.abs(r.predicted[SQUARE.guard_indices]).max() < 1e-6 * 2e-6
    assert r.scale == 1.0 and r.target_index == location - 1
    assert_allclose(r.reached_peak_m, 2e-6, rtol=1e-3)
    m = r.metrics()
    assert m["fidelity"] > 1 - 1e-9
    assert_allclose(r.t0, N / 2 / FS)


def test_funneling_drives_are_gains_times_ricker(H_ref):
    r = render("funneling", H_ref, FS, REF, 1, scale_to_limit=False)
    gains = funneling_gains(REF.actuators_xy, REF.locations_xy[0])
    assert_allclose(r.drives, gains[:, None] * ricker(FS, 1e-3, N / FS)[None], rtol=1e-12, atol=1e-15)
    assert_allclose(r.predicted, respond(H_ref, r.drives), atol=1e-18)
    assert r.control_indices.size == 0 and r.scale == 1.0


def test_combination_targets_the_funneling_prediction(H_square):
    r = render("combination", H_square, FS, SQUARE, 2, limit_v=1e3, scale_to_limit=False)
    funnel = render("funneling", H_square, FS, SQUARE, 2, limit_v=1e3, scale_to_limit=False)
    assert_allclose(r.desired, band_limited(funnel.predicted[1]), atol=1e-9 * np.abs(r.desired).max())
    assert_allclose(r.predicted[1], r.desired, atol=1e-6 * np.abs(r.desired).max())
    assert np.abs(r.predicted[SQUARE.guard_indices]).max() < 1e-6 * np.abs(r.desired).max()


def test_time_reversal_is_conjugate_transfer_normalized_to_limit(H_ref):
    r = render("time_reversal", H_ref, FS, REF, 5, limit_v=8.0)
    assert_allclose(np.abs(r.drives).max(), 8.0, rtol=1e-12)
    # Single non-zero target: each actuator plays conj(H_tq) U_t.
    spectrum = np.conj(H_ref[:, 4, :]).T * np.fft.rfft(band_limited(ricker(FS, 1e-3, N / FS)))
    expected = np.fft.irfft(spectrum, N, axis=-1)
    assert_allclose(r.drives, expected * 8.0 / np.abs(expected).max(), atol=1e-9)


def test_limit_scales_or_refuses(H_square):
    free = render("inverse", H_square, FS, SQUARE, 5, limit_v=1e3, scale_to_limit=False)
    limit = 0.25 * free.needed_peak_v
    scaled = render("inverse", H_square, FS, SQUARE, 5, limit_v=limit, scale_to_limit=False)
    assert_allclose(scaled.scale, 0.25, rtol=1e-12)
    assert_allclose(np.abs(scaled.drives).max(), limit, rtol=1e-12)
    assert_allclose(scaled.reached_peak_m, 0.25 * free.reached_peak_m, rtol=1e-12)
    with pytest.raises(DriveLimitError, match="location 5 needs .* peak drive, over the limit"):
        render("inverse", H_square, FS, SQUARE, 5, limit_v=limit, on_limit="refuse", scale_to_limit=False)
    funnel = render("funneling", H_square, FS, SQUARE, 5, limit_v=1.0, scale_to_limit=False)  # 2.5 V per actuator needed
    assert_allclose(funnel.scale, 1.0 / 2.5, rtol=1e-12)


@pytest.mark.parametrize("guard_weight", [1.0, 0.1])
def test_reference_layout_least_squares_design_is_consistent(H_ref, guard_weight):
    # 5 control points (target + 4 guards), 4 actuators: the (weighted) least-squares
    # design. With W = diag(1, w, w, w, w), its residual at the control points satisfies
    # the weighted normal equations H_c^H W^2 (H_c S - U_c) = 0 at every frequency of
    # the band; w = 1 is the paper's plain pseudo-inverse.
    r = render("inverse", H_ref, FS, REF, 5, limit_v=1e3, guard_weight=guard_weight, scale_to_limit=False)
    assert list(r.control_indices) == [4, 9, 10, 11, 12]
    Hc = H_ref[:, r.control_indices, :]
    w2 = np.array([1.0] + [guard_weight**2] * 4)
    wanted = np.zeros((5, N))
    wanted[0] = r.desired
    residual = np.fft.rfft(r.predicted[r.control_indices] - wanted, axis=-1).T  # (F, 5)
    normal = np.einsum("fcq,fc->fq", Hc.conj(), w2 * residual)
    scale = np.abs(np.einsum("fcq,fc->fq", Hc.conj(), w2 * np.fft.rfft(wanted, axis=-1).T)).max()
    assert np.abs(normal).max() < 1e-9 * scale
    assert np.abs(residual).max() > 1e-3 * np.abs(np.fft.rfft(r.desired)).max()  # not met exactly
    all_points = render("inverse", H_ref, FS, REF, 5, control="all", regularization="tikhonov", scale_to_limit=False)
    assert list(all_points.control_indices) == [4, 0, 1, 2, 3, 5, 6, 7, 8, 9, 10, 11, 12]


def test_lighter_guards_let_the_target_be_reached(H_ref):
    # 5 x 4 least squares: lowering the guards' weight moves the solution toward the
    # target at the guards' expense.
    reached, guard_peak = [], []
    for weight in (1.0, 0.3, 0.1, 0.01):
        r = render("inverse", H_ref, FS, REF, 5, guard_weight=weight, limit_v=1e3, scale_to_limit=False)
        reached.append(r.reached_peak_m)
        guard_peak.append(np.abs(r.predicted[REF.guard_indices]).max())
    assert np.all(np.diff(reached) > 0) and np.all(np.diff(guard_peak) > 0)
    assert reached[-1] > 0.9 * 2e-6


def test_window_too_short_raises_causality_error():
    # 120 ms of latency in a 2048-sample window whose target sits at 102 ms: the drive
    # would have to start before the window.
    H = layout_medium(REF, 2048, FS, latency_s=0.12)
    with pytest.raises(CausalityError, match="too short"):
        render("inverse", H, FS, REF, 5, regularization="tikhonov", scale_to_limit=False)
    later = render("inverse", H, FS, REF, 5, regularization="tikhonov", t0=0.16, scale_to_limit=False)
    assert later.wraparound_fraction < 1e-3


def test_sleeve_of_32_actuators_through_the_same_code():
    n = 2048
    # Without guards, control="guards" leaves the target alone: 1 x 32, met exactly, and
    # labelled "no focus control".
    sleeve = ArrayLayout.sleeve()
    assert sleeve.n_actuators == 32 and sleeve.n_points == 108
    H = layout_medium(sleeve, n, FS, speed_m_s=20.0)
    r = render("inverse", H, FS, sleeve, 50, n_samples=n, limit_v=1e3, scale_to_limit=False, control="guards")
    assert r.drives.shape == (32, n) and r.predicted.shape == (108, n)
    assert_allclose(r.predicted[49], r.desired, atol=1e-6 * 2e-6)
    assert r.control_note.startswith("no focus control") and r.control_indices.tolist() == [49]
    # The default holds down the calibrated area instead (the other locations) and says so.
    r = render("inverse", H, FS, sleeve, 50, n_samples=n, limit_v=1e3, scale_to_limit=False, check_wraparound=False)
    assert len(r.control_indices) == 108 and "no guard points" in r.control_note
    # With a guard by every actuator: 33 control points, the least-squares design.
    guarded = ArrayLayout.grid((8, 4), (0.21 / 8, 0.045), (9, 12), 0.01, guard_offset_m=0.006, name="sleeve")
    H = layout_medium(guarded, n, FS, speed_m_s=20.0)
    for method in ("funneling", "inverse", "combination", "time_reversal"):
        r = render(method, H, FS, guarded, 50, regularization="tikhonov")
        assert r.drives.shape == (32, n) and r.predicted.shape == (140, n)
        assert np.abs(r.drives).max() <= 10.0 * (1 + 1e-12)


def test_bad_input(H_ref):
    with pytest.raises(ValidationError, match="location 10 is outside the layout's locations 1..9"):
        render("inverse", H_ref, FS, REF, 10, scale_to_limit=False)
    with pytest.raises(ValidationError, match="location must be an integer"):
        render("inverse", H_ref, FS, REF, 2.5, scale_to_limit=False)
    with pytest.raises(ValidationError, match="method must be one of"):
        render("beamforming", H_ref, FS, REF, 1)
    with pytest.raises(ValidationError, match=r"H must have shape \(n_freqs, 13, 4\)"):
        render("inverse", H_ref[:, :9], FS, REF, 1, scale_to_limit=False)
    with pytest.raises(ValidationError, match="layout must be an ArrayLayout"):
        render("inverse", H_ref, FS, "reference", 1, scale_to_limit=False)
    with pytest.raises(ValidationError, match="band must satisfy"):
        render("inverse", H_ref, FS, REF, 1, band=(10, 8000), scale_to_limit=False)
    with pytest.raises(ValidationError, match="n_samples implies n = 4000"):
        render("inverse", H_ref, FS, REF, 1, n_samples=4000, scale_to_limit=False)
    bad = H_ref.copy()
    bad[3, 2, 1] = np.nan
    with pytest.raises(ValidationError, match="H contains 1 non-finite"):
        render("inverse", bad, FS, REF, 1, scale_to_limit=False)
    with pytest.raises(ValidationError, match="H is all zero"):
        render("inverse", np.zeros_like(H_ref), FS, REF, 1, scale_to_limit=False)
    with pytest.raises(ValidationError, match=r"band=\(5, 1000\) Hz reaches outside the calibrated band \(10, 1000\)"):
        render("inverse", H_ref, FS, REF, 1, band=(5, 1000), calibrated_band=(10, 1000), scale_to_limit=False)
    with pytest.raises(ValidationError, match="regularization must be one of"):
        render("funneling", H_ref, FS, REF, 1, regularization="lasso", scale_to_limit=False)
    with pytest.raises(ValidationError, match="guard_weight must be > 0"):
        render("inverse", H_ref, FS, REF, 1, guard_weight=0, scale_to_limit=False)
    with pytest.raises(ValidationError, match="control must be one of"):
        render("inverse", H_ref, FS, REF, 1, control="none", scale_to_limit=False)


@pytest.mark.parametrize("n_samples, words", [
    (2**40, r"n_samples=1099511627776 \(1\.1e\+08 s at 10000 Hz\) needs about 4\.26e\+06 GiB"),
    (10**6, r"n_samples=1000000 \(100 s at 10000 Hz\) needs about 3\.87 GiB .* more than the 2 GiB a design window "
            r"may take; the longest window of this layout is 262144 samples"),
    (4097, r"n_samples must be an even integer >= 16, got 4097"),
])
def test_a_window_beyond_the_design_memory_is_refused_before_allocating(n_samples, words):
    """On main 2**40 raised MemoryError, and 10**6 was designed after 32 s at 3.4 GB (128 s here)."""
    from vibrofocus.rigs import SimulatedForearm

    arm = SimulatedForearm(seed=0)
    assert arm.fs == 10_000.0 and (REF.n_points, REF.n_actuators) == (13, 4)
    with pytest.raises(ValidationError, match=words):
        render("inverse", arm, arm.fs, REF, 5, n_samples=n_samples)


def test_the_longest_window_the_cap_admits_designs():
    """2**18 samples (26 s at 10 kHz) on the reference layout: under the cap; twice that is not."""
    from vibrofocus.rendering._checks import H_COPIES, MAX_DESIGN_BYTES, check_window

    n = 2**18
    assert H_COPIES * 16 * (n // 2 + 1) * 13 * 4 <= MAX_DESIGN_BYTES < H_COPIES * 16 * (n + 1) * 13 * 4
    assert check_window(n, 13, 4, 10_000.0) == n
