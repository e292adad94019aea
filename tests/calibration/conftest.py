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


@pytest.fixture(scope="module")
def fir_calibration(layout, firs):
    """A quick noise-free h1 calibration of the FIR rig (2 repeats of a 1 s sweep)."""
    rig = FIRRig(firs, layout)
    return rig, calibrate(rig, participant_id="FIR", method="h1", sweep_s=1.0, repeats=2)


@pytest.fixture(scope="module")
def forearm_calibration():
    """The default (mimo) calibration of simulated participant 0 (noise and dropouts on),
    on the voigt-fit skin, for the tests of fit_model's homogeneous law (an arm of that
    family; test_fit_model_layered.py tests the layered law on the nominal skin)."""
    from vibrofocus.skin import SimulatedForearm

    rig = SimulatedForearm(seed=0, skin="voigt-fit")
    return rig, calibrate(rig, participant_id="S00")
