"""wraparound_fraction against impulses through pure-delay media (exact energies)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus.errors import CausalityError, ValidationError
from vibrofocus.rendering import check_wraparound, wraparound_fraction

from ._media import FS, delay_gain_medium


def impulse(n, k, amplitude=1.0):
    x = np.zeros((1, n))
    x[0, k] = amplitude
    return x


@pytest.mark.parametrize("k, delay, expected", [(10, 50, 0.0), (200, 100, 1.0), (255, 1, 1.0), (254, 1, 0.0)])
def test_pure_delay_impulse(k, delay, expected):
    n = 256
    H = delay_gain_medium(n, FS, np.array([[delay]]), np.array([[3.0]]))
    assert_allclose(wraparound_fraction(impulse(n, k), H), expected, atol=1e-6)


def test_two_paths_share_the_energy():
    # Point 0 hears the impulse at once, point 1 after 100 samples: from sample 200 of a
    # 256-sample window, point 1's arrival (amplitude 2, energy 4) falls past the end.
    n = 256
    H = delay_gain_medium(n, FS, np.array([[0], [100]]), np.array([[1.0], [2.0]]))
    assert_allclose(wraparound_fraction(impulse(n, 200), H), 4 / 5, rtol=1e-6)
    assert_allclose(wraparound_fraction(impulse(n, 100), H), 0.0, atol=1e-6)


def test_silence_is_not_wrapped():
    n = 64
    H = delay_gain_medium(n, FS, np.array([[3]]), np.array([[1.0]]))
    assert wraparound_fraction(np.zeros((1, n)), H) == 0.0


def test_chunked_points_equal_unchunked(monkeypatch, rng):
    import vibrofocus.rendering.causality as causality

    n = 128
    H = delay_gain_medium(n, FS, rng.uniform(0, 200, (7, 3)), rng.uniform(0.5, 2, (7, 3)))
    drives = rng.standard_normal((3, n))
    whole = wraparound_fraction(drives, H)
    monkeypatch.setattr(causality, "_CHUNK_BYTES", 1)  # one point per chunk
    assert_allclose(wraparound_fraction(drives, H), whole, rtol=1e-6)
    assert 0.2 < whole < 0.9  # random drives through long delays do spill


def test_check_raises_warns_and_validates():
    n = 256
    H = delay_gain_medium(n, FS, np.array([[100]]), np.array([[1.0]]))
    with pytest.raises(CausalityError, match="256 samples is too short"):
        check_wraparound(impulse(n, 200), H)
    with pytest.warns(UserWarning, match="too short"):
        assert check_wraparound(impulse(n, 200), H, action="warn") == pytest.approx(1.0)
    assert check_wraparound(impulse(n, 10), H) == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValidationError, match="H must have shape"):
        wraparound_fraction(impulse(n, 10), H[:-1])
    with pytest.raises(ValidationError, match="tol must lie in"):
        check_wraparound(impulse(n, 10), H, tol=2.0)
