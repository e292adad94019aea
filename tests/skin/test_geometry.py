"""Tests of the forearm surface geometry."""

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.skin import ForearmGeometry


def test_plane_path_lengths_are_euclidean(rng):
    geo = ForearmGeometry(kind="plane")
    p = rng.uniform(-0.05, 0.05, (7, 2))
    s = rng.uniform(-0.05, 0.05, (3, 2))
    d = geo.path_lengths(p, s)
    assert d.shape == (7, 3, 1)
    np.testing.assert_allclose(d[..., 0], np.linalg.norm(p[:, None] - s[None], axis=2), rtol=1e-12)


def test_cylinder_images_at_one_level_are_shifted_by_the_circumference():
    geo = ForearmGeometry(n_images=2)
    c = float(geo.circumference(0.0))
    d = geo.path_lengths(np.array([[0.03, 0.0]]), np.array([[-0.01, 0.0]]))[0, 0]
    np.testing.assert_allclose(d, np.abs(0.04 + np.arange(-2, 3) * c), rtol=1e-12)


def test_circumference_tapers_from_elbow_to_wrist():
    geo = ForearmGeometry()
    np.testing.assert_allclose(geo.circumference([-0.125, 0.0, 0.125]), [0.25, 0.21, 0.17], rtol=1e-12)


def test_path_lengths_are_symmetric(rng):
    geo = ForearmGeometry()
    a = rng.uniform(-0.06, 0.06, (5, 2))
    b = rng.uniform(-0.06, 0.06, (4, 2))
    # Swapping ends turns a path m times around one way into one -m times around.
    swapped = np.swapaxes(geo.path_lengths(b, a), 0, 1)[..., ::-1]
    np.testing.assert_allclose(geo.path_lengths(a, b), swapped, rtol=1e-12)


def test_surface_points_lie_on_the_arm_and_paths_beat_chords(rng):
    geo = ForearmGeometry()
    p = rng.uniform(-0.08, 0.08, (50, 2))
    xyz = geo.to_3d(p)
    radius = np.hypot(xyz[:, 0], xyz[:, 2])
    np.testing.assert_allclose(radius, geo.circumference(p[:, 1]) / (2 * np.pi), rtol=1e-12)
    # No path over the surface is shorter than the straight line through the arm.
    shortest = geo.path_lengths(p, p).min(axis=2)
    chord = np.linalg.norm(xyz[:, None] - xyz[None], axis=2)
    assert np.all(shortest >= chord - 1e-12)


def test_far_side_chord_is_the_diameter():
    geo = ForearmGeometry()
    c = float(geo.circumference(0.0))
    xyz = geo.to_3d(np.array([[0.0, 0.0], [c / 2, 0.0]]))
    np.testing.assert_allclose(np.linalg.norm(xyz[1] - xyz[0]), c / np.pi, rtol=1e-12)


@pytest.mark.parametrize("kwargs, word", [({"kind": "torus"}, "geometry"), ({"n_images": -1}, "n_images")])
def test_bad_geometry_is_refused(kwargs, word):
    with pytest.raises(ValidationError, match=word):
        ForearmGeometry(**kwargs)
