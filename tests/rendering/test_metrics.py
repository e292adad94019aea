"""focus_metrics on waveforms whose metrics are known analytically."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad

from vibrofocus import focus_metrics, ricker
from vibrofocus.errors import ValidationError

FS, N, SIGMA = 10_000.0, 4096, 1e-3


def test_perfect_focus():
    desired = 2e-6 * ricker(FS, SIGMA, N / FS)
    response = np.stack([0.5 * desired, desired, -0.25 * desired])
    drives = np.array([np.linspace(-3, 7.5, N)])
    m = focus_metrics(response, 1, desired, FS, drives=drives)
    assert_allclose(m["fidelity"], 1.0, rtol=1e-12)
    assert_allclose(m["contrast_db"], 20 * np.log10(2), rtol=1e-12)
    assert_allclose(m["target_peak_m"], 2e-6, rtol=1e-12)
    assert_allclose(m["peak_drive_v"], 7.5, rtol=1e-12)
    assert_allclose(m["timing_error_s"], 0.0, atol=1 / FS)
    assert_allclose(m["relative_error"], 0.0, atol=1e-12)
    assert m["compactness"] > 0.85


def test_compactness_is_the_energy_share_within_two_sigma():
    # sigma = 20.5 samples / 2: the window t0 +- 2 sigma ends half-way between samples, so
    # the sampled energy sum is a midpoint rule of the integral over exactly +-2 sigma.
    sigma = 20.5 / FS / 2
    desired = ricker(FS, sigma, N / FS)
    energy = lambda x: ((1 - x**2) * np.exp(-x**2 / 2)) ** 2  # noqa: E731  (x = tau / sigma)
    share = quad(energy, -2, 2)[0] / quad(energy, -np.inf, np.inf)[0]
    m = focus_metrics(desired[None], 0, desired, FS, sigma=sigma, t0=N / 2 / FS)
    assert_allclose(m["compactness"], share, rtol=2e-3)


def test_inverted_and_delayed():
    desired = ricker(FS, SIGMA, N / FS)
    assert_allclose(focus_metrics(-desired[None], 0, desired, FS)["fidelity"], -1.0, rtol=1e-12)
    late = np.roll(desired, int(20 * SIGMA * FS))  # 20 sigma late: no overlap, no compactness
    m = focus_metrics(late[None], 0, desired, FS)
    assert abs(m["fidelity"]) < 1e-12
    assert m["compactness"] < 1e-12
    assert_allclose(m["timing_error_s"], 20 * SIGMA, rtol=1e-9)
    assert np.isnan(m["peak_drive_v"])
    assert np.isnan(m["contrast_db"])  # a single point has nothing to contrast with


def test_shape_fidelity_finds_a_late_copy_and_its_lag():
    desired = ricker(FS, SIGMA, N / FS)
    delay = 97  # samples
    late = 0.3 * np.roll(desired, delay)
    m = focus_metrics(late[None], 0, desired, FS)
    assert abs(m["fidelity"]) < 0.05  # zero lag barely overlaps a copy 9.7 sigma late
    assert_allclose(m["shape_fidelity"], 1.0, rtol=1e-9)
    assert_allclose(m["shape_lag_s"], delay / FS, rtol=1e-12)
    # A different shape stays below 1 at every lag: the Ricker's derivative is orthogonal
    # to it at zero lag and still unlike it at its best lag.
    other = np.gradient(desired)
    assert focus_metrics(other[None], 0, desired, FS)["shape_fidelity"] < 0.9


def test_a_recording_with_a_decay_tail_is_compared_with_the_padded_design():
    desired = ricker(FS, SIGMA, N / FS)
    tail = 500
    recorded = np.concatenate([desired, np.zeros(tail)])[None]
    m = focus_metrics(recorded, 0, desired, FS, drives=np.ones((2, N)))
    assert_allclose(m["fidelity"], 1.0, rtol=1e-12)
    with pytest.raises(ValidationError, match="desired has 4096 samples, more than the 4000"):
        focus_metrics(recorded[:, :4000], 0, desired, FS)


def test_fidelity_is_scale_invariant_and_band_option_filters_desired():
    desired = ricker(FS, SIGMA, N / FS, form="printed")  # non-zero mean: DC removed by the band
    band_limited = focus_metrics(desired[None] * 3, 0, desired, FS, band=(10, 1000))
    raw = focus_metrics(desired[None] * 3, 0, desired, FS)
    assert_allclose(raw["fidelity"], 1.0, rtol=1e-12)
    assert band_limited["fidelity"] < 1.0 - 1e-4


def test_contrast_edge_cases_and_compare_indices():
    desired = ricker(FS, SIGMA, N / FS)
    quiet = np.stack([desired, np.zeros(N)])
    assert focus_metrics(quiet, 0, desired, FS)["contrast_db"] == np.inf
    loud_guard = np.stack([desired, 0.5 * desired, 4 * desired])
    assert_allclose(focus_metrics(loud_guard, 0, desired, FS, compare_indices=[0, 1])["contrast_db"],
                    20 * np.log10(2), rtol=1e-12)
    assert_allclose(focus_metrics(loud_guard, 0, desired, FS)["contrast_db"], -20 * np.log10(4), rtol=1e-12)
    silent = focus_metrics(np.zeros((2, N)), 0, desired, FS)
    assert np.isnan(silent["fidelity"]) and np.isnan(silent["compactness"])


def test_bad_input():
    desired = ricker(FS, SIGMA, N / FS)
    with pytest.raises(ValidationError, match="target_index=3 is outside the 2 points"):
        focus_metrics(np.zeros((2, N)), 3, desired, FS)
    with pytest.raises(ValidationError, match="desired has 4096 samples, more than the 4095"):
        focus_metrics(np.zeros((2, N - 1)), 0, desired, FS)
    with pytest.raises(ValidationError, match="desired must have 1 dimension"):
        focus_metrics(np.zeros((2, N)), 0, desired[None], FS)
    with pytest.raises(ValidationError, match="response contains"):
        focus_metrics(np.full((2, N), np.nan), 0, desired, FS)
    with pytest.raises(ValidationError, match="drives must have 4096 samples"):
        focus_metrics(np.zeros((2, N)), 0, desired, FS, drives=np.zeros((4, 10)))
    with pytest.raises(ValidationError, match="band must satisfy"):
        focus_metrics(np.zeros((2, N)), 0, desired, FS, band=(10, 9000))


def test_an_empty_compare_list_gives_nan_contrast_not_an_index_error():
    desired = ricker(FS, SIGMA, N / FS)
    response = np.stack([desired, 0.5 * desired])
    m = focus_metrics(response, 0, desired, FS, compare_indices=[])
    assert np.isnan(m["contrast_db"])
    assert_allclose(m["fidelity"], 1.0, rtol=1e-12)
    # Only the target listed: nothing left to compare with.
    assert np.isnan(focus_metrics(response, 0, desired, FS, compare_indices=[0])["contrast_db"])


def test_an_empty_desired_waveform_is_refused():
    desired = ricker(FS, SIGMA, N / FS)
    with pytest.raises(ValidationError, match="desired"):
        focus_metrics(np.stack([desired, desired]), 0, np.zeros(0), FS)


@pytest.mark.parametrize("t0", [-0.01, N / FS + 0.01])
def test_t0_outside_the_response_is_refused(t0):
    desired = ricker(FS, SIGMA, N / FS)
    with pytest.raises(ValidationError, match="t0"):
        focus_metrics(np.stack([desired, desired]), 0, desired, FS, t0=t0)


def test_a_recording_with_dropouts_gets_an_actionable_message():
    # SimulatedForearm and hardware rigs mark vibrometer dropouts as NaN runs; the
    # message must say what they are and what to do (repeat), not just "non-finite".
    desired = ricker(FS, SIGMA, N / FS)
    rec = np.stack([desired, desired])
    rec[1, 100:110] = np.nan
    with pytest.raises(ValidationError, match=r"response.*10 NaN.*point\(s\) 1:.*dropout.*repeat"):
        focus_metrics(rec, 0, desired, FS)
