"""Funneling gains: bilinear and energy laws."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose

from vibrofocus import ArrayLayout
from vibrofocus.rendering import funneling_gains
from vibrofocus.errors import ValidationError
from vibrofocus.rendering import funneling_weights

REF = ArrayLayout.reference()
SLEEVE = ArrayLayout.sleeve()


@pytest.mark.parametrize("layout", [REF, SLEEVE], ids=["reference", "sleeve"])
@pytest.mark.parametrize("law", ["linear", "energy"])
def test_at_an_actuator_only_that_actuator_plays(layout, law):
    for q, xy in enumerate(layout.actuators_xy):
        gains = funneling_gains(layout.actuators_xy, xy, amplitude=7.0, law=law)
        expected = np.zeros(layout.n_actuators)
        expected[q] = 7.0
        assert_allclose(gains, expected, atol=1e-12)


def test_reference_centre_and_location_1_by_hand():
    # Centre: every actuator 22.5 mm from it on both axes: w = 0.5 * 0.5.
    assert_allclose(funneling_gains(REF.actuators_xy, [0.0, 0.0]), [2.5, 2.5, 2.5, 2.5], rtol=1e-12)
    # Location 1 at (-10, +10) mm; A1 at (-22.5, +22.5): d = 12.5 mm on both axes.
    near = 1 - 12.5 / 45
    far = 1 - 32.5 / 45
    expected = 10 * np.array([near * near, far * near, near * far, far * far])
    assert_allclose(funneling_gains(REF.actuators_xy, REF.locations_xy[0]), expected, rtol=1e-12)
    assert_allclose(funneling_gains(REF.actuators_xy, REF.locations_xy[0], law="energy"), 10 * np.sqrt(expected / 10),
                    rtol=1e-12)


def _inside(layout):
    lo, hi = layout.actuators_xy.min(axis=0), layout.actuators_xy.max(axis=0)
    return st.tuples(st.floats(0, 1), st.floats(0, 1)).map(lambda u: lo + np.array(u) * (hi - lo))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(point=_inside(REF), amplitude=st.floats(0.1, 20))
def test_linear_weights_sum_to_amplitude_inside_reference(point, amplitude):
    assert_allclose(funneling_gains(REF.actuators_xy, point, amplitude).sum(), amplitude, rtol=1e-12)
    energy = funneling_gains(REF.actuators_xy, point, amplitude, law="energy")
    assert_allclose(np.sum(energy**2), amplitude**2, rtol=1e-12)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(point=_inside(SLEEVE))
def test_sleeve_laws_hold_and_at_most_four_actuators_play(point):
    gains = funneling_gains(SLEEVE.actuators_xy, point, 10.0, spacing_xy=SLEEVE.spacing_xy)
    assert_allclose(gains.sum(), 10.0, rtol=1e-12)
    assert np.count_nonzero(gains) <= 4
    energy = funneling_gains(SLEEVE.actuators_xy, point, 10.0, law="energy", spacing_xy=SLEEVE.spacing_xy)
    assert_allclose(np.sum(energy**2), 100.0, rtol=1e-12)


def test_spacing_inferred_like_layout():
    act = SLEEVE.actuators_xy
    point = np.array([0.004, -0.01])
    assert_allclose(funneling_gains(act, point), funneling_gains(act, point, spacing_xy=SLEEVE.spacing_xy), rtol=1e-12)


def test_weights_clip_beyond_one_spacing():
    # A point just outside the array: the two far actuators are more than one spacing away.
    w = funneling_weights(REF.actuators_xy, [-0.03, 0.0])
    assert w[1] == 0 and w[3] == 0
    assert 0 < w.sum() < 1


def test_bad_input():
    with pytest.raises(ValidationError, match="law must be one of"):
        funneling_gains(REF.actuators_xy, [0, 0], law="cubic")
    with pytest.raises(ValidationError, match="target_xy must have shape"):
        funneling_gains(REF.actuators_xy, [0, 0, 0])
    with pytest.raises(ValidationError, match="target_xy contains 1 non-finite"):
        funneling_gains(REF.actuators_xy, [np.nan, 0])
    with pytest.raises(ValidationError, match="one spacing or more from every actuator"):
        funneling_gains(REF.actuators_xy, [1.0, 1.0])
    with pytest.raises(ValidationError, match="actuators_xy must have shape"):
        funneling_gains(np.zeros((4, 3)), [0, 0])
    with pytest.raises(ValidationError, match="amplitude must be >= 0"):
        funneling_gains(REF.actuators_xy, [0, 0], amplitude=-1)
    with pytest.raises(ValidationError, match="spacing_xy must be > 0"):
        funneling_gains(REF.actuators_xy, [0, 0], spacing_xy=(0.0, 0.045))
