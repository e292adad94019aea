"""Fixtures of the calibration tests: an analytic FIR rig and one simulated calibration."""

import numpy as np
import pytest

from vibrofocus import ArrayLayout
from vibrofocus.calibration import calibrate

from .firrig import FIRRig, analytic_firs


@pytest.fixture(scope="module")
def layout() -> ArrayLayout:
    return ArrayLayout.reference()


@pytest.fixture(scope="module")
def firs(layout) -> np.ndarray:
    return analytic_firs(layout, 10_000.0)


@pytest.fixture(scope="session")
def fir_calibration():
    """A quick noise-free h1 calibration of the FIR rig (2 repeats of a 1 s sweep) on the
    reference layout, made once per test process for the tests that only read it."""
    layout = ArrayLayout.reference()
    rig = FIRRig(analytic_firs(layout, 10_000.0), layout)
    return rig, calibrate(rig, participant_id="FIR", method="h1", sweep_s=1.0, repeats=2)


@pytest.fixture(scope="session")
def fir_calibration_file(fir_calibration, tmp_path_factory):
    """:func:`fir_calibration` saved once per test process, for the tests that only read the
    file (never write to it: copy it, or rewrite it to another path, to edit it)."""
    from vibrofocus.calibration import save_calibration

    return save_calibration(fir_calibration[1], tmp_path_factory.mktemp("fir-cal") / "P01.nc")


@pytest.fixture(scope="session")
def forearm_calibration(simulated_calibration_of):
    """The default (mimo) calibration of simulated participant 0 (noise and dropouts on),
    on the voigt-fit skin, for the tests of fit_model's homogeneous law (an arm of that
    family; test_fit_model_layered.py tests the layered law on the nominal skin). Made once
    per test process (tests/conftest.py)."""
    return simulated_calibration_of("voigt-fit")
