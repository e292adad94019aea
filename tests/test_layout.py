"""ArrayLayout: the reference geometry (docs/method.md, "Reference setup") and other layouts through the same code."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from vibrofocus import ArrayLayout
from vibrofocus.errors import ValidationError

MM = 1e-3


def test_reference_actuators_and_locations_exactly_as_spec():
    layout = ArrayLayout.reference()
    assert_allclose(layout.actuators_xy, MM * np.array([[-22.5, 22.5], [22.5, 22.5], [-22.5, -22.5], [22.5, -22.5]]),
                    rtol=0, atol=1e-15)
    # Row by row from the wrist side (+y), left to right.
    expected = MM * np.array([[-10, 10], [0, 10], [10, 10], [-10, 0], [0, 0], [10, 0], [-10, -10], [0, -10], [10, -10]])
    assert_allclose(layout.locations_xy, expected, rtol=0, atol=1e-15)
    assert layout.spacing_xy == pytest.approx((45 * MM, 45 * MM))
    assert layout.actuator_names == ("A1", "A2", "A3", "A4")
    assert layout.point_labels == ("1", "2", "3", "4", "5", "6", "7", "8", "9", "G1", "G2", "G3", "G4")


def test_reference_guards_9_mm_toward_the_origin():
    layout = ArrayLayout.reference()
    offset = layout.actuators_xy - layout.guards_xy
    assert_allclose(np.linalg.norm(offset, axis=1), 9 * MM, rtol=1e-12)  # outside the 14 mm exciter
    # Pointing from the actuator to the origin: parallel to the actuator's position.
    unit = layout.actuators_xy / np.linalg.norm(layout.actuators_xy, axis=1, keepdims=True)
    assert_allclose(offset / (9 * MM), unit, rtol=1e-12)
    assert np.all(np.linalg.norm(layout.guards_xy, axis=1) < np.linalg.norm(layout.actuators_xy, axis=1))
    assert_array_equal(layout.guard_indices, [9, 10, 11, 12])
    assert_allclose(layout.points_xy[9:], layout.guards_xy)


def test_location_index_and_bad_locations():
    layout = ArrayLayout.reference()
    assert [layout.location_index(k) for k in (1, 5, 9)] == [0, 4, 8]
    with pytest.raises(ValidationError, match="location 0 is outside the layout's locations 1..9"):
        layout.location_index(0)
    with pytest.raises(ValidationError, match="location 10 is outside"):
        layout.location_index(10)
    with pytest.raises(ValidationError, match="location must be an integer"):
        layout.location_index("5")


def test_sleeve_of_32_actuators():
    sleeve = ArrayLayout.sleeve()
    assert sleeve.n_actuators == 32 and sleeve.n_locations == 108 and sleeve.n_guards == 0
    assert_allclose(sleeve.spacing_xy, (0.21 / 8, 0.045))
    # Inferred spacing agrees with the declared one.
    inferred = ArrayLayout(sleeve.actuators_xy, sleeve.locations_xy)
    assert_allclose(inferred.spacing_xy, sleeve.spacing_xy, rtol=1e-9)
    # Centred, rows from +y down, each row from -x to +x.
    assert_allclose(sleeve.actuators_xy.mean(axis=0), 0, atol=1e-15)
    assert sleeve.actuators_xy[0, 1] > sleeve.actuators_xy[-1, 1]
    assert sleeve.actuators_xy[0, 0] < sleeve.actuators_xy[1, 0]


def test_round_trip_and_equality():
    layout = ArrayLayout.grid((3, 2), 0.03, (4, 4), 0.01, guard_offset_m=0.005)
    again = ArrayLayout.from_dict(layout.to_dict())
    assert again == layout
    assert again.guard_names == layout.guard_names
    with pytest.raises(ValidationError, match="lacks the key 'actuators_xy'"):
        ArrayLayout.from_dict({"locations_xy": [[0, 0]]})


def test_arrays_are_read_only():
    layout = ArrayLayout.reference()
    with pytest.raises(ValueError):
        layout.actuators_xy[0, 0] = 1.0


def test_bad_layouts():
    with pytest.raises(ValidationError, match="actuators_xy must hold at least one actuator"):
        ArrayLayout(np.zeros((0, 2)), np.zeros((1, 2)))
    with pytest.raises(ValidationError, match="two actuators at the same position"):
        ArrayLayout(np.zeros((2, 2)), np.zeros((1, 2)))
    with pytest.raises(ValidationError, match="locations_xy must have shape"):
        ArrayLayout(np.eye(2), np.zeros((3, 3)))
    with pytest.raises(ValidationError, match="actuators_xy contains 1 non-finite"):
        ArrayLayout(np.array([[0.0, np.nan], [1.0, 1.0]]), np.zeros((1, 2)))
    with pytest.raises(ValidationError, match="actuator_names has 1 names for 2 actuators"):
        ArrayLayout(np.eye(2), np.zeros((1, 2)), actuator_names=("X",))
    with pytest.raises(ValidationError, match="spacing_xy must be > 0"):
        ArrayLayout(np.eye(2), np.zeros((1, 2)), spacing_xy=(0.0, 1.0))
