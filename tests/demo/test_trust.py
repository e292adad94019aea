"""The demo's statement of where a calibration can be trusted."""

import numpy as np
import pytest

from vibrofocus.demo import calibration_trust, tap_band


def test_tap_band_brackets_the_ricker_peak():
    low, high = tap_band(1e-3)
    peak = 1 / (np.sqrt(2) * np.pi * 1e-3)  # about 225 Hz
    assert low < peak < high
    # f^2 exp(-(2 pi f sigma)^2 / 2) at the band's ends is 20 dB under the peak
    spec = lambda f: f**2 * np.exp(-((2 * np.pi * f * 1e-3) ** 2) / 2)  # noqa: E731
    # (to the 0.5 Hz grid of tap_band: 3 % near 44 Hz where the spectrum rises as f^2)
    np.testing.assert_allclose([spec(low) / spec(peak), spec(high) / spec(peak)], 0.1, rtol=0.03)


@pytest.mark.parametrize(("skin", "covered"), [("nominal", True), ("voigt-fit", False)])
def test_nominal_calibration_is_coherent_over_the_taps_band(simulated_calibration_of, skin, covered):
    rig, cal = simulated_calibration_of(skin)
    trust = calibration_trust(cal, rig.transfer(rig.layout.points_xy, cal.freqs))
    assert trust["covers_tap_band"] is covered
    assert trust["error_inside"] < 0.02
    if not covered:  # the voigt-fit arm's far paths die out above about 300 Hz
        assert trust["coherent_band_hz"][1] < tap_band()[1] and trust["error_outside"] > 0.1
