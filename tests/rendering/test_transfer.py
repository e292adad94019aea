"""TransferMatrix: validated once, its metadata, its caches, and what makes one."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import ArrayLayout, TransferMatrix, render
from vibrofocus.errors import ValidationError
from vibrofocus.rendering import InverseOperator, WraparoundCheck
from vibrofocus.rendering._checks import as_transfer
from vibrofocus.rendering.transfer import as_transfer_matrix

from ._media import FS, layout_medium

N = 2048
REF = ArrayLayout.reference()


@pytest.fixture(scope="module")
def H():
    return layout_medium(REF, N, FS)


def test_holds_its_grid_layout_band_and_provenance(H):
    tm = TransferMatrix(H, FS, REF, band=(20, 900), provenance={"rig": {"kind": "analytic"}, "participant": "A"})
    assert tm.shape == H.shape and tm.n_points == REF.n_points and tm.n_actuators == REF.n_actuators
    assert tm.n_samples == N and tm.band == (20.0, 900.0)
    assert_allclose(tm.freqs, np.fft.rfftfreq(N, 1 / FS), rtol=0, atol=0)
    assert tm.provenance["participant"] == "A" and tm.coherence is None
    assert "n_points=13" in repr(tm) and "20-900 Hz" in repr(tm)


def test_keeps_a_read_only_copy(H):
    source = H.copy()
    tm = TransferMatrix(source, FS, REF)
    source[:] = 0  # the caller's array stays the caller's
    assert np.abs(tm.H).max() > 0
    with pytest.raises(ValueError):
        tm.H[0, 0, 0] = 1.0


def test_is_validated_once_and_passed_through_unchecked(H):
    tm = TransferMatrix(H, FS, REF)
    assert as_transfer(tm) is tm.H


@pytest.mark.parametrize("bad, message", [
    (lambda H: H[:, :9], r"H must have shape \(n_freqs, 13, 4\)"),
    (lambda H: np.zeros_like(H), "H is all zero"),
    (lambda H: np.where(np.arange(H.size).reshape(H.shape) == 7, np.nan, H), "H contains 1 non-finite"),
])
def test_refuses_a_bad_matrix_when_made(H, bad, message):
    with pytest.raises(ValidationError, match=message):
        TransferMatrix(bad(H), FS, REF)


def test_refuses_a_bad_band_a_bad_window_and_a_bad_layout(H):
    with pytest.raises(ValidationError, match="calibrated_band"):
        TransferMatrix(H, FS, REF, band=(900, 20))
    with pytest.raises(ValidationError, match="n_samples implies n = 4000"):
        TransferMatrix(H, FS, REF, n_samples=4000)
    with pytest.raises(ValidationError, match="layout must be an ArrayLayout"):
        TransferMatrix(H, FS, "reference")


def test_keeps_its_wraparound_check_and_one_operator_per_set_of_options(H):
    tm = TransferMatrix(H, FS, REF)
    check = tm.wraparound_check()
    assert isinstance(check, WraparoundCheck) and tm.wraparound_check() is check and check.H is tm.H
    control = [4, 9, 10, 11, 12]
    op = tm.inverse_operator(control, band=(10, 1000))
    assert tm.inverse_operator(np.array(control), band=(10, 1000)) is op
    assert tm.inverse_operator(control, band=(10, 1000), regularization="tikhonov") is not op
    # The kept operator is the one a user would build on the bare array.
    direct = InverseOperator(H, FS, control=control, band=(10, 1000))
    tap = np.sin(2 * np.pi * 200 * np.arange(N) / FS) * np.hanning(N)
    assert_allclose(op.drives_for_point(4, tap), direct.drives_for_point(4, tap), rtol=1e-12, atol=1e-20)


def test_rows_keep_the_grid_without_a_second_check(H):
    tm = TransferMatrix(H, FS, REF)
    sub = tm.rows([3, 0])
    assert_allclose(sub.H, H[:, [3, 0]], rtol=0, atol=0)
    assert sub.n_samples == N and sub.fs == FS


def test_a_calibration_and_the_simulated_arm_make_one():
    from vibrofocus.calibration import Calibration  # noqa: F401 - the method lives on the class
    from vibrofocus.rigs import SimulatedForearm

    arm = SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)
    tm = arm.transfer_matrix(N)
    assert tm.n_samples == N and tm.layout == arm.layout
    assert tm.provenance["skin"] == arm.skin and tm.provenance["participant"] == 1
    assert_allclose(tm.H, arm.transfer(arm.layout.points_xy, np.fft.rfftfreq(N, 1 / arm.fs)), rtol=0, atol=0)


def test_render_takes_it_and_gives_what_the_array_gives(H):
    tm = TransferMatrix(H, FS, REF)
    for method in ("inverse", "contrast"):
        a = render(method, H, FS, REF, 5)
        b = render(method, tm, FS, REF, 5)
        assert_allclose(b.drives, a.drives, rtol=0, atol=1e-12 * np.abs(a.drives).max())


def test_render_refuses_a_sample_rate_other_than_its_own(H):
    tm = TransferMatrix(H, FS, REF)
    with pytest.raises(ValidationError, match="differs from the transfer matrix's sample rate"):
        as_transfer_matrix(tm, FS / 2, REF)


def test_a_caller_band_narrows_a_kept_one_and_keeps_the_check(H):
    tm = TransferMatrix(H, FS, REF, band=(10, 1000))
    check = tm.wraparound_check()
    narrowed = as_transfer_matrix(tm, FS, REF, calibrated_band=(50, 500))
    assert narrowed.band == (50.0, 500.0) and narrowed.wraparound_check() is check
    with pytest.raises(ValidationError, match=r"reaches outside the calibrated band \(50, 500\)"):
        render("inverse", narrowed, FS, REF, 5)
