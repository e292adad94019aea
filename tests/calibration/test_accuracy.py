"""Tests of the transfer-matrix accuracy measure."""

import numpy as np
import pytest

from vibrofocus.calibration import transfer_error
from vibrofocus.errors import ValidationError


def test_error_counts_only_bins_within_the_dynamic_range(rng):
    f = np.linspace(10, 1000, 100)
    truth = np.exp(-f / 100.0)[:, None, None] * np.ones((1, 2, 3))  # falls 86 dB over the band
    measured = truth * (1 + 0.03 * np.exp(2j * np.pi * rng.uniform(size=truth.shape)))
    # Beyond 40 dB the estimate is noise: 100 % wrong.
    weak = np.abs(truth) < np.abs(truth).max(axis=0) * 1e-2
    measured[weak] = 0.0
    out = transfer_error(measured, truth, dynamic_range_db=40.0)
    np.testing.assert_allclose(out["median_relative_error"], 0.03, rtol=1e-9)
    np.testing.assert_allclose(out["coverage"], np.mean(~weak), rtol=1e-12)
    # Counting every bin would report the noise.
    assert transfer_error(measured, truth, dynamic_range_db=200.0)["median_relative_error"] > 0.5


def test_shape_mismatch_and_zero_truth_are_refused():
    with pytest.raises(ValidationError, match="truth"):
        transfer_error(np.ones((3, 2, 2)), np.ones((3, 2, 1)))
    with pytest.raises(ValidationError, match="zero"):
        transfer_error(np.ones((3, 2, 2)), np.zeros((3, 2, 2)))
