"""render gives the drives saved before the methods became objects (issue 28).

``tests/rendering/data/reference_designs.npz`` holds the drives of every built-in method,
rendered by the former single ``render`` function (``scripts/save_reference_designs.py``, i.e.
``vibrofocus_tools.reference_designs``,
run on that code) on a seeded simulated calibration. Each case is rendered again here,
through the string API, the method objects and a user-built ``TransferMatrix``.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import TransferMatrix, render
from vibrofocus.defaults import METHODS
from vibrofocus.rendering import make_method

import vibrofocus_tools.reference_designs as saved

DATA = Path(__file__).with_name("data") / "reference_designs.npz"

# Relative to each design's peak drive.
RTOL = 1e-12
# The exact-target designs (the combination, inverse-exact) solve a constrained system whose
# rounding follows the LAPACK build: with numpy 2.4.6 and scipy 1.17.1 (OpenBLAS) they differ
# from the file by 1.5e-9 (inverse-exact) and 6.2e-10 (combination) of their peak, the same
# with one thread or two; every other design stays within 1e-12.
RTOL_EXACT_TARGET = 1e-8
EXACT_TARGET = ("combination", "inverse-exact")


@pytest.fixture(scope="module")
def stored():
    with np.load(DATA) as data:
        return json.loads(str(data["meta"])), {k: data[k] for k in data.files if k != "meta"}


@pytest.fixture(scope="module")
def cal():
    return saved.simulated_calibration()


def same(drives, reference, method):
    assert drives.shape == reference.shape
    rtol = RTOL_EXACT_TARGET if method in EXACT_TARGET else RTOL
    assert_allclose(drives, reference, rtol=0, atol=rtol * np.abs(reference).max())


def test_the_file_holds_every_method_at_every_location(stored):
    meta, designs = stored
    for location in meta["locations"]:
        for method in METHODS:
            assert f"calibration/{method}/{location}" in designs
    assert meta["n_samples"] == saved.N_SAMPLES


def test_render_reproduces_the_saved_drives(stored, cal):
    meta, designs = stored
    now = saved.reference_designs(cal)
    assert sorted(now) == sorted(designs)
    for key, reference in designs.items():
        same(now[key], reference, key.split("/")[1])


@pytest.mark.parametrize("method", METHODS)
def test_method_objects_through_a_built_transfer_matrix_give_the_same_drives(stored, cal, method):
    meta, designs = stored
    H = cal.transfer_for(meta["n_samples"])
    tm = TransferMatrix(H, cal.fs, cal.layout, band=cal.band)
    for location in meta["locations"]:
        same(make_method(method).design(tm, location).drives, designs[f"calibration/{method}/{location}"], method)


def test_a_second_design_reuses_the_kept_operator_and_check(cal):
    tm = TransferMatrix.from_calibration(cal, saved.N_SAMPLES)
    first = render("inverse", tm, cal.fs, cal.layout, 5)
    operators = dict(tm._operators)
    check = tm.wraparound_check()
    second = render("inverse", tm, cal.fs, cal.layout, 5)
    assert tm._operators == operators and tm.wraparound_check() is check
    assert_allclose(second.drives, first.drives, rtol=0, atol=0)
