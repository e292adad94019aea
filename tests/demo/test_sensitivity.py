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


@pytest.mark.slow
def test_documented_sensitivity_table_is_recomputed_by_the_code():
    documented = _documented_rows()
    computed = attenuation_sensitivity()
    assert len(documented) == len(computed) == 4 * len(METHODS)
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


def test_attenuation_ends_bracket_the_nominal_law():
    rows = attenuation_sensitivity(methods=("inverse",), peak_bounds=False)
    alpha = [r["alpha250_np_m"] for r in rows]
    assert [r["law"] for r in rows] == ["low", "nominal", "high", "voigt-fit"]
    assert alpha[0] < alpha[1] < alpha[2] < alpha[3]
    # More attenuation, less of the tap reaches the target for the same design.
    fidelity = np.array([r["fidelity"] for r in rows])
    assert fidelity[0] > fidelity[2] > fidelity[3]


def test_no_method_beats_the_bound_for_its_own_waveform():
    rows = attenuation_sensitivity(methods=("inverse", "contrast"), peak_bounds=False)
    for r in rows:
        assert r["predicted_energy_contrast_db"] <= r["bound_own_db"] + 1e-6, r
