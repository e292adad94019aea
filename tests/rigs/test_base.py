"""The final public methods of Rig leave every output at zero, whatever happens; checked
with the simulated forearm as backend."""

import numpy as np
import pytest

from vibrofocus import SimulatedForearm
from vibrofocus.errors import ValidationError


class _FailingForearm(SimulatedForearm):
    """Fails half-way through playback, with the outputs live."""

    def __init__(self, exc: BaseException, **kwargs):
        super().__init__(noise_m=0.0, dropout_rate=0.0, **kwargs)
        self.exc = exc
        self.outputs_when_failing = None

    def _play(self, drive):
        super()._play(drive)
        self.outputs_v = drive[:, drive.shape[1] // 2].copy()  # mid-drive voltages
        self.outputs_when_failing = self.outputs_v.copy()
        raise self.exc

    def _play_and_record(self, drive, points_xy, n_tail):
        self._play(drive)


def _drive():
    drive = np.zeros((4, 400))
    drive[:, 150:250] = 3.0
    return drive


@pytest.mark.parametrize("exc", [RuntimeError("device lost"), KeyboardInterrupt()])
@pytest.mark.parametrize("how", ["play", "play_and_record"])
def test_error_during_playback_leaves_zero_outputs(exc, how):
    rig = _FailingForearm(exc)
    with pytest.raises(type(exc)):
        getattr(rig, how)(_drive())
    assert np.abs(rig.outputs_when_failing).max() > 0  # the failure happened with outputs live
    np.testing.assert_array_equal(rig.outputs_v, 0.0)


def test_normal_playback_ends_at_zero_and_stop_zeroes():
    rig = SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)
    drive = np.ones((4, 300))  # holds 1 V until the fade; the backend keeps the last value
    rig.play(drive)
    np.testing.assert_array_equal(rig.outputs_v, 0.0)
    rig.outputs_v = np.full(4, 2.0)  # as if stuck mid-drive
    rig.stop()
    np.testing.assert_array_equal(rig.outputs_v, 0.0)
    with rig:
        pass
    np.testing.assert_array_equal(rig.outputs_v, 0.0)


def test_recording_shape_and_tail():
    rig = SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)
    out = rig.play_and_record(_drive(), np.zeros((3, 2)), tail_s=0.01)
    assert out.shape == (3, 400 + 100)
    assert rig.play_and_record(_drive()).shape == (rig.layout.n_points, 400 + 500)


def test_single_spot_rig_refuses_several_points():
    class SingleSpot(SimulatedForearm):
        max_points_per_recording = 1

    rig = SingleSpot(seed=0)
    with pytest.raises(ValidationError, match="one at a time"):
        rig.play_and_record(_drive(), np.zeros((2, 2)))
    assert rig.n_played == 0


def test_describe_is_json_ready():
    import json

    desc = SimulatedForearm(seed=4).describe()
    assert desc["kind"] == "simulated" and desc["seed"] == 4
    assert json.loads(json.dumps(desc))["participant"]["seed"] == 4
