"""An interrupted calibration keeps its completed points, and --resume continues from them."""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus import ArrayLayout
from vibrofocus.calibration import calibrate
from vibrofocus.calibration.checkpoint import partial_path
from vibrofocus.errors import CalibrationFileError

from .firrig import FIRRig, analytic_firs

FS = 10_000.0


class _PowerCut(Exception):
    pass


@pytest.fixture
def firs():
    return analytic_firs(ArrayLayout.reference(), FS, length=512)


def _rig(firs, fail_at=None):
    rig = FIRRig(firs, ArrayLayout.reference(), single_spot=True)
    if fail_at is not None:
        real = rig._play_and_record

        def play_and_record(drive, points_xy, n_tail):
            if rig.n_recordings == fail_at:
                raise _PowerCut("the lab lost power")
            return real(drive, points_xy, n_tail)

        rig._play_and_record = play_and_record
    return rig


@pytest.mark.parametrize("method, repeats", [("mimo", 4), ("h1", 2)])
def test_resume_measures_only_the_missing_points_and_gives_the_same_h(tmp_path, firs, method, repeats):
    options = dict(participant_id="P01", method=method, repeats=repeats, sweep_s=0.3)
    per_point = repeats * (1 if method == "mimo" else 4)
    whole = _rig(firs)
    reference = calibrate(whole, prompt=whole.aim, **options)

    partial = partial_path(tmp_path / "P01.nc")
    cut = _rig(firs, fail_at=3 * per_point + 1)  # in the middle of the 4th point
    with pytest.raises(_PowerCut):
        calibrate(cut, prompt=cut.aim, checkpoint=partial, **options)
    assert partial.exists()

    again = _rig(firs)
    steps = []
    cal = calibrate(again, prompt=again.aim, checkpoint=partial, resume=True,
                    progress=lambda done, total, msg: steps.append((done, total, msg)), **options)
    n_points = ArrayLayout.reference().n_points
    assert again.n_recordings == (n_points - 3) * per_point  # three points kept, not measured again
    assert sum("kept from the partial file" in m for _, _, m in steps) == 3
    assert steps[-1][0] == steps[-1][1] == n_points * per_point
    np.testing.assert_allclose(cal.H, reference.H, rtol=1e-6, atol=1e-6 * np.abs(reference.H).max())
    assert cal.recorded_s == pytest.approx(reference.recorded_s)


def test_a_partial_file_is_never_overwritten_or_mixed_with_another_plan(tmp_path, firs):
    partial = partial_path(tmp_path / "P01.nc")
    cut = _rig(firs, fail_at=5)
    options = dict(participant_id="P01", method="mimo", repeats=4, sweep_s=0.3)
    with pytest.raises(_PowerCut):
        calibrate(cut, prompt=cut.aim, checkpoint=partial, **options)
    before = partial.read_bytes()
    rig = _rig(firs)
    with pytest.raises(CalibrationFileError, match="continue it with --resume"):
        calibrate(rig, prompt=rig.aim, checkpoint=partial, **options)
    with pytest.raises(CalibrationFileError, match="another plan or rig"):
        calibrate(rig, prompt=rig.aim, checkpoint=partial, resume=True, **{**options, "sweep_s": 0.4})
    with pytest.raises(CalibrationFileError, match="another plan or rig"):
        calibrate(rig, prompt=rig.aim, checkpoint=partial, resume=True, **{**options, "participant_id": "P02"})
    assert rig.n_recordings == 0
    assert partial.read_bytes() == before
