"""The sensitivity table documented in docs/skin-model.md is what the code computes."""

from pathlib import Path

import numpy as np
import pytest

from vibrofocus.defaults import METHODS
from vibrofocus.demo.sensitivity import attenuation_sensitivity

PAGE = Path(__file__).resolve().parents[2] / "docs" / "skin-model.md"


def _documented_rows() -> list[list[str]]:
    text = PAGE.read_text(encoding="utf-8")
    table = text.split("<!-- sensitivity-table:start -->", 1)[1].split("<!-- sensitivity-table:end -->", 1)[0]
    lines = [line for line in table.strip().splitlines()[2:] if line.startswith("|")]
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in lines]


SKINS = ("low", "nominal", "high", "voigt-fit")


def test_the_documented_table_has_every_skin_and_method_in_order():
    documented = _documented_rows()
    assert [(doc[0], doc[3]) for doc in documented] == [(skin, method) for skin in SKINS for method in METHODS]


# A skin at a time (its rows do not depend on the others'): four tests of 15-45 s that two
# workers share, not one of three minutes at the end of the slow phase.
@pytest.mark.slow
@pytest.mark.parametrize("skin", SKINS)
def test_documented_sensitivity_table_is_recomputed_by_the_code(skin):
    documented = [doc for doc in _documented_rows() if doc[0] == skin]
    computed = attenuation_sensitivity(skins=[skin])
    assert len(documented) == len(computed) == len(METHODS)
    for doc, row in zip(documented, computed):
        assert doc[0] == row["law"] and doc[3] == row["method"]
        # each printed number equals the computed one to its printed precision
        for cell, value, half_unit in (
            (doc[1], row["c250_m_s"], 0.005), (doc[2], row["alpha250_np_m"], 0.5),
            (doc[4], row["fidelity"], 0.005), (doc[5], row["contrast_db"], 0.05),
            (doc[6], row["contrast_all_points_db"], 0.05), (doc[7], row["predicted_energy_contrast_db"], 0.05),
            (doc[8], row["bound_own_db"], 0.05), (doc[9], row["bound_db"], 0.05),
            (doc[10], row["peak_bound_db"], 0.05), (doc[11], 1e6 * row["target_peak_m"], 0.0005),
        ):
            assert abs(float(cell) - value) <= half_unit * 1.001 + 1e-12, (doc, row)


@pytest.fixture(scope="module")
def two_methods():
    """The inverse and contrast rows of every skin, without peak bounds (made once: a run per skin)."""
    return attenuation_sensitivity(methods=("inverse", "contrast"), peak_bounds=False)


def test_attenuation_ends_bracket_the_nominal_law(two_methods):
    rows = [r for r in two_methods if r["method"] == "inverse"]
    alpha = [r["alpha250_np_m"] for r in rows]
    assert [r["law"] for r in rows] == ["low", "nominal", "high", "voigt-fit"]
    assert alpha[0] < alpha[1] < alpha[2] < alpha[3]
    # More attenuation, less of the tap reaches the target for the same design.
    fidelity = np.array([r["fidelity"] for r in rows])
    assert fidelity[0] > fidelity[2] > fidelity[3]


def test_no_method_beats_the_bound_for_its_own_waveform(two_methods):
    assert [r["method"] for r in two_methods] == ["inverse", "contrast"] * 4
    for r in two_methods:
        assert r["predicted_energy_contrast_db"] <= r["bound_own_db"] + 1e-6, r


def test_skins_are_presets_chosen_without_laws():
    from vibrofocus.errors import ValidationError
    from vibrofocus.skin.parameters import NOMINAL_LAW

    with pytest.raises(ValidationError, match="skins must be among low, nominal, high, voigt-fit, got rubber"):
        attenuation_sensitivity(skins=["rubber"])
    with pytest.raises(ValidationError, match="without laws"):
        attenuation_sensitivity({"n": NOMINAL_LAW}, skins=["low"])
