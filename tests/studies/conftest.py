"""Fixtures of the study tests: one real calibration file, made once (it takes seconds)."""

import pytest


@pytest.fixture(scope="session")
def calibration_file(tmp_path_factory):
    from vibrofocus.calibration import calibrate, save_calibration
    from vibrofocus.rigs import make_rig

    rig = make_rig("simulated", seed=5)
    cal = calibrate(rig, participant_id="p-real")
    path = tmp_path_factory.mktemp("cal") / "p-real.nc"
    save_calibration(cal, path)
    return path
