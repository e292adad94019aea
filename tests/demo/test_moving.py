"""A moving focus: taps along a path from a skin model, animated as a GIF."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import ArrayLayout
from vibrofocus.demo.moving import moving_focus, write_moving_gif
from vibrofocus.errors import ValidationError
from vibrofocus.rigs import SimulatedForearm


@pytest.fixture(scope="module")
def arm():
    return SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)


def test_taps_follow_the_path_at_the_speed(arm):
    lay = ArrayLayout.reference()
    focus = moving_focus(arm, lay, arm.fs, start_xy=(-0.01, 0.0), end_xy=(0.01, 0.0), speed_m_s=0.25,
                         tap_interval_s=0.04)
    # 20 mm at 0.25 m/s: a tap every 10 mm -> 3 taps at x = -10, 0, 10 mm.
    assert_allclose(focus.targets_xy, [[-0.01, 0], [0, 0], [0.01, 0]], atol=1e-12)
    assert_allclose(np.diff(focus.onsets_s), 0.04, atol=1 / arm.fs)
    assert np.abs(focus.drives).max() <= 10.0  # the limit, not one rounding over it
    # The focus moves: at tap k's onset, target k moves more than the other targets.
    u = arm.field(focus.drives, focus.targets_xy, focus.onsets_s)
    assert np.array_equal(np.argmax(np.abs(u), axis=0), np.arange(3))


def test_the_animation_is_a_gif_with_a_frame_per_step(tmp_path, arm):
    from PIL import Image

    lay = ArrayLayout.reference()
    focus = moving_focus(arm, lay, arm.fs, start_xy=(0.0, -0.01), end_xy=(0.0, 0.01), speed_m_s=0.5,
                         tap_interval_s=0.02)
    path = write_moving_gif(focus, arm, tmp_path / "m.gif", n_grid=9, frames_per_tap=2)
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames == 2 * len(focus.targets_xy)
    assert [p.name for p in tmp_path.iterdir()] == ["m.gif"]  # no temporary left behind


def test_bad_paths_are_refused(arm):
    lay = ArrayLayout.reference()
    with pytest.raises(ValidationError, match="same point"):
        moving_focus(arm, lay, arm.fs, start_xy=(0, 0), end_xy=(0, 0))
    with pytest.raises(ValidationError, match="speed_m_s"):
        moving_focus(arm, lay, arm.fs, start_xy=(0, 0), end_xy=(0.01, 0), speed_m_s=0)
